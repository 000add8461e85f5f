"""Meshes for the estimator's unit tests, built with trimesh (no harness)."""
from __future__ import annotations

import numpy as np
import trimesh

from estimator import TriangleMesh


def sphere(subdivisions: int) -> TriangleMesh:
    """Unit geodesic sphere, 20 x 4^subdivisions outward-facing faces."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return TriangleMesh(np.asarray(s.vertices), np.asarray(s.faces))


def lobed(subdivisions: int, lobes: int = 3, depth: float = 0.3) -> TriangleMesh:
    """A sphere with ``lobes`` bulges around the equator between concave valleys, which shadow
    their faces: radius 1 + depth x cos(lobes x azimuth) x sin^2(polar angle from +Y)."""
    s = sphere(subdivisions)
    d = s.vertices
    radius = 1.0 + depth * np.cos(lobes * np.arctan2(d[:, 0], d[:, 2])) * (1.0 - d[:, 1] ** 2)
    return TriangleMesh(d * radius[:, None], s.faces)


def with_slivers(mesh: TriangleMesh, faces: np.ndarray, depth: float = 0.03) -> tuple[TriangleMesh, np.ndarray]:
    """``mesh`` with each of ``faces`` (K,) (a, b, c) split at the point p a ``depth`` share of
    the way from the midpoint of a-b towards c: (b, c, p) keeps its place, (c, a, p) and the
    sliver (a, b, p) along a-b (about ``depth`` / 2 of its area, sharing a-b with the face
    beyond) are appended, the slivers last. Returns the mesh and the slivers' indices (K,)."""
    a, b, c = (mesh.faces[faces, k] for k in range(3))
    middle = 0.5 * (mesh.vertices[a] + mesh.vertices[b])
    points = middle + depth * (mesh.vertices[c] - middle)
    p = len(mesh.vertices) + np.arange(len(faces))
    split = mesh.faces.copy()
    split[faces] = np.stack([b, c, p], axis=1)
    others, slivers = np.stack([c, a, p], axis=1), np.stack([a, b, p], axis=1)
    out = TriangleMesh(np.vstack([mesh.vertices, points]), np.vstack([split, others, slivers]))
    return out, mesh.num_faces + len(faces) + np.arange(len(faces))
