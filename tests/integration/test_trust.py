"""Trust without ground truth: per-view residuals and outlier shares, per-face standard
errors, conditioning, warnings, and leave-views-out cross-validation."""
import json

import numpy as np
import pytest

from estimator import estimate
from estimator.config import EstimatorConfig
from estimator.core.data import MultiViewData
from estimator.core.errors import InputError
from estimator.diagnostics.validation import cross_validate, holdout_indices
from harness.io.dataset import read_dataset
from harness.scene.generate import generate
from harness.scene.spec import load_spec, resolve_scene


@pytest.fixture(scope="module")
def glare_earth(tmp_path_factory):
    """tiny earth-specular with one training view under a 30 px glare patch of +0.5."""
    out = str(tmp_path_factory.mktemp("glare") / "earth")
    generate(load_spec(resolve_scene("earth-specular"), "tiny", {"faults.glare_views": 1, "faults.glare_size": 30,
                                                                   "faults.glare_value": 0.5}), out)
    return out


def _settings(folder, **overrides):
    from harness.io.runs import estimator_settings

    ds = read_dataset(folder, load_test=False, load_truth=False)
    return ds, *estimator_settings(ds.meta, None, overrides)


def test_clean_estimates_do_not_warn(tiny_earth):
    ds, method, config = _settings(tiny_earth, robust_loss="cauchy")
    est = estimate(ds.data, method, config)
    assert est.info["warnings"] == [] and max(v["gross_share"] for v in est.info["trust"]["views"]) == 0.0
    assert 1 <= est.info["trust"]["light_condition"] < 1e7


def test_estimate_reports_trust(tiny_sparse_data):
    est = estimate(tiny_sparse_data.data, "bilinear-clustered", EstimatorConfig())
    trust = est.info["trust"]
    assert len(trust["views"]) == len(tiny_sparse_data.data.views)
    assert trust["residual"]["median_relative"] < 0.05 and 1 <= trust["light_condition"] < 1e7
    counts, se = est.face_stats["observations"], est.face_stats["albedo_se"]
    assert counts.shape == (tiny_sparse_data.data.mesh.num_faces,) and se.shape == (len(counts), 3)
    assert np.all(counts[est.observed] >= 1)
    assert np.mean(np.isfinite(se[counts > 0]).all(axis=1)) > 0.95   # inf: every row of the face an outlier
    # a face seen more often is known better (same shading level): standard error falls with the count
    many, few = counts >= np.percentile(counts[counts > 0], 75), (counts > 0) & (counts <= 2)
    if few.any():
        assert np.median(se[many].mean(axis=1)) < np.median(se[few].mean(axis=1))


def test_a_glare_view_is_flagged_by_the_robust_fit(glare_earth):
    """A glare view stands out by its gross errors once the fit ignores it (robust loss);
    a least-squares fit bends towards the glare and spreads the error over other views."""
    ds, method, config = _settings(glare_earth, robust_loss="cauchy")
    glare_view = json.load(open(f"{glare_earth}/transforms.json"))["faults"]["patches"][0]["view"]
    est = estimate(ds.data, method, config)
    shares = [v["gross_share"] or 0.0 for v in est.info["trust"]["views"]]
    assert int(np.argmax(shares)) == glare_view
    name = ds.data.views[glare_view].name
    assert any(line.startswith(f"outlier view {name}") for line in est.info["warnings"])


def test_holdout_indices_spread_and_refuse_bad_counts():
    np.testing.assert_array_equal(holdout_indices(10, 2), [3, 6])
    assert len(holdout_indices(24, 4)) == 4
    for k in (0, 9):
        with pytest.raises(InputError, match="held-out views must lie in"):
            holdout_indices(10, k)


def test_cross_validation_drops_when_a_fault_is_injected(tiny_sparse_data):
    def solve(data):
        return estimate(data, "bilinear-clustered", EstimatorConfig())

    clean = cross_validate(tiny_sparse_data.data, 3, solve)
    assert len(clean["views"]) == 3 and clean["psnr"] > 18   # tiny: 1 spp, grazing views extrapolated
    rng = np.random.default_rng(0)
    noisy_views = [type(v)(v.name, v.camera, v.rgb + 0.2 * rng.standard_normal(v.rgb.shape).astype(np.float32),
                           v.alpha) for v in tiny_sparse_data.data.views]
    noisy = cross_validate(MultiViewData(tiny_sparse_data.data.mesh, noisy_views), 3, solve)
    assert noisy["psnr"] < clean["psnr"] - 3


