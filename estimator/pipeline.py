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
    d_rows : (N, M) specular rows of ``obs`` (:func:`specular_rows`). Both multiply the
        solver's light unknown: h, or L for the lobe model (:func:`radiance_unknown`).
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


def radiance_unknown(config: EstimatorConfig) -> bool:
    """True when the solver's light unknown is the radiance L (``specular_model='lobe'``),
    False when it is the pseudo illumination h (the paper's model)."""
    return config.specular_model == "lobe"


def diffuse_gains(config: EstimatorConfig) -> np.ndarray:
    """Per-coefficient gains on C turning the solver's light unknown into the light of the
    diffuse term: ones (the paper: h; or the lobe model: L itself), or 1 / (Phong filter)
    up to ``defilter_order`` (``diffuse_light='defiltered'``). Shape ((L + 1)^2,)."""
    gains = np.ones(config.sh_order + 1)
    if not radiance_unknown(config) and config.diffuse_light == "defiltered":
        f = sh.phong_filter(config.sh_order, config.phong_exponent)
        gains[: config.defilter_order + 1] = 1.0 / f[: config.defilter_order + 1]
    return sh.expand_per_degree(gains)


def specular_rows(config: EstimatorConfig, faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                  visibility: Visibility) -> np.ndarray:
    """(N, M) rows multiplying the light unknown in the specular term (mirror matrix D for h,
    or the lobe matrix for L)."""
    if radiance_unknown(config):
        return lobe_matrix(faces, mirror, sampling, visibility, config.sh_order, config.phong_exponent)
    return mirror_matrix(faces, mirror, sampling, visibility, config.sh_order)


def pseudo_from_unknown(config: EstimatorConfig, unknown: np.ndarray) -> np.ndarray:
    """The pseudo illumination h (M, C) from the solver's light unknown (M, C)."""
    if radiance_unknown(config):
        return unknown * sh.expand_per_degree(sh.phong_filter(config.sh_order, config.phong_exponent))[:, None]
    return unknown


def _model_matrices(data: MultiViewData, config: EstimatorConfig, sampling: SphereSampling,
                    visibility: Visibility, obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    c_matrix = diffuse_matrix(data.mesh, sampling, visibility, config.sh_order) * diffuse_gains(config)[None]
    mirror = mirror_directions(data.mesh.face_normals[obs.face], obs.view_dir)
    return c_matrix, specular_rows(config, obs.face, mirror, sampling, visibility)


def with_config(prep: Prepared, config: EstimatorConfig) -> Prepared:
    """The same observations and shadow function under another model configuration
    (e.g. another Phong exponent): only the reflection matrices are recomputed."""
    for key in ("directions", "min_cos_view", "min_pixels", "pure_pixels", "variant"):
        if getattr(config, key) != getattr(prep.config, key):
            raise ValueError(f"with_config cannot change {key}; run prepare() again")
    t = time.perf_counter()
    c_matrix, d_rows = _model_matrices(prep.data, config, prep.sampling, prep.visibility, prep.obs)
    timings = {**prep.timings, "reflection": time.perf_counter() - t}
    return Prepared(prep.data, config, prep.caster, prep.sampling, prep.visibility, prep.all_obs, prep.obs,
                    c_matrix, d_rows, timings)


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
    c_matrix, d_rows = _model_matrices(data, config, sampling, visibility, obs)
    timings["reflection"] = time.perf_counter() - t
    return Prepared(data, config, caster, sampling, visibility, all_obs, obs, c_matrix, d_rows, timings)
