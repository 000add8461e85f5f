"""The stages every method shares: observations, shadow function, reflection matrices."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .config import EstimatorConfig
from .data import MultiViewData
from .models import ReflectionModel, reflection_model
from .observations import Observations, gather_observations
from .raycast import RayCaster
from .reflection import mirror_directions
from .visibility import SphereSampling, Visibility, compute_visibility, sphere_sampling
from .errors import InputError


@dataclass
class Prepared:
    """Inputs of the solvers, computed once per dataset.

    Attributes
    ----------
    model : the reflection model of ``config``.
    all_obs : every observation (for median colours).
    obs : observations kept for the solve (``min_cos_view`` cut).
    c_matrix : (F, M) the model's diffuse rows of every face.
    d_rows : (N, M) the model's specular rows of ``obs``. Both multiply the model's
        light unknown (h, or L for a radiance model).
    timings : seconds per stage.
    """

    data: MultiViewData
    config: EstimatorConfig
    model: ReflectionModel
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


def _model_matrices(data: MultiViewData, model: ReflectionModel, sampling: SphereSampling,
                    visibility: Visibility, obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    c_matrix = model.diffuse_matrix(data.mesh, sampling, visibility)
    mirror = mirror_directions(data.mesh.face_normals[obs.face], obs.view_dir)
    return c_matrix, model.specular_rows(obs.face, mirror, sampling, visibility)


def with_config(prep: Prepared, config: EstimatorConfig) -> Prepared:
    """The same observations and shadow function under another model configuration
    (e.g. another Phong exponent): only the reflection matrices are recomputed."""
    for key in ("directions", "min_cos_view", "min_pixels", "pure_pixels", "min_coverage", "negative_tolerance",
                "variant"):
        if getattr(config, key) != getattr(prep.config, key):
            raise InputError(f"with_config cannot change {key}; run prepare() again")
    t = time.perf_counter()
    model = reflection_model(config)
    c_matrix, d_rows = _model_matrices(prep.data, model, prep.sampling, prep.visibility, prep.obs)
    timings = {**prep.timings, "reflection": time.perf_counter() - t}
    return Prepared(prep.data, config, model, prep.caster, prep.sampling, prep.visibility, prep.all_obs, prep.obs,
                    c_matrix, d_rows, timings)


def prepare(data: MultiViewData, config: EstimatorConfig, log=None) -> Prepared:
    """Run the shared stages. ``log`` (optional callable) receives progress lines."""
    say = log or (lambda message: None)
    timings = {}
    t = time.perf_counter()
    caster = RayCaster(data.mesh, config.variant)
    all_obs = gather_observations(caster, data.views, config.min_pixels, config.min_coverage, config.pure_pixels,
                                  config.negative_tolerance)
    normals = data.mesh.face_normals
    cos_view = np.sum(normals[all_obs.face] * all_obs.view_dir, axis=1)
    obs = all_obs.subset(cos_view > config.min_cos_view)
    if len(obs.face) == 0:
        raise InputError(f"no observation passes min_cos_view={config.min_cos_view}")
    timings["observations"] = time.perf_counter() - t
    say(f"observations: {len(all_obs.face)} (face, view) pairs, {len(obs.face)} kept "
        f"(view within acos({config.min_cos_view}) of the normal)")

    t = time.perf_counter()
    sampling = sphere_sampling(config.directions)
    visibility = compute_visibility(caster, sampling)
    timings["visibility"] = time.perf_counter() - t
    say(f"visibility: {data.mesh.num_faces} faces x {config.directions} directions")

    t = time.perf_counter()
    model = reflection_model(config)
    c_matrix, d_rows = _model_matrices(data, model, sampling, visibility, obs)
    timings["reflection"] = time.perf_counter() - t
    return Prepared(data, config, model, caster, sampling, visibility, all_obs, obs, c_matrix, d_rows, timings)
