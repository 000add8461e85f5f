"""Mean-shift colour clustering (the paper's Eq. 14-16)."""
from __future__ import annotations

import numpy as np

from ..core.errors import InputError


def _histogram_seeds(points: np.ndarray, bins: int) -> np.ndarray:
    """Centres of the non-empty cells of a bins^3 histogram of ``points`` (N, 3)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    cell = np.minimum(((points - lo) / span * bins).astype(np.int64), bins - 1)
    occupied = np.unique(cell, axis=0)
    return lo + (occupied + 0.5) / bins * span


def _merge_peaks(peaks: np.ndarray, distance, bandwidth: float) -> np.ndarray:
    """Greedy merge of peaks closer than ``bandwidth`` (first come, first kept)."""
    kept: list[np.ndarray] = []
    for p in peaks:
        if not kept or distance(p[None], np.array(kept)).min() >= bandwidth:
            kept.append(p)
    return np.array(kept)


def _angular(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(a @ b.T, -1.0, 1.0))


def _euclidean(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(np.sum(a * a, 1)[:, None] + np.sum(b * b, 1)[None] - 2 * a @ b.T, 0.0))


def mean_shift(points: np.ndarray, bandwidth: float, metric: str = "angular", bins: int = 10,
               iterations: int = 100, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Mean shift with a Gaussian kernel, seeded from a colour histogram.

    Parameters
    ----------
    points : (N, 3). For ``metric='angular'`` they are normalised to unit length
        and the distance is d1 = acos(va . vb) (Eq. 14-15); for 'euclidean' it is
        |va - vb| (Eq. 16).
    bandwidth : kernel sigma (radians for 'angular').

    Returns
    -------
    labels : (N,) int64, each point's nearest peak.
    peaks : (P, 3) the modes found, merged when closer than ``bandwidth``.
    """
    if bandwidth <= 0:
        raise InputError(f"mean-shift bandwidth must be > 0, got {bandwidth}")
    x = np.asarray(points, dtype=np.float64)
    if x.ndim != 2 or len(x) == 0:
        raise InputError(f"mean shift needs a non-empty (N, D) array, got {x.shape}")
    angular = metric == "angular"
    if angular:
        x = x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)
    distance = _angular if angular else _euclidean
    modes = _histogram_seeds(x, bins)
    if angular:
        modes /= np.linalg.norm(modes, axis=1, keepdims=True)
    for _ in range(iterations):
        w = np.exp(-0.5 * (distance(modes, x) / bandwidth) ** 2)        # (S, N)
        new = (w @ x) / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
        if angular:
            new /= np.maximum(np.linalg.norm(new, axis=1, keepdims=True), 1e-300)
        shift = np.abs(new - modes).max()
        modes = new
        if shift < tol:
            break
    # strongest modes first, so merging keeps the densest representative
    density = np.exp(-0.5 * (distance(modes, x) / bandwidth) ** 2).sum(axis=1)
    peaks = _merge_peaks(modes[np.argsort(-density)], distance, bandwidth)
    labels = np.argmin(distance(x, peaks), axis=1)
    return labels.astype(np.int64), peaks


def split_clusters(values: np.ndarray, labels: np.ndarray, relative_bandwidth: float,
                   valid: np.ndarray | None = None, min_size: int = 1) -> np.ndarray:
    """Split each cluster by Euclidean mean shift on ``values`` (N, 3).

    The bandwidth of each cluster is ``relative_bandwidth`` times the median
    norm of its values, so dark and bright regions of one chromaticity (the
    fish's black lines on yellow) separate at any exposure. Points where
    ``valid`` is false (e.g. faces in deep shadow) join the nearest sub-peak.
    Sub-peaks supported by fewer than ``min_size`` valid points are dropped
    (their points join the nearest kept peak), which keeps the partition
    from flickering between solver rounds.

    Returns
    -------
    (N,) int64 new labels, numbered 0..P-1.
    """
    valid = np.ones(len(values), bool) if valid is None else valid
    out = np.zeros(len(values), dtype=np.int64)
    next_label = 0
    for label in np.unique(labels):  # loop over clusters (a handful), not faces
        members = np.nonzero(labels == label)[0]
        good = members[valid[members]]
        if len(good) < 2:
            out[members] = next_label
            next_label += 1
            continue
        scale = np.median(np.linalg.norm(values[good], axis=1))
        sub, peaks = mean_shift(values[good], max(relative_bandwidth * scale, 1e-12), metric="euclidean")
        support = np.bincount(sub, minlength=len(peaks))
        if (support >= min_size).any():
            peaks = peaks[support >= min_size]
        out[members] = next_label + np.argmin(_euclidean(values[members], peaks), axis=1)
        next_label += len(peaks)
    return np.unique(out, return_inverse=True)[1].astype(np.int64)


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two labelings group the items identically (labels may be renamed)."""
    pairs = np.unique(np.stack([a, b], 1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))
