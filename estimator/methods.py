"""Estimation methods, registered by name. A new method is one class here (or anywhere)
decorated with :func:`register_method`; nothing else changes."""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import replace
from typing import ClassVar

import numpy as np

from . import albedo_prior, coat, indirect, lobe_light, pose, reflected_light, retinex, robust, sh, sun, trust
from .clustering import mean_shift, split_clusters
from .config import EstimatorConfig
from .data import Estimate, MultiViewData
from .models import reflection_model
from .pipeline import Prepared, prepare, with_config
from .raycast import RayCaster
from .reflection import diffuse_matrix, lobe_matrix, mirror_directions, phong_lobe
from .segmentation import albedo_features, group_quantile, segment
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
    default_loss: ClassVar[str] = "none"
    streams: ClassVar[bool] = False   # solve() accepts a streamed problem (Prepared.streamed)

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
        groups = len(np.unique(face_group[prep.obs.face]))
        per_group = 2 if self.config.components == "both" else 1
        light_unknowns = 0 if self.needs_illumination else result.light.shape[0] - 1   # unit DC: the gauge
        info = {**info, "residuals": result.residuals, "lm_residuals": result.lm_residuals,
                "lm_steps": [len(r) for r in result.lm_residuals],
                "degrees_of_freedom": {"observations": int(3 * len(prep.obs.face)),
                                       "unknowns": int(3 * (groups * per_group + light_unknowns))}}
        radiance = result.light if self.model.light == "radiance" else None
        return Estimate(diffuse, specular, self.model.pseudo_from_light(result.light), labels, observed,
                        self.name, self.config, info, radiance)

    def _solve_groups(self, prep: Prepared, face_group: np.ndarray, num_groups: int,
                      fixed_light: np.ndarray | None = None, weights: np.ndarray | None = None) -> BilinearResult:
        """The bilinear solve over groups; ``weights`` (N,) scale each observation's squared
        residual. With ``config.robust_loss`` other than 'none', the solve is iteratively
        reweighted (:mod:`estimator.robust`): glints are clipped at ``glint_ratio`` x the
        face's median colour first, then ``robust_rounds`` rounds reweight every row by the
        loss of its relative residual. The result's ``weights`` are the final ones."""
        base = np.ones(len(prep.obs.face)) if weights is None else weights
        if self.loss == "none":
            result = self._weighted_solve(prep, face_group, num_groups, fixed_light, weights)
            result.weights = base
            return result
        w = base * self._initial_weights(prep)
        result = None
        for round_ in range(self.config.robust_rounds + 1):
            result = self._weighted_solve(prep, face_group, num_groups, fixed_light, w,
                                          None if result is None else result.light)
            if round_ < self.config.robust_rounds:
                w = base * self._reweight(prep, face_group, result, base)
        result.weights = w
        return result

    @property
    def loss(self) -> str:
        """The robust loss in use: ``config.robust_loss``, or the method's own for 'auto'."""
        return self.default_loss if self.config.robust_loss == "auto" else self.config.robust_loss

    def _initial_weights(self, prep: Prepared) -> np.ndarray:
        """(N,) glint clipping before the first robust solve (ones without a robust loss)."""
        if self.loss == "none":
            return np.ones(len(prep.obs.face))
        obs = prep.obs
        return robust.initial_weights(obs.face, obs.rgb, obs.num_faces, self.config.glint_ratio)

    def _reweight(self, prep: Prepared, face_group: np.ndarray, result: BilinearResult,
                  base: np.ndarray | None = None) -> np.ndarray:
        """(N,) robust weights of every observation under ``result`` (ones without a robust
        loss); the scale is taken over the rows with ``base`` > 0."""
        obs = prep.obs
        if self.loss == "none":
            return np.ones(len(obs.face))
        g = face_group[obs.face]
        predicted = self.model.predict(result.diffuse[g], result.specular[g], prep.c_rows, prep.d_rows, result.light)
        r = robust.relative_residuals(obs.rgb, predicted)
        return robust.irls_weights(r, self.loss, robust.robust_scale(r, base))

    def _weighted_solve(self, prep: Prepared, face_group: np.ndarray, num_groups: int,
                        fixed_light: np.ndarray | None, weights: np.ndarray | None,
                        initial_light: np.ndarray | None = None) -> BilinearResult:
        """One bilinear solve; rows are multiplied by the square root of ``weights`` (the
        model is linear in its rows)."""
        c = self.config
        rgb, c_rows, d_rows = prep.obs.rgb, prep.c_rows, prep.d_rows
        if weights is not None:
            root = np.sqrt(weights)[:, None]
            rgb, c_rows, d_rows = rgb * root, c_rows * root, d_rows * root
        return solve_bilinear(rgb, face_group[prep.obs.face], c_rows, d_rows, num_groups,
                              c.components, c.iterations, c.tol, fixed_light, schedule=c.lm_schedule,
                              initial_light=initial_light)

    def _solve_per_face(self, prep: Prepared, fixed_light: np.ndarray | None = None) -> Estimate:
        """Every observed face its own group. A streamed problem (:attr:`Prepared.streamed`)
        is solved in two steps of bounded memory: the light from the observations of
        ``config.light_faces`` observed faces drawn at random (seed 0), then every face's
        albedos with that light fixed, on the rows' projections onto it."""
        group, observed, g = _per_face_groups(prep)
        info = {"clusters": g}
        if not prep.streamed:
            return self._from_groups(prep, group, self._solve_groups(prep, group, g, fixed_light), observed, info)
        light = fixed_light
        if light is None:
            seen = np.nonzero(observed)[0]
            sample = np.sort(np.random.default_rng(0).choice(seen, min(self.config.light_faces, len(seen)),
                                                             replace=False))
            sub = prep.face_subset(sample)
            sub_group, _, sub_g = _per_face_groups(sub)
            light = self._solve_groups(sub, sub_group, sub_g).light
            info["light_faces"] = int(len(sample))
        result = self._solve_groups(prep.projected(light), group, g, np.eye(3))
        result.light = light
        return self._from_groups(prep, group, result, observed, info)


def _per_face_groups(prep: Prepared) -> tuple[np.ndarray, np.ndarray, int]:
    observed = prep.obs.observed_faces()
    group = np.cumsum(observed) - 1
    return np.where(observed, group, 0), observed, int(observed.sum())


