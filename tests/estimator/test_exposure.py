"""Per-view exposure and white balance: cross-validation measures each held-out view's gain
against the estimate solved without it."""
import numpy as np

from estimator import MultiViewData, View, estimate
from estimator.diagnostics.validation import (
    cross_validate,
    exposure_gain,
    holdout_indices,
)

from .micro import micro_config, micro_scene


def test_a_held_out_view_exposed_otherwise_is_measured_and_named():
    """The micro scene with one held-out view recorded 1.6 x brighter and bluer (auto-exposure)."""
    data, _ = micro_scene()
    held = holdout_indices(len(data.views), 2)
    gain = np.array([1.6, 1.6, 1.9])
    views = [View(v.name, v.camera, v.rgb * (gain if k == held[0] else 1.0), v.alpha)
             for k, v in enumerate(data.views)]
    cv = cross_validate(MultiViewData(data.mesh, views), 2,
                        lambda d: estimate(d, "bilinear-clustered", micro_config()))
    scores = {v["view"]: v for v in cv["views"]}
    np.testing.assert_allclose(scores[data.views[held[0]].name]["gain"], gain, rtol=0.02)
    np.testing.assert_allclose(scores[data.views[held[1]].name]["gain"], 1.0, atol=0.02)


def test_a_held_out_views_gain_is_its_median_ratio_to_the_prediction():
    rng = np.random.default_rng(0)
    predicted = rng.uniform(0.1, 1.0, (500, 3))
    actual = predicted * [1.5, 1.5, 1.2]
    actual[:20] *= 5.0                                          # a highlight the model missed
    np.testing.assert_allclose(exposure_gain(actual, predicted), [1.5, 1.5, 1.2], rtol=1e-9)
    assert exposure_gain(np.zeros((3, 3)), np.zeros((3, 3))) == [None, None, None]
