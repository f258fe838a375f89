"""Mesh shapes: resolved relative to the scene file, loaded at load time, closed when they hold smoke."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from emulator.errors import SceneError
from emulator.scene import MeshFile, load_scene


def write_closed_box(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(1.0, 2.0, 3.0)).export(path)
    return path


def write_open_box(path: Path) -> Path:
    """A box with one triangle removed: a hole, so it encloses no volume."""
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    open_box = trimesh.Trimesh(box.vertices, np.delete(box.faces, 0, axis=0), process=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    open_box.export(path)
    return path


def scene_text(table: str, mesh: str) -> str:
    if table == "objects":
        return f'[[objects]]\nname = "thing"\nmesh = "{mesh}"\n'
    return f'[[smoke.regions]]\nname = "cloud"\nmesh = "{mesh}"\ndensity = 0.01\n'


def test_a_closed_mesh_may_hold_smoke_and_its_path_becomes_absolute(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    mesh_path = write_closed_box(tmp_path / "scenes" / "meshes" / "room.stl")
    scene_path = tmp_path / "scenes" / "x.toml"
    scene_path.write_text(scene_text("regions", "meshes/room.stl"))
    monkeypatch.chdir(tmp_path)  # the mesh path is relative to the scene file, not the working directory
    region = load_scene(scene_path).regions[0]
    assert region.shape == MeshFile(mesh_path.resolve())
    assert region.shape.path.is_absolute()


def test_an_open_mesh_cannot_hold_smoke(tmp_path: Path) -> None:
    write_open_box(tmp_path / "open.stl")
    assert not trimesh.load(tmp_path / "open.stl", force="mesh").is_watertight
    scene_path = tmp_path / "x.toml"
    scene_path.write_text(scene_text("regions", "open.stl"))
    with pytest.raises(SceneError) as raised:
        load_scene(scene_path)
    assert str(raised.value) == (
        "x.toml: smoke.regions[0].mesh: mesh open.stl is not watertight; a smoke region must be a closed volume"
    )


def test_an_open_mesh_is_fine_as_a_solid_surface(tmp_path: Path) -> None:
    mesh_path = write_open_box(tmp_path / "open.stl")
    scene_path = tmp_path / "x.toml"
    scene_path.write_text(scene_text("objects", "open.stl"))
    assert load_scene(scene_path).objects[0].shape == MeshFile(mesh_path.resolve())


@pytest.mark.parametrize("table", ["objects", "regions"])
def test_a_missing_mesh_file_is_named(tmp_path: Path, table: str) -> None:
    scene_path = tmp_path / "x.toml"
    scene_path.write_text(scene_text(table, "meshes/gone.obj"))
    where = "objects[0]" if table == "objects" else "smoke.regions[0]"
    with pytest.raises(SceneError) as raised:
        load_scene(scene_path)
    assert str(raised.value) == f"x.toml: {where}.mesh: mesh file not found: {tmp_path.resolve() / 'meshes' / 'gone.obj'}"


def test_a_corrupt_mesh_file_is_rejected_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "broken.ply").write_bytes(b"ply\nformat nonsense\n\x00\x01")
    scene_path = tmp_path / "x.toml"
    scene_path.write_text(scene_text("objects", "broken.ply"))
    with pytest.raises(SceneError) as raised:
        load_scene(scene_path)
    message = str(raised.value)
    assert message.startswith("x.toml: objects[0].mesh: ")
    assert "broken.ply" in message and "\n" not in message


@pytest.mark.parametrize(("vertex", "expected"), [
    ("1e300 0 0", "vertex 3 lies beyond ±100000 m"), ("nan 0 0", "vertex 3 is not finite"), ("0 -2e5 0", "vertex 3 lies beyond ±100000 m"),
])
@pytest.mark.parametrize("table", ["objects", "regions"])
def test_a_mesh_vertex_outside_the_scenes_bounds_is_refused_in_one_line(tmp_path: Path, table: str, vertex: str, expected: str) -> None:
    """A scene file's coordinates lie within ±100 km; a mesh's were taken as they came (1e300 ran, with
    numpy's overflow warnings from trimesh and the ray tracer; NaN silently)."""
    faces = "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n"
    (tmp_path / "far.obj").write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nv {vertex}\n" + faces)
    scene_path = tmp_path / "x.toml"
    scene_path.write_text(scene_text(table, "far.obj"))
    where = "objects[0]" if table == "objects" else "smoke.regions[0]"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused before trimesh computes with them
        with pytest.raises(SceneError) as raised:
            load_scene(scene_path)
    assert str(raised.value) == f"x.toml: {where}.mesh: mesh far.obj: {expected}"


def test_a_mesh_linked_to_a_device_is_named_not_a_regular_file(tmp_path: Path) -> None:
    """A link to /dev/zero resolves to a path with no suffix: it read "unsupported mesh format ''"."""
    (tmp_path / "zero.stl").symlink_to("/dev/zero")
    scene_path = tmp_path / "x.toml"
    scene_path.write_text(scene_text("objects", "zero.stl"))
    with pytest.raises(SceneError) as raised:
        load_scene(scene_path)
    assert str(raised.value) == "x.toml: objects[0].mesh: mesh /dev/zero is not a regular file"
