"""Procedural geometry -> TriangleMesh (mesh files: :mod:`harness.io.mesh`)."""
from __future__ import annotations

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