@register_method
class BilinearPerFace(Method):
    """Every face its own cluster (the paper's Fig. 7 d, e): exact for specular-only
    data, ambiguous between diffuse and the constant part of specular otherwise."""

    name = "bilinear-per-face"
    default_loss = "cauchy"  # one glare view ruins a least-squares per-face fit (0.058 within ±10 % against 0.980)
    streams = True

    def solve(self, prep):
        est = self._solve_per_face(prep)
        width = self.config.albedo_prior
        if width > 0:
            diffuse_precision, specular_precision = trust.albedo_precision(prep, est)
            edges = prep.data.mesh.face_adjacency
            spreads = {}
            for name, precision in (("diffuse", diffuse_precision), ("specular", specular_precision)):
                if self.config.components in (name, "both"):
                    smoothed, spread = albedo_prior.smooth_albedo(getattr(est, name), precision, edges,
                                                                  est.observed, width)
                    setattr(est, name, smoothed)
                    spreads[name] = spread.tolist()
            est.info["albedo_prior"] = {"width": width, "spread": spreads}
        return est


@register_method
class KnownIllumination(Method):
    """The oracle: the light fixed to the truth (the pseudo illumination h, or the radiance L
    for the lobe model), per-face albedos by linear least squares."""

    name = "known-illumination"
    needs_illumination = True
    streams = True

    def solve(self, prep):
        known, what = self.model.known_light(self.known_sh, self.known_radiance)
        if known is None:
            raise InputError(f"known-illumination needs {what} for the {self.model.name!r} reflection model")
        m = sh.num_coeffs(self.config.sh_order)
        fixed = np.zeros((m, 3))
        k = min(m, known.shape[0])
        fixed[:k] = known[:k]
        fixed /= np.where(np.abs(fixed[0]) > 0, fixed[0], 1.0)
        return self._solve_per_face(prep, fixed)


@register_method
class MedianColor(Method):
    """The naive baseline: albedo = median observed colour, no illumination model."""

    name = "median-color"
    streams = True

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


