"""Load a scene file (docs/scene-format.md) into the immutable dataclasses of `model.py`.

Validation is strict so that a typo never silently becomes a default: unknown
keys, wrong types (a boolean is not a number), NaN/inf, out-of-range values,
duplicate names, unknown materials, unusable meshes and shared endpoints are
all rejected. Every problem is one `SceneError` line naming the file, the table
and the key, e.g. ``railway.toml: smoke.plumes[1].rate: must be > 0, got -3``.

A scene's cost is bounded before anything is built (docs/scene-format.md,
"Limits"): coordinates and lengths within MAX_EXTENT_M, at most
MAX_PARTICLES_ALIVE plume particles alive at once (Σ rate × lifetime), smoke
densities up to MAX_DENSITY, bodies no faster than MAX_BODY_SPEED_M_S, at most
MAX_SCENE_ITEMS objects, regions and plumes together, and MAX_MESH_TRIANGLES
mesh triangles in all. Live changes (emulator/control) are held to the same
limits through `particle_budget_error` and these constants.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import stat
import tomllib
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from types import MappingProxyType
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from emulator.errors import SceneError, UserError
from emulator.scene.bodies import LIVE, Body, Keyframes, Trajectory, euler_quaternion
from emulator.scene import drive as drive_defaults
from emulator.scene.drive import Drive
from emulator.scene.endpoints import Address, EndpointClaims, parse_endpoint
from emulator.scene.geometry import MAX_EXTENT_M, MeshLoadError, load_mesh_file
from emulator.scene.materials import BUILTIN_MATERIALS, DEFAULT_MATERIAL
from emulator.scene.sick_models import ANGLE_TICKS_PER_DEG, FREQUENCY_TICKS_PER_HZ
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.scene.model import (
    Box,
    Cylinder,
    Density,
    Material,
    MeshFile,
    Plume,
    Pose,
    Scene,
    SceneObject,
    SensorSpec,
    Shape,
    SmokeRegion,
    Sphere,
    Vec3,
)

ENDPOINT_SYNTAX = '"pty:PATH", "tcp:HOST:PORT" or "rfc2217:HOST:PORT" with PORT 0..65535'
BUNDLED_PACKAGE = "emulator.bundled_scenes"
SCENE_SUFFIX = ".toml"

SCENE_MODELS = ("formsma2011", "physical")
SCIP22_MODELS = ("utm-30lx", "utm-30lx-ew", "ust-10lx", "ust-20lx")
SENSOR_MODELS = ("urg-04lx", *SCIP22_MODELS, "lms200", *SICK_MODELS)
# Ethernet Hokuyos: `tcp:HOST` without a port means the unit's own port (docs/scene-format.md).
DEFAULT_TCP_PORTS = {"utm-30lx-ew": 10940, "ust-10lx": 10940, "ust-20lx": 10940}
SHAPE_KEYS = ("box", "sphere", "cylinder", "mesh")
ORIGIN: Vec3 = (0.0, 0.0, 0.0)

TOP_KEYS = ("scene", "materials", "bodies", "objects", "smoke", "sensors")
SCENE_KEYS = ("name", "description", "seed", "model", "density_to_extinction", "camera_reference")
SMOKE_KEYS = ("regions", "plumes")
OBJECT_KEYS = ("name", *SHAPE_KEYS, "position", "rotation_deg", "material", "body")
BODY_KEYS = ("name", "position", "rotation_deg", "trajectory", "drive")
DRIVE_KEYS = ("radius", "height", "clearance", "max_speed", "max_turn_rate", "watchdog")
TRAJECTORY_KEYS = ("keyframes", "file")
PLANAR_ROW = 4  # [t, x, y, yaw_deg]
FULL_ROW = 7  # [t, x, y, z, roll_deg, pitch_deg, yaw_deg]
TUM_NUMBERS = 8  # t x y z qx qy qz qw
TUM_MAX_BYTES = 64 * 1024 * 1024
TUM_MAX_LINES = 1_000_000
REGION_KEYS = ("name", *SHAPE_KEYS, "position", "rotation_deg", "density")
PLUME_KEYS = (
    "name", "source", "rate", "lifetime", "size", "growth",
    "velocity", "spread", "wind", "density", "start", "stop",
)
MATERIAL_KEYS = tuple(field.name for field in dataclasses.fields(Material))

# Model options with the real device's defaults (docs/scene-format.md; firmware_profile is ours).
URG_OPTION_KEYS = ("boot_protocol", "serial", "timing")
LMS_OPTION_KEYS = ("baud", "angle_deg", "resolution_deg", "units", "type_string", "firmware_profile")
COLA_OPTION_KEYS = ("scan_frequency_hz", "resolution_deg", "serial", "fog_filter")
SCIP22_OPTION_KEYS = ("serial",)
OPTION_KEYS = {
    "urg-04lx": URG_OPTION_KEYS, **{model: SCIP22_OPTION_KEYS for model in SCIP22_MODELS}, "lms200": LMS_OPTION_KEYS,
    **{name: COLA_OPTION_KEYS for name in SICK_MODELS},
}
SENSOR_KEYS = tuple(dict.fromkeys(
    ("name", "model", "body", "position", "rotation_deg", "endpoints", *URG_OPTION_KEYS, *LMS_OPTION_KEYS, *COLA_OPTION_KEYS)
))
URG_SERIAL_MAX_CHARS = 16
LMS_TYPE_STRING_CHARS = 21
LMS_BAUDS = (9600, 19200, 38400, 500000)
LMS_ANGLES_DEG = (180, 100)
LMS_RESOLUTIONS_DEG = (1.0, 0.5, 0.25)

_PRINTABLE_ASCII = re.compile(r"[\x20-\x7e]*")
_TOML_LOCATION = re.compile(r"^(?P<message>.*) \(at line (?P<line>\d+), column (?P<column>\d+)\)$")
_MISSING: Any = object()


@dataclass(frozen=True)
class BundledScene:
    """A scene shipped with the package, addressable by `name`."""

    name: str
    description: str
    path: Path


# --------------------------------------------------------------------------- finding and reading


def load_scene(name_or_path: str | os.PathLike[str]) -> Scene:
    """The validated scene: a bundled scene's name (no '/' and no '.toml') or a path to a TOML file."""
    path = _locate(name_or_path)
    return _build_scene(_read_toml(path), path)


