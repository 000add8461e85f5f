"""Numbers that compare an estimate with ground truth."""
from __future__ import annotations

import numpy as np
from scipy.special import comb


def adjusted_rand_index(truth: np.ndarray, labels: np.ndarray) -> float:
    """Adjusted Rand index (Hubert & Arabie 1985) of two labelings (N,); 1 = same partition."""
    truth, labels = np.asarray(truth), np.asarray(labels)
    if truth.shape != labels.shape or truth.ndim != 1:
        raise ValueError(f"labelings must be 1-D of equal length, got {truth.shape} and {labels.shape}")
    _, t = np.unique(truth, return_inverse=True)
    _, l = np.unique(labels, return_inverse=True)
    table = np.zeros((t.max() + 1, l.max() + 1), dtype=np.int64)
    np.add.at(table, (t, l), 1)
    index = comb(table, 2).sum()
    rows, cols = comb(table.sum(1), 2).sum(), comb(table.sum(0), 2).sum()
    total = comb(len(truth), 2)
    expected = rows * cols / total if total > 0 else 0.0
    maximum = 0.5 * (rows + cols)
    if maximum == expected:
        return 1.0
    return float((index - expected) / (maximum - expected))
