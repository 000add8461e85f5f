"""The coat term: Fresnel reflectance, the rows' shapes, and the fitted weight."""
import numpy as np
import pytest

from estimator.core import sh
from estimator.light.coat import admissible_scale, coat_rows, fit_coat
from estimator.model.reflection import fresnel_dielectric


def test_fresnel_limits():
    np.testing.assert_allclose(fresnel_dielectric(np.array([1.0]), 1.5), ((1.5 - 1) / 2.5) ** 2, rtol=1e-12)
    assert fresnel_dielectric(np.array([1e-6]), 1.5)[0] > 0.999          # grazing: a mirror
    f = fresnel_dielectric(np.linspace(1, 0.01, 50), 1.5)
    assert np.all(np.diff(f) > 0)                                         # rises towards grazing


def test_rows_follow_the_light_at_the_mirror_direction():
    rng = np.random.default_rng(1)
    n = np.tile([[0.0, 1.0, 0.0]], (5, 1))
    v = rng.normal(size=(5, 3))
    v[:, 1] = np.abs(v[:, 1]) + 0.2
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    light = np.zeros((sh.num_coeffs(4), 3))
    light[0] = 1.0
    rows = coat_rows(n, v, light, 4, 1.5)
    assert rows.shape == (5, 3)
    # a constant light: the row is the Fresnel factor times the constant radiance Y_00
    np.testing.assert_allclose(rows[:, 0], fresnel_dielectric(v[:, 1], 1.5) * sh.basis(0, v)[:, 0], rtol=1e-10)


@pytest.mark.parametrize("true_k", [0.0, 0.05])
def test_fit_recovers_the_weight_and_ignores_the_diffuse(true_k):
    rng = np.random.default_rng(2)
    faces, views = 300, 12
    face = np.repeat(np.arange(faces), views)
    x = rng.uniform(0.0, 1.0, size=(faces * views, 3))
    diffuse = rng.uniform(0.05, 0.8, size=(faces, 3))[face]            # constant over views, any level
    rgb = diffuse + true_k * x
    rgb[::97] += 5.0                                                    # glints the coat term does not explain
    k = fit_coat(face, rgb, x, faces)
    np.testing.assert_allclose(k, true_k, atol=2e-3)


def test_admissible_scale_caps_what_turns_negative():
    rgb = np.full((1000, 3), 0.1)
    coat = np.zeros((1000, 3))
    coat[:, 0] = np.linspace(0.0, 0.2, 1000)        # subtracting all of it makes half the rows <= 0
    t = admissible_scale(rgb, coat, 0.01)
    share = np.mean(np.any(rgb - t * coat <= 0, axis=1))
    assert share <= 0.01 and 0.49 < t < 0.51     # rows turn <= 0 where coat >= 0.1 / t: t ~ 0.505 at 1 %
    assert admissible_scale(rgb, np.full_like(rgb, 0.05), 0.0) == 1.0          # harmless: the whole weight