def bundled_scenes() -> list[BundledScene]:
    """The scenes shipped in `scenes/`, sorted by name, with their one-line descriptions."""
    result = []
    for path in _bundled_paths():
        scene_table = _read_toml(path).get("scene", {})
        description = scene_table.get("description", "") if isinstance(scene_table, dict) else ""
        result.append(BundledScene(path.stem, str(description), path))
    return result


def _bundled_dir() -> Path:
    return Path(os.fspath(files(BUNDLED_PACKAGE)))


def _bundled_paths() -> list[Path]:
    return sorted(_bundled_dir().glob(f"*{SCENE_SUFFIX}"), key=lambda path: path.stem)


def _locate(name_or_path: str | os.PathLike[str]) -> Path:
    text = os.fspath(name_or_path)
    is_bundled_name = "/" not in text and not text.endswith(SCENE_SUFFIX)
    path = _bundled_dir() / f"{text}{SCENE_SUFFIX}" if is_bundled_name else Path(text)
    if not text or not path.is_file():
        hint = "give a scene's .toml file or a bundled scene's name"
        if text and os.path.isdir(text):  # a bundled name wins over a directory of that name (it is found above)
            raise SceneError(f"{text}: is a directory, not a scene file ({hint})")
        if not is_bundled_name and os.path.exists(text):  # a FIFO, a device: there, but not a file to read
            raise SceneError(f"{text}: is not a regular file ({hint})")
        known = ", ".join(path.stem for path in _bundled_paths()) or "none"
        raise SceneError(f"no such scene: {text!r} (bundled: {known})")
    return path.resolve()


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError(f"{path.name}: not UTF-8 text (byte {error.start})") from error
    except OSError as error:
        raise SceneError(f"{path.name}: cannot read: {error.strerror}") from error
    text = text.removeprefix("\ufeff")  # a byte-order mark some editors write first: not a TOML statement
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path.name}: {_describe_toml_error(error, text)}") from error
    except ValueError:  # Python's bound on the digits of an int read from text (4300), raised inside tomllib
        huge = re.search(r"[0-9_]{4300,}", text)
        line = text.count("\n", 0, huge.start()) + 1 if huge else max(1, len(text.splitlines()))
        raise SceneError(f"{path.name}: line {line}: an integer of more than 4300 digits") from None
    except RecursionError:
        raise SceneError(f"{path.name}: arrays or tables nested too deeply for a scene file") from None


def _describe_toml_error(error: tomllib.TOMLDecodeError, text: str) -> str:
    """tomllib's message led by its line number, which it gives only inside its text."""
    message = str(error)
    located = _TOML_LOCATION.match(message)
    if located:
        return f"line {located['line']}: {located['message']} (column {located['column']})"
    last_line = max(1, len(text.splitlines()))
    return f"line {last_line}: {message.replace(' (at end of document)', '')} (at the end of the file)"


# --------------------------------------------------------------------------- typed access with places


def _show(value: Any, depth: int = 0) -> str:
    """A value as the user wrote it in TOML, short enough for a one-line message
    (nesting past a few levels is elided: a JSON body can nest deeper than the stack).
    TOML has no null: None comes from JSON (the control API, an event log) and reads as JSON's `null`."""
    if value is None:
        text = "null"
    elif isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, str):
        text = json.dumps(value[:64])
    elif isinstance(value, float) and not math.isfinite(value):
        text = "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    elif isinstance(value, (list, dict)) and depth >= _SHOWN_DEPTH:
        text = "[...]" if isinstance(value, list) else "{ ... }"
    elif isinstance(value, list):
        text = "[" + ", ".join(_show(item, depth + 1) for item in value[:8]) + (", ..." if len(value) > 8 else "") + "]"
    elif isinstance(value, dict):
        items = list(value.items())[:8]
        text = "{ " + ", ".join(f"{key} = {_show(item, depth + 1)}" for key, item in items) + " }"
    elif isinstance(value, int) and abs(value) >= 10**18:
        text = f"{'-' if value < 0 else ''}{str(abs(value))[:6]}...e{len(str(abs(value))) - 1}"
    else:
        text = str(value)
    return text if len(text) <= 60 else text[:57] + "..."


_SHOWN_DEPTH = 4


@dataclass(frozen=True)
class _Place:
    """Where a value sits in the file: `objects[0].box.size` in `x.toml`."""

    file: str
    path: str = ""

    def key(self, name: str) -> _Place:
        return _Place(self.file, f"{self.path}.{name}" if self.path else name)

    def index(self, position: int) -> _Place:
        return _Place(self.file, f"{self.path}[{position}]")

    def error(self, message: str) -> SceneError:
        where = ": ".join(part for part in (self.file, self.path) if part)
        return SceneError(f"{where}: {message}" if where else message, self.path)


