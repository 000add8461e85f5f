"""Per-view exposure and white balance: cross-validation measures each held-out view's gain
against the estimate solved without it."""
import numpy as np

from estimator import MultiViewData, View, estimate
from estimator.diagnostics.validation import (
    cross_validate,
    exposure_gain,
    holdout_indices,
)
from estimator.pipeline.exposure import view_gains
from estimator.pipeline.observations import Observations

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


# auto-exposure and auto white balance: a gain per view and channel
GAINS = np.array([[1.6, 1.6, 1.6], [0.7, 0.7, 0.7], [1.0, 1.1, 0.9], [1.3, 1.3, 1.3],
                  [1.0, 1.0, 1.0], [0.8, 0.8, 0.8], [1.2, 1.0, 0.9], [1.0, 1.0, 1.0]])


def _median_albedo_error(est, truth) -> float:
    """Median relative error of the observed faces' diffuse albedos after a per-channel scale."""
    o = est.observed
    a, t = est.diffuse[o], truth.diffuse[o]
    return float(np.median(np.abs(a * ((a * t).sum(0) / (a * a).sum(0)) / t - 1)))


def test_view_gains_are_the_view_effects_of_the_faces_log_colours():
    """Diffuse faces (each colour constant over views) seen by random views with a gain per view
    and channel, a highlight on 10 % of the rows and faces seen once: median polish recovers
    the gains (geometric mean 1) to 1e-6."""
    rng = np.random.default_rng(4)
    faces, views = 600, 12
    face = np.repeat(np.arange(faces), 5)
    view = rng.integers(0, views, face.size)
    gains = np.exp(rng.normal(0.0, 0.3, (views, 3)))
    gains /= np.exp(np.log(gains).mean(axis=0))
    rgb = rng.uniform(0.02, 0.9, (faces, 3))[face] * gains[view]
    rgb[rng.random(face.size) < 0.1] += 2.0                       # glints on a minority of each view's faces
    once = np.arange(faces, faces + 50)                            # faces seen once: no say in the gains
    obs = Observations(np.concatenate([face, once]), np.vstack([rgb, rng.uniform(5, 9, (50, 3))]),
                       np.zeros((face.size + 50, 3)), faces + 50, views, view=np.concatenate([view, view[:50]]))
    np.testing.assert_allclose(view_gains(obs), gains, rtol=0.02)
    same = Observations(face, rgb / gains[view], np.zeros((face.size, 3)), faces, views, view=view)
    np.testing.assert_allclose(view_gains(same), 1.0, atol=0.02)
    single = Observations(np.arange(30), rgb[:30], np.zeros((30, 3)), 30, views, view=view[:30])
    np.testing.assert_array_equal(view_gains(single), 1.0)                # no face seen twice: nothing to say


def test_with_view_gains_the_estimate_does_not_depend_on_the_views_exposures():
    """The micro scene recorded with a gain per view and channel: without view_gains the
    albedos are off by 3 % at the median face; with it the estimate is the one from views of a
    single exposure (the fitted gains follow the recorded ones exactly, so the views divided by
    them are the same), and the gains found on the jittered views are the recorded gains times
    those found on the clean ones."""
    data, truth = micro_scene()
    jittered = MultiViewData(data.mesh, [View(v.name, v.camera, v.rgb * g, v.alpha) for v, g in zip(data.views, GAINS)])
    assert _median_albedo_error(estimate(jittered, "bilinear-clustered", micro_config()), truth) > 0.02
    clean = estimate(data, "bilinear-clustered", micro_config(view_gains=True))
    jitter = estimate(jittered, "bilinear-clustered", micro_config(view_gains=True))
    assert set(jitter.info["view_gains"]) == {v.name for v in data.views}
    found = np.array([jitter.info["view_gains"][v.name] for v in data.views])
    base = np.array([clean.info["view_gains"][v.name] for v in data.views])
    np.testing.assert_allclose(found / base, GAINS / np.exp(np.log(GAINS).mean(axis=0)), rtol=1e-4)
    o = clean.observed & jitter.observed
    scale = (jitter.diffuse[o] * clean.diffuse[o]).sum(0) / (jitter.diffuse[o] ** 2).sum(0)   # the common gain
    np.testing.assert_allclose(jitter.diffuse[o] * scale, clean.diffuse[o], rtol=1e-3, atol=1e-6)


def test_the_trust_summary_gives_each_views_exposure_relative_to_the_others():
    """Without view_gains the diagnostics still report each view's exposure (the two-way fit):
    on views re-exposed by GAINS the figures are the clean ones times each view's gain (its
    geometric mean over channels, relative to the views')."""
    data, _ = micro_scene()
    jittered = MultiViewData(data.mesh, [View(v.name, v.camera, v.rgb * g, v.alpha) for v, g in zip(data.views, GAINS)])
    clean = estimate(data, "bilinear-clustered", micro_config())
    jitter = estimate(jittered, "bilinear-clustered", micro_config())
    ratio = np.array([j["exposure"] / c["exposure"] for j, c in zip(jitter.info["trust"]["views"],
                                                                    clean.info["trust"]["views"])])
    level = np.exp(np.log(GAINS).mean(axis=1))
    np.testing.assert_allclose(ratio, level / np.exp(np.log(level).mean()), rtol=1e-4)
