"""Faces whose albedo the data do not determine are marked unestimated with a reason and never
written as a number."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from estimator import Estimate, EstimatorConfig, MultiViewData, RayCaster, estimate
from estimator.diagnostics import screening

from .micro import micro_config, micro_scene


def _estimate(diffuse, labels=None, components="both"):
    f = len(diffuse)
    return Estimate(np.array(diffuse, float), np.zeros((f, 3)), np.eye(9, 3), np.arange(f) if labels is None
                    else np.array(labels), np.ones(f, bool), "test", EstimatorConfig(components=components))


def test_non_finite_and_out_of_range_faces_get_their_reason():
    diffuse = np.full((10, 3), 0.3)
    diffuse[2] = [np.nan, 0.1, 0.1]
    diffuse[5] = [0.2, 0.2, 4e5]          # the blue channel beyond 100 x the median face
    diffuse[7] = [20.0, 20.0, 20.0]       # 67 x the median face: within the physical range
    code = screening.out_of_range(_estimate(diffuse))
    np.testing.assert_array_equal(np.nonzero(code)[0], [2, 5])
    assert code[2] == 1 and code[5] == 2


def test_a_region_is_judged_by_its_summed_precision():
    diffuse = np.full((4, 3), 0.5)
    precision = np.full((4, 3), 3.0)       # one face alone: relative SE 1/sqrt(3) x sqrt(3) / 0.87 > 1
    alone = screening.undetermined(_estimate(diffuse), precision)
    shared = screening.undetermined(_estimate(diffuse, labels=[0, 0, 0, 0]), precision)
    assert alone.all() and not shared.any()


def test_a_region_face_whose_own_observations_all_reject_its_albedo_is_contradicted():
    """Faces 0-3 share a region; face 2 has rows but no inlier (zero own precision), face 3 has
    no row at all (its region speaks for it), face 4 is alone (the SE test judges it)."""
    precision = np.full((5, 3), 2.0)
    precision[2] = 0.0
    precision[3] = 0.0
    precision[4] = 0.0
    rows = np.array([4, 4, 3, 0, 2])
    out = screening.contradicted(_estimate(np.full((5, 3), 0.5), labels=[0, 0, 0, 0, 1]), precision, rows)
    np.testing.assert_array_equal(out, [False, False, True, False, False])


def test_marked_faces_are_zero_unlabelled_and_counted():
    est = _estimate(np.full((3, 3), 0.4))
    counts = screening.mark_unestimated(est, np.array([0, 2, 3], np.int8))
    assert counts == {"beyond physical range": 1, "undetermined": 1}
    np.testing.assert_array_equal(est.observed, [True, False, False])
    np.testing.assert_array_equal(est.labels, [0, -1, -1])
    assert np.all(est.diffuse[1:] == 0)
    np.testing.assert_array_equal(est.face_stats["unestimated_reason"], [0, 2, 3])


@pytest.fixture(scope="module")
def scene():
    return micro_scene()


def test_a_face_made_absurd_on_purpose_is_not_written(scene):
    """One face's pixels made 10^4 times too bright in every view: the per-face solve gives it an
    absurd albedo, which the estimate marks unestimated and warns of."""
    data, _ = scene
    caster = RayCaster(data.mesh)
    target = 7
    views = []
    for view in data.views:
        face = caster.face_id_buffers([view.camera])[0].reshape(view.rgb.shape[:2])
        rgb = view.rgb.copy()
        rgb[face == target] *= 1e4
        views.append(replace(view, rgb=rgb))
    est = estimate(MultiViewData(data.mesh, views), "bilinear-per-face", micro_config(robust_loss="none"))
    assert not est.observed[target] and np.all(est.diffuse[target] == 0)
    assert est.face_stats["unestimated_reason"][target] == 2
    assert est.info["unestimated"]["beyond physical range"] >= 1
    assert any("left unestimated" in w for w in est.info["warnings"])
    assert np.all(np.abs(est.diffuse[est.observed]).max(axis=1) <= 100 * np.median(est.diffuse[est.observed]))


@pytest.mark.parametrize("method", ["retinex-segmented", "known-illumination"])
def test_clean_data_lose_no_face(scene, method):
    data, truth = scene
    known = {"known_sh": truth.pseudo_sh} if method == "known-illumination" else {}
    est = estimate(data, method, micro_config(), **known)
    assert est.info["unestimated"] == {}


def test_faces_a_per_face_solve_leaves_at_zero_are_undetermined(scene):
    """Without the light, per-face diffuse and specular trade against each other; faces whose
    solve ends at zero in both carry no albedo and are marked, not written as 0."""
    data, _ = scene
    est = estimate(data, "bilinear-per-face", micro_config())
    reason = est.face_stats["unestimated_reason"]
    assert est.info["unestimated"].get("undetermined", 0) == int(np.sum(reason == 3))
    assert np.all(est.diffuse[est.observed] + est.specular[est.observed] > 0)


def test_the_range_is_judged_per_channel_so_a_coloured_light_sets_no_face_aside():
    """Each channel has its own gauge (1 / the light's DC there): under a 2500 K light six dark
    bluish faces and four red ones, all correct, stay estimated; a negative channel does not."""
    light = np.array([2.06, 0.77, 0.14])                 # the light's DC per channel
    diffuse = np.array([[0.012, 0.012, 0.036]] * 6 + [[0.8, 0.03, 0.03]] * 4) / light
    assert not screening.out_of_range(_estimate(diffuse)).any()
    diffuse[3, 1] = -0.01
    np.testing.assert_array_equal(np.nonzero(screening.out_of_range(_estimate(diffuse)))[0], [3])


def test_faces_a_view_shows_but_the_method_left_out_are_counted_and_warned():
    """bilinear-clustered leaves out faces darker than min_brightness x the bright faces' level
    (a point light's shadow): each face a kept view shows but without an albedo is counted under
    'left out by the method' and stated in the warning, never silently missing."""
    data, _ = micro_scene()
    est = estimate(data, "bilinear-clustered", micro_config(min_brightness=0.6))
    left = int(est.info["unestimated"]["left out by the method"])
    reason = est.face_stats["unestimated_reason"]
    assert left > 0 and int(np.sum(reason == len(screening.REASONS))) == left
    assert not est.observed[reason == len(screening.REASONS)].any()
    assert sum(est.info["unestimated"].values()) + est.observed.sum() <= est.observed.size
    assert any(f"{left} left out by the method" in w for w in est.info["warnings"])


def _fitted(sizes, columns, rng):
    """Rows of groups of ``sizes`` rows, each group's albedos (one per column) fitted by least
    squares to data with Gaussian noise of 0.01: (group (N,), columns [(N, 3)], residual (N, 3))."""
    group = np.repeat(np.arange(len(sizes)), sizes)
    xs = [rng.uniform(0.2, 1.0, (len(group), 3)) for _ in range(columns)]
    data = sum(0.5 * x for x in xs) + 0.01 * rng.normal(size=xs[0].shape)
    residual = np.empty_like(data)
    for k in range(3):   # a test's reference fit: one small lstsq per group
        for g in range(len(sizes)):
            rows = group == g
            design = np.stack([x[rows, k] for x in xs], 1)
            fit = np.linalg.lstsq(design, data[rows, k], rcond=None)[0]
            residual[rows, k] = data[rows, k] - design @ fit
    return group, xs, residual


def test_the_noise_level_is_read_from_residuals_no_fit_interpolates():
    """Groups of 1-5 rows fitted with one albedo per channel, noise 0.01: the level from the
    residuals divided by sqrt(1 - leverage) is 0.01 within 6 % (3,000 groups), where their plain
    median absolute residual is 12 % or more low; the groups of one row (residual 0, whatever
    the noise) are left out; with no other row (an exact fit, warned as underdetermined) the
    level is the residuals' as they are, and without an estimated row it is infinite and no
    face gets a precision."""
    from estimator.diagnostics.trust import _precision, noise_level

    rng = np.random.default_rng(0)
    sizes = rng.integers(1, 6, 3000)
    group, (rows,), residual = _fitted(sizes, 1, rng)
    everything = np.ones(len(group), bool)
    np.testing.assert_allclose(noise_level([rows], residual, everything, group), 0.01, rtol=0.06)
    assert np.all(1.4826 * np.median(np.abs(residual), axis=0) < 0.0088)
    alone = sizes[group] == 1
    assert np.all(np.abs(residual[alone]) < 1e-12)
    np.testing.assert_allclose(noise_level([rows[alone]], residual[alone], everything[alone], group[alone]),
                               1.4826 * np.median(np.abs(residual[alone]), axis=0))
    nothing = np.zeros(len(group), bool)
    sigma = noise_level([rows], residual, nothing, group)
    assert np.all(np.isinf(sigma))
    assert np.all(_precision(group, len(sizes), rows, nothing, sigma) == 0)


def test_a_fit_of_two_albedos_per_group_takes_both_columns_leverage():
    """Groups of 2-6 rows each fitted with a diffuse and a specular albedo (noise 0.01): with both
    columns' leverage the level is 0.01 within 8 %; with one column's it is 25 % or more low
    (the second unknown's share of each residual is not given back)."""
    from estimator.diagnostics.trust import noise_level

    rng = np.random.default_rng(1)
    sizes = rng.integers(2, 7, 2000)
    group, (shade, gloss), residual = _fitted(sizes, 2, rng)
    everything = np.ones(len(group), bool)
    np.testing.assert_allclose(noise_level([shade, gloss], residual, everything, group), 0.01, rtol=0.08)
    assert np.all(noise_level([shade], residual, everything, group) < 0.0075)


def test_a_zero_or_collinear_second_column_takes_the_first_columns_leverage():
    """A group whose gloss is 0 (no highlight), or proportional to its shading, fits one albedo:
    its leverage is the one-column leverage, so the level equals the one-column level (and a
    group of one row stays interpolated)."""
    from estimator.diagnostics.trust import noise_level

    rng = np.random.default_rng(2)
    sizes = rng.integers(1, 6, 2000)
    group, (shade,), residual = _fitted(sizes, 1, rng)
    everything = np.ones(len(group), bool)
    one = noise_level([shade], residual, everything, group)
    np.testing.assert_allclose(noise_level([shade, np.zeros_like(shade)], residual, everything, group), one)
    np.testing.assert_allclose(noise_level([shade, 2.0 * shade], residual, everything, group), one, rtol=1e-9)


def test_free_faces_that_share_one_specular_give_no_specular_column():
    """info['own_specular_groups'] = R: rows of labels below R keep their gloss column, the
    others (free faces sharing one specular) get zeros."""
    from types import SimpleNamespace

    from estimator.diagnostics.trust import _fitted_columns

    face = np.array([0, 0, 1, 1, 2])
    gloss = np.full((5, 3), 0.5)
    prep = SimpleNamespace(obs=SimpleNamespace(face=face), gloss=lambda light: gloss)
    est = SimpleNamespace(config=EstimatorConfig(components="both"), light=None, labels=np.array([0, 1, 2]),
                          info={"own_specular_groups": 1})
    shade, kept = _fitted_columns(prep, est, np.ones((5, 3)))
    np.testing.assert_array_equal(kept[:, 0], [0.5, 0.5, 0.0, 0.0, 0.0])
    est.info = {}
    assert np.all(_fitted_columns(prep, est, np.ones((5, 3)))[1] == 0.5)