# Limits on what a scene may cost (docs/scene-format.md, "Limits").
# Σ over plumes of rate × lifetime: the bound on a scan's smoke cost, so that a scan stays within its
# sensor's period even after a live change (docs/scene-format.md, "Limits"; railway has 80, marulan 462)
MAX_PARTICLES_ALIVE = 2_000
# Far beyond opaque (× the default 250 /m per unit: an extinction of 250 000 /m), and every product of
# density, extinction and range stays finite in float64.
MAX_DENSITY = 1000.0
MAX_DENSITY_TO_EXTINCTION = 1e6  # 1/m per density unit
# Faster than anything a scanner rides on; a faster body's scan spreads its beams over more of the scene.
MAX_BODY_SPEED_M_S = 1000.0
# A plume's particles are numbered from its start at its rate: within these the numbers stay exact in int64
# (a start of -1e20 overflowed them, and with a tiny lifetime a rate of 1e12 passed the particle budget).
MAX_PLUME_START_S = 1e9  # |start| (s): 31 years
MAX_PLUME_RATE = 1e6  # particles per second
NAME_SEPARATORS = ("=", ",", "/")  # what the command line and the control API's paths read between names
MAX_SCENE_ITEMS = 10_000  # objects + smoke regions + plumes
MAX_MESH_TRIANGLES = 2_000_000  # triangles of every mesh file, counted once per use
MAX_SENSORS = 256  # a fleet-sized scene: bench --section serve runs 120 sensors in one daemon
MAX_ENDPOINTS_PER_SENSOR = 8


def _as_number(value: Any, place: _Place) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise place.error(f"expected a number, got {_show(value)}")
    try:
        finite = math.isfinite(value)
    except OverflowError:  # an integer too large for a float (JSON has no limit)
        finite = False
    if not finite:
        raise place.error(f"must be finite, got {_show(value)}")
    return float(value)


def _check_bounds(
    value: float, raw: Any, place: _Place, *, above: float | None = None,
    at_least: float | None = None, at_most: float | None = None,
) -> None:
    if above is not None and not value > above:
        raise place.error(f"must be > {_show(above)}, got {_show(raw)}")
    if at_least is not None and not value >= at_least:
        raise place.error(f"must be >= {_show(at_least)}, got {_show(raw)}")
    if at_most is not None and not value <= at_most:
        raise place.error(f"must be <= {_show(at_most)}, got {_show(raw)}")


def _as_string(value: Any, place: _Place) -> str:
    if not isinstance(value, str):
        raise place.error(f"expected a string, got {_show(value)}")
    return value


def _choices(options: Iterable[Any]) -> str:
    return ", ".join(_show(option) for option in options)


def _as_table(value: Any, place: _Place, allowed: Sequence[str]) -> _Table:
    if not isinstance(value, dict):
        raise place.error(f"expected a table, got {_show(value)}")
    for key in value:
        if key not in allowed:
            raise place.key(key).error(f"unknown key (expected one of: {', '.join(allowed)})")
    return _Table(value, place)


def _as_tables(value: Any, place: _Place, allowed: Sequence[str]) -> list[_Table]:
    if not isinstance(value, list) or not all(isinstance(item, dict) for item in value):
        raise place.error(f"expected an array of tables ([[{place.path}]]), got {_show(value)}")
    return [_as_table(item, place.index(position), allowed) for position, item in enumerate(value)]


class _Table:
    """A TOML table whose keys have already been checked against the allowed ones."""

    def __init__(self, data: dict[str, Any], place: _Place) -> None:
        self.data = data
        self.place = place

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        """The value as parsed, or `default`; a missing key without a default is an error."""
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.place.key(key).error("missing required key")
        return default

    def number(self, key: str, default: Any = _MISSING, **bounds: float) -> float:
        raw = self.raw(key, default)
        value = _as_number(raw, self.place.key(key))
        _check_bounds(value, raw, self.place.key(key), **bounds)
        return value

    def number_choice(self, key: str, default: float, choices: Sequence[float]) -> float:
        raw = self.raw(key, default)
        value = _as_number(raw, self.place.key(key))
        if value not in choices:
            raise self.place.key(key).error(f"must be one of {_choices(choices)}, got {_show(raw)}")
        return value

    def integer(self, key: str, default: Any = _MISSING, **bounds: float) -> int:
        raw = self.raw(key, default)
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise self.place.key(key).error(f"expected an integer, got {_show(raw)}")
        _check_bounds(raw, raw, self.place.key(key), **bounds)
        return raw

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        raw = self.raw(key, default)
        if not isinstance(raw, bool):
            raise self.place.key(key).error(f"expected true or false, got {_show(raw)}")
        return raw

    def string(self, key: str, default: Any = _MISSING, choices: Sequence[str] | None = None) -> str:
        value = _as_string(self.raw(key, default), self.place.key(key))
        if choices is not None and value not in choices:
            raise self.place.key(key).error(f"must be one of {_choices(choices)}, got {_show(value)}")
        return value

    def ascii_text(self, key: str, default: str, *, max_chars: int, exact: bool = False, forbidden: str = "") -> str:
        """Printable ASCII that a device sends verbatim (serial number, type string)."""
        value = self.string(key, default)
        place = self.place.key(key)
        if not _PRINTABLE_ASCII.fullmatch(value) or any(char in value for char in forbidden):
            extra = f" without {_choices(forbidden)}" if forbidden else ""
            raise place.error(f"must be printable ASCII{extra}, got {_show(value)}")
        if exact and len(value) != max_chars:
            raise place.error(f"must be exactly {max_chars} characters, got {len(value)}: {_show(value)}")
        if not 1 <= len(value) <= max_chars:
            raise place.error(f"must be 1 to {max_chars} characters, got {len(value)}: {_show(value)}")
        return value

    def vec3(self, key: str, default: Any = _MISSING, **bounds: float) -> Vec3:
        raw = self.raw(key, default)
        place = self.place.key(key)
        if not isinstance(raw, (list, tuple)) or len(raw) != 3:
            raise place.error(f"expected 3 numbers, got {_show(raw)}")
        values = []
        for position, item in enumerate(raw):
            if isinstance(item, bool) or not isinstance(item, (int, float)):
                raise place.error(f"expected 3 numbers, got {_show(raw)}")
            value = _as_number(item, place.index(position))
            _check_bounds(value, item, place.index(position), **bounds)
            if abs(value) > MAX_EXTENT_M:
                raise place.index(position).error(f"must lie within ±{MAX_EXTENT_M:g}, got {_show(item)}")
            values.append(value)
        return (values[0], values[1], values[2])

    def table(self, key: str, allowed: Sequence[str]) -> _Table:
        return _as_table(self.raw(key, _MISSING), self.place.key(key), allowed)

    def tables(self, key: str, allowed: Sequence[str]) -> list[_Table]:
        return _as_tables(self.raw(key, []), self.place.key(key), allowed)

    def name(self, seen: dict[str, str]) -> str:
        """This item's `name`, which must differ from every name in `seen` (name → its table path)."""
        value = self.string("name")
        if not value.strip():
            raise self.place.key("name").error("must not be empty")
        if not value.isprintable() or any(character in value for character in NAME_SEPARATORS):
            raise self.place.key("name").error(
                f"{_show(value)}: a name holds no control character and none of {' '.join(NAME_SEPARATORS)} "
                "(it is named on the command line, SENSOR=URI and a,b lists, and in the control API's paths)"
            )
        if value in seen:
            raise self.place.key("name").error(f"duplicate name {_show(value)} (also {seen[value]})")
        seen[value] = self.place.path
        return value

    def pose(self) -> Pose:
        return Pose(self.vec3("position", ORIGIN), self.vec3("rotation_deg", ORIGIN))


