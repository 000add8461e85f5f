import numpy as np
import pytest

from estimator import estimate
from estimator.config import EstimatorConfig
from estimator.core.errors import InputError
from estimator.solvers.albedo_prior import smooth_albedo


def chain(n: int) -> np.ndarray:
    return np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)


def two_regions(n: int = 400) -> np.ndarray:
    """(n, 3) albedo: 0.2 grey on the first half, (0.7, 0.5, 0.3) on the second."""
    truth = np.full((n, 3), 0.2)
    truth[n // 2:] = [0.7, 0.5, 0.3]
    return truth


def test_noise_is_averaged_and_the_edge_kept():
    rng = np.random.default_rng(0)
    truth = two_regions()
    sigma = 0.05
    noisy = truth + sigma * rng.standard_normal(truth.shape)
    smoothed, spread = smooth_albedo(noisy, np.full(truth.shape, 1 / sigma ** 2), chain(len(truth)),
                                     np.ones(len(truth), bool), 2.0)
    before = np.sqrt(np.mean((noisy - truth) ** 2))
    after = np.sqrt(np.mean((smoothed - truth) ** 2))
    assert after < 0.35 * before                      # measured 0.22 x
    assert spread.shape == (3,) and np.all(spread > 0)
    n = len(truth)   # the step survives: a face two away from the boundary keeps its side's value
    np.testing.assert_allclose(smoothed[n // 2 - 3], truth[0], atol=2 * sigma / 3)
    np.testing.assert_allclose(smoothed[n // 2 + 2], truth[-1], atol=2 * sigma / 3)


def test_precise_estimates_do_not_move():
    truth = two_regions()
    truth[::7] *= 1.3                                   # texture: many small edges
    smoothed, _ = smooth_albedo(truth, np.full(truth.shape, 1e8), chain(len(truth)), np.ones(len(truth), bool), 2.0)
    np.testing.assert_allclose(smoothed, truth, rtol=1e-3)


def test_unestimated_faces_are_left_alone_and_no_edges_is_identity():
    rng = np.random.default_rng(1)
    a = rng.uniform(0.1, 0.9, (50, 3))
    estimated = np.ones(50, bool)
    estimated[10:20] = False
    smoothed, _ = smooth_albedo(a, np.full(a.shape, 10.0), chain(50), estimated, 2.0)
    np.testing.assert_array_equal(smoothed[10:20], a[10:20])
    same, spread = smooth_albedo(a, np.full(a.shape, 10.0), np.zeros((0, 2), np.int64), estimated, 2.0)
    np.testing.assert_array_equal(same, a)
    np.testing.assert_array_equal(spread, 0.0)


def test_albedo_prior_setting(tiny_earth_data):
    with pytest.raises(InputError, match="albedo_prior"):
        EstimatorConfig(albedo_prior=-1.0)
    data = tiny_earth_data.data
    off = estimate(data, "bilinear-per-face", EstimatorConfig(components="specular", albedo_prior=0.0))
    on = estimate(data, "bilinear-per-face", EstimatorConfig(components="specular"))
    assert "albedo_prior" not in off.info and set(on.info["albedo_prior"]["spread"]) == {"specular"}
    np.testing.assert_array_equal(on.diffuse, off.diffuse)            # the component not estimated stays 0
    moved = np.abs(on.specular - off.specular)[on.observed].max()
    assert 0 < moved                                                  # the prior did act


def test_a_uniform_albedo_is_not_pulled_toward_zero():
    # regression: a ridge once added to the diagonal alone shrank flat regions by p / (p + 1)
    a = np.full((100, 3), 0.5)
    for precision in (1.0, 4.0, 100.0):
        smoothed, _ = smooth_albedo(a, np.full(a.shape, precision), chain(100), np.ones(100, bool), 2.0)
        np.testing.assert_allclose(smoothed, 0.5, rtol=1e-6)
