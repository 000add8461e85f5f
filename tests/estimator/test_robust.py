"""Robust weights: the M-estimators' shapes, glint clipping, and a solve that a glint no
longer pulls."""
import numpy as np
import pytest

from estimator.core.errors import InputError
from estimator.pipeline.observations import Observations
from estimator.solvers import robust
from estimator.solvers.bilinear import solve_bilinear


@pytest.mark.parametrize("loss", ["huber", "cauchy", "tukey"])
def test_weights_are_one_at_zero_and_do_not_grow(loss):
    r = np.linspace(0, 20, 200)
    w = robust.irls_weights(r, loss, 1.0)
    assert w[0] == pytest.approx(1.0) and np.all(np.diff(w) <= 1e-15) and np.all((w >= 0) & (w <= 1))


def test_tukey_rejects_beyond_its_constant_and_none_keeps_all():
    r = np.array([0.0, 4.0, 4.7, 50.0])
    np.testing.assert_array_equal(robust.irls_weights(r, "tukey", 1.0)[2:], 0.0)
    np.testing.assert_array_equal(robust.irls_weights(r, "none", 1.0), 1.0)
    with pytest.raises(InputError, match="robust loss"):
        robust.irls_weights(r, "l7", 1.0)


def test_initial_weights_clip_glints_to_the_ratio():
    face = np.array([0, 0, 0, 0, 1, 1])
    rgb = np.array([[1, 1, 1], [1, 1, 1], [1.1, 1, 1], [40, 40, 40], [2, 2, 2], [2, 2, 2]], float)
    w = robust.initial_weights(face, rgb, 2, ratio=4.0)
    np.testing.assert_array_equal(w[[0, 1, 2, 4, 5]], 1.0)
    level = np.linalg.norm([1.05, 1, 1])                     # the median colour of face 0
    assert w[3] == pytest.approx((4 * level / np.linalg.norm(rgb[3])) ** 2)


def test_initial_weights_take_the_levels_the_observations_keep():
    """Observations.face_levels is robust.face_levels of its rows, computed once (the same array
    on every read); initial_weights given it equal those that compute it."""
    rng = np.random.default_rng(0)
    face = rng.integers(0, 5, 60)
    rgb = rng.random((60, 3)) * rng.choice([1.0, 30.0], (60, 1), p=[0.9, 0.1])
    obs = Observations(face, rgb, np.tile([0.0, 0.0, 1.0], (60, 1)), 6, 1)
    np.testing.assert_array_equal(obs.face_levels, robust.face_levels(face, rgb, 6))
    assert obs.face_levels is obs.face_levels
    np.testing.assert_array_equal(robust.initial_weights(face, rgb, 6, 4.0, obs.face_levels),
                                  robust.initial_weights(face, rgb, 6, 4.0))


def test_robust_scale_is_the_normalised_median():
    assert robust.robust_scale(np.array([1.0, 2.0, 3.0])) == pytest.approx(1.4826 * 2.0)
    assert robust.robust_scale(np.zeros(5)) == pytest.approx(1e-3)   # the floor


def test_reweighted_solve_ignores_a_glint():
    """A bilinear system (two groups, diffuse only, DC + one SH-like column) with one
    observation 50x too bright: least squares is pulled, IRLS with Cauchy weights is not."""
    rng = np.random.default_rng(0)
    n = 400
    group = np.arange(n) % 2
    c_rows = np.column_stack([np.ones(n), rng.uniform(-0.5, 0.5, n)])
    light = np.array([[1.0] * 3, [0.6] * 3])
    albedo = np.array([[0.8, 0.5, 0.2], [0.2, 0.4, 0.6]])
    rgb = albedo[group] * (c_rows @ light)
    rgb[7] *= 50
    d_rows = np.zeros_like(c_rows)

    def error(weights):
        root = np.sqrt(weights)[:, None]
        res = solve_bilinear(rgb * root, group, c_rows * root, d_rows * root, 2, "diffuse")
        return np.max(np.abs(res.diffuse - albedo) / albedo), res

    plain, res = error(np.ones(n))
    w = robust.initial_weights(np.arange(n), rgb, n, 4.0)          # one row per "face": no clipping
    for _ in range(3):
        pred = res.diffuse[group] * (c_rows @ res.light)
        r = robust.relative_residuals(rgb, pred)
        w = robust.irls_weights(r, "cauchy", robust.robust_scale(r))
        robust_err, res = error(w)
    assert plain > 0.05 and robust_err < 1e-3