def checked_values(where: str, data: Any, allowed: Sequence[str]) -> _Table:
    """Values from outside the scene file (a control API body, an event log line), to be read by
    the scene's own rules and words: errors read `where.key: ...`, e.g.
    `smoke.regions[room].density: must be >= 0, got -1`; unknown keys are refused."""
    return _as_table(data, _Place("", where), allowed)


# --------------------------------------------------------------------------- the scene's parts


def _build_scene(raw: dict[str, Any], path: Path) -> Scene:
    root = _as_table(raw, _Place(path.name), TOP_KEYS)
    header = root.table("scene", SCENE_KEYS) if "scene" in root else _Table({}, root.place.key("scene"))
    description = header.string("description", "")
    if len(description.splitlines()) > 1:
        raise header.place.key("description").error("must be one line")
    materials = _materials(root.tables("materials", MATERIAL_KEYS))
    smoke = root.table("smoke", SMOKE_KEYS) if "smoke" in root else _Table({}, root.place.key("smoke"))
    object_tables = root.tables("objects", OBJECT_KEYS)
    region_tables, plume_tables = _region_tables(smoke), smoke.tables("plumes", PLUME_KEYS)
    items = len(object_tables) + len(region_tables) + len(plume_tables)
    if items > MAX_SCENE_ITEMS:
        raise root.place.key("objects").error(
            f"{len(object_tables)} objects, {len(region_tables)} smoke.regions and {len(plume_tables)} smoke.plumes: "
            f"at most {MAX_SCENE_ITEMS} in all"
        )
    budget = _MeshBudget()
    body_tables = root.tables("bodies", BODY_KEYS)
    bodies = _bodies(body_tables, path.parent)
    objects = _objects(object_tables, materials, path.parent, bodies, budget)
    sensors = _sensors(root.tables("sensors", SENSOR_KEYS), bodies)
    _check_bodies_carry(body_tables, bodies, objects, sensors)
    return Scene(
        path=path,
        name=header.string("name", path.stem),
        description=description,
        seed=header.integer("seed", 0, at_least=0),
        model=header.string("model", "formsma2011", SCENE_MODELS),
        density_to_extinction=header.number("density_to_extinction", 250.0, above=0, at_most=MAX_DENSITY_TO_EXTINCTION),
        materials=materials,
        objects=objects,
        regions=_regions(region_tables, path.parent, budget),
        plumes=_plumes(plume_tables),
        sensors=sensors,
        bodies=bodies,
        camera_reference=header.boolean("camera_reference", False),
    )


def _materials(tables: list[_Table]) -> Mapping[str, Material]:
    """The built-ins, plus the scene's own: a new name adds a material, a built-in's name overrides it."""
    materials = dict(BUILTIN_MATERIALS)
    seen: dict[str, str] = {}
    for table in tables:
        name = table.name(seen)
        base = materials.get(name)
        required = _MISSING if base is None else base.reflectivity
        values: dict[str, Any] = {"reflectivity": table.number("reflectivity", required, at_least=0, at_most=1)}
        for key in MATERIAL_KEYS:
            if key == "retroreflective" and key in table:
                values[key] = table.boolean(key, False)
            elif key not in ("name", "reflectivity", "retroreflective") and key in table:
                values[key] = table.number(key)
        materials[name] = dataclasses.replace(base, **values) if base else Material(name, **values)
    return MappingProxyType(materials)


class _MeshBudget:
    """Mesh triangles used so far in one scene, against MAX_MESH_TRIANGLES."""

    def __init__(self) -> None:
        self.triangles = 0

    def spend(self, triangles: int, place: _Place) -> None:
        self.triangles += triangles
        if self.triangles > MAX_MESH_TRIANGLES:
            raise place.error(
                f"the scene's meshes reach {self.triangles} triangles; at most {MAX_MESH_TRIANGLES} in all"
            )


