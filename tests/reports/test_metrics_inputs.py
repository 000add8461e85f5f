"""The metrics refuse what they would score wrongly without a word (0/1 integer masks read as
face indices, negative or non-finite estimates, unknown gauge and component names)."""
from __future__ import annotations

import numpy as np
import pytest

from estimator import InputError


def test_metrics_refuse_what_they_would_score_wrongly():
    from reports import metrics
    from reports.ground_truth import GroundTruth, evaluation_mask

    rng = np.random.default_rng(0)
    a = rng.uniform(0.1, 0.9, (20, 3))
    with pytest.raises(InputError, match=r"mask must be \(20,\) bool"):
        metrics.albedo_ratios(a, a, (np.arange(20) < 5).astype(int), "lstsq")
    with pytest.raises(InputError, match="non-finite or negative estimated albedo"):
        metrics.albedo_psnr(-a, a, np.ones(20, bool))
    with pytest.raises(InputError, match="gauge must be"):
        metrics.albedo_psnr(a, a, np.ones(20, bool), gauge="nope")
    gt = GroundTruth(a, a, np.eye(9, 3), {"exponent": 10.0}, {})
    with pytest.raises(InputError, match="component must be"):
        evaluation_mask(gt, a, np.ones(20, bool), "nope")
    light = np.zeros((9, 3))
    light[0] = 1.0
    assert metrics.irradiance_error(light, light[:1]) < 1e-12   # a truth of a lower order is padded, not spread
