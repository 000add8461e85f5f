"""Light reflected by the object onto itself, from the observed radiance (one bounce).

Where a face's shadow function is 0 the distant light is blocked by another face of the
object, and that face's own outgoing radiance arrives instead. With Lambertian faces that
radiance is what the images show of it, so the indirect part of the diffuse shading needs
no unknown:

    I_f = (1/pi) sum_k w_k max(0, w_k . n_f) (1 - s_f(w_k)) R_{g(f, k)}

with g(f, k) the face hit from f along direction k and R its diffuse radiance. The shading
of face f is then C_f . L + I_f (same units as the radiance: the light's scale, which the
unit-DC gauge leaves free, becomes an unknown of the fit).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..core.data import TriangleMesh
from ..core.settings import Section
from ..rays.raycast import RayCaster
from ..rays.visibility import SphereSampling, Visibility


@dataclass
class IndirectConfig(Section):
    """One bounce of light between the object's own faces (:func:`indirect_shading`).

    Attributes
    ----------
    interreflection : add to each face's shading the light the object reflects onto it (from
        the observed radiance of the faces its blocked directions hit); the light's scale
        becomes an unknown.
    """

    interreflection: bool = True


def indirect_shading(caster: RayCaster, sampling: SphereSampling, visibility: Visibility, radiance: np.ndarray,
                     max_rays: int = 4_000_000, offset: float = 1e-4) -> np.ndarray:
    """(F, 3) one-bounce indirect diffuse shading of every face, traced in chunks of faces (memory
    bounded by ``max_rays``; :func:`indirect_transfer` holds the same operator whole, for a solve
    that asks again).

    Parameters
    ----------
    radiance : (F, 3) diffuse radiance of each face (0 where unknown); a ray that hits no face
        of ``caster.mesh`` (a miss, or a face in none of a
        :class:`~estimator.rays.raycast.ClusterCaster`'s clusters) adds nothing.
    max_rays : rays traced per batch (faces are taken in chunks of max_rays / K).
    offset : ray origins sit this fraction of the bounding-box diagonal above the centroid.
    """
    f = caster.mesh.num_faces
    out = np.zeros((f, 3))
    for start, stop, rows, hit, weight in _bounces(caster, sampling, visibility, max_rays, offset):
        contribution = weight[:, None] * radiance[hit]
        out[start:stop] = np.stack([np.bincount(rows, contribution[:, c], minlength=stop - start)
                                    for c in range(3)], axis=1)
    return out


def indirect_transfer(caster: RayCaster, sampling: SphereSampling, visibility: Visibility,
                      max_rays: int = 4_000_000, offset: float = 1e-4) -> sparse.csr_matrix:
    """(F, F) the operator T of :func:`indirect_shading`, whose result is T @ radiance: T[f, g]
    sums (1/pi) w_k max(0, w_k . n_f) over the directions k blocked at f by face g. It depends
    on the mesh alone, so a solve that shades several radiances (the default's fit and its coat
    refits) traces the rays once; it holds one entry per blocked direction that hits a face,
    which is why :func:`indirect_shading` streams instead for a problem shaded once."""
    f = caster.mesh.num_faces
    parts = [(start + rows, hit, weight) for start, _, rows, hit, weight in
             _bounces(caster, sampling, visibility, max_rays, offset)]
    if not parts:
        return sparse.csr_matrix((f, f))
    face, hit, weight = (np.concatenate(column) for column in zip(*parts))
    return sparse.csr_matrix((weight, (face, hit)), shape=(f, f))


def _bounces(caster: RayCaster, sampling: SphereSampling, visibility: Visibility, max_rays: int, offset: float):
    """Per chunk of faces [start, stop): the face (relative to start), the face hit and the
    weight (1/pi) w_k max(0, w_k . n_f) of every blocked direction k that hits a face."""
    mesh: TriangleMesh = caster.mesh
    f, k = mesh.num_faces, len(sampling.directions)
    normals, centroids = mesh.face_normals, mesh.centroids
    weight = sampling.weights / np.pi
    chunk = max(1, max_rays // k)
    for start in range(0, f, chunk):
        stop = min(start + chunk, f)
        cos = normals[start:stop] @ sampling.directions.T                                 # (n, K)
        blocked = (cos > 0) & ~visibility.unpack(slice(start, stop))
        rows, cols = np.nonzero(blocked)
        if not len(rows):
            continue
        faces = start + rows
        origins = centroids[faces] + offset * caster.scale * normals[faces]
        hit = caster.first_hit_faces(origins, sampling.directions[cols])
        seen = hit >= 0
        yield start, stop, rows[seen], hit[seen], (weight[cols] * cos[rows, cols])[seen]
