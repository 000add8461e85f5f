import numpy as np
import pytest

from estimator.core import sh
from reports import metrics
from reports.regression import TRACKED, check, make_baseline


def test_identical_estimate_gives_unit_ratios_and_capped_psnr():
    rng = np.random.default_rng(0)
    albedo = rng.uniform(0.1, 0.9, (50, 3))
    mask = np.ones(50, bool)
    for scale in metrics.SCALES:
        r = metrics.albedo_ratios(albedo, albedo, mask, scale, dc=np.ones(3))
        np.testing.assert_allclose(r, 1.0)
    s = metrics.ratio_summary(np.ones(50))
    assert s == {"count": 50, "median_ratio": 1.0, "iqr": 0.0, "within_5": 1.0, "within_10": 1.0}
    image = rng.random((20, 30, 3))
    m = np.ones((20, 30), bool)
    out = metrics.image_metrics(image, image, m)
    assert out["psnr_linear"] == 100.0 and out["psnr_srgb"] == 100.0
    assert out["ssim_linear"] == pytest.approx(1.0) and out["relative_l2"] == 0.0


def test_known_scales_are_removed():
    rng = np.random.default_rng(1)
    truth = rng.uniform(0.1, 0.9, (40, 3))
    scaled = truth * np.array([2.0, 0.5, 3.0])
    r = metrics.albedo_ratios(scaled, truth, np.ones(40, bool), "lstsq")
    np.testing.assert_allclose(r, 1.0)
    # DC gauge: an estimate in units where the light's DC is 1 absorbs the light's DC per channel
    dc = np.array([0.7, 0.8, 0.9])
    r = metrics.albedo_ratios(truth * dc, truth, np.ones(40, bool), "dc", dc=dc)
    np.testing.assert_allclose(r, 1.0)
    image = rng.random((16, 16, 3))
    out = metrics.image_metrics(image * np.array([4.0, 2.0, 0.5]), image, np.ones((16, 16), bool))
    assert out["psnr_linear"] == 100.0
    assert metrics.image_metrics(image * 2, image, np.ones((16, 16), bool), align=False)[
        "relative_l2"
    ] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="scale"):
        metrics.albedo_ratios(truth, truth, np.ones(40, bool), "median")


def test_psnr_and_ssim_values():
    ref = np.zeros((32, 32, 3))
    ref[8:24, 8:24] = 1.0
    noisy = ref + 0.1
    m = np.ones((32, 32), bool)
    assert metrics.psnr(noisy, ref, m, 1.0) == pytest.approx(20.0)
    assert 0.0 < metrics.ssim(noisy, ref, m, 1.0) < 1.0


def test_ssim_compares_the_masked_pixels_alone():
    # a textured reference; the prediction equals it on the mask and is black in a hole the
    # mask leaves out (a face the estimate did not estimate): the hole's edge must not count
    rng = np.random.default_rng(3)
    ref = rng.uniform(0.2, 0.8, (40, 40, 3))
    mask = np.ones((40, 40), bool)
    mask[15:25, 15:25] = False
    pred = np.where(mask[..., None], ref, 0.0)
    assert metrics.ssim(pred, ref, mask, 1.0) == pytest.approx(1.0)
    # a difference inside the mask still counts
    worse = pred.copy()
    worse[2:8, 2:8] += 0.3
    assert metrics.ssim(worse, ref, mask, 1.0) < 0.99


def test_sh_comparison_and_pseudo_illumination_gauge():
    rng = np.random.default_rng(2)
    radiance = rng.normal(size=(169, 3))
    radiance[0] = [2.0, 3.0, 4.0]
    h = sh.pseudo_illumination(radiance, 10.0, 10)
    np.testing.assert_allclose(h[0], 1.0)  # unit DC per channel
    f = sh.phong_filter(10, 10.0)
    np.testing.assert_allclose(h[sh.index(3, 1)], radiance[sh.index(3, 1)] * f[3] / radiance[0])
    cmp = metrics.sh_comparison(h, h)
    assert cmp["relative_l2"] == 0.0 and cmp["sh_order"] == 10 and len(cmp["band_energy_truth"]) == 11
    assert metrics.sh_comparison(1.1 * h, h)["relative_l2"] == pytest.approx(0.1)


def test_ciede2000_is_zero_for_equal_colours_and_grows():
    a = np.array([[0.5, 0.2, 0.1], [0.1, 0.1, 0.1]])
    np.testing.assert_allclose(metrics.ciede2000(a, a), 0.0, atol=1e-9)
    assert np.all(metrics.ciede2000(a * 1.3, a) > 1.0)


def _metrics(**over):
    m = {"scene": "s", "method": "m", "illumination": {"relative_l2": 0.05},
         "albedo": {"specular": {"dc": {"luminance": {"within_10": 0.9}}}},
         "clusters": {"ari": 0.95}, "novel_views": {"psnr_srgb": 30.0}}
    for path, value in over.items():
        node = m
        *parents, leaf = path.split(".")
        for key in parents:
            node = node[key]
        node[leaf] = value
    return m


