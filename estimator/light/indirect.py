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
    """(F, 3) one-bounce indirect diffuse shading of every face.

    Parameters
    ----------
    radiance : (F, 3) diffuse radiance of each face (0 where unknown); a ray that hits no face
        of ``caster.mesh`` (a miss, or a face in none of a
        :class:`~estimator.rays.raycast.ClusterCaster`'s clusters) adds nothing.
    max_rays : rays traced per batch (faces are taken in chunks of max_rays / K).
    offset : ray origins sit this fraction of the bounding-box diagonal above the centroid.
    """
    mesh: TriangleMesh = caster.mesh
    f, k = mesh.num_faces, len(sampling.directions)
    normals, centroids = mesh.face_normals, mesh.centroids
    weight = sampling.weights / np.pi
    out = np.zeros((f, 3))
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
        contribution = (weight[cols] * cos[rows, cols])[seen, None] * radiance[hit[seen]]
        out[start:stop] = np.stack([np.bincount(rows[seen], contribution[:, c], minlength=stop - start)
                                    for c in range(3)], axis=1)
    return out
