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


def quantile_color(face: np.ndarray, rgb: np.ndarray, num_faces: int, q: float) -> np.ndarray:
    """(F, 3) per-face, per-channel ``q``-quantile (lower neighbour) of observation colours
    (N, 3) of faces (N,); NaN where a face has no observation.

    Specular reflection only adds light, so a low quantile over views is the
    view-independent diffuse radiance with the highlights left out.
    """
    out = np.full((num_faces, rgb.shape[1]), np.nan)
    counts = np.bincount(face, minlength=num_faces)
    seen = counts > 0
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    pick = starts[seen] + np.floor(q * (counts[seen] - 1)).astype(np.int64)
    for c in range(rgb.shape[1]):
        order = np.lexsort((rgb[:, c], face))
        out[seen, c] = rgb[order, c][pick]
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
    order = np.argsort(inverse, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    values = feat[valid][order]
    medians, spreads = [], []
    for start, count in zip(starts, counts):
        part = values[start:start + count]
        med = np.median(part, axis=0)
        medians.append(med)
        spreads.append(float(np.max(np.median(np.abs(part - med), axis=0))))
    medians, spreads = np.array(medians), np.array(spreads)
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
    region_medians = np.array([np.median(albedo[labels == r], axis=0) for r in range(len(present))])
    return labels, region_medians