@register_method
class BilinearSegmented(BilinearClustered):
    """The paper's bilinear solve with clusters found on the mesh instead of in colour space.

    Beyond the paper (measured on the real-light family, ``benchmarks/real_light.py``):

    * Clusters are regions of the face-adjacency graph: neighbours whose shading-corrected
      albedos agree within ``segment_threshold`` (log) join; regions of uniform albedo
      (spread below ``uniform_spread``) with similar albedo merge (mean shift). Hue alone
      never merges a dark and a bright region, and a region is a region wherever it lies.
    * The solve is robust: observations the model does not explain (glints of a sharp
      light in a smooth coat, interreflected highlights, lobes that are not Phong) get
      Cauchy weights (``robust_loss``; IRLS across the partition rounds, glints clipped
      at ``glint_ratio`` x the face's median colour before the first solve).
    * Boundary faces move to the neighbouring region whose albedos best predict their
      observations, then the light is solved again (``relabel_rounds``).
    * A face is unestimated only when the estimated light does not reach it (shading
      below 2 % of the 95th percentile), not because its albedo is dark.
    * Faces outside every uniform region (texture) form clusters of their own.
    """

    name = "bilinear-segmented"
    default_loss = "cauchy"

    def solve(self, prep):
        c = self.config
        mesh = prep.data.mesh
        f = mesh.num_faces
        med = prep.all_obs.median_color()
        seen = ~np.isnan(med[:, 0])
        edges = mesh.face_adjacency
        t = time.perf_counter()
        face_group = np.zeros(f, dtype=np.int64)
        angular, _ = mean_shift(med[seen], c.bandwidth, metric="angular")
        face_group[seen] = angular
        history = [int(angular.max()) + 1]
        in_solve = seen.copy()
        # the first light is reweighted to convergence (it decides the first segmentation); then one
        # solve per partition, with robust weights from the latest solve (IRLS across rounds)
        result = self._solve_groups(prep, face_group, int(face_group.max()) + 1)
        visited = []
        for _ in range(c.recluster_rounds):
            albedo, usable = self._face_albedo(prep, face_group, result, seen)
            labels, _ = segment(np.where(usable[:, None], albedo, 1.0), edges, usable,
                                c.segment_threshold, c.uniform_spread)
            new_group = self._assign(labels, albedo, seen, edges, 2.5 * c.segment_threshold)
            new_in_solve = seen & (new_group < int(labels.max()) + 1)  # faces of uniform regions carry the light
            history.append(int(labels.max()) + 1)
            if new_in_solve.sum() < 0.5 * seen.sum():
                break  # no piecewise-uniform structure this round: keep the partition that had one
            in_solve = new_in_solve
            if any(_same_partition(new_group[seen], old) for old in visited):
                break
            visited.append(new_group[seen].copy())
            result = self._resolve(prep, face_group, new_group, in_solve, result)
            face_group = new_group
        regions = int(face_group[in_solve].max()) + 1 if in_solve.any() else 0
        for _ in range(c.relabel_rounds if regions > 1 else 0):
            relabelled = self._relabel(prep, face_group, result, regions, edges, c.relabel_free_ratio)
            if np.array_equal(relabelled, face_group):
                break
            in_solve = seen & (relabelled < regions)
            result = self._resolve(prep, face_group, relabelled, in_solve, result)
            face_group = relabelled
        albedo, usable = self._face_albedo(prep, face_group, result, seen)
        in_solve = seen & (face_group < regions)
        diffuse = np.where(np.isfinite(albedo), albedo, 0.0)
        member = usable & in_solve
        region_albedo = group_quantile(face_group[member], albedo[member], regions, 0.5, interpolate=True)
        if c.tie_regions and regions > 1:
            region_albedo = self._tie_regions(region_albedo, albedo, usable, face_group, edges, regions)
        diffuse[in_solve] = np.nan_to_num(region_albedo[face_group[in_solve]])  # a uniform region shares one albedo
        shading = (prep.c_matrix @ result.light).mean(axis=1)
        observed = seen & (shading > 0.02 * max(float(np.percentile(shading[seen], 95)), 1e-30)) \
            & np.all(np.isfinite(albedo) | (face_group < regions)[:, None], axis=1)
        specular = np.zeros((f, 3))
        grouped = face_group < regions
        specular[grouped] = result.specular[face_group[grouped]]
        if (~grouped & seen).any() and regions:
            specular[~grouped] = np.median(result.specular[:regions], axis=0)
        labels_out = np.where(observed, face_group, -1).astype(np.int64)
        info = {"clusters": int(len(np.unique(face_group[observed]))), "uniform_regions": regions,
                "uniform_share": float(np.mean(grouped[observed])) if observed.any() else 0.0,
                "angular_clusters": history[0], "regions_per_round": history,
                "clustering_s": time.perf_counter() - t,
                "residuals": result.residuals, "lm_residuals": result.lm_residuals}
        return Estimate(np.where(observed[:, None], diffuse, 0.0), np.where(observed[:, None], specular, 0.0),
                        self.model.pseudo_from_light(result.light), labels_out, observed, self.name, c, info,
                        result.light if self.model.light == "radiance" else None)

    @staticmethod
    def _tie_regions(region_albedo, albedo, usable, face_group, edges, regions, anchor: float = 1e-3):
        """Region albedos whose ratios agree with their boundaries.

        Faces on either side of a boundary receive nearly the same light, so the median
        log-ratio of their (shading-corrected) albedos across the boundary is the ratio of
        the two regions' albedos, whatever the light; this holds where the light estimate
        is weakest (a region lit from directions only it sees). Per channel, the region
        log-albedos a solve min sum_pairs n_rs (a_r - a_s - rho_rs)^2 (n_rs boundary edges)
        with their face-weighted mean held at the solve's, and a weak pull ``anchor`` x
        faces towards each region's own solve value (a region with no boundary keeps it).
        """
        i, j = edges[:, 0], edges[:, 1]
        gi, gj = face_group[i], face_group[j]
        cross = (gi != gj) & (gi < regions) & (gj < regions) & usable[i] & usable[j]
        if not cross.any():
            return region_albedo
        la = np.log(np.maximum(albedo, 1e-30))
        pairs = np.sort(np.stack([gi[cross], gj[cross]], 1), axis=1)
        flip = gi[cross] > gj[cross]
        diff = np.where(flip[:, None], la[j[cross]] - la[i[cross]], la[i[cross]] - la[j[cross]])
        keys, inverse = np.unique(pairs, axis=0, return_inverse=True)
        member = usable & (face_group < regions)
        sizes = np.bincount(face_group[member], minlength=regions).astype(float)
        base = np.log(np.maximum(region_albedo, 1e-30))
        out = region_albedo.copy()
        for c in range(region_albedo.shape[1]):
            rows, rhs, w = [], [], []
            for k, (r, s_) in enumerate(keys):
                sel = inverse.ravel() == k
                row = np.zeros(regions)
                row[r], row[s_] = 1.0, -1.0
                rows.append(row)
                rhs.append(np.median(diff[sel, c]))
                w.append(sel.sum())
            known = np.isfinite(base[:, c])
            level = sizes * known / max(float(np.sum(sizes * known)), 1e-30)   # keeps the mean log-albedo
            a = np.vstack([np.array(rows) * np.sqrt(w)[:, None], np.sqrt(np.sum(w)) * level[None],
                           np.diag(np.sqrt(anchor * sizes * known))])
            b = np.concatenate([np.array(rhs) * np.sqrt(w), [np.sqrt(np.sum(w)) * level @ np.nan_to_num(base[:, c])],
                                np.sqrt(anchor * sizes * known) * np.nan_to_num(base[:, c])])
            out[:, c] = np.exp(np.linalg.lstsq(a, b, rcond=None)[0])
        return out

    def _face_albedo(self, prep, face_group, result, seen) -> tuple[np.ndarray, np.ndarray]:
        """(F, 3) per-face diffuse albedo: a low quantile over views of the colour less the
        fitted specular, divided by the diffuse shading; and where it is usable (lit)."""
        c = self.config
        obs = prep.obs
        g = face_group[obs.face]
        spec = result.specular[g] * (prep.d_rows @ result.light)
        radiance = group_quantile(obs.face, obs.rgb - spec, len(face_group), c.diffuse_quantile)
        shade = prep.c_matrix @ result.light
        lum = shade.mean(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            albedo = radiance / shade
        level = np.percentile(lum[seen], c.recluster_shading_percentile) if seen.any() else 0.0
        usable = seen & (lum > c.segment_min_shading * level) & np.all(np.isfinite(albedo) & (albedo > 0), axis=1)
        return albedo, usable

    @staticmethod
    def _assign(labels: np.ndarray, albedo: np.ndarray, seen: np.ndarray, edges: np.ndarray,
                reach: float) -> np.ndarray:
        """Groups: the uniform regions; a face outside them joins the region whose albedo
        features are within ``reach`` of its own (shading noise in dim faces), or, when its
        albedo is unknown (no light) or 90 % of the faces are in regions already, the region
        most of its neighbours joined; any other face is a group of its own (texture)."""
        group = labels.copy()
        regions = int(group.max()) + 1
        if regions:
            finite = np.all(np.isfinite(albedo) & (albedo > 0), axis=1)
            feat = albedo_features(np.where(finite[:, None], albedo, 1.0))
            centres = group_quantile(group[group >= 0], feat[group >= 0], regions, 0.5, interpolate=True)
            dist = np.max(np.abs(feat[:, None, :] - centres[None]), axis=2)
            near = (group < 0) & seen & finite & (dist.min(axis=1) < reach)
            group[near] = np.argmin(dist[near], axis=1)
            # in a piecewise-uniform object (nearly every face in a region) the rest are faces
            # the shading model fails on (concavities, silhouettes): they follow their neighbours
            piecewise = np.mean(group[seen] >= 0) >= 0.9
            for _ in range(8):  # faces without a usable albedo follow their neighbours
                todo = (group < 0) & seen & (~finite | piecewise)
                if not todo.any():
                    break
                votes = np.zeros((len(group), regions))
                for src, dst in ((edges[:, 0], edges[:, 1]), (edges[:, 1], edges[:, 0])):
                    ok = todo[src] & (group[dst] >= 0)
                    np.add.at(votes, (src[ok], group[dst[ok]]), 1.0)
                decided = todo & (votes.max(axis=1) > 0)
                group[decided] = np.argmax(votes[decided], axis=1)
        free = np.nonzero((group < 0) & seen)[0]
        group[free] = regions + np.arange(len(free))
        group[~seen] = 0
        _, compact = np.unique(group, return_inverse=True)
        return compact.astype(np.int64)

    @staticmethod
    def _relabel(prep, face_group, result, regions, edges, free_penalty: float) -> np.ndarray:
        """(F,) groups after moving faces to the region, among their neighbours', whose
        albedos best predict their observations (sum over views of the L1 colour residual).

        A face of a uniform region moves when a neighbouring region predicts it better: a
        boundary face labelled with its neighbour's region, whose one wrong albedo costs more
        PSNR than the whole light error, moves back. A face outside every region (its own
        per-face albedo, fitted here with the light fixed) joins a neighbouring region when
        that region's cost is within ``free_penalty`` x its own: a region explains it with
        three unknowns fewer (model selection by residual and complexity).
        """
        obs = prep.obs
        f = len(face_group)
        shade, gloss = prep.c_rows @ result.light, prep.d_rows @ result.light          # (N, 3)
        pred = (result.diffuse[None, :regions] * shade[:, None] + result.specular[None, :regions] * gloss[:, None])
        cost_obs = np.abs(obs.rgb[:, None] - pred).sum(axis=2)                          # (N, R)
        cost = np.stack([np.bincount(obs.face, cost_obs[:, r], minlength=f) for r in range(regions)], 1)
        # the free faces' own fit: per-face diffuse albedo, the regions' median specular
        spec = np.median(result.specular[:regions], axis=0)
        rest = obs.rgb - spec[None] * gloss
        td = np.stack([np.bincount(obs.face, rest[:, k] * shade[:, k], minlength=f)
                       / np.maximum(np.bincount(obs.face, shade[:, k] ** 2, minlength=f), 1e-300) for k in range(3)], 1)
        own = np.bincount(obs.face, np.abs(rest - np.maximum(td, 0.0)[obs.face] * shade).sum(axis=1), minlength=f)
        inside = face_group < regions
        candidate = np.zeros((f, regions), dtype=bool)
        candidate[np.nonzero(inside)[0], face_group[inside]] = True
        for src, dst in ((edges[:, 0], edges[:, 1]), (edges[:, 1], edges[:, 0])):
            ok = inside[dst]
            candidate[src[ok], face_group[dst[ok]]] = True
        masked = np.where(candidate, cost, np.inf)
        best = np.argmin(masked, axis=1)
        counted = np.bincount(obs.face, minlength=f) > 0
        joins = ~inside & counted & (masked[np.arange(f), best] <= free_penalty * own)
        group = np.where((inside & counted) | joins, best, face_group)
        free = group >= regions
        group[free] = regions + np.unique(group[free], return_inverse=True)[1]
        return group

    def _resolve(self, prep, old_group, new_group, in_solve, result) -> BilinearResult:
        """The solve of a new partition, restricted to faces of uniform regions: rows weighted
        by the robust loss of their residual under the previous solve (its partition),
        started from the previous light."""
        keep = in_solve[prep.obs.face].astype(float)
        weights = self._reweight(prep, old_group, result, keep) * keep
        result = self._weighted_solve(prep, new_group, int(new_group.max()) + 1, None, weights, result.light)
        result.weights = weights
        return result


@register_method
class RetinexSegmented(Method):
    """The light from albedo edges and uniform regions, in the log domain (beyond the paper).

    1. A face's diffuse radiance is a low quantile (``retinex_quantile``) of its colours
       over the views.
    2. The light is fitted to the log radiance ratios of neighbouring faces, with a robust
       loss that lets albedo edges go (:func:`estimator.retinex.log_shading_fit`): a
       Retinex prior on the mesh, which needs no region and holds on textures.
    3. Radiance over that shading gives per-face albedos; uniform regions are found on the
       face-adjacency graph (:func:`estimator.segmentation.segment`).
    4. When at least ``retinex_min_uniform_share`` of the lit faces lie in uniform
       regions, the light is fitted again with each region's faces tied to one albedo
       (far-apart faces of a region constrain the light as the edges cannot), and each
       region takes that albedo, unless the faces drift from their region's albedo beyond
       ``region_max_deviation`` and ``region_max_drift`` times the noise between neighbours
       (a texture chained into regions). Otherwise the edges alone set the light and every
       face keeps its own albedo (a texture).
    5. The specular albedo is solved with that light fixed (per region; faces outside
       every region share the regions' median, or one fit over all faces without regions).
    6. With ``coat_correction``, the reflection of a dielectric coat (``coat_ior``) of the
       light's low orders (``coat_order``) is fitted to the colours' changes across views
       (:mod:`estimator.coat`), scaled down until at most ``coat_max_negative`` more of the
       observations would turn non-positive, subtracted, and steps 1-5 run again.

    On a coated texture (step 4 finds no uniform regions, the edge search kept no sun) the
    light comes instead from the coat's reflection (:mod:`estimator.reflected_light`), which
    the texture cannot bias, when that map is determined and explains at least
    ``reflected_min_explained`` of the view changes; step 6 is then skipped. The albedo is
    then that fit's diffuse radiance (the coat's reflection removed, its exit transmission
    1 - F(n . v) divided out) over the light's shading through the coat (the cosine weighted
    by 1 - F(n . w) on the way in, as in Mitsuba's ``plastic``); on a texture the light's SH
    part is fitted to the edges of that diffuse radiance, beside the map's sun. Where the
    map's light fails that gate but the map explains at least
    ``reflected_diffuse_min_explained``, the light still comes from the edges, fitted on
    that diffuse radiance through the coat. Where a
    shared Phong lobe without Fresnel explains the view changes better than the coat
    (``reflected_lobe``), the light comes from the lobe's reflection
    (:mod:`estimator.lobe_light`) and regions are found again under it.
    """

    name = "retinex-segmented"
    default_loss = "cauchy"

    def solve(self, prep):
        c = self.config
        if c.components == "specular":
            raise InputError("retinex-segmented estimates the diffuse albedo from shading; for specular-only "
                             "data (components='specular') use bilinear-per-face")
        t = time.perf_counter()
        self._reflected = None   # the coat's reflected light, fitted on first need from these observations
        self._lobe = None        # the lobe's (LobeLight, lobe rows or None after a failed preview), likewise
        self._original_obs = prep.obs
        est = self._fit(prep)
        weight = np.zeros(3)
        if c.coat_correction and not est.info["light_from"].startswith("reflection"):   # that light models the coat
            obs = prep.obs
            rows = coat.coat_rows(prep.data.mesh.face_normals[obs.face], obs.view_dir,
                                  est.light, c.coat_order, c.coat_ior)
            weight = coat.fit_coat(obs.face, obs.rgb, rows, obs.num_faces, self.loss)
            weight = weight * coat.admissible_scale(obs.rgb, weight * rows, c.coat_max_negative)
            coat_level = np.median(np.linalg.norm(weight * rows, axis=1))
            if coat_level > c.coat_min_share * np.median(np.linalg.norm(obs.rgb, axis=1)):
                s = est.info["sun"]
                found = s and sun.Sun(np.array(s["direction"]), s["cost_ratio"], 0,
                                      c.coat_ior if s["through_coat"] else None)
                est = self._fit(replace(prep, obs=replace(obs, rgb=obs.rgb - weight * rows)), found)
            else:
                weight = np.zeros(3)  # negligible: not applied
        est.info["coat_weight"] = weight.tolist()
        est.info["clustering_s"] = time.perf_counter() - t
        return est

    def _fit(self, prep, found: sun.Sun | None = None) -> Estimate:
        """Steps 1-5 on the observations of ``prep``; ``found``: the sun of an earlier fit
        (None: search for one when ``sun_min_gain`` < 1)."""
        c = self.config
        mesh, obs = prep.data.mesh, prep.obs
        f = mesh.num_faces
        radiance = group_quantile(obs.face, obs.rgb, f, c.retinex_quantile)
        usable = np.all(np.isfinite(radiance) & (radiance > 0), axis=1)
        if not usable.any():
            raise InputError("no face has a positive diffuse radiance in its kept views: nothing to estimate from")
        edges = mesh.face_adjacency
        fit = dict(loss=self.loss, ridge=c.retinex_ridge, iterations=c.retinex_iterations)
        if c.interreflection:
            fit["indirect"] = indirect.indirect_shading(prep.caster, prep.sampling, prep.visibility,
                                                        np.where(usable[:, None], radiance, 0.0))
        extra = fit.get("indirect", 0.0)
        columns = prep.c_matrix
        if found is None and c.sun_min_gain < 1:
            found = sun.find_sun(radiance, columns, edges, usable, mesh, prep.caster, prep.sampling.directions,
                                 loss=self.loss, coat_ior=c.coat_ior if c.coat_correction else None)
        if found is not None and found.cost_ratio <= 1 - c.sun_min_gain:
            columns = np.hstack([columns, sun.sun_shading(mesh, prep.caster, found.direction, found.coat_ior)[:, None]])
        light, _ = retinex.log_shading_fit(radiance, columns, edges, usable, **fit)
        if columns.shape[1] > prep.c_matrix.shape[1] and np.any(light[-1] <= 0):   # no dark "sun"
            columns = prep.c_matrix
            light, _ = retinex.log_shading_fit(radiance, columns, edges, usable, **fit)
        albedo, lit = self._divide(columns, radiance, light, usable, extra)
        labels, _ = segment(np.where(lit[:, None], albedo, 1.0), edges, lit, c.segment_threshold, c.uniform_spread)
        share = float(np.mean(labels[lit] >= 0))
        regions = int(labels.max()) + 1
        light_from = "edges"
        deviation = drift = None
        if regions and share >= c.retinex_min_uniform_share:
            tied_fit = self._tie_regions(radiance, columns, edges, usable, np.where(lit, labels, -1), regions,
                                         light, fit, extra)
            deviation, drift = tied_fit[-2:]
            if deviation <= c.region_max_deviation or drift <= c.region_max_drift:
                light_from = "edges and regions"
                light, albedo, lit, labels = tied_fit[:4]
        if light_from == "edges":
            regions, labels = 0, np.full(f, -1, dtype=np.int64)
        reflection, lobe = self._usable_reflection(prep, regions > 0), self._usable_lobe(prep)
        if reflection is not None and lobe is not None and np.mean(lobe.explained) > np.mean(reflection.explained):
            reflection = None     # a lobe without Fresnel explains the view changes better than a coat
        if reflection is not None:
            reflected = np.where(np.isfinite(reflection.diffuse) & (reflection.diffuse > 0), reflection.diffuse, radiance)
            r_light, r_columns, r_sun = self._reflected_light(prep, reflected, edges, usable, fit)
            edge_sun = columns.shape[1] > prep.c_matrix.shape[1]
            if not edge_sun or (r_sun is not None and np.degrees(np.arccos(np.clip(
                    r_sun.direction @ found.direction, -1.0, 1.0))) <= c.reflected_sun_max_angle):
                radiance, light, columns, found = reflected, r_light, r_columns, r_sun or found
                light_from = "reflection"
                if not regions:   # a texture: the map's diffuse and sun, the edges' SH light on them
                    edge_light, _ = retinex.log_shading_fit(radiance, columns, edges, usable, **fit)
                    if columns.shape[1] == prep.c_matrix.shape[1] or np.all(edge_light[-1] > 0):   # no dark sun
                        light, light_from = edge_light, "reflection's diffuse, edges' light"
                albedo, lit = self._divide(columns, radiance, light, usable, extra)
                if regions:   # each region takes its faces' median albedo under that light
                    labels = np.where(lit, labels, -1)
                    tied = labels >= 0
                    albedo[tied] = group_quantile(labels[tied], albedo[tied], regions, 0.5)[labels[tied]]
                    light_from = "reflection and regions"
        elif lobe is not None:
            edge_sun = found
            radiance, light, columns, ratio = self._lobe_reflected_light(prep, edges, usable, edge_sun)
            found = (sun.Sun(edge_sun.direction, ratio, edge_sun.evaluations)   # no coat on its way
                     if columns.shape[1] > prep.c_matrix.shape[1] else None)
            albedo, lit = self._divide(columns, radiance, light, usable, extra)
            light_from = "reflection (lobe)"
            # regions found under the edges' light saw the lobe's reflection as albedo: found again
            labels, _ = segment(np.where(lit[:, None], albedo, 1.0), edges, lit, c.segment_threshold, c.uniform_spread)
            share, regions = float(np.mean(labels[lit] >= 0)), int(labels.max()) + 1
            deviation = drift = None
            if regions and share >= c.retinex_min_uniform_share:
                tied = labels >= 0
                median = group_quantile(labels[tied], albedo[tied], regions, 0.5)
                deviation = _deviation(albedo[tied], median[labels[tied]])
                if deviation <= c.region_max_deviation:
                    albedo[tied] = median[labels[tied]]
                    light_from = "reflection (lobe) and regions"
            if light_from == "reflection (lobe)":
                regions, labels = 0, np.full(f, -1, dtype=np.int64)
        if light_from == "edges" and not regions:
            coated = self._coated_diffuse(prep, radiance, columns, found)
            if coated is not None:   # the edges' light, on radiance with the coat's reflection removed
                radiance, columns = coated
                if columns.shape[1] > prep.c_matrix.shape[1]:
                    found = sun.Sun(found.direction, found.cost_ratio, found.evaluations, c.coat_ior)
                light, _ = retinex.log_shading_fit(radiance, columns, edges, usable, **fit)
                albedo, lit = self._divide(columns, radiance, light, usable, extra)
                light_from = "reflection's diffuse, edges' light"
        m = prep.c_matrix.shape[1]
        sun_info = None if found is None else {"direction": found.direction.tolist(), "cost_ratio": found.cost_ratio,
                                                "evaluations": found.evaluations, "used": columns.shape[1] > m,
                                                "through_coat": found.coat_ior is not None}
        irradiance = light[m:m + 1]
        if columns.shape[1] > m:   # the sun joins the reported light as a delta light in SH
            light = light[:m] + self.model.unknown_from_radiance(
                sh.project_directional(sh.order_of(m), found.direction[None, :], irradiance))
        dc = light[0].copy()
        light, albedo = light / dc, albedo * dc          # the unit-DC gauge (the indirect term fixed a scale)
        if sun_info and sun_info["used"]:                # in the reported light's gauge
            sun_info["irradiance"] = (irradiance[0] / dc).tolist()
        group = labels.copy()
        free = np.nonzero(group < 0)[0]
        group[free] = regions + np.arange(len(free))
        result = self._solve_groups(prep, group, f if regions == 0 else regions + len(free), light)
        specular = np.zeros((f, 3))
        reference = result.specular[:regions] if regions else result.specular[group[lit]]
        specular[:] = np.median(reference, axis=0) if len(reference) else 0.0
        specular[labels >= 0] = result.specular[labels[labels >= 0]]
        observed = lit & np.all(np.isfinite(albedo), axis=1)
        labels_out = np.where(observed, group, -1).astype(np.int64)
        per_group = 2 if c.components == "both" else 1
        info = {"clusters": int(len(np.unique(group[observed]))), "uniform_regions": regions,
                "uniform_share": share, "residuals": result.residuals, "lm_residuals": result.lm_residuals,
                "sun": sun_info, "light_from": light_from, "region_deviation": deviation, "region_drift": drift,
                "reflection_explained": None if self._reflected is None else self._reflected.explained.tolist(),
                "lobe_explained": None if self._lobe is None else self._lobe[0].explained.tolist(),
                "degrees_of_freedom": {"observations": int(3 * len(obs.face)),
                                       "unknowns": int(3 * (per_group * (regions + (~(labels >= 0) & observed).sum())
                                                            + light.shape[0] - 1))}}
        zero = ~observed[:, None]
        return Estimate(np.where(zero, 0.0, albedo), np.where(zero, 0.0, specular),
                        self.model.pseudo_from_light(light), labels_out, observed, self.name, c, info,
                        light if self.model.light == "radiance" else None)

    def _tie_regions(self, radiance, columns, edges, usable, labels, regions, light, fit, extra):
        """The light refitted with each uniform region's faces tied to one albedo (twice; faces
        near a region in albedo join it after the first fit), and each region's faces given
        that albedo.

        Returns the light (M', 3), albedo (F, 3), lit (F,), labels (F,) (-1: no region), the
        regions' deviation: the median over their faces of the mean over channels of
        |log(face albedo / region albedo)|, each face's own albedo under the tied fit's light,
        and its drift: that deviation over the same median between neighbouring faces of a
        region (noise alone gives about 0.7; a texture chained into one region by small steps
        drifts further from its region's albedo than neighbours differ)."""
        c = self.config
        for _ in range(2):
            light, region_albedo = retinex.log_shading_fit(radiance, columns, edges, usable, labels,
                                                           initial=light, **fit)
            albedo, lit = self._divide(columns, radiance, light, usable, extra)
            joined = BilinearSegmented._assign(labels, albedo, lit, edges, 2.5 * c.segment_threshold)
            labels = np.where(lit & (joined < regions), joined, -1)
        tied = lit & (labels >= 0)
        a, b = edges[:, 0], edges[:, 1]
        inside = tied[a] & tied[b] & (labels[a] == labels[b])
        deviation = _deviation(albedo[tied], region_albedo[labels[tied]]) if tied.any() else np.inf
        noise = _deviation(albedo[a[inside]], albedo[b[inside]]) if inside.any() else 0.0
        albedo[tied] = region_albedo[labels[tied]]
        return light, albedo, lit, labels, deviation, deviation / max(noise, 1e-12)

    def _usable_reflection(self, prep, regions: bool) -> reflected_light.ReflectedLight | None:
        """The coat's reflected light when this fit may use it: ``reflected_light`` on (and
        ``reflected_regions`` for an object of uniform regions), no interreflection term, the
        map determined and explaining at least ``reflected_min_explained`` of the view changes
        (mean over the channels). Where the edge search kept a sun, :meth:`_fit` takes the
        map's light only when the map's own sun is kept too."""
        c = self.config
        if not c.reflected_light or (regions and not c.reflected_regions) or c.interreflection:
            return None
        r = self._reflection(prep)
        return r if r.determined and np.mean(r.explained) >= c.reflected_min_explained else None

    def _coated_diffuse(self, prep, radiance, columns, found: sun.Sun | None):
        """Each face's diffuse radiance from the coat's map fit (its reflection removed, the
        exit transmission divided out) and the shading columns through the coat (the edge
        search's sun through it too, when kept), where the map's light itself failed its gate
        but the map is determined and explains at least ``reflected_diffuse_min_explained``
        of the view changes; None otherwise. Faces the map fit did not see keep ``radiance``."""
        c = self.config
        if not c.reflected_light or c.interreflection:
            return None
        r = self._reflection(prep)
        if not r.determined or np.mean(r.explained) < c.reflected_diffuse_min_explained:
            return None
        mesh = prep.data.mesh
        through = self.model.diffuse_matrix(mesh, prep.sampling, prep.visibility, coat_ior=c.coat_ior)
        if columns.shape[1] > prep.c_matrix.shape[1]:
            through = np.hstack([through, sun.sun_shading(mesh, prep.caster, found.direction, c.coat_ior)[:, None]])
        return np.where(np.isfinite(r.diffuse) & (r.diffuse > 0), r.diffuse, radiance), through

    def _reflection(self, prep) -> reflected_light.ReflectedLight:
        """The light the coat reflects, fitted once per solve on the observations before any
        coat correction."""
        if self._reflected is None:
            obs = self._original_obs
            self._reflected = reflected_light.fit_reflected_light(
                obs.face, obs.rgb, obs.view_dir, prep.data.mesh.face_normals, prep.sampling, prep.visibility,
                self.config.coat_ior, loss=self.loss)
        return self._reflected

    def _reflected_light(self, prep, radiance, edges, usable, fit):
        """The texture's light from the coat's reflection (:mod:`estimator.reflected_light`).
        The map's brightest compact source is tried as a sun with exact shadows beside the
        map's sky (that source cut out), its irradiance over the sky's fitted to the albedo
        edges per channel (one unknown each); it is kept when positive in every channel and
        the edge cost ratio is at most ``reflected_sun_max_ratio``. Otherwise the whole map
        is the light (cutting its peak out without a sun cost plastic/lab 8.7 dB).

        Returns the light (M', 3) (unit sky DC, the sun's irradiance last when kept), the
        shading columns (F, M') through the coat and the sun (or None)."""
        c = self.config
        through_coat = self.model.diffuse_matrix(prep.data.mesh, prep.sampling, prep.visibility, coat_ior=c.coat_ior)
        sky_map, direction = self._reflected.sky_and_sun()
        sky = self.model.unknown_from_radiance(sh.project_latlong(c.sh_order, sky_map))
        sky = sky / sky[0]
        sun_column = sun.sun_shading(prep.data.mesh, prep.caster, direction, c.coat_ior)
        sky_shading = through_coat @ sky                                    # (F, 3)
        with_sun = np.zeros(3)
        for k in range(3):   # one unknown per channel: the sun's irradiance over the sky's
            pair = np.stack([sky_shading[:, k], sun_column], axis=1)
            with_sun[k] = retinex.log_shading_fit(radiance[:, [k, k, k]], pair, edges, usable, **fit)[0][1, 0]
        both = sky_shading + with_sun * sun_column[:, None]
        base = retinex.edge_residuals(radiance, sky_shading, edges, usable)
        trial = retinex.edge_residuals(radiance, np.maximum(both, 1e-300), edges, usable)
        finite = np.all(np.isfinite(base), axis=1) & np.all(np.isfinite(trial), axis=1)   # unlit faces
        scale = sun.edge_scale(base[finite])
        ratio = sun.edge_cost(trial[finite], scale) / max(sun.edge_cost(base[finite], scale), 1e-300)
        if np.all(with_sun > 0) and ratio <= c.reflected_sun_max_ratio:
            found = sun.Sun(direction, ratio, 3, c.coat_ior)   # 3 evaluations: one fit per channel
            return (np.vstack([sky, with_sun[None]]), np.hstack([through_coat, sun_column[:, None]]), found)
        whole = self.model.unknown_from_radiance(self._reflected.sh(c.sh_order))
        return whole / whole[0], through_coat, None

    def _usable_lobe(self, prep) -> lobe_light.LobeLight | None:
        """The light a shared Phong lobe reflects (:mod:`estimator.lobe_light`), fitted once
        per solve on the observations before any coat correction, when ``reflected_lobe`` is
        on, there is no interreflection term, the rows fit in memory and it explains at least
        ``reflected_min_explained`` of the view changes (mean over the channels)."""
        c = self.config
        if not c.reflected_lobe or c.interreflection or prep.streamed:
            return None
        if self._lobe is None:
            obs = self._original_obs
            if prep.model.name == "lobe" and obs is prep.obs:
                rows = prep.d_rows
            else:
                # a first fit on every LOBE_PREVIEW-th face: a coat or a bare surface (0.01-0.93) is
                # far below the gate and costs no more (about 1.5 s at full size for the whole fit)
                part = obs.face % LOBE_PREVIEW == 0
                preview = lobe_light.fit_lobe_light(obs.face[part], obs.rgb[part], self._lobe_rows(prep, obs, part),
                                                    obs.num_faces, loss=self.loss)
                if np.mean(preview.explained) < c.reflected_min_explained - 0.05:
                    self._lobe = (preview, None)
                    return None
                rows = self._lobe_rows(prep, obs, np.ones(len(obs.face), bool))
            self._lobe = (lobe_light.fit_lobe_light(obs.face, obs.rgb, rows, obs.num_faces, loss=self.loss), rows)
        fitted = self._lobe[0]
        return fitted if self._lobe[1] is not None and np.mean(fitted.explained) >= c.reflected_min_explained else None

    def _lobe_rows(self, prep, obs, rows: np.ndarray) -> np.ndarray:
        """(n, M) the Phong lobe rows (exponent ``phong_exponent``) of the observations ``rows`` (N,) bool."""
        normals = prep.data.mesh.face_normals[obs.face[rows]]
        return lobe_matrix(obs.face[rows], mirror_directions(normals, obs.view_dir[rows]), prep.sampling,
                           prep.visibility, self.config.sh_order, self.config.phong_exponent)

    def _lobe_reflected_light(self, prep, edges, usable, found: sun.Sun | None):
        """The texture's light from the lobe's reflection: the SH radiance, its DC from the
        edges (:func:`estimator.lobe_light.dc_from_edges`). The edge search's sun, whether
        or not that search kept it, is tried as a delta light in both terms (its lobe column
        in the view fit, its exact shadows in the shading) and kept when its irradiance is
        positive in every channel and it lowers the edges' robust cost to at most
        ``reflected_sun_max_ratio`` of the cost without it.

        Returns each face's diffuse radiance (F, 3) (negative clipped to 0), the light (M', 3)
        (the model's light unknown, the sun's irradiance last when kept), the shading columns
        (F, M') and the sun's edge cost ratio (None: no sun tried)."""
        c, mesh = self.config, prep.data.mesh
        fitted, rows = self._lobe
        plain = diffuse_matrix(mesh, prep.sampling, prep.visibility, c.sh_order)   # rows of the radiance

        def split(fit, shading_rows):
            light, diffuse = fit.with_dc(lobe_light.dc_from_edges(fit, shading_rows, edges, usable))
            return light, np.maximum(np.nan_to_num(diffuse), 0.0), shading_rows

        light, diffuse, plain = chosen = split(fitted, plain)
        sun_column, ratio = None, None
        if found is not None:
            obs = self._original_obs
            shading = sun.sun_shading(mesh, prep.caster, found.direction)
            cosine = np.maximum(mesh.face_normals @ found.direction, 0.0)
            share = np.where(cosine > 0, shading * np.pi / np.maximum(cosine, 1e-300), 0.0)   # lit share
            mirror = mirror_directions(mesh.face_normals[obs.face], obs.view_dir)
            lobe = phong_lobe(mirror, found.direction[None, :], c.phong_exponent) * share[obs.face, None]   # (N, 1)
            with_sun = lobe_light.fit_lobe_light(obs.face, obs.rgb, np.hstack([rows, lobe]), obs.num_faces, loss=self.loss)
            if np.all(with_sun.light[-1] > 0):
                s_light, s_diffuse, s_plain = trial = split(with_sun, np.hstack([plain, shading[:, None]]))
                base = retinex.edge_residuals(diffuse, plain @ light, edges, usable)
                other = retinex.edge_residuals(s_diffuse, np.maximum(s_plain @ s_light, 1e-300), edges, usable)
                finite = np.all(np.isfinite(base), axis=1) & np.all(np.isfinite(other), axis=1)
                scale = sun.edge_scale(base[finite])
                ratio = sun.edge_cost(other[finite], scale) / max(sun.edge_cost(base[finite], scale), 1e-300)
                if ratio <= c.reflected_sun_max_ratio:
                    chosen, sun_column = trial, shading
        light, diffuse, _ = chosen
        m = prep.c_matrix.shape[1]
        columns = self.model.diffuse_matrix(mesh, prep.sampling, prep.visibility)
        if sun_column is not None:
            columns = np.hstack([columns, sun_column[:, None]])
        return diffuse, np.vstack([self.model.unknown_from_radiance(light[:m]), light[m:]]), columns, ratio

    @staticmethod
    def _divide(columns, radiance, light, usable, extra=0.0) -> tuple[np.ndarray, np.ndarray]:
        """(F, 3) radiance over the shading ``columns @ light`` (columns (F, M'): the diffuse
        matrix, and a sun's column when one was found; plus an ``extra`` indirect shading),
        and (F,) where that is an albedo: usable and lit above 2 % of the 95th-percentile shading."""
        shade = columns @ light + extra
        lum = shade.mean(axis=1)
        level = max(float(np.percentile(lum[usable], 95)), 1e-30)
        lit = usable & np.all(shade > 0, axis=1) & (lum > 0.02 * level)
        with np.errstate(divide="ignore", invalid="ignore"):
            albedo = np.where(lit[:, None], radiance / np.where(shade > 0, shade, 1.0), 0.0)
        return albedo, lit


LOBE_PREVIEW = 4   # the lobe's gate is first tried on every 4th face


def _deviation(albedo: np.ndarray, reference: np.ndarray) -> float:
    """The median over rows of the mean over channels of |log(albedo / reference)| (both (n, 3))."""
    return float(np.median(np.abs(np.log(np.maximum(albedo, 1e-12) / np.maximum(reference, 1e-12))).mean(axis=1)))


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two labelings group the items identically (labels may be renamed)."""
    pairs = np.unique(np.stack([a, b], 1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


EXPONENT_CANDIDATES = (5.0, 7.0, 10.0, 14.0, 20.0, 28.0, 40.0)

# the default for datasets that recommend no method: on the real-light family (36 cases) it
# reaches a median diffuse PSNR of 33.9 dB against the paper's 24.9 (28 cases meet all three
# targets against 5; benchmarks/README.md); the paper's algorithm stays available, unchanged,
# as 'bilinear-clustered', and the previous default as 'bilinear-segmented'
DEFAULT_METHOD = "retinex-segmented"


def estimate(data: MultiViewData, method: str | None = None, config: EstimatorConfig | None = None,
             known_sh: np.ndarray | None = None, known_radiance: np.ndarray | None = None, log=None,
             exponent_candidates: tuple[float, ...] | None = None) -> Estimate:
    """Run a registered method on in-memory data (the estimator's one entry point).

    Parameters
    ----------
    method : a registered name; None: :data:`DEFAULT_METHOD`.
    known_sh : (M', 3) pseudo illumination for 'known-illumination' (truncated/padded to the order).
    known_radiance : (M', 3) radiance SH, for 'known-illumination' with ``specular_model='lobe'``.
    log : optional callable receiving progress lines.
    exponent_candidates : estimate the Phong exponent too: solve with each candidate
        (observations and shadow function computed once) and keep the lowest final
        residual. Only models that depend on the exponent qualify
        (``specular_model='lobe'`` or ``diffuse_light='defiltered'``).
    """
    config = config or EstimatorConfig()
    cls = get_method(method or DEFAULT_METHOD)
    t0 = time.perf_counter()
    poses, rounds, offsets = None, config.pose_rounds, None
    caster = RayCaster(data.mesh, config.variant)   # one for the pose check, the refinement and the solve
    if rounds == 0 and config.auto_pose > 0 and len(data.views) >= 2:
        offsets = pose.outline_offsets(data, caster)
        if np.nanmax(offsets, initial=0.0) > config.auto_pose:
            rounds = pose.POSE_ROUNDS
            if log:
                log(f"a view's outline is {np.nanmax(offsets):.1f} px off its alpha: refining the poses")
    if rounds > 0:
        fixed = replace(config, pose_rounds=0, auto_pose=0.0)
        data, poses = pose.refine_poses(
            data, lambda d: estimate(d, method, fixed, known_sh, known_radiance, None, exponent_candidates),
            rounds, min(config.pose_folds, len(data.views)), caster, log)
    pose_seconds = time.perf_counter() - t0
    prep = prepare(data, config, log, cls.name, cls.streams, caster)
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
    solve_seconds = time.perf_counter() - t
    est.info["observations"] = int(len(prep.obs.face))
    est.info["observations_all"] = int(len(prep.all_obs.face))
    est.info["unobserved_share"] = float(1.0 - est.observed.mean())
    est.info["faces_without_kept_views"] = float(1.0 - prep.obs.observed_faces().mean())
    rejected = prep.all_obs.rejected
    est.info["rejected_pixels"] = {v.name: int(n) for v, n in zip(data.views, rejected) if n > 0}
    t = time.perf_counter()
    est.info["trust"], stats = trust.diagnose(prep, est, [v.name for v in data.views])
    est.info["timings"] = {**prep.timings, "solve": solve_seconds, "trust": time.perf_counter() - t,
                           "total": time.perf_counter() - t0}
    if offsets is not None:
        est.info["outline_offsets_px"] = {v.name: (None if np.isnan(o) else float(o))
                                          for v, o in zip(data.views, offsets)}
    if poses is not None:
        est.info["timings"]["pose_refinement"] = pose_seconds
        est.info["poses"] = poses
    est.face_stats = {**est.face_stats, **stats}
    automatic = [] if poses is None or config.pose_rounds > 0 else [
        f"poses refined automatically ({pose.POSE_ROUNDS} rounds): the alpha outline of "
        f"{data.views[int(np.nanargmax(offsets))].name} lay {np.nanmax(offsets):.1f} px from the mesh's "
        f"(auto_pose {config.auto_pose:g} px); the corrected cameras are in 'poses'"]
    est.info["warnings"] = trust.warnings_for(est) + automatic + [
        f"pose refinement of {p['name']} diverged (beyond {pose.POSE_MAX_DEGREES:g} deg or "
        f"{pose.POSE_MAX_SHIFT:g} x the distance): it keeps its silhouette-aligned pose" for p in poses or []
        if p["diverged"]]
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


from . import peer  # noqa: E402,F401  (registers 'mitsuba-ad'; it subclasses Method)
