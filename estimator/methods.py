"""Estimation methods, registered by name. A new method is one class here (or anywhere)
decorated with :func:`register_method`; nothing else changes."""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import replace
from typing import ClassVar

import numpy as np

from . import sh
from .clustering import mean_shift, split_clusters
from .config import EstimatorConfig
from .data import Estimate, MultiViewData
from .models import reflection_model
from .pipeline import Prepared, prepare, with_config
from .solver import BilinearResult, solve_bilinear
from .errors import InputError


REGISTRY: dict[str, type["Method"]] = {}


def register_method(cls: type["Method"]) -> type["Method"]:
    """Class decorator: make a method available under ``cls.name``."""
    if not getattr(cls, "name", None):
        raise InputError(f"{cls.__name__} needs a 'name'")
    REGISTRY[cls.name] = cls
    return cls


def get_method(name: str) -> type["Method"]:
    if name not in REGISTRY:
        raise InputError(f"unknown method {name!r}; registered: {', '.join(sorted(REGISTRY))}")
    return REGISTRY[name]


class Method(ABC):
    """A way to turn prepared observations into an Estimate."""

    name: ClassVar[str] = ""
    needs_illumination: ClassVar[bool] = False

    def __init__(self, config: EstimatorConfig, known_sh: np.ndarray | None = None,
                 known_radiance: np.ndarray | None = None):
        self.config = config
        self.model = reflection_model(config)
        self.known_sh = known_sh
        self.known_radiance = known_radiance

    @abstractmethod
    def solve(self, prep: Prepared) -> Estimate: ...

    def _from_groups(self, prep: Prepared, face_group: np.ndarray, result: BilinearResult,
                     observed: np.ndarray, info: dict) -> Estimate:
        f = prep.data.mesh.num_faces
        diffuse, specular = np.zeros((f, 3)), np.zeros((f, 3))
        diffuse[observed] = result.diffuse[face_group[observed]]
        specular[observed] = result.specular[face_group[observed]]
        labels = np.where(observed, face_group, -1).astype(np.int64)
        info = {**info, "residuals": result.residuals, "lm_residuals": result.lm_residuals,
                "lm_steps": [len(r) for r in result.lm_residuals]}
        radiance = result.light if self.model.light == "radiance" else None
        return Estimate(diffuse, specular, self.model.pseudo_from_light(result.light), labels, observed,
                        self.name, self.config, info, radiance)

    def _solve_groups(self, prep: Prepared, face_group: np.ndarray, num_groups: int,
                       fixed_light: np.ndarray | None = None) -> BilinearResult:
        c = self.config
        return solve_bilinear(prep.obs.rgb, face_group[prep.obs.face], prep.c_rows, prep.d_rows, num_groups,
                              c.components, c.iterations, c.tol, fixed_light, schedule=c.lm_schedule)


def _per_face_groups(prep: Prepared) -> tuple[np.ndarray, np.ndarray, int]:
    observed = prep.obs.observed_faces()
    group = np.cumsum(observed) - 1
    return np.where(observed, group, 0), observed, int(observed.sum())


@register_method
class BilinearPerFace(Method):
    """Every face its own cluster (the paper's Fig. 7 d, e): exact for specular-only
    data, ambiguous between diffuse and the constant part of specular otherwise."""

    name = "bilinear-per-face"

    def solve(self, prep):
        group, observed, g = _per_face_groups(prep)
        return self._from_groups(prep, group, self._solve_groups(prep, group, g), observed, {"clusters": g})


@register_method
class KnownIllumination(Method):
    """The oracle: the light fixed to the truth (the pseudo illumination h, or the radiance L
    for the lobe model), per-face albedos by linear least squares."""

    name = "known-illumination"
    needs_illumination = True

    def solve(self, prep):
        known, what = self.model.known_light(self.known_sh, self.known_radiance)
        if known is None:
            raise InputError(f"known-illumination needs {what} for the {self.model.name!r} reflection model")
        m = sh.num_coeffs(self.config.sh_order)
        fixed = np.zeros((m, 3))
        k = min(m, known.shape[0])
        fixed[:k] = known[:k]
        fixed /= np.where(np.abs(fixed[0]) > 0, fixed[0], 1.0)
        group, observed, g = _per_face_groups(prep)
        return self._from_groups(prep, group, self._solve_groups(prep, group, g, fixed), observed, {"clusters": g})


@register_method
class MedianColor(Method):
    """The naive baseline: albedo = median observed colour, no illumination model."""

    name = "median-color"

    def solve(self, prep):
        med = prep.all_obs.median_color()
        observed = ~np.isnan(med[:, 0])
        med = np.nan_to_num(med)
        f = len(med)
        zero = np.zeros_like(med)
        diffuse, specular = (zero, med) if self.config.components == "specular" else (med, zero)
        h = np.zeros((sh.num_coeffs(self.config.sh_order), 3))
        h[0] = 1.0
        labels = np.where(observed, np.arange(f), -1)
        return Estimate(diffuse, specular, h, labels, observed, self.name, self.config,
                        {"clusters": int(observed.sum())}, h.copy() if self.model.light == "radiance" else None)


