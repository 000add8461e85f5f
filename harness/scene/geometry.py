"""Geometry kinds -> TriangleMesh: procedural bodies and mesh files.

Each kind of ``[geometry] type`` is one function registered with :func:`geometry_kind`:
it takes the validated geometry spec and the scene's seed and returns the mesh and its
per-vertex texture coordinates (None when it has none). A new kind is one such function
here (its spec keys in :class:`harness.scene.spec.GeometrySpec`).
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import trimesh

from estimator import TriangleMesh
from harness.io.mesh import load_mesh_with_uv

Builder = Callable[..., "tuple[TriangleMesh, np.ndarray | None]"]
GEOMETRY_KINDS: dict[str, Builder] = {}


def geometry_kind(name: str) -> Callable[[Builder], Builder]:
    """Decorator: register a builder ``(spec, seed) -> (mesh, uv or None)`` as ``type = name``."""
    def register(builder: Builder) -> Builder:
        GEOMETRY_KINDS[name] = builder
        return builder
    return register


def build_geometry(spec, seed: int) -> tuple[TriangleMesh, np.ndarray | None]:
    """The mesh of a validated geometry spec (``spec.type`` a registered kind)."""
    return GEOMETRY_KINDS[spec.type](spec, seed)


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


def bumpy(subdivisions: int, radius: float = 1.0, lobes: int = 4, depth: float = 0.3, bumps: float = 0.08,
          frequency: int = 6, seed: int = 0) -> TriangleMesh:
    """The :func:`blob` with seeded random bumps: concavities of many sizes that shadow
    themselves and reflect light onto each other.

    The blob's radius is multiplied by 1 + ``bumps`` x b(d), b a random combination of
    real SH of degrees 3 to ``frequency`` (seeded) scaled to unit RMS over the sphere.
    """
    from estimator import sh

    base = blob(subdivisions, radius, lobes, depth)
    d = base.vertices / np.linalg.norm(base.vertices, axis=1, keepdims=True)
    rng = np.random.default_rng(seed)
    coeffs = rng.standard_normal(sh.num_coeffs(frequency))
    coeffs[: sh.num_coeffs(2)] = 0.0
    field = sh.basis(frequency, d) @ coeffs
    field /= max(float(np.sqrt(np.mean(field ** 2))), 1e-12)
    return TriangleMesh(base.vertices * (1.0 + bumps * field)[:, None], base.faces)


@geometry_kind("icosphere")
def _icosphere_kind(spec, seed: int):
    return icosphere(spec.subdivisions, spec.radius), None


@geometry_kind("blob")
def _blob_kind(spec, seed: int):
    return blob(spec.subdivisions, spec.radius, spec.lobes, spec.depth), None


@geometry_kind("bumpy")
def _bumpy_kind(spec, seed: int):
    return bumpy(spec.subdivisions, spec.radius, spec.lobes, spec.depth, spec.bumps, spec.frequency, seed), None


@geometry_kind("mesh")
def _mesh_kind(spec, seed: int):
    return load_mesh_with_uv(spec.file)
