"""Every registered method on the same micro scene (as Mitsuba's tests run every integrator):
the result's type and shapes, finite values, the ``info`` keys that :func:`estimator.estimate`
and the reports rely on, and the Phong exponent's selection by the methods' residuals."""
from __future__ import annotations

import numpy as np
import pytest

from estimator import REGISTRY, Estimate, InputError, estimate, sh

from .micro import ORDER, micro_config, micro_scene

# mitsuba-ad capped at 3 steps under a budget no machine reaches: the same run everywhere
SETTINGS = {"mitsuba-ad": {"ad_time_budget": 3600.0, "ad_max_steps": 3, "ad_resolution": 8, "ad_envmap_height": 4}}


@pytest.fixture(scope="module")
def scene():
    return micro_scene()


def _known(method, truth):
    if not REGISTRY[method].needs_illumination:
        return {}
    return {"known_sh": truth.pseudo_sh, "known_radiance": truth.radiance_sh}


@pytest.mark.parametrize("method", sorted(REGISTRY))
def test_every_method_keeps_the_contract(scene, method):
    data, truth = scene
    est = estimate(data, method, micro_config(**SETTINGS.get(method, {})), **_known(method, truth))
    f, m = data.mesh.num_faces, sh.num_coeffs(ORDER)
    assert isinstance(est, Estimate) and est.method == method
    assert est.diffuse.shape == est.specular.shape == (f, 3)
    assert est.pseudo_sh.shape == (m, 3)
    assert est.labels.shape == (f,) and est.labels.dtype == np.int64
    assert est.observed.shape == (f,) and est.observed.dtype == bool and est.observed.any()
    assert np.all(est.labels[~est.observed] == -1)
    for name in ("diffuse", "specular", "pseudo_sh"):
        assert np.all(np.isfinite(getattr(est, name))), name
    np.testing.assert_allclose(est.pseudo_sh[0], 1.0, rtol=1e-12)   # the unit-DC gauge
    for key in ("timings", "trust", "warnings", "observations", "unobserved_share", "clusters"):
        assert key in est.info, key
    if REGISTRY[method].reports_residual:
        residuals = est.info["residuals"]
        assert len(residuals) >= 1 and all(np.isfinite(r) and r >= 0 for r in residuals)
        dof = est.info["degrees_of_freedom"]    # the trust line prints them
        assert 0 < dof["unknowns"] and 0 < dof["observations"] == 3 * est.info["observations"]


@pytest.mark.parametrize("method", sorted(REGISTRY))
def test_exponent_selection_follows_the_contract(scene, method):
    data, truth = scene
    config = micro_config(specular_model="lobe", **SETTINGS.get(method, {}))
    run = lambda: estimate(data, method, config, **_known(method, truth), exponent_candidates=(5.0, 10.0))  # noqa: E731
    if not REGISTRY[method].reports_residual:
        with pytest.raises(InputError, match=f"{method} reports none"):
            run()
        return
    est = run()
    assert set(est.info["exponent_selection"]) == {"5.0", "10.0"}
    assert est.config.phong_exponent in (5.0, 10.0)
    chosen = est.info["exponent_selection"][str(est.config.phong_exponent)]
    assert chosen == min(est.info["exponent_selection"].values())


def test_progress_lines_name_the_chosen_exponent_and_the_peers_steps(scene):
    data, _ = scene
    lines = []
    estimate(data, "bilinear-per-face", micro_config(specular_model="lobe"), log=lines.append,
             exponent_candidates=(5.0, 10.0))
    assert any(line.startswith("phong exponent chosen: ") for line in lines)
    lines.clear()
    estimate(data, "mitsuba-ad", micro_config(**SETTINGS["mitsuba-ad"]), log=lines.append)
    steps = [line for line in lines if line.startswith("mitsuba-ad: step ")]
    assert steps and "loss" in steps[-1]
