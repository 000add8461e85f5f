"""The stages every method shares: observations, shadow function, reflection matrices."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import sh
from .config import EstimatorConfig
from .data import MultiViewData
from .observations import Observations, gather_observations
from .raycast import RayCaster
from .reflection import diffuse_matrix, lobe_matrix, mirror_directions, mirror_matrix
from .visibility import SphereSampling, Visibility, compute_visibility, sphere_sampling


@dataclass
class Prepared:
    """Inputs of the solvers, computed once per dataset.

    Attributes
    ----------
    all_obs : every observation (for median colours).
    obs : observations kept for the solve (``min_cos_view`` cut).
    c_matrix : (F, M) diffuse matrix C, columns scaled by :func:`diffuse_gains`.
    d_rows : (N, M) specular rows of ``obs`` (:func:`specular_rows`).
    timings : seconds per stage.
    """

    data: MultiViewData
    config: EstimatorConfig
    caster: RayCaster
    sampling: SphereSampling
    visibility: Visibility
    all_obs: Observations
    obs: Observations
    c_matrix: np.ndarray
    d_rows: np.ndarray
    timings: dict = field(default_factory=dict)

    @property
    def c_rows(self) -> np.ndarray:
        """(N, M) diffuse matrix row of each kept observation's face."""
        return self.c_matrix[self.obs.face]


def diffuse_gains(config: EstimatorConfig) -> np.ndarray:
    """Per-coefficient gains that turn the pseudo illumination h into the light of the
    diffuse term: ones (the paper), 1 / (Phong filter) up to ``defilter_order``
    (``diffuse_light='defiltered'``), or at every order (``specular_model='lobe'``,
    where the radiance L = h / filter is modelled exactly). Shape ((L + 1)^2,)."""
    gains = np.ones(config.sh_order + 1)
    f = sh.phong_filter(config.sh_order, config.phong_exponent)
    if config.specular_model == "lobe":
        gains = 1.0 / f
    elif config.diffuse_light == "defiltered":
        gains[: config.defilter_order + 1] = 1.0 / f[: config.defilter_order + 1]
    return sh.expand_per_degree(gains)


def specular_rows(config: EstimatorConfig, faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                  visibility: Visibility) -> np.ndarray:
    """(N, M) rows multiplying h in the specular term, for the configured model."""
    if config.specular_model == "lobe":
        radiance_rows = lobe_matrix(faces, mirror, sampling, visibility, config.sh_order, config.phong_exponent)
        inverse_filter = 1.0 / sh.expand_per_degree(sh.phong_filter(config.sh_order, config.phong_exponent))
        return radiance_rows * inverse_filter[None]
    return mirror_matrix(faces, mirror, sampling, visibility, config.sh_order)


def prepare(data: MultiViewData, config: EstimatorConfig, log=None) -> Prepared:
    """Run the shared stages. ``log`` (optional callable) receives progress lines."""
    say = log or (lambda message: None)
    timings = {}
    t = time.perf_counter()
    caster = RayCaster(data.mesh, config.variant)
    all_obs = gather_observations(caster, data.views, config.min_pixels, pure_pixels=config.pure_pixels)
    normals = data.mesh.face_normals
    cos_view = np.sum(normals[all_obs.face] * all_obs.view_dir, axis=1)
    obs = all_obs.subset(cos_view > config.min_cos_view)
    if len(obs.face) == 0:
        raise ValueError(f"no observation passes min_cos_view={config.min_cos_view}")
    timings["observations"] = time.perf_counter() - t
    say(f"observations: {len(all_obs.face)} (face, view) pairs, {len(obs.face)} kept "
        f"(view within acos({config.min_cos_view}) of the normal)")

    t = time.perf_counter()
    sampling = sphere_sampling(config.directions)
    visibility = compute_visibility(caster, sampling)
    timings["visibility"] = time.perf_counter() - t
    say(f"visibility: {data.mesh.num_faces} faces x {config.directions} directions")

    t = time.perf_counter()
    c_matrix = diffuse_matrix(data.mesh, sampling, visibility, config.sh_order) * diffuse_gains(config)[None]
    mirror = mirror_directions(normals[obs.face], obs.view_dir)
    d_rows = specular_rows(config, obs.face, mirror, sampling, visibility)
    timings["reflection"] = time.perf_counter() - t
    return Prepared(data, config, caster, sampling, visibility, all_obs, obs, c_matrix, d_rows, timings)
