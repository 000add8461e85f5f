"""The forward model: predict the image of any camera from an estimate."""
from __future__ import annotations

import numpy as np

from ..core import sh
from ..core.camera import Camera
from ..core.data import TriangleMesh
from ..core.errors import InputError
from ..rays.raycast import RayCaster
from ..rays.visibility import shadow_function, sphere_sampling
from .estimate import Estimate
from .reflection import mirror_directions


class Predictor:
    """Renders an estimate's reflection model, R = t_d (C . x) + t_s (D . x), per pixel.

    The diffuse matrix and shadow function are computed once; each pixel uses
    its face (centre ray), the mirrored direction of its own view ray, and the
    face's shadow function.

    Parameters
    ----------
    mesh : TriangleMesh (the estimate's face order).
    estimate : Estimate.
    caster : ray queries of ``mesh`` already built (None: built here); the face-ID buffers
        of the cameras it has traced are reused.
    """

    def __init__(self, mesh: TriangleMesh, estimate: Estimate, caster: RayCaster | None = None):
        if estimate.diffuse.shape[0] != mesh.num_faces:
            raise InputError(f"the estimate has {estimate.diffuse.shape[0]} faces, the mesh {mesh.num_faces}")
        if caster is not None and caster.mesh is not mesh:
            raise InputError("Predictor: the caster was built for another mesh")
        self.mesh, self.estimate, self.model = mesh, estimate, estimate.model
        self.caster = caster or RayCaster(mesh, estimate.config.variant)
        self.sampling = sphere_sampling(estimate.config.directions)
        self.visibility = shadow_function(self.caster, self.sampling)
        self.c_matrix = self.model.diffuse_matrix(mesh, self.sampling, self.visibility)

    def light(self, rotation: np.ndarray | None = None) -> np.ndarray:
        """(M, 3) the estimate's light unknown, turned by ``rotation`` (3, 3) when given."""
        x = self.estimate.light
        return x if rotation is None else sh.rotation_matrix(self.estimate.sh_order, rotation) @ x

    def predict(self, camera: Camera, rotation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Predicted image of ``camera``.

        Returns
        -------
        rgb : (H, W, 3) float32 linear; 0 on background and unestimated faces.
        coverage : (H, W) float32, 1 where the pixel centre sees an estimated face (0 off the
            mesh and on unestimated faces, whose colour 0 is no prediction).
        """
        est = self.estimate
        face = self.caster.face_id_buffer(camera).ravel()
        hit = np.nonzero(face >= 0)[0]
        f = face[hit]
        mirror = mirror_directions(self.mesh.face_normals[f], -camera.subpixel_directions(hit, 1).T)
        light = self.light(rotation)
        value = self.model.predict(est.diffuse[f], est.specular[f], (self.c_matrix @ light)[f],
                                   self.model.specular_shading(f, mirror, self.sampling, self.visibility, light))
        rgb = np.zeros((camera.height * camera.width, 3), dtype=np.float32)
        with np.errstate(over="ignore"):   # beyond float32: Inf, which the caller judges (an absurd estimate)
            rgb[hit] = value
        coverage = ((face >= 0) & est.observed[np.maximum(face, 0)]).astype(np.float32)
        return rgb.reshape(camera.height, camera.width, 3), coverage.reshape(camera.height, camera.width)
