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