@register_method
class BilinearClustered(Method):
    """The full method: angular mean-shift clusters of median colours, ALS solve,
    Euclidean re-clustering of shading-corrected colours, repeated until stable."""

    name = "bilinear-clustered"

    def solve(self, prep):
        c = self.config
        med = prep.all_obs.median_color()
        brightness = np.nan_to_num(med).mean(axis=1)
        # faces that stay dark in every view carry no colour: they are not estimated
        observed = ~np.isnan(med[:, 0]) & (brightness > c.min_brightness * np.percentile(brightness, 95))
        seen = np.nonzero(observed)[0]
        face_group = np.zeros(len(med), dtype=np.int64)
        t = time.perf_counter()
        angular, _ = mean_shift(med[seen], c.bandwidth, metric="angular")
        face_group[seen] = angular
        history = [int(angular.max()) + 1]
        visited = [angular]
        result = None
        for _ in range(c.recluster_rounds):
            result = self._solve_groups(prep, face_group, int(face_group.max()) + 1)
            albedo, valid = self._shading_corrected(prep, face_group, result, med)
            min_size = max(3, int(c.min_cluster_fraction * len(seen)))
            split = split_clusters(albedo[seen], angular, c.split_bandwidth, valid[seen], min_size)
            history.append(int(split.max()) + 1)
            if any(_same_partition(split, old) for old in visited):
                break  # stable (or cycling back to a partition already solved)
            visited.append(split)
            face_group[seen] = split
        else:
            result = self._solve_groups(prep, face_group, int(face_group.max()) + 1)
        info = {"clusters": int(face_group[seen].max()) + 1, "angular_clusters": history[0],
                "clusters_per_round": history, "clustering_s": time.perf_counter() - t}
        return self._from_groups(prep, face_group, result, observed, info)

    def _shading_corrected(self, prep, face_group, result, med):
        """Per-face diffuse albedo with the light and the cluster's specular albedo fixed
        (the paper divides colours by the diffuse shading sum h C)."""
        obs = prep.obs
        f = len(med)
        shade_face = prep.c_matrix @ result.light                               # (F, 3)
        spec = result.specular[face_group[obs.face]] * (prep.d_rows @ result.light)
        num = np.stack([np.bincount(obs.face, (obs.rgb[:, k] - spec[:, k]), minlength=f) for k in range(3)], 1)
        cnt = np.bincount(obs.face, minlength=f)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            diffuse_colour = np.where(cnt > 0, num / np.maximum(cnt, 1), med)
            albedo = diffuse_colour / shade_face
        lum = shade_face.mean(axis=1)
        level = np.percentile(lum, self.config.recluster_shading_percentile)
        valid = (lum > self.config.recluster_min_shading * level) & np.all(np.isfinite(albedo), axis=1)
        return np.where(np.isfinite(albedo), albedo, 0.0), valid


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two labelings group the items identically (labels may be renamed)."""
    pairs = np.unique(np.stack([a, b], 1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


EXPONENT_CANDIDATES = (5.0, 7.0, 10.0, 14.0, 20.0, 28.0, 40.0)


def estimate(data: MultiViewData, method: str = "bilinear-clustered", config: EstimatorConfig | None = None,
             known_sh: np.ndarray | None = None, known_radiance: np.ndarray | None = None, log=None,
             exponent_candidates: tuple[float, ...] | None = None) -> Estimate:
    """Run a registered method on in-memory data (the estimator's one entry point).

    Parameters
    ----------
    known_sh : (M', 3) pseudo illumination for 'known-illumination' (truncated/padded to the order).
    known_radiance : (M', 3) radiance SH, for 'known-illumination' with ``specular_model='lobe'``.
    log : optional callable receiving progress lines.
    exponent_candidates : estimate the Phong exponent too: solve with each candidate
        (observations and shadow function computed once) and keep the lowest final
        residual. Only models that depend on the exponent qualify
        (``specular_model='lobe'`` or ``diffuse_light='defiltered'``).
    """
    config = config or EstimatorConfig()
    cls = get_method(method)
    t0 = time.perf_counter()
    prep = prepare(data, config, log)
    if not np.any(prep.obs.rgb > 0):
        raise InputError("every observed pixel is black or negative: there is no light to estimate from "
                         "(check the images' exposure and sign)")
    t = time.perf_counter()
    try:
        est = _solve(cls, prep, config, known_sh, known_radiance, log, exponent_candidates)
    except np.linalg.LinAlgError as exc:
        raise InputError(f"the solve is singular ({exc}): the observations do not determine the albedos and "
                         "the light (too few lit views or faces?)") from None
    for name in ("diffuse", "specular", "pseudo_sh"):
        if not np.all(np.isfinite(getattr(est, name))):
            raise InputError(f"the solve produced non-finite {name}: the observations do not determine the "
                             "albedos and the light (too few lit views or faces?)")
    est.info["timings"] = {**prep.timings, "solve": time.perf_counter() - t, "total": time.perf_counter() - t0}
    est.info["observations"] = int(len(prep.obs.face))
    est.info["observations_all"] = int(len(prep.all_obs.face))
    est.info["unobserved_share"] = float(1.0 - est.observed.mean())
    est.info["faces_without_kept_views"] = float(1.0 - prep.obs.observed_faces().mean())
    rejected = prep.all_obs.rejected
    est.info["rejected_pixels"] = {v.name: int(n) for v, n in zip(data.views, rejected) if n > 0}
    return est


def _solve(cls, prep, config, known_sh, known_radiance, log, exponent_candidates) -> Estimate:
    if exponent_candidates:
        if not reflection_model(config).uses_exponent:
            raise InputError("estimating the Phong exponent needs a model that depends on it: "
                             "specular_model='lobe' or diffuse_light='defiltered'")
        tried = {}
        for n in exponent_candidates:
            candidate = cls(replace(config, phong_exponent=float(n)), known_sh, known_radiance)
            tried[float(n)] = candidate.solve(with_config(prep, candidate.config))
            if log:
                log(f"phong exponent {n}: residual {tried[float(n)].info['residuals'][-1]:.5f}")
        est = min(tried.values(), key=lambda e: e.info["residuals"][-1])
        est.info["exponent_selection"] = {str(n): e.info["residuals"][-1] for n, e in tried.items()}
        return est
    return cls(config, known_sh, known_radiance).solve(prep)
