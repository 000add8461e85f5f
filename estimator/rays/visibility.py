"""The shadow function: which sample directions are unoccluded from each face."""
from __future__ import annotations

import functools
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
        """(N,) index of the sample direction nearest to each of ``dirs`` (N, 3), by
        :func:`nearest_candidates` (exact; 2.4x faster than a k-d tree query at the paper's
        1164 directions, and every specular row and predicted pixel makes one)."""
        dirs = np.asarray(dirs, dtype=np.float64)
        if not np.all(np.isfinite(dirs)):
            raise InputError("nearest sample direction: the directions must be finite")
        candidates = self._candidates
        if candidates is None:   # directions that do not surround the origin
            return cKDTree(self.directions).query(dirs)[1]
        rows, cols = candidates.shape[:2]
        theta = np.arccos(np.clip(dirs[:, 2] / np.maximum(np.linalg.norm(dirs, axis=1), 1e-300), -1.0, 1.0))
        phi = np.arctan2(dirs[:, 1], dirs[:, 0])
        row = np.minimum((theta * (rows / np.pi)).astype(np.int64), rows - 1)
        col = np.minimum(((phi + np.pi) * (cols / (2 * np.pi))).astype(np.int64), cols - 1)
        near = candidates[row, col]                                                    # (N, K)
        cosine = sum(self.directions[:, k][near] * dirs[:, k, None] for k in range(3))
        return near[np.arange(len(near)), np.argmax(cosine, axis=1)]

    @functools.cached_property
    def _candidates(self) -> np.ndarray | None:
        return nearest_candidates(self.directions)


def nearest_candidates(directions: np.ndarray) -> np.ndarray | None:
    """(rows, cols, K) int: for each cell of a latitude-longitude grid (polar axis +Z), the
    sample directions (K, 3) one of which is nearest to any point of the cell, padded by
    repeating the last; None when the directions do not surround the origin.

    Every point of the sphere lies within the covering radius R of some sample: R is the
    largest angular radius of the circles through the convex hull's facets (the hull of
    points on a sphere is their spherical Delaunay triangulation, each point lies in the cap
    of the facet its radius crosses, and no point of a triangle is further than its
    circumradius from all of its corners). A cell whose corners lie within rho of its centre
    therefore keeps the samples within rho + R of that centre. Cells of half the samples'
    mean spacing keep a handful (at most 6 of the paper's 1164 directions).
    """
    hull = ConvexHull(directions)
    plane = -hull.equations[:, 3]            # each facet's plane: normal . x = plane, unit normals
    if np.any(plane <= 1e-9):
        return None
    cover = float(np.arccos(np.clip(plane.min(), -1.0, 1.0)))
    spacing = np.sqrt(4.0 * np.pi / len(directions))
    rows = max(int(np.ceil(2.0 * np.pi / spacing)), 4)
    cols = 2 * rows
    theta = np.linspace(0.0, np.pi, rows + 1)
    phi = np.linspace(-np.pi, np.pi, cols + 1)

    def unit(t, p):
        return np.stack(np.broadcast_arrays(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)), axis=-1)

    t_mid, p_mid = 0.5 * (theta[:-1] + theta[1:]), 0.5 * (phi[:-1] + phi[1:])
    centre = unit(t_mid[:, None], p_mid[None, :])                                     # (rows, cols, 3)
    # the farthest point of a cell from its centre is a corner (distance grows along each edge)
    corners = [unit(t[:, None], p[None, :]) for t in (theta[:-1], theta[1:]) for p in (phi[:-1], phi[1:])]
    rho = np.max([np.arccos(np.clip(np.sum(c * centre, axis=-1), -1.0, 1.0)) for c in corners], axis=0)
    reach = np.minimum(rho + cover + 1e-9, np.pi).ravel()
    found = cKDTree(directions).query_ball_point(centre.reshape(-1, 3), 2.0 * np.sin(reach / 2.0))
    counts = np.array([len(f) for f in found])
    width = int(counts.max())
    flat = np.concatenate([np.asarray(f, dtype=np.int64) for f in found])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.minimum(np.arange(width)[None, :], counts[:, None] - 1)                # repeat the last one
    return flat[starts[:, None] + slot].reshape(rows, cols, width)


@functools.lru_cache(maxsize=8)
def sphere_sampling(count: int = 1164) -> SphereSampling:
    """``count`` golden-spiral directions, weighted by their convex-hull triangulation (one
    read-only sampling per count, shared by every estimate and prediction of a process, with
    its nearest-direction lookup).

    The paper uses 1164 directions (2324 hull triangles).
    """
    dirs = fibonacci_sphere(count)
    tris = ConvexHull(dirs).simplices
    corners = dirs[tris]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    weights = np.zeros(count)
    np.add.at(weights, tris.ravel(), np.repeat(areas / 3.0, 3))
    weights *= 4.0 * np.pi / weights.sum()
    dirs.flags.writeable = weights.flags.writeable = False
    return SphereSampling(dirs, weights)


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