def _shape(table: _Table, scene_dir: Path, budget: _MeshBudget, *, closed: bool) -> Shape:
    """Exactly one of box, sphere, cylinder, mesh; a smoke region's mesh must be `closed` (watertight)."""
    present = [key for key in SHAPE_KEYS if key in table]
    if not present:
        raise table.place.error(f"needs exactly one shape key: {', '.join(SHAPE_KEYS)}")
    if len(present) > 1:
        raise table.place.key(present[1]).error(f"only one shape key allowed, already has {present[0]}")
    kind = present[0]
    if kind == "box":
        return Box(table.table("box", ("size",)).vec3("size", above=0))
    if kind == "sphere":
        return Sphere(table.table("sphere", ("radius",)).number("radius", above=0, at_most=MAX_EXTENT_M))
    if kind == "cylinder":
        cylinder = table.table("cylinder", ("radius", "height"))
        return Cylinder(cylinder.number("radius", above=0, at_most=MAX_EXTENT_M),
                        cylinder.number("height", above=0, at_most=MAX_EXTENT_M))
    mesh_path = (scene_dir / table.string("mesh")).resolve()
    place = table.place.key("mesh")
    try:
        mesh = load_mesh_file(mesh_path)
    except MeshLoadError as error:
        raise place.error(str(error)) from error
    budget.spend(len(mesh.faces), place)
    if closed and not mesh.is_watertight:
        raise place.error(f"mesh {mesh_path.name} is not watertight; a smoke region must be a closed volume")
    return MeshFile(mesh_path)


def _body_of(table: _Table, bodies: tuple[Body, ...]) -> str | None:
    """The item's `body`, which must name one of the scene's bodies (None when absent)."""
    if "body" not in table:
        return None
    name = table.string("body")
    if name not in {body.name for body in bodies}:
        known = ", ".join(body.name for body in bodies) or "none"
        raise table.place.key("body").error(f"unknown body {_show(name)} (bodies: {known})")
    return name


def _objects(
    tables: list[_Table], materials: Mapping[str, Material], scene_dir: Path, bodies: tuple[Body, ...],
    budget: _MeshBudget,
) -> tuple[SceneObject, ...]:
    seen: dict[str, str] = {}
    objects = []
    for table in tables:
        name = table.name(seen)
        material = table.string("material", DEFAULT_MATERIAL)
        if material not in materials:
            known = ", ".join(sorted(materials))
            raise table.place.key("material").error(f"unknown material {_show(material)} (known: {known})")
        objects.append(
            SceneObject(name, _shape(table, scene_dir, budget, closed=False), table.pose(), material, _body_of(table, bodies))
        )
    return tuple(objects)


def _density(table: _Table) -> Density:
    """A constant density >= 0, or { keyframes = [[t, density], ...] } with times that do not decrease
    (two rows at one time are a step)."""
    place = table.place.key("density")
    raw = table.raw("density", _MISSING)
    if isinstance(raw, dict):
        return _keyframes(_as_table(raw, place, ("keyframes",)))
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise place.error(f"expected a number or {{ keyframes = [[time, density], ...] }}, got {_show(raw)}")
    return Density(((0.0, table.number("density", at_least=0, at_most=MAX_DENSITY)),))


def _keyframes(table: _Table) -> Density:
    place = table.place.key("keyframes")
    raw = table.raw("keyframes", _MISSING)
    if not isinstance(raw, list) or not raw:
        raise place.error(f"expected a non-empty list of [time, density], got {_show(raw)}")
    keyframes: list[tuple[float, float]] = []
    for position, pair in enumerate(raw):
        pair_place = place.index(position)
        if not isinstance(pair, list) or len(pair) != 2:
            raise pair_place.error(f"expected [time, density], got {_show(pair)}")
        time_s = _as_number(pair[0], pair_place.index(0))
        density = _as_number(pair[1], pair_place.index(1))
        _check_bounds(density, pair[1], pair_place.index(1), at_least=0, at_most=MAX_DENSITY)
        if keyframes and time_s < keyframes[-1][0]:
            raise pair_place.index(0).error(
                f"keyframe times must not decrease, got {_show(pair[0])} after {_show(raw[position - 1][0])}"
            )
        keyframes.append((time_s, density))
    return Density(tuple(keyframes))


def _region_tables(smoke: _Table) -> list[_Table]:
    """The [[smoke.regions]] tables; a `body` key there gets its own answer, not just "unknown key"."""
    raw = smoke.raw("regions", [])
    for position, item in enumerate(raw if isinstance(raw, list) else []):
        if isinstance(item, dict) and "body" in item:
            place = smoke.place.key("regions").index(position).key("body")
            raise place.error("smoke regions cannot ride on a body (the paper's smoke areas never move)")
    return smoke.tables("regions", REGION_KEYS)


def _regions(tables: list[_Table], scene_dir: Path, budget: _MeshBudget) -> tuple[SmokeRegion, ...]:
    seen: dict[str, str] = {}
    return tuple(
        SmokeRegion(table.name(seen), _shape(table, scene_dir, budget, closed=True), table.pose(), _density(table))
        for table in tables
    )


def _plumes(tables: list[_Table]) -> tuple[Plume, ...]:
    seen: dict[str, str] = {}
    plumes = []
    alive = 0.0
    for table in tables:
        name = table.name(seen)
        start = table.number("start", 0.0, at_least=-MAX_PLUME_START_S, at_most=MAX_PLUME_START_S)
        stop = table.number("stop", 1e9)
        if not start < stop:
            start_text, stop_text = _show(table.raw("start", start)), _show(table.raw("stop", stop))
            raise table.place.key("stop").error(f"must be > start ({start_text}), got {stop_text}")
        plumes.append(
            Plume(
                name=name,
                source=table.vec3("source"),
                rate=table.number("rate", above=0, at_most=MAX_PLUME_RATE),
                lifetime=table.number("lifetime", above=0),
                size=table.number("size", above=0, at_most=MAX_EXTENT_M),
                growth=table.number("growth", 0.0, at_least=0, at_most=MAX_EXTENT_M),
                velocity=table.vec3("velocity", ORIGIN),
                spread=table.number("spread", 0.0, at_least=0, at_most=MAX_EXTENT_M),
                wind=table.vec3("wind", ORIGIN),
                density=table.number("density", at_least=0, at_most=MAX_DENSITY),
                start=start,
                stop=stop,
            )
        )
        alive += plumes[-1].rate * plumes[-1].lifetime
        if alive > MAX_PARTICLES_ALIVE:
            raise table.place.key("rate").error(
                f"rate × lifetime of the plumes so far is {alive:.6g} particles alive at once; "
                f"{particle_budget_words()} (lower rate or lifetime)"
            )
    return tuple(plumes)


