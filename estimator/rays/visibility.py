"""The shadow function: which sample directions are unoccluded from each face."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, cKDTree

from ..core.data import TriangleMesh
from ..core.errors import InputError
from ..core.settings import Section
from ..core.sh import fibonacci_sphere
from .raycast import RayCaster

MAX_DIRECTIONS = 65_536   # 0.9-degree spacing, 56x the paper's; the shadow bits grow as faces x directions
MAX_SHADOW_BYTES = 2 * 2**30   # the shadow bits, checked before allocation (1.3M faces x 1164: 0.2 GiB)


@dataclass
class VisibilityConfig(Section):
    """The shadow function's sampling of the sphere.

    Attributes
    ----------
    directions : sample directions of the shadow function (the paper's 1164); at most
        :data:`MAX_DIRECTIONS`.
    """

    directions: int = 1164

    def check(self):
        return [(12 <= self.directions <= MAX_DIRECTIONS, f"directions must lie in [12, {MAX_DIRECTIONS}]")]


@dataclass(frozen=True)
class SphereSampling:
    """Directions spread uniformly on the unit sphere with quadrature weights.

    Attributes
    ----------
    directions : (K, 3) unit vectors.
    weights : (K,) quadrature weights: a vertex gets a third of the area of
        each hull triangle around it (the paper's Eq. 13), normalised to sum to 4 pi.
    """

    directions: np.ndarray
    weights: np.ndarray

    def nearest(self, dirs: np.ndarray) -> np.ndarray:
        """(N,) index of the sample direction nearest to each of ``dirs`` (N, 3)."""
        return cKDTree(self.directions).query(np.asarray(dirs, dtype=np.float64))[1]


def sphere_sampling(count: int = 1164) -> SphereSampling:
    """``count`` golden-spiral directions, weighted by their convex-hull triangulation.

    The paper uses 1164 directions (2324 hull triangles).
    """
    dirs = fibonacci_sphere(count)
    tris = ConvexHull(dirs).simplices
    corners = dirs[tris]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    weights = np.zeros(count)
    np.add.at(weights, tris.ravel(), np.repeat(areas / 3.0, 3))
    return SphereSampling(dirs, weights * (4.0 * np.pi / weights.sum()))


@dataclass(frozen=True)
class Visibility:
    """Packed (F, K) visibility bits: bit k of face i is 1 when direction k is
    above the face's plane and unoccluded from its centroid."""

    bits: np.ndarray
    num_directions: int
    # what is computed from these bits once and read again (the diffuse rows of each held-out
    # estimate and prediction of a pose refinement), by key; read-only arrays
    derived: dict = field(default_factory=dict, repr=False, compare=False)

    def unpack(self, faces: slice | np.ndarray) -> np.ndarray:
        """(n, K) bool visibility of the given faces."""
        return np.unpackbits(self.bits[faces], axis=1, count=self.num_directions).astype(bool)

    def lookup(self, faces: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) bool visibility of pairs (face, direction index)."""
        byte = self.bits[faces, directions >> 3]
        return ((byte >> (7 - (directions & 7))) & 1).astype(bool)


def shadow_function(caster: RayCaster, sampling: SphereSampling) -> Visibility:
    """:func:`compute_visibility` of ``caster``'s mesh, computed once per caster and sampling
    and kept on the caster (read-only): it depends on the mesh alone, and a run asks for it
    again for each held-out estimate and prediction (pose refinement, cross-validation)."""
    key = np.ascontiguousarray(sampling.directions).tobytes()
    held = caster.shadow_functions.get(key)
    if held is None:
        held = compute_visibility(caster, sampling)
        held.bits.flags.writeable = False
        caster.shadow_functions[key] = held
    return held


def compute_visibility(caster: RayCaster, sampling: SphereSampling, max_rays: int = 8_000_000,
                       offset: float = 1e-4, progress=None) -> Visibility:
    """Shadow rays from every face centroid to every direction of its upper hemisphere.

    Rays start at the centroid moved ``offset`` x (bounding-box diagonal) along
    the normal. Everything runs in Dr.Jit: the (face, direction) pairs of each
    chunk are enumerated from the lane index, the upper-hemisphere pairs are
    compacted (``dr.compress``, so the tracer gets only real rays), traced with
    ``scene.ray_test``, and scattered back; no per-ray array is built in
    Python. Faces are processed in chunks of at most ``max_rays`` pairs, so
    memory stays bounded; the result is stored as bits (F x K / 8 bytes).
    """
    mi = caster.mi
    import drjit as dr

    mesh: TriangleMesh = caster.mesh
    normals = mesh.face_normals
    origins = mesh.centroids + offset * caster.scale * normals
    k = len(sampling.directions)

    def vec(cls, a):
        return cls(*(np.ascontiguousarray(a[:, i], dtype=np.float32) for i in range(3)))

    size = mesh.num_faces * ((k + 7) // 8)
    if size > MAX_SHADOW_BYTES:
        raise InputError(f"the shadow function of {mesh.num_faces} faces x {k} directions needs {size / 2**30:.1f} GiB "
                         f"(at most {MAX_SHADOW_BYTES / 2**30:g} GiB): lower directions")
    o_all, n_all, d_all = vec(mi.Point3f, origins), vec(mi.Vector3f, normals), vec(mi.Vector3f, sampling.directions)
    bits = np.zeros((mesh.num_faces, (k + 7) // 8), dtype=np.uint8)
    chunk = max(1, max_rays // k)
    for start in range(0, mesh.num_faces, chunk):
        stop = min(start + chunk, mesh.num_faces)
        lanes = (stop - start) * k
        lane = dr.arange(mi.UInt32, lanes)
        face = lane // k + start
        up = dr.dot(dr.gather(mi.Vector3f, n_all, face), dr.gather(mi.Vector3f, d_all, lane % k)) > 0
        dr.eval(up)
        pair = dr.compress(up)
        face = pair // k + start
        d = dr.gather(mi.Vector3f, d_all, pair % k)
        hit = caster.scene.ray_test(mi.Ray3f(dr.gather(mi.Point3f, o_all, face), d))
        visible = dr.zeros(mi.Bool, lanes)
        dr.scatter(visible, ~hit, pair)
        visible = np.asarray(visible, dtype=bool).reshape(stop - start, k)
        bits[start:stop] = np.packbits(visible, axis=1)
        if progress is not None:
            progress(stop - start)
    return Visibility(bits, k)
