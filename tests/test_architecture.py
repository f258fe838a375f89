"""Imports run down the flow (docs/architecture.md): scene → optics → sensors → protocols → transport.

The check reads every module's imports (top level and inside functions) with
`ast`, maps each module to its room (the first package under `emulator`, or
`protocols`), and compares against what the room's `__init__` docstring says
it may import. A new room must be added to `MAY_IMPORT`, so the map stays the
tree's own description.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FLOW = ("emulator.errors", "emulator.scene", "emulator.optics", "emulator.sensors")
# room → the rooms it may import (its own room always)
MAY_IMPORT: dict[str, set[str]] = {
    "emulator.errors": set(),
    "emulator.scene": {"emulator.errors"},
    "emulator.optics": {"emulator.errors", "emulator.scene"},
    "emulator.sensors": {"emulator.errors", "emulator.scene", "emulator.optics"},
    "protocols": set(),  # sans-I/O: nothing of the emulator
    "emulator.transport": {"emulator.errors", "emulator.scene", "protocols.device"},  # no protocol bytes
    "emulator.recording": {*FLOW},
    "emulator.plots": {*FLOW},
    "emulator.daemon": {*FLOW, "protocols", "emulator.transport", "emulator.recording"},
    "emulator.control": {*FLOW, "protocols", "emulator.transport", "emulator.recording", "emulator.daemon"},
    "emulator.view": {*FLOW, "emulator.recording", "emulator.daemon", "emulator.control"},
    "emulator.validation": {*FLOW, "emulator.plots", "emulator.recording"},
    "emulator.bench": {*FLOW, "protocols", "emulator.transport", "emulator.recording", "emulator.daemon",
                       "emulator.control", "emulator.view", "emulator.plots"},
    "emulator.commands": {*FLOW, "protocols", "emulator.transport", "emulator.recording", "emulator.daemon",
                          "emulator.control", "emulator.view", "emulator.plots", "emulator.validation",
                          "emulator.bench"},
    "emulator.cli": {"emulator.errors", "emulator.commands"},
    "emulator": set(),  # the package's own __init__
}
# sans-I/O: a protocol state machine is bytes and time in, bytes out
NO_IO = {"asyncio", "socket", "os", "select", "selectors", "threading", "subprocess", "serial", "time"}


def room_of(module: str) -> str:
    """`emulator.sensors.physical.beams` → `emulator.sensors`; `protocols.scip.device` → `protocols`."""
    parts = module.split(".")
    return parts[0] if parts[0] == "protocols" else ".".join(parts[:2])


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, module) for every import in the file, relative imports resolved."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found.append((node.lineno, base))
    return found


def _allowed(room: str, target: str) -> bool:
    if room_of(target) == room:
        return True
    return any(target == allowed or target.startswith(allowed + ".") for allowed in MAY_IMPORT[room])


def violations(root: Path) -> list[str]:
    """Every import under `root`'s `emulator/` and `protocols/` that runs against the flow."""
    problems = []
    for path in sorted([*root.glob("emulator/**/*.py"), *root.glob("protocols/**/*.py")]):
        module = _module_name(path, root)
        room = room_of(module)
        if room not in MAY_IMPORT:
            problems.append(f"{path.relative_to(root)}: room {room} is not in the import map")
            continue
        for line, target in imported_modules(path, module):
            where = f"{path.relative_to(root)}:{line}"
            if room == "protocols" and target.split(".")[0] in NO_IO:
                problems.append(f"{where}: protocols/ is sans-I/O but imports {target}")
            if room_of(target) in MAY_IMPORT and target.split(".")[0] in ("emulator", "protocols"):
                if not _allowed(room, target):
                    problems.append(f"{where}: {room} may not import {target}")
    return problems


def test_every_import_runs_down_the_flow() -> None:
    assert violations(ROOT) == []


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    return tmp_path


@pytest.mark.parametrize(
    ("files", "expected"),
    [
        ({"emulator/scene/loader.py": "from emulator.daemon.service import Daemon\n"},
         "emulator/scene/loader.py:1: emulator.scene may not import emulator.daemon.service"),
        ({"emulator/scene/loader.py": "def late():\n    import emulator.transport.tcp\n"},
         "emulator/scene/loader.py:2: emulator.scene may not import emulator.transport.tcp"),
        ({"emulator/transport/tcp.py": "from protocols.scip import UrgDevice\n"},
         "emulator/transport/tcp.py:1: emulator.transport may not import protocols.scip"),
        ({"protocols/scip/device.py": "from emulator.sensors.scan import Scan\n"},
         "protocols/scip/device.py:1: protocols may not import emulator.sensors.scan"),
        ({"protocols/scip/device.py": "import asyncio\n"},
         "protocols/scip/device.py:1: protocols/ is sans-I/O but imports asyncio"),
        ({"emulator/optics/world.py": "from ..sensors import urg04lx\n"},
         "emulator/optics/world.py:1: emulator.optics may not import emulator.sensors"),
        ({"emulator/gadgets/thing.py": "x = 1\n"},
         "emulator/gadgets/thing.py: room emulator.gadgets is not in the import map"),
    ],
)
def test_a_wrong_import_is_named(tmp_path: Path, files: dict[str, str], expected: str) -> None:
    assert violations(_tree(tmp_path, files)) == [expected]


def test_imports_down_the_flow_pass(tmp_path: Path) -> None:
    tree = _tree(tmp_path, {
        "emulator/sensors/urg04lx.py": "from emulator.optics import World\nfrom . import scan\n",
        "emulator/transport/link.py": "from protocols.device import Output\nfrom emulator.scene.endpoints import TcpAddress\n",
        "emulator/daemon/service.py": "from protocols.scip import UrgDevice\nimport asyncio\n",
    })
    assert violations(tree) == []
