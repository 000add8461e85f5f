"""The shadow function: which sample directions are unoccluded from each face."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, cKDTree

from .data import TriangleMesh
from .raycast import RayCaster
from .sh import fibonacci_sphere


@dataclass(frozen=True)
class SphereSampling:
    """Directions spread uniformly on the unit sphere and their triangulation.

    Attributes
    ----------
    directions : (K, 3) unit vectors.
    triangles : (T, 3) indices into ``directions`` (convex hull, T = 2K - 4).
    weights : (K,) quadrature weights: a vertex gets a third of the area of
        each hull triangle around it (the paper's Eq. 13), normalised to sum to 4 pi.
    """

    directions: np.ndarray
    triangles: np.ndarray
    weights: np.ndarray

    def nearest(self, dirs: np.ndarray) -> np.ndarray:
        """(N,) index of the sample direction nearest to each of ``dirs`` (N, 3)."""
        return cKDTree(self.directions).query(np.asarray(dirs, dtype=np.float64))[1]


def sphere_sampling(count: int = 1164) -> SphereSampling:
    """``count`` golden-spiral directions with their convex-hull triangulation.

    The paper uses 1164 directions (2324 triangles).
    """
    dirs = fibonacci_sphere(count)
    tris = ConvexHull(dirs).simplices
    corners = dirs[tris]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    weights = np.zeros(count)
    np.add.at(weights, tris.ravel(), np.repeat(areas / 3.0, 3))
    return SphereSampling(dirs, tris, weights * (4.0 * np.pi / weights.sum()))


@dataclass(frozen=True)
class Visibility:
    """Packed (F, K) visibility bits: bit k of face i is 1 when direction k is
    above the face's plane and unoccluded from its centroid."""

    bits: np.ndarray
    num_directions: int

    def unpack(self, faces: slice | np.ndarray) -> np.ndarray:
        """(n, K) bool visibility of the given faces."""
        return np.unpackbits(self.bits[faces], axis=1, count=self.num_directions).astype(bool)

    def lookup(self, faces: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) bool visibility of pairs (face, direction index)."""
        byte = self.bits[faces, directions >> 3]
        return ((byte >> (7 - (directions & 7))) & 1).astype(bool)


def compute_visibility(caster: RayCaster, sampling: SphereSampling, max_rays: int = 4_000_000,
                       offset: float = 1e-4, progress=None) -> Visibility:
    """Shadow rays from every face centroid to every direction of its upper hemisphere.

    Rays start at the centroid moved ``offset`` x (bounding-box diagonal) along
    the normal. Faces are processed in chunks of at most ``max_rays`` rays, so
    memory stays bounded; the result is stored as bits (F x K / 8 bytes).
    """
    mesh: TriangleMesh = caster.mesh
    normals, centroids = mesh.face_normals, mesh.centroids
    eps = offset * caster.scale
    k = len(sampling.directions)
    bits = np.zeros((mesh.num_faces, (k + 7) // 8), dtype=np.uint8)
    chunk = max(1, max_rays // max(1, k // 2))
    for start in range(0, mesh.num_faces, chunk):
        stop = min(start + chunk, mesh.num_faces)
        up = normals[start:stop] @ sampling.directions.T > 0.0           # (n, K)
        fi, di = np.nonzero(up)
        origins = centroids[start:stop][fi] + eps * normals[start:stop][fi]
        vis = np.zeros_like(up)
        vis[fi, di] = ~caster.occluded(origins, sampling.directions[di])
        bits[start:stop] = np.packbits(vis, axis=1)
        if progress is not None:
            progress(stop - start)
    return Visibility(bits, k)
