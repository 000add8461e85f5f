import numpy as np
import pytest

from estimator.solvers.clustering import mean_shift, same_partition, split_clusters


def _colours(rng):
    albedo = np.array([[0.7, 0.5, 0.08], [0.175, 0.125, 0.02], [0.65, 0.1, 0.08], [0.1, 0.2, 0.6]])
    truth = rng.integers(0, 4, 600)
    shading = rng.uniform(0.3, 1.5, 600)[:, None]
    noise = 1 + 0.03 * rng.normal(size=(600, 3))
    return truth, albedo[truth] * shading * noise, albedo[truth] * noise


def test_angular_mean_shift_groups_by_chromaticity_whatever_the_shading():
    truth, colours, _ = _colours(np.random.default_rng(0))
    labels, peaks = mean_shift(colours, 0.08, metric="angular")
    same_chroma = np.where(truth == 1, 0, truth)  # dark lines share the body's chromaticity
    assert len(peaks) == 3
    assert same_partition(same_chroma, labels)
    np.testing.assert_allclose(np.linalg.norm(peaks, axis=1), 1.0)


def test_euclidean_split_separates_same_chromaticity_by_brightness():
    truth, _, albedo = _colours(np.random.default_rng(1))
    angular = np.where(truth == 1, 0, truth)
    split = split_clusters(albedo, angular, 0.2, min_size=5)
    assert same_partition(truth, split)


def test_small_sub_clusters_are_absorbed_and_errors():
    rng = np.random.default_rng(2)
    values = np.concatenate([rng.normal(1.0, 0.01, (200, 3)), rng.normal(3.0, 0.01, (3, 3))])
    labels = np.zeros(203, int)
    assert split_clusters(values, labels, 0.1, min_size=2).max() == 1
    assert split_clusters(values, labels, 0.1, min_size=10).max() == 0
    with pytest.raises(ValueError, match="bandwidth"):
        mean_shift(values, 0.0)
    with pytest.raises(ValueError, match="non-empty"):
        mean_shift(np.zeros((0, 3)), 0.1)
