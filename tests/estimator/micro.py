"""A micro scene built from the estimator alone (no harness): an icosphere of two uniform
regions with a Phong specular, lit by an order-2 SH light, seen by 8 cameras and rendered by
the estimator's own forward model (:class:`estimator.Predictor`), so its images follow the
paper's model exactly."""
from __future__ import annotations

import numpy as np
import trimesh

from estimator import Camera, Estimate, EstimatorConfig, MultiViewData, Predictor, TriangleMesh, View, look_at, sh

ORDER = 2
SIZE = 40


def micro_config(**overrides) -> EstimatorConfig:
    """Settings scaled to the micro scene: order-2 light, 300 shadow directions."""
    return EstimatorConfig(**{"sh_order": ORDER, "directions": 300, "auto_pose": 0.0, **overrides})


def micro_scene(config: EstimatorConfig | None = None, specular: float = 0.2, mesh: TriangleMesh | None = None,
                size: int = SIZE) -> tuple[MultiViewData, Estimate]:
    """The views (``size`` pixels square) and the true estimate (per-face albedos, the light)
    they were rendered from; ``specular``: every face's grey specular albedo (a Phong lobe of
    exponent 10; 0: matte); ``mesh``: another mesh about the origin than the icosphere (its
    faces above y = 0.2 the first region)."""
    config = config or micro_config()
    if mesh is None:
        ico = trimesh.creation.icosphere(subdivisions=2)
        mesh = TriangleMesh(np.asarray(ico.vertices), np.asarray(ico.faces))
    f = mesh.num_faces
    top = mesh.centroids[:, 1] > 0.2
    diffuse = np.where(top[:, None], [0.7, 0.3, 0.1], [0.1, 0.4, 0.6])
    specular = np.full((f, 3), float(specular))
    radiance = np.zeros((sh.num_coeffs(ORDER), 3))
    radiance[0] = 1.0
    radiance[sh.index(1, 1)] = [0.5, 0.45, 0.4]     # brighter towards +Y
    radiance[sh.index(1, -1)] = [0.2, 0.2, 0.25]
    truth = Estimate(diffuse, specular, sh.pseudo_illumination(radiance, 10.0, ORDER), np.zeros(f, np.int64),
                     np.ones(f, bool), "truth", config, radiance_sh=radiance)
    predictor = Predictor(mesh, truth)
    views = []
    for k in range(8):
        azimuth, elevation = 2 * np.pi * k / 8, (0.5 if k % 2 else -0.3)
        eye = 3.0 * np.array([np.cos(elevation) * np.sin(azimuth), np.sin(elevation),
                              np.cos(elevation) * np.cos(azimuth)])
        camera = Camera(look_at(eye, np.zeros(3)), size, size, size / 2, size / 2, size, size)
        rgb, coverage = predictor.predict(camera)
        views.append(View(f"view{k}", camera, rgb, coverage))
    return MultiViewData(mesh, views), truth