def particle_budget_words() -> str:
    """How a refusal names the particle budget (scene files and live changes alike)."""
    return f"the particle budget allows at most {MAX_PARTICLES_ALIVE}"


# --------------------------------------------------------------------------- sensors


def _endpoint_address(text: str, place: _Place) -> Address:
    """An endpoint URI parsed as `serve --endpoint` parses it (port 0 included: the
    system chooses a free port and the `ready` line names it)."""
    try:
        return parse_endpoint(text)
    except UserError:
        raise place.error(f"expected {ENDPOINT_SYNTAX}, got {_show(text)}") from None


def _endpoints(table: _Table, claims: EndpointClaims, sensor: str, default_port: int | None = None) -> tuple[str, ...]:
    place = table.place.key("endpoints")
    raw = table.raw("endpoints", [])
    if not isinstance(raw, list):
        raise place.error(f"expected a list of endpoints, got {_show(raw)}")
    if len(raw) > MAX_ENDPOINTS_PER_SENSOR:
        raise place.error(f"{len(raw)} endpoints; a sensor may have at most {MAX_ENDPOINTS_PER_SENSOR}")
    endpoints = []
    for position, item in enumerate(raw):
        item_place = place.index(position)
        text = _with_default_port(_as_string(item, item_place), default_port)
        address = _endpoint_address(text, item_place)
        clash = claims.claim(address, sensor)
        if clash is not None:
            taken, owner = clash
            spelled = "" if str(taken) == str(address) else f" as {_show(str(taken))}"
            raise item_place.error(f"endpoint {_show(text)} already used by sensor {_show(owner)}{spelled}")
        endpoints.append(text)
    return tuple(endpoints)


def _with_default_port(text: str, default_port: int | None) -> str:
    """`tcp:HOST` as `tcp:HOST:PORT` with the unit's own port (an Ethernet Hokuyo's 10940)."""
    if default_port is None or not text.startswith("tcp:"):
        return text
    host = text[len("tcp:"):]
    bare = host and (":" not in host or (host.startswith("[") and host.endswith("]")))
    return f"{text}:{default_port}" if bare else text


def _scip22_options(table: _Table) -> dict[str, Any]:
    """The SCIP 2.2 Hokuyos: their serial number (VV SERI); the rest is the model's."""
    if "serial" not in table:
        return {}
    return {"serial": table.ascii_text("serial", "", max_chars=URG_SERIAL_MAX_CHARS, forbidden=";")}


def _urg_options(table: _Table) -> dict[str, Any]:
    return {
        "boot_protocol": table.string("boot_protocol", "scip2", ("scip2", "scip1")),
        # ';' separates the fields of the SCIP VV reply, so a serial must not contain one.
        "serial": table.ascii_text("serial", "H0706400", max_chars=URG_SERIAL_MAX_CHARS, forbidden=";"),
        # "real": replies at the unit's 100 ms command cycle; "fast": at once, for quick CI.
        "timing": table.string("timing", "real", ("real", "fast")),
    }


def _lms_options(table: _Table) -> dict[str, Any]:
    angle_deg = int(table.number_choice("angle_deg", 180, LMS_ANGLES_DEG))
    resolution_deg = table.number_choice("resolution_deg", 0.5, LMS_RESOLUTIONS_DEG)
    if angle_deg == 180 and resolution_deg == 0.25:
        raise table.place.key("resolution_deg").error("0.25 needs angle_deg = 100 (no 180° scan at 0.25°)")
    baud = table.integer("baud", 9600)
    if baud not in LMS_BAUDS:
        raise table.place.key("baud").error(f"must be one of {_choices(LMS_BAUDS)}, got {baud}")
    return {
        "baud": baud,
        "angle_deg": angle_deg,
        "resolution_deg": resolution_deg,
        "units": table.string("units", "mm", ("mm", "cm")),
        "type_string": table.ascii_text(
            "type_string", "LMS200;301063;V02.10 ", max_chars=LMS_TYPE_STRING_CHARS, exact=True
        ),
        "firmware_profile": table.string("firmware_profile", "v2.30", ("v2.30", "32-byte-config")),
    }


def _option_of(key: str, model: str) -> str | None:
    """The model `key` is an option of, when it is not one of `model`'s (None: it is, or no model's)."""
    if key in OPTION_KEYS[model]:
        return None
    return next((other for other, keys in OPTION_KEYS.items() if key in keys), None)


def _plain(number: float) -> float | int:
    """25.0 → 25, so a list of choices reads as a user writes them."""
    return int(number) if float(number).is_integer() else number


def _cola_options(table: _Table, model: str) -> dict[str, Any]:
    """A CoLa SICK's power-on scan configuration (one its datasheet offers), serial number, fog filter."""
    sick = SICK_MODELS[model]
    default_hz, default_res = sick.default[0] / FREQUENCY_TICKS_PER_HZ, sick.default[1] / ANGLE_TICKS_PER_DEG
    frequencies = tuple(_plain(ticks / FREQUENCY_TICKS_PER_HZ) for ticks in sick.scan_configs)
    frequency_hz = table.number_choice("scan_frequency_hz", default_hz, frequencies)
    offered = sick.scan_configs[int(round(frequency_hz * FREQUENCY_TICKS_PER_HZ))]
    resolution_deg = table.number_choice(
        "resolution_deg", default_res if sick.offers(int(round(frequency_hz * 100)), sick.default[1]) else offered[0] / ANGLE_TICKS_PER_DEG,
        tuple(_plain(ticks / ANGLE_TICKS_PER_DEG) for ticks in offered),
    )
    serial = table.ascii_text("serial", "12345678", max_chars=8)
    if not serial.isdigit():
        raise table.place.key("serial").error(f"must be up to 8 decimal digits, got {_show(serial)}")
    fog_filter = table.raw("fog_filter", False)
    if not isinstance(fog_filter, bool) or (fog_filter and sick.family != "LMS5xx"):
        raise table.place.key("fog_filter").error(f"must be true or false (true only on an LMS5xx), got {_show(fog_filter)}")
    return {"scan_frequency_hz": frequency_hz, "resolution_deg": resolution_deg, "serial": serial, "fog_filter": fog_filter}


