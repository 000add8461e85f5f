"""The forward model: predict the image of any camera from an estimate."""
from __future__ import annotations

import numpy as np

from . import sh
from .camera import Camera
from .data import TriangleMesh
from .methods import Estimate
from .pipeline import diffuse_gains, specular_rows
from .raycast import RayCaster
from .reflection import diffuse_matrix, mirror_directions
from .visibility import compute_visibility, sphere_sampling


class Predictor:
    """Renders R = t_d sum h C + t_s sum h D per pixel, with the estimate's own settings.

    The diffuse matrix and shadow function are computed once; each pixel uses
    its face (centre ray), the mirrored direction of its own view ray, and the
    face's shadow function.

    Parameters
    ----------
    mesh : TriangleMesh (the estimate's face order).
    estimate : Estimate.
    """

    def __init__(self, mesh: TriangleMesh, estimate: Estimate):
        if estimate.diffuse.shape[0] != mesh.num_faces:
            raise ValueError(f"the estimate has {estimate.diffuse.shape[0]} faces, the mesh {mesh.num_faces}")
        self.mesh, self.estimate = mesh, estimate
        cfg = estimate.config
        self.caster = RayCaster(mesh, cfg.variant)
        self.sampling = sphere_sampling(cfg.directions)
        self.visibility = compute_visibility(self.caster, self.sampling)
        self.c_matrix = diffuse_matrix(mesh, self.sampling, self.visibility, estimate.sh_order) \
            * diffuse_gains(cfg)[None]

    def illumination(self, rotation: np.ndarray | None = None, light: np.ndarray | None = None) -> np.ndarray:
        """(M, 3) pseudo illumination (or ``light``), turned by ``rotation`` (3, 3) when given."""
        h = self.estimate.sh if light is None else light
        return h if rotation is None else sh.rotation_matrix(self.estimate.sh_order, rotation) @ h

    def predict(self, camera: Camera, rotation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Predicted image of ``camera``.

        Returns
        -------
        rgb : (H, W, 3) float32 linear; 0 on background and unestimated faces.
        coverage : (H, W) float32, 1 where the pixel centre sees the mesh.
        """
        est, cfg = self.estimate, self.estimate.config
        h = self.illumination(rotation, est.light_unknown)
        origins, dirs = camera.pixel_rays()
        face, _ = self.caster.first_hits(origins, dirs)
        hit = np.nonzero(face >= 0)[0]
        f = face[hit]
        mirror = mirror_directions(self.mesh.face_normals[f], -dirs[hit])
        d_rows = specular_rows(cfg, f, mirror, self.sampling, self.visibility)
        value = est.diffuse[f] * (self.c_matrix[f] @ h) + est.specular[f] * (d_rows @ h)
        rgb = np.zeros((camera.height * camera.width, 3), dtype=np.float32)
        rgb[hit] = value
        coverage = (face >= 0).astype(np.float32)
        return rgb.reshape(camera.height, camera.width, 3), coverage.reshape(camera.height, camera.width)