def test_regression_passes_equal_and_fails_worse():
    base = make_baseline(_metrics())
    assert set(base["metrics"]) == {"illumination.relative_l2", "albedo.specular.dc.luminance.within_10",
                                    "clusters.ari", "novel_views.psnr_srgb"}
    assert all(r["status"] == "ok" for r in check(_metrics(), base))
    rows = {r["metric"]: r for r in check(_metrics(**{"illumination.relative_l2": 0.2, "clusters.ari": 0.99}), base)}
    assert rows["illumination.relative_l2"]["status"] == "worse"   # higher error
    assert rows["clusters.ari"]["status"] == "ok"                   # improved
    small = _metrics(**{"novel_views.psnr_srgb": 30.0 - 0.5 * TRACKED["novel_views.psnr_srgb"][1]})
    assert all(r["status"] == "ok" for r in check(small, base))     # within tolerance
    missing = _metrics()
    missing["clusters"]["ari"] = None
    assert {r["metric"]: r["status"] for r in check(missing, base)}["clusters.ari"] == "missing"
    with pytest.raises(ValueError, match="metrics"):
        check(_metrics(), {})


def test_a_baseline_metric_the_report_does_not_name_is_named_with_the_closest_metric():
    """A typo in a hand-written baseline still fails the check (the report cannot show the
    baseline's figure holds), but says so, with the closest metric; a metric the report names
    without a value (one the run could not compute) carries no such note."""
    base = {"metrics": {"clusters.arii": 0.9, "clusters.ari": 0.9, "nothing.like.it": 1.0}}
    missing = _metrics()
    missing["clusters"]["ari"] = None
    rows = {r["metric"]: r for r in check(missing, base)}
    assert all(r["status"] == "missing" for r in rows.values())
    assert rows["clusters.arii"]["note"] == "not a metric of this report; did you mean 'clusters.ari'?"
    assert rows["nothing.like.it"]["note"] == "not a metric of this report"
    assert "note" not in rows["clusters.ari"]
    assert "note" not in {r["metric"]: r for r in check(_metrics(), {"metrics": {"clusters.ari": 0.9}})}["clusters.ari"]


def test_adjusted_rand_index_known_values():
    a = np.array([0, 0, 1, 1, 2, 2])
    assert metrics.adjusted_rand_index(a, a) == 1.0
    assert metrics.adjusted_rand_index(a, np.array([5, 5, 7, 7, 9, 9])) == 1.0
    assert metrics.adjusted_rand_index(a, np.array([0, 1, 0, 1, 0, 1])) < 0


def test_a_handful_of_absurd_faces_cannot_overturn_the_robust_gauge():
    """One glare patch left 5 of 1,280 faces 11-15 times too bright: the least-squares gauge then
    put nearly every face outside ±10 %; the robust gauge sets those 5 aside and says so."""
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.05, 0.8, (1280, 3))
    estimate = 0.37 * truth * rng.normal(1.0, 0.01, (1280, 3))     # right up to a gauge and 1 % noise
    estimate[:5] *= rng.uniform(11, 15, (5, 1))
    mask = np.ones(1280, bool)
    within = {s: metrics.ratio_summary(metrics.albedo_ratios(estimate, truth, mask, s)[:, 3])["within_10"]
              for s in ("lstsq", "robust")}
    assert within["lstsq"] < 0.5 and within["robust"] > 0.99
    scale, aside = metrics.robust_scale(estimate, truth)
    np.testing.assert_allclose(scale, 1 / 0.37, rtol=0.01)
    assert aside.sum() == 5 and aside[:5].all()


def test_the_robust_gauge_sets_aside_no_exact_face_of_a_saturated_colour():
    truth = np.array([[0.5, 0.0, 0.0], [0.0, 0.6, 0.1], [0.3, 0.3, 0.3], [0.02, 0.05, 0.7]])
    scale, aside = metrics.robust_scale(2.0 * truth, truth)
    assert not aside.any()
    np.testing.assert_allclose(scale, 0.5)


def test_illumination_metrics_beyond_the_sh_l2():
    """Irradiance error is scale-free and zero for the truth, grows with a wrong light; the
    lat-long PSNR is capped for the truth up to scale; a sun's direction is found to the
    search grid's spacing (~1.6 degrees), and a light turned about +Y is off by the turn's angle."""
    from estimator import PSNR_CAP_DB, axis_angle_matrix, sh
    from reports import metrics

    sun = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    light = sh.project_directional(8, sun[None], np.array([[1.0, 0.9, 0.8]]))
    light[0] += 0.3
    assert metrics.irradiance_error(2.5 * light, light) < 1e-12
    wrong = light.copy()
    wrong[1:4] = 0.0                                             # the light's direction lost
    assert metrics.irradiance_error(wrong, light) > 0.3
    assert metrics.latlong_psnr(3.0 * light, light) == PSNR_CAP_DB
    assert metrics.latlong_psnr(wrong, light) < 40.0   # the delta peak dominates the PSNR's scale
    assert metrics.direction_error_deg(light, sun) < 2.0
    rotation = axis_angle_matrix("y", 30.0)
    turned = sh.rotation_matrix(8, rotation) @ light
    expected = np.degrees(np.arccos(np.clip(sun @ rotation @ sun, -1, 1)))
    assert abs(metrics.direction_error_deg(turned, sun) - expected) < 2.0 and expected > 10.0