def _sensors(tables: list[_Table], bodies: tuple[Body, ...]) -> tuple[SensorSpec, ...]:
    if len(tables) > MAX_SENSORS:
        raise tables[MAX_SENSORS].place.error(f"{len(tables)} sensors; a scene may have at most {MAX_SENSORS}")
    seen: dict[str, str] = {}
    claims = EndpointClaims()
    sensors = []
    for table in tables:
        name = table.name(seen)
        model = table.string("model", choices=SENSOR_MODELS)
        foreign = next((key for key in SENSOR_KEYS if key in table and _option_of(key, model)), None)
        if foreign:
            raise table.place.key(foreign).error(f"is an option of {_option_of(foreign, model)}, not of {model}")
        if model == "urg-04lx":
            options = _urg_options(table)
        elif model == "lms200":
            options = _lms_options(table)
        elif model in SCIP22_MODELS:
            options = _scip22_options(table)
        else:
            options = _cola_options(table, model)
        endpoints = _endpoints(table, claims, name, DEFAULT_TCP_PORTS.get(model))
        body = _body_of(table, bodies)
        sensors.append(SensorSpec(name, model, table.pose(), endpoints, MappingProxyType(options), body))
    return tuple(sensors)


# --------------------------------------------------------------------------- bodies


def _bodies(tables: list[_Table], scene_dir: Path) -> tuple[Body, ...]:
    seen: dict[str, str] = {}
    bodies = []
    for table in tables:
        name = table.name(seen)
        pose = table.pose()
        trajectory = _trajectory(table, pose, scene_dir) if "trajectory" in table else None
        if "drive" in table and trajectory is not LIVE:
            raise table.place.key("drive").error('only a body with trajectory = "live" is driven by twists')
        drive = _drive(table.table("drive", DRIVE_KEYS)) if "drive" in table else Drive()
        bodies.append(Body(name, pose, trajectory, drive))
    return tuple(bodies)


def _drive(table: _Table) -> Drive:
    """A live body's footprint, speed limits and watchdog (scene/drive.py); defaults for what is left out."""
    radius = table.number("radius", drive_defaults.DEFAULT_RADIUS_M, above=0, at_most=MAX_EXTENT_M)
    clearance = table.number("clearance", drive_defaults.DEFAULT_CLEARANCE_M, at_least=0, at_most=MAX_EXTENT_M)
    height = table.number("height", drive_defaults.DEFAULT_HEIGHT_M, above=clearance, at_most=MAX_EXTENT_M)
    return Drive(
        radius=radius,
        height=height,
        clearance=clearance,
        max_speed=table.number("max_speed", drive_defaults.DEFAULT_MAX_SPEED, above=0, at_most=drive_defaults.MAX_BODY_SPEED),
        max_turn_rate=table.number("max_turn_rate", drive_defaults.DEFAULT_MAX_TURN_RATE, above=0,
                                   at_most=drive_defaults.MAX_BODY_TURN_RATE),
        watchdog_s=table.number("watchdog", drive_defaults.DEFAULT_WATCHDOG_S, above=0, at_most=drive_defaults.MAX_WATCHDOG_S),
    )


def _check_bodies_carry(
    tables: list[_Table], bodies: tuple[Body, ...], objects: tuple[SceneObject, ...], sensors: tuple[SensorSpec, ...]
) -> None:
    """A body that carries nothing is almost surely a typo in some `body` key."""
    used = {item.body for item in (*objects, *sensors)}
    for table, body in zip(tables, bodies):
        if body.name not in used:
            raise table.place.key("name").error(
                f"body {_show(body.name)} carries nothing (no sensor or object has body = {_show(body.name)})"
            )


def _trajectory(table: _Table, pose: Pose, scene_dir: Path) -> Trajectory:
    """`"live"`, `{ keyframes = [...] }` or `{ file = "run.tum" }`."""
    place = table.place.key("trajectory")
    raw = table.raw("trajectory")
    if raw == "live":
        return LIVE
    if not isinstance(raw, dict):
        raise place.error(f'expected "live", {{ keyframes = [...] }} or {{ file = "run.tum" }}, got {_show(raw)}')
    spec = _as_table(raw, place, TRAJECTORY_KEYS)
    if ("keyframes" in spec) == ("file" in spec):
        raise place.error("needs exactly one of: keyframes, file")
    if "file" in spec:
        return _tum_file(scene_dir / spec.string("file"), spec.place.key("file"))
    return _pose_keyframes(spec, pose)


