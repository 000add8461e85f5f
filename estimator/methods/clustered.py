"""``bilinear-clustered``: the paper's full method (mean-shift clusters in colour, ALS, re-clustering)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..core.settings import Section
from ..solvers.clustering import mean_shift, same_partition, split_clusters
from .base import Method, register_method


@dataclass
class ClusteredConfig(Section):
    """Clusters in colour space and their refinement (``bilinear-clustered``; the first
    clusters of ``bilinear-segmented``).

    Attributes
    ----------
    min_brightness : faces whose median colour is below this share of the 95th percentile
        are left unestimated: unlit in every view, they carry no colour.
    bandwidth : angular mean-shift sigma on unit colours (radians).
    split_bandwidth : Euclidean split sigma, relative to a cluster's median albedo.
    min_cluster_fraction : a split-off cluster needs at least this share of the estimated
        faces (else its faces join the nearest kept sub-cluster).
    recluster_rounds : cap on solve + re-cluster rounds.
    recluster_min_shading, recluster_shading_percentile : re-clustering judges a face's
        shading-corrected colour only when its diffuse shading is at least
        ``recluster_min_shading`` of the ``recluster_shading_percentile`` of all faces'
        shading (dividing by a small shading amplifies noise).
    """

    min_brightness: float = 0.03
    bandwidth: float = 0.08
    split_bandwidth: float = 0.2
    min_cluster_fraction: float = 0.01
    recluster_rounds: int = 5
    recluster_min_shading: float = 0.25
    recluster_shading_percentile: float = 90.0

    def check(self):
        return [
            (self.bandwidth > 0 and self.split_bandwidth > 0, "bandwidth and split_bandwidth must be > 0"),
            (0 <= self.min_brightness < 1, "min_brightness must lie in [0, 1)"),
            (0 <= self.min_cluster_fraction < 0.5, "min_cluster_fraction must lie in [0, 0.5)"),
            (self.recluster_rounds >= 1, "recluster_rounds must be >= 1"),
            (0 <= self.recluster_min_shading < 1, "recluster_min_shading must lie in [0, 1)"),
            (0 < self.recluster_shading_percentile <= 100, "recluster_shading_percentile must lie in (0, 100]"),
        ]


@register_method
class BilinearClustered(Method):
    """The full method: angular mean-shift clusters of median colours, ALS solve,
    Euclidean re-clustering of shading-corrected colours, repeated until stable."""

    name = "bilinear-clustered"

    def solve(self, prep):
        c = self.config
        med = prep.all_obs.median_color()
        brightness = np.nan_to_num(med).mean(axis=1)
        # faces dark in most views (their median colour) carry no colour: they are not estimated
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
            if any(same_partition(split, old) for old in visited):
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