def _with_trust(trust, **info):
    from estimator.model.estimate import Estimate

    f = 4
    pseudo = np.zeros((9, 3))
    pseudo[0] = 1.0
    return Estimate(np.ones((f, 3)), np.zeros((f, 3)), pseudo, np.zeros(f, int), np.ones(f, bool), "x",
                    EstimatorConfig(sh_order=2), {"trust": trust, **info})


def _trust(median=0.01, condition=10.0, shares=(0.0, 0.0, 0.0, 0.0), se=0.09):
    return {"residual": {"median_relative": median, "robust_scale": median}, "light_condition": condition,
            "albedo_relative_se": {"median": se, "p90": 0.7, "max": 3.0},
            "views": [{"view": f"v{i}", "observations": 100, "outlier_share": s, "gross_share": s,
                       "exposure": 1.0 + s} for i, s in enumerate(shares)]}


@pytest.mark.parametrize("trust, info, needle", [
    (_trust(median=0.3), {}, "high residual"),
    (_trust(condition=1e9), {}, "ill-conditioned"),
    (_trust(condition=None), {}, "condition number infinite"),
    (_trust(shares=(0.0, 0.3, 0.0, 0.0)), {}, "outlier view v1"),
    (_trust(shares=(0.0, 0.3, 0.0, 0.0)), {}, "its exposure is 1.30x the views' (view_gains"),
    (_trust(), {"faces_without_kept_views": 0.5}, "50 % of the faces have no observation"),
    (_trust(), {"degrees_of_freedom": {"observations": 10, "unknowns": 12}}, "underdetermined"),
    (_trust(se=0.28), {}, "albedo only to ±28 %"),
])
def test_each_warning_fires_on_its_condition(trust, info, needle):
    from estimator.diagnostics.trust import warnings_for

    lines = warnings_for(_with_trust(trust, **info))
    assert len(lines) == 1 and needle in lines[0]
    assert warnings_for(_with_trust(_trust())) == []     # a median relative SE of 9 % is silent


def test_gross_errors_a_reflection_explains_raise_no_outlier_view():
    """A view whose gross errors other views reflecting the same directions share (its
    ``fault_share`` 0), or whose neighbouring views err as much, is not an outlier however
    large its gross share."""
    from estimator.diagnostics.trust import warnings_for

    trust = _trust(shares=(0.0, 0.3, 0.0, 0.0))
    for v in trust["views"]:
        v["fault_share"] = 0.0
    assert warnings_for(_with_trust(trust)) == []
    trust["views"][1]["fault_share"] = 0.2
    assert [line[:15] for line in warnings_for(_with_trust(trust))] == ["outlier view v1"]
    trust["views"][1]["neighbour_gross_share"] = 0.05   # 5x that is 0.25 > 0.2: its neighbours err too
    assert warnings_for(_with_trust(trust)) == []


def test_a_view_exposed_apart_from_its_neighbours_is_named_unless_the_views_spread_as_far():
    """A view half as bright as its neighbouring views, where the other views' exposures agree
    with their neighbours' within a few per cent, is named with view_gains as the remedy; the
    same view among views whose reflections spread their exposures as far (a glossy object),
    or a run that divided the gains out, stays silent; so does one within the ±10 % band."""
    from estimator.diagnostics.trust import warnings_for

    def views(ratios):
        trust = _trust(shares=(0.0,) * len(ratios))
        for v, r in zip(trust["views"], ratios):
            v["exposure"], v["neighbour_exposure"] = r, 1.0
        return trust

    steady = [1.0, 1.001, 0.999, 1.0005, 0.9995, 1.0015, 0.9985, 1.0]   # 6 scales: under 1 %
    lines = warnings_for(_with_trust(views(steady[:3] + [0.49] + steady[4:])))
    assert len(lines) == 1 and lines[0].startswith("view v3 is exposed 0.49x its neighbouring views")
    assert "view_gains=true" in lines[0]
    assert warnings_for(_with_trust(views(steady))) == []
    assert warnings_for(_with_trust(views(steady[:3] + [0.92] + steady[4:]))) == []      # within ±10 %
    assert len(warnings_for(_with_trust(views(steady[:3] + [0.88] + steady[4:])))) == 1  # beyond it
    glossy = [1.0, 1.5, 0.6, 1.3, 0.7, 1.6, 0.55, 1.2]
    assert warnings_for(_with_trust(views(glossy[:3] + [0.49] + glossy[4:]))) == []
    assert warnings_for(_with_trust(views(steady[:3] + [0.49] + steady[4:]), view_gains={"v0": [1, 1, 1]})) == []
