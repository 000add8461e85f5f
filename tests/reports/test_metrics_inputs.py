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
    with pytest.raises(InputError, match="gauge would be negative"):
        metrics.albedo_psnr(-a, a, np.ones(20, bool))
    inf = a.copy()
    inf[3, 1] = np.inf
    with pytest.raises(InputError, match="non-finite estimated albedo"):
        metrics.albedo_ratios(inf, a, np.ones(20, bool), "lstsq")
    with pytest.raises(InputError, match="gauge must be"):
        metrics.albedo_psnr(a, a, np.ones(20, bool), gauge="nope")
    gt = GroundTruth(a, a, np.eye(9, 3), {"exponent": 10.0}, {})
    with pytest.raises(InputError, match="component must be"):
        evaluation_mask(gt, a, np.ones(20, bool), "nope")
    light = np.zeros((9, 3))
    light[0] = 1.0
    assert metrics.irradiance_error(light, light[:1]) < 1e-12   # a truth of a lower order is padded, not spread


def test_image_metrics_ari_and_psnr_refuse_what_has_no_value():
    from reports import metrics

    image = np.ones((5, 5, 3))
    with pytest.raises(InputError, match="at least 7 x 7 pixels"):
        metrics.image_metrics(image, image, np.ones((5, 5), bool))
    with pytest.raises(InputError, match="mask is empty"):
        metrics.psnr(image, image, np.zeros((5, 5), bool), 1.0)
    with pytest.raises(InputError, match="one length > 0"):
        metrics.adjusted_rand_index(np.zeros(0, int), np.zeros(0, int))
