"""Uniform-albedo regions on the mesh: per-face diffuse radiance, albedo features and
graph segmentation (used by the ``bilinear-segmented`` method).

Neighbouring faces receive nearly the same light, so where their shading-corrected
albedos agree they belong to one region (a Retinex edge cue), whatever the hue.
"""
from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from .clustering import mean_shift


def group_quantile(group: np.ndarray, values: np.ndarray, num_groups: int, q: float,
                   interpolate: bool = False) -> np.ndarray:
    """(G, C) per-group, per-column ``q``-quantile of ``values`` (N, C) whose rows belong to
    ``group`` (N,); NaN for a group with no row. One sort per column, no loop over groups.

    The lower neighbour of the quantile's position, or with ``interpolate`` the linear
    interpolation between its neighbours (numpy's default: q = 0.5 is ``np.median``).
    With faces as groups and observation colours as values, a low quantile over views is
    the view-independent diffuse radiance (specular reflection only adds light).
    """
    out = np.full((num_groups, values.shape[1]), np.nan)
    counts = np.bincount(group, minlength=num_groups)
    seen = counts > 0
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])[seen]
    position = q * (counts[seen] - 1)
    lo = starts + np.floor(position).astype(np.int64)
    hi = starts + np.ceil(position).astype(np.int64) if interpolate else lo
    frac = position - np.floor(position)
    for c in range(values.shape[1]):
        ordered = values[np.lexsort((values[:, c], group)), c]
        out[seen, c] = ordered[lo] + frac * (ordered[hi] - ordered[lo])
    return out


def albedo_features(albedo: np.ndarray) -> np.ndarray:
    """(F, 4) features in which a distance is a relative albedo difference whatever the
    colour: log brightness (mean over channels) and half the chromaticity (albedo /
    brightness). Per-channel logs are not used: a channel near zero (the blue of a
    yellow) would turn noise into large differences."""
    level = np.maximum(albedo.mean(axis=1), 1e-30)
    return np.column_stack([np.log(level), 0.5 * albedo / level[:, None]])


def segment(albedo: np.ndarray, edges: np.ndarray, valid: np.ndarray, threshold: float = 0.12,
            uniform_spread: float = 0.08, min_size: int = 10, merge_bandwidth: float = 0.12
            ) -> tuple[np.ndarray, np.ndarray]:
    """Uniform-albedo regions on the face-adjacency graph.

    Neighbours whose :func:`albedo_features` differ by less than ``threshold`` (largest
    component) are joined (connected components). A component of at least ``min_size``
    faces whose feature spread (median absolute deviation, largest component) is below
    ``uniform_spread`` is uniform; uniform components with similar albedo (mean shift,
    ``merge_bandwidth``) are one region even when apart.

    Returns
    -------
    labels : (F,) int64 region of each valid face in a uniform region, else -1.
    medians : (R, C) median albedo of each region.
    """
    f = len(albedo)
    feat = albedo_features(np.where(valid[:, None], albedo, 1.0))
    e0, e1 = edges[:, 0], edges[:, 1]
    close = valid[e0] & valid[e1] & (np.max(np.abs(feat[e0] - feat[e1]), axis=1) < threshold)
    graph = sparse.csr_matrix((np.ones(close.sum()), (e0[close], e1[close])), shape=(f, f))
    _, comp = connected_components(graph, directed=False)
    ids, inverse, counts = np.unique(comp[valid], return_inverse=True, return_counts=True)
    values = feat[valid]
    medians = group_quantile(inverse, values, len(ids), 0.5, interpolate=True)
    spreads = group_quantile(inverse, np.abs(values - medians[inverse]), len(ids), 0.5, interpolate=True).max(axis=1)
    uniform = (counts >= min_size) & (spreads < uniform_spread)
    labels = np.full(f, -1, dtype=np.int64)
    if not uniform.any():
        return labels, np.zeros((0, albedo.shape[1]))
    merged, _ = mean_shift(medians[uniform], merge_bandwidth, metric="euclidean")
    region_of_component = np.full(len(ids), -1)
    region_of_component[np.nonzero(uniform)[0]] = merged
    labels[valid] = region_of_component[inverse]
    present, compact = np.unique(labels[labels >= 0], return_inverse=True)
    labels[labels >= 0] = compact
    inside = labels >= 0
    return labels, group_quantile(labels[inside], albedo[inside], len(present), 0.5, interpolate=True)
