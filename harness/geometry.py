"""Procedural geometry and mesh files -> TriangleMesh (face order preserved)."""
from __future__ import annotations

import os

import numpy as np
import trimesh

from estimator.data import TriangleMesh


def icosphere(subdivisions: int, radius: float = 1.0) -> TriangleMesh:
    """Geodesic sphere with 20 * 4^subdivisions faces, outward facing, flat shaded."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return TriangleMesh(np.asarray(s.vertices), np.asarray(s.faces))


def blob(subdivisions: int, radius: float = 1.0, lobes: int = 4, depth: float = 0.3) -> TriangleMesh:
    """A non-convex star-shaped body that shadows itself.

    The icosphere is displaced radially to
    r = radius * (1 + depth * cos(lobes * phi) * sin(theta)^2) * (1 - 0.15 cos(2 theta)),
    with theta measured from +Y: ``lobes`` bulges around the equator separated by
    concave valleys, and a waist that makes the poles concave-adjacent.
    """
    if not 0.0 <= depth < 1.0:
        raise ValueError(f"geometry.depth must lie in [0, 1), got {depth}")
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    d = np.asarray(s.vertices)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    cos_t = d[:, 1]
    sin2 = 1.0 - cos_t ** 2
    phi = np.arctan2(d[:, 0], -d[:, 2])
    r = radius * (1.0 + depth * np.cos(lobes * phi) * sin2) * (1.0 - 0.15 * (2 * cos_t ** 2 - 1))
    return TriangleMesh(d * r[:, None], np.asarray(s.faces))


def load_mesh_file(path: str | os.PathLike) -> TriangleMesh:
    """Load a triangle mesh file without merging, dropping or reordering faces."""
    return load_mesh_with_uv(path)[0]


def load_mesh_with_uv(path: str | os.PathLike) -> tuple[TriangleMesh, np.ndarray | None]:
    """(mesh, per-vertex texture coordinates (V, 2) or None) of a mesh file, face order kept."""
    path = str(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        loaded = trimesh.load(path, process=False, force="mesh")
    except Exception as exc:
        raise ValueError(f"cannot read mesh file {path}: {exc}") from exc
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))))
    if faces.size == 0:
        raise ValueError(f"mesh file {path} has no faces")
    uv = getattr(getattr(loaded, "visual", None), "uv", None)
    uv = None if uv is None or len(uv) != len(loaded.vertices) else np.asarray(uv, dtype=np.float64)
    return TriangleMesh(np.asarray(loaded.vertices), faces), uv


def save_mesh_ply(mesh: TriangleMesh, path: str | os.PathLike) -> None:
    """Write a binary PLY in the mesh's exact vertex and face order."""
    t = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    t.export(str(path), file_type="ply")
