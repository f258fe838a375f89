"""Helpers only the tests use (the package ships none): free ports, the interop clients' set-up.

`tests/conftest.py` puts `tests/` on the import path, so a test imports `support.interop`.
"""
