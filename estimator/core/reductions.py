"""Per-group reductions over rows (observations grouped by face, faces by region), vectorised."""
from __future__ import annotations

import numpy as np


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
