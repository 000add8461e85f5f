"""An estimate's observations are re-predicted with the shading its solve used: a sun it used
shades the faces through its exact shadowed column, not through its blurred SH projection
(``estimator.diagnostics.trust.diffuse_shading``)."""
from dataclasses import replace

import numpy as np
import pytest

import estimator.diagnostics.trust as trust
from estimator.core import sh
from estimator.diagnostics.trust import diffuse_shading, observation_residuals
from estimator.light.sun import sun_shadings
from estimator.pipeline.prepared import prepare

from .micro import micro_config, micro_scene


@pytest.fixture(scope="module")
def lit_by_a_sun():
    """The micro scene's faces (specular 0) under its sky plus a sun: the observations are
    rewritten as albedo x (C . sky + the sun's exact column x E), and the estimate reports the
    sun as the solve does (projected into its SH light, with its direction and irradiance)."""
    config = micro_config()
    data, truth = micro_scene(config, specular=0.0)
    prep = prepare(data, config)
    sky = truth.light
    direction, irradiance = np.array([[0.48, 0.8, 0.36]]), np.array([[2.0, 1.8, 1.2]])
    direction /= np.linalg.norm(direction)
    column = sun_shadings(data.mesh, prep.caster, direction)
    shade = prep.shading(sky) + column @ irradiance
    prep = replace(prep, obs=replace(prep.obs, rgb=truth.diffuse[prep.obs.face] * shade[prep.obs.face]))
    light = sky + prep.model.unknown_from_radiance(sh.project_directional(sh.order_of(len(sky)), direction,
                                                                          irradiance))
    sun = {"direction": direction[0].tolist(), "irradiance": irradiance[0].tolist(), "others": [], "used": True,
           "through_coat": False}
    est = replace(truth, pseudo_sh=light, specular=np.zeros_like(truth.specular), info={"sun": sun})
    return prep, est, shade


def test_a_used_sun_shades_through_its_exact_column(lit_by_a_sun):
    prep, est, shade = lit_by_a_sun
    np.testing.assert_allclose(diffuse_shading(prep, est), shade, rtol=1e-9, atol=1e-12)
    residual, relative, _ = observation_residuals(prep, est)
    assert np.max(relative) < 1e-9
    # the same light read as SH alone (the sun blurred at order 2) mispredicts the faces
    blurred = replace(est, info={"sun": {**est.info["sun"], "used": False}})
    assert np.median(observation_residuals(prep, blurred)[1]) > 0.01


def test_the_sun_columns_are_traced_once_per_direction(lit_by_a_sun, monkeypatch):
    prep, est, shade = lit_by_a_sun
    diffuse_shading(prep, est)                       # kept on the shadow function
    monkeypatch.setattr(trust, "sun_shadings", lambda *a, **k: pytest.fail("traced again"))
    np.testing.assert_allclose(diffuse_shading(prep, est), shade, rtol=1e-9, atol=1e-12)


def test_the_light_condition_is_the_singular_value_ratio_and_infinite_where_singular():
    """sqrt of the normal matrix's eigenvalue ratio, the singular values' ratio of the system;
    a rank-deficient system (a box's six normals cannot fix an order-2 light) is infinite, not
    the ratio of two rounding errors (it read 1e+150)."""
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(40, 6)) * [1, 1, 1, 1, 1, 1e-3]
    singular = np.linalg.svd(jac, compute_uv=False)
    assert trust.normal_condition(jac.T @ jac) == pytest.approx(singular[0] / singular[-1], rel=1e-6)
    deficient = np.hstack([jac[:, :5], jac[:, :1] + jac[:, 1:2]])       # the last column repeats two
    assert trust.normal_condition(deficient.T @ deficient) == np.inf
    assert trust.normal_condition(np.zeros((3, 3))) == np.inf
    # an order-10 light's 121 columns at condition 8e6: finite, so the warning's 1e7 bound can fire
    q, _ = np.linalg.qr(rng.normal(size=(400, 121)))
    wide = q * np.geomspace(1.0, 1 / 8e6, 121)
    assert trust.normal_condition(wide.T @ wide) == pytest.approx(8e6, rel=0.01)
    assert 8e6 < trust.ILL_CONDITIONED < 1 / np.sqrt(np.finfo(float).eps)
