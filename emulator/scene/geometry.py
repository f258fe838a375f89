"""Shapes as triangle meshes, in their local frame or placed in the world.

trimesh builds and loads the meshes; the optics casts rays against them with
Embree. Analytic shapes keep their exact form in `model.py` for exact chord
lengths; the meshes here are what Embree sees.
"""

from __future__ import annotations

import stat
from pathlib import Path

import numpy as np
import trimesh

from emulator.scene.model import Box, Cylinder, MeshFile, Pose, Shape, Sphere

MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".stl", ".ply")
MAX_MESH_FILE_BYTES = 256 * 1024 * 1024  # 2 M triangles of binary STL are 100 MB
SPHERE_SUBDIVISIONS = 3
CYLINDER_SECTIONS = 64


MAX_EXTENT_M = 100_000.0  # every coordinate, length, speed (m, m/s) of a scene, and of its meshes, lies within ±100 km


class MeshLoadError(ValueError):
    """A mesh file that cannot be used; the message says why."""


def load_mesh_file(path: Path) -> trimesh.Trimesh:
    """Load a mesh file as one triangle mesh (a glTF scene is flattened)."""
    unsupported = MeshLoadError(f"unsupported mesh format {path.suffix!r} (use {', '.join(MESH_SUFFIXES)})")
    try:
        status = path.stat()
    except OSError as error:
        if path.suffix.lower() not in MESH_SUFFIXES:
            raise unsupported from None
        raise MeshLoadError(f"mesh file not found: {path}" if isinstance(error, FileNotFoundError)
                            else f"cannot read mesh {path}: {error.strerror}") from None
    if not stat.S_ISREG(status.st_mode):  # never open a FIFO (it would block) or a device (a link to /dev/zero)
        raise MeshLoadError(f"mesh {path} is not a regular file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise unsupported
    if status.st_size > MAX_MESH_FILE_BYTES:
        raise MeshLoadError(f"mesh {path.name} is {status.st_size} bytes; at most {MAX_MESH_FILE_BYTES}")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises many kinds for a corrupt file
        raise MeshLoadError(f"cannot read mesh {path.name}: {error}") from error
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshLoadError(f"mesh {path.name} has no triangles")
    _check_vertices(mesh.vertices, path)
    mesh.process()  # merged and cleaned once its numbers are known to be sane (1e300 overflowed in trimesh)
    if len(mesh.faces) == 0:
        raise MeshLoadError(f"mesh {path.name} has no triangles")
    return mesh


def _check_vertices(vertices: np.ndarray, path: Path) -> None:
    """Every coordinate finite and within ±MAX_EXTENT_M, as a scene file's own must be."""
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise MeshLoadError(f"mesh {path.name}: vertex {int(bad.argmax())} is not finite")
    far = (np.abs(vertices) > MAX_EXTENT_M).any(axis=1)
    if far.any():
        raise MeshLoadError(f"mesh {path.name}: vertex {int(far.argmax())} lies beyond ±{MAX_EXTENT_M:g} m")


def shape_mesh(shape: Shape) -> trimesh.Trimesh:
    """The shape as a triangle mesh in its local frame, centred on the origin."""
    if isinstance(shape, Box):
        return trimesh.creation.box(extents=shape.size)
    if isinstance(shape, Sphere):
        return trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=shape.radius)
    if isinstance(shape, Cylinder):
        return trimesh.creation.cylinder(radius=shape.radius, height=shape.height, sections=CYLINDER_SECTIONS)
    if isinstance(shape, MeshFile):
        return load_mesh_file(shape.path)
    raise TypeError(f"unknown shape {shape!r}")


def world_mesh(shape: Shape, pose: Pose) -> trimesh.Trimesh:
    """The shape's mesh placed in the world frame by `pose`."""
    mesh = shape_mesh(shape).copy()
    mesh.apply_transform(pose.matrix())
    return mesh


def world_to_local(pose: Pose, points: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and directions expressed in the pose's local frame."""
    rotation = pose.rotation_matrix()
    local_points = (np.asarray(points) - np.asarray(pose.position)) @ rotation
    local_directions = np.asarray(directions) @ rotation
    return local_points, local_directions
