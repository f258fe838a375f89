"""User errors: reported as one line on stderr with exit status 2, never a traceback."""


class UserError(Exception):
    """Something the user can fix: a bad scene file, argument or log."""


class SceneError(UserError):
    """A scene file breaks the scene format (docs/scene-format.md); the message names file, table and key (`key` alone:
    the table path, such as `smoke.regions[room].density`, for answers that name it apart)."""

    def __init__(self, message: str, key: str = "") -> None:
        super().__init__(message)
        self.key = key
