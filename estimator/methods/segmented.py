"""``bilinear-segmented``: the paper's bilinear solve over regions found on the mesh."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..core.reductions import group_quantile
from ..core.settings import Section
from ..model.estimate import Estimate
from ..solvers.bilinear import BilinearResult
from ..solvers.clustering import mean_shift, same_partition
from ..solvers.segmentation import assign_to_regions, segment
from .base import register_method
from .clustered import BilinearClustered


@dataclass
class SegmentedConfig(Section):
    """``bilinear-segmented``: regions on the mesh, boundary relabelling, tied regions.

    Attributes
    ----------
    diffuse_quantile : a face's diffuse radiance is this quantile of its colours (less the
        fitted specular) over the views.
    segment_min_shading : faces are segmented when their diffuse shading is at least this
        share of the ``recluster_shading_percentile`` level.
    tie_regions : make the regions' albedo ratios agree with the radiance ratios across
        their boundaries (neighbours see the same light).
    relabel_rounds : boundary faces move to the neighbouring region that best predicts their
        observations, then the light is solved again, up to this many times.
    relabel_free_ratio : a face outside every region joins a neighbouring region when that
        region's cost is within this factor of its own fit's (three unknowns fewer).
    """

    diffuse_quantile: float = 0.25
    segment_min_shading: float = 0.05
    tie_regions: bool = True
    relabel_rounds: int = 3
    relabel_free_ratio: float = 3.0

    def check(self):
        return [
            (0 <= self.diffuse_quantile <= 1, "diffuse_quantile must lie in [0, 1]"),
            (0 <= self.segment_min_shading < 1, "segment_min_shading must lie in [0, 1)"),
            (self.relabel_rounds >= 0, "relabel_rounds must be >= 0"),
            (self.relabel_free_ratio >= 1, "relabel_free_ratio must be >= 1"),
        ]


@register_method
class BilinearSegmented(BilinearClustered):
    """The paper's bilinear solve with clusters found on the mesh instead of in colour space.

    Beyond the paper (its accuracy: ``benchmarks/README.md``):

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
                                c.segment_threshold, c.uniform_spread, bridges=prep.blends_albedos)
            new_group = assign_to_regions(labels, albedo, seen, edges, 2.5 * c.segment_threshold)
            new_in_solve = seen & (new_group < int(labels.max()) + 1)  # faces of uniform regions carry the light
            history.append(int(labels.max()) + 1)
            if new_in_solve.sum() < 0.5 * seen.sum():
                break  # no piecewise-uniform structure this round: keep the partition that had one
            in_solve = new_in_solve
            if any(same_partition(new_group[seen], old) for old in visited):
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
        # a diffuse and a specular albedo per region, a diffuse one per free face (their specular
        # the regions' median), the light less its DC gauge
        per_region = 2 if c.components == "both" else 1
        unknowns = per_region * regions + int((observed & ~grouped).sum()) + result.light.shape[0] - 1
        info = {"clusters": int(len(np.unique(face_group[observed]))), "uniform_regions": regions,
                "own_specular_groups": regions,   # the labels below fit a specular of their own
                "uniform_share": float(np.mean(grouped[observed])) if observed.any() else 0.0,
                "angular_clusters": history[0], "regions_per_round": history,
                "clustering_s": time.perf_counter() - t,
                "residuals": result.residuals, "lm_residuals": result.lm_residuals,
                "degrees_of_freedom": {"observations": int(3 * len(prep.obs.face)), "unknowns": int(3 * unknowns)}}
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