def _pose_keyframes(table: _Table, pose: Pose) -> Keyframes:
    """Rows [t, x, y, yaw_deg] (z, roll, pitch from the body's pose) or [t, x, y, z, roll_deg, pitch_deg, yaw_deg]."""
    place = table.place.key("keyframes")
    raw = table.raw("keyframes")
    if not isinstance(raw, list) or not raw:
        raise place.error(f"expected a non-empty list of [t, x, y, yaw_deg] or [t, x, y, z, roll_deg, pitch_deg, yaw_deg], got {_show(raw)}")
    rows: list[list[float]] = []
    for position, row in enumerate(raw):
        row_place = place.index(position)
        expected = len(raw[0]) if isinstance(raw[0], list) and len(raw[0]) in (PLANAR_ROW, FULL_ROW) else None
        if not isinstance(row, list) or len(row) not in (PLANAR_ROW, FULL_ROW) or (expected and len(row) != expected):
            wanted = f"{expected} numbers like row 0" if expected else f"{PLANAR_ROW} numbers [t, x, y, yaw_deg] or {FULL_ROW} [t, x, y, z, roll_deg, pitch_deg, yaw_deg]"
            got = f"{len(row)} numbers" if isinstance(row, list) else _show(row)
            raise row_place.error(f"expected {wanted}, got {got}")
        numbers = [_as_number(item, row_place.index(column)) for column, item in enumerate(row)]
        for column in range(1, 3 if len(row) == PLANAR_ROW else 4):  # x, y (, z)
            if abs(numbers[column]) > MAX_EXTENT_M:
                raise row_place.index(column).error(f"must lie within ±{MAX_EXTENT_M:g}, got {_show(row[column])}")
        if rows and numbers[0] < rows[-1][0]:
            raise row_place.index(0).error(f"keyframe times must not decrease, got {_show(row[0])} after {_show(raw[position - 1][0])}")
        rows.append(numbers)
    table_rows = np.array(rows, dtype=float)
    if table_rows.shape[1] == PLANAR_ROW:
        z, (roll, pitch, _) = pose.position[2], pose.rotation_deg
        count = len(table_rows)
        positions = np.column_stack([table_rows[:, 1], table_rows[:, 2], np.full(count, z)])
        angles = np.column_stack([np.full(count, roll), np.full(count, pitch), table_rows[:, 3]])
    else:
        positions, angles = table_rows[:, 1:4], table_rows[:, 4:7]
    _check_speed(table_rows[:, 0], positions, lambda row: place.index(row).error)
    return _frozen_keyframes(table_rows[:, 0], positions, euler_quaternion(angles))


def _check_speed(times: np.ndarray, positions: np.ndarray, error_at) -> None:
    """Between rows at different times a body moves at most MAX_BODY_SPEED_M_S (rows at one time are a jump)."""
    steps = np.diff(times)
    distances = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    moving = steps > 0
    speeds = np.zeros_like(steps)
    speeds[moving] = distances[moving] / steps[moving]
    if np.any(speeds > MAX_BODY_SPEED_M_S):
        row = int(np.argmax(speeds > MAX_BODY_SPEED_M_S)) + 1
        raise error_at(row)(
            f"the body moves {distances[row - 1]:.6g} m in {steps[row - 1]:.6g} s, {speeds[row - 1]:.6g} m/s;"
            f" a body may move at most {MAX_BODY_SPEED_M_S:g} m/s"
        )


def _frozen_keyframes(times: np.ndarray, positions: np.ndarray, quaternions: np.ndarray) -> Keyframes:
    for array in (times, positions, quaternions):
        array.flags.writeable = False
    return Keyframes(times, positions, quaternions)


def _tum_file(path: Path, place: _Place) -> Keyframes:
    """A TUM trajectory: lines `t x y z qx qy qz qw`; blank lines and `#` comments skipped. Bounded: a file
    over TUM_MAX_BYTES or TUM_MAX_LINES is refused before it is parsed."""
    try:
        with os.fdopen(os.open(path, os.O_RDONLY | os.O_NONBLOCK), "rb") as stream:  # a FIFO's open must not block
            if not stat.S_ISREG(os.fstat(stream.fileno()).st_mode):
                raise place.error(f"{path.name} is not a regular file (a FIFO or device is never read: give a TUM file)")
            data = stream.read(TUM_MAX_BYTES + 1)
    except OSError as error:
        raise place.error(f"cannot read {path.name}: {error.strerror}") from error
    if len(data) > TUM_MAX_BYTES:
        raise place.error(f"{path.name} is larger than {TUM_MAX_BYTES // (1024 * 1024)} MiB")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise place.error(f"{path.name}: not UTF-8 text (byte {error.start})") from error
    lines = text.splitlines()
    if len(lines) > TUM_MAX_LINES:
        raise place.error(f"{path.name} has more than {TUM_MAX_LINES} lines")
    rows: list[list[float]] = []
    for number, line in enumerate(lines, start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        where = f"{path.name} line {number}"
        if len(fields) != TUM_NUMBERS:
            raise place.error(f"{where}: expected {TUM_NUMBERS} numbers, got {len(fields)}")
        try:
            values = [float(field) for field in fields]
        except ValueError:
            bad = next(field for field in fields if not _parses_as_float(field))
            raise place.error(f"{where}: not a number: {_show(bad[:20])}") from None
        if not all(math.isfinite(value) for value in values):
            raise place.error(f"{where}: numbers must be finite")
        if max(abs(value) for value in values[1:4]) > MAX_EXTENT_M:
            raise place.error(f"{where}: x y z must lie within ±{MAX_EXTENT_M:g}")
        if math.hypot(*values[4:8]) < 1e-9:
            raise place.error(f"{where}: quaternion qx qy qz qw must not be zero")
        if rows and values[0] < rows[-1][0]:
            raise place.error(f"{where}: times must not decrease, got {fields[0]} after {rows[-1][0]:g}")
        rows.append(values)
    if not rows:
        raise place.error(f"{path.name} holds no pose (lines 't x y z qx qy qz qw')")
    table = np.array(rows)
    line_numbers = [number for number, line in enumerate(lines, start=1) if line.split() and not line.split()[0].startswith("#")]
    _check_speed(table[:, 0], table[:, 1:4], lambda row: lambda message: place.error(f"{path.name} line {line_numbers[row]}: {message}"))
    quaternions = table[:, 4:8] / np.linalg.norm(table[:, 4:8], axis=1, keepdims=True)
    return _frozen_keyframes(table[:, 0].copy(), table[:, 1:4].copy(), quaternions)


def _parses_as_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
