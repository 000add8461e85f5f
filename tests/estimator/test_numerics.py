"""The shared numerics: the unit-DC gauge, the edge-cost ratio and PSNR."""
from __future__ import annotations

import numpy as np
import pytest

from estimator import PSNR_CAP_DB, psnr_db, unit_dc
from estimator.light.edge_fit import edge_cost_ratio


def test_unit_dc_gives_dc_one_and_keeps_the_product():
    rng = np.random.default_rng(1)
    light = rng.normal(size=(9, 3))
    light[0] = [2.0, -0.5, 4.0]
    albedo = rng.random((5, 3))
    unit, dc = unit_dc(light)
    np.testing.assert_allclose(unit[0], 1.0)
    np.testing.assert_allclose(unit * dc, light, rtol=1e-15)     # albedo x dc keeps albedo x light
    np.testing.assert_array_equal(dc, light[0])
    assert unit.shape == light.shape and np.all(np.isfinite(albedo * dc))


def test_unit_dc_leaves_a_dark_channel_as_it_is():
    light = np.array([[1.0, 0.0, 1e-310], [0.5, 0.2, 0.1]])
    unit, dc = unit_dc(light)
    np.testing.assert_array_equal(dc, [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(unit, light)


def test_edge_cost_ratio_is_one_for_the_same_residuals_and_below_for_smaller_ones():
    rng = np.random.default_rng(2)
    base = rng.standard_cauchy((500, 3)) * 0.1
    assert edge_cost_ratio(base, base) == pytest.approx(1.0)
    assert edge_cost_ratio(base, 0.5 * base) < 1.0 < edge_cost_ratio(base, 2.0 * base)


def test_edge_cost_ratio_leaves_out_unlit_edges():
    base = np.array([[0.1, 0.2, 0.1], [0.3, 0.1, 0.2], [np.inf, 0.0, 0.0], [0.2, 0.2, 0.2]])
    trial = base.copy()
    trial[1, 0] = np.nan
    finite = [0, 3]
    assert edge_cost_ratio(base, trial) == pytest.approx(edge_cost_ratio(base[finite], trial[finite]))


def test_psnr_convention():
    assert psnr_db(0.01, 1.0) == pytest.approx(20.0)
    assert psnr_db(1.0, 10.0) == pytest.approx(20.0)          # the peak scales with the signal
    assert psnr_db(0.0, 1.0) == PSNR_CAP_DB == psnr_db(1e-12, 1.0)


def test_held_out_scores_clip_to_the_views_display_range():
    """The PSNR over the view's display range: a prediction right but for a small light's mirror
    image (0.5 % of the pixels at 100 x the diffuse level: below 0 dB unclipped) errs on those
    pixels by at most the peak. The relative RMSE, unclipped: a black prediction scores exactly
    1, one that diverged (1000 x) above 1 (and below 10 dB)."""
    from estimator.diagnostics.validation import image_scores

    rng = np.random.default_rng(0)
    actual = rng.uniform(0.1, 1.0, (2000, 3))
    predicted = actual * (1.0 + 0.01 * rng.standard_normal(actual.shape))
    actual[:10] *= 100.0
    assert psnr_db(float(np.mean((actual - predicted) ** 2)), 1.0) < 0.0
    near = image_scores(actual, predicted)
    assert near["psnr"] > 25.0 and near["relative_rmse"] < 1.0
    assert image_scores(actual, np.zeros_like(actual))["relative_rmse"] == pytest.approx(1.0)
    diverged = image_scores(actual, 1000.0 * predicted)
    assert diverged["relative_rmse"] > 1.0 and diverged["psnr"] < 10.0
    assert image_scores(np.zeros((5, 3)), np.ones((5, 3)))["psnr"] is None


def test_cross_validation_warns_below_its_floor_and_on_a_diverged_view():
    from estimator import cross_validation_warnings

    good = {"psnr": 31.0, "views": [{"view": "a", "relative_rmse": 0.05}, {"view": "b", "relative_rmse": 0.08}]}
    assert cross_validation_warnings(good) == []
    diverged = {"psnr": -25.7, "views": [{"view": "a", "relative_rmse": 0.1}, {"view": "b", "relative_rmse": 1175.0}]}
    lines = cross_validation_warnings(diverged)
    assert len(lines) == 2 and "-25.7 dB" in lines[0] and "b" in lines[1] and "1.18e+03" in lines[1]
    assert cross_validation_warnings({"psnr": None, "views": [], "held_out": []}) == []
