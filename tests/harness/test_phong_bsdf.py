"""The Phong BSDF plugin: sampling against pdf (chi2), energy, eval against the formula."""
import numpy as np
import pytest

from harness import plugins

plugins.register_all()
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain  # noqa: E402


def _bsdf(td, ts, n):
    return {"type": plugins.PHONG, "exponent": n,
            "diffuse_reflectance": {"type": "rgb", "value": td},
            "specular_reflectance": {"type": "rgb", "value": ts}}


def _unit(v):
    v = np.asarray(v, float)
    return (v / np.linalg.norm(v)).tolist()


@pytest.mark.parametrize("td,ts,n,wi", [
    (0.5, 0.5, 10.0, [0.3, 0.1, 0.9]),
    (0.0, 0.8, 10.0, [0.7, 0.0, 0.3]),     # lobe cut by the horizon
    (0.3, 0.05, 50.0, [0.0, 0.0, 1.0]),
    (0.6, 0.0, 10.0, [0.2, 0.4, 0.5]),
])
def test_sampling_matches_pdf_chi2(td, ts, n, wi):
    sample_func, pdf_func = BSDFAdapter(plugins.PHONG, _bsdf(td, ts, n), wi=_unit(wi))
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=200000, res=41)
    assert chi2.run(0.01, test_count=4), chi2.messages


def _eval(bsdf, wi, wo):
    si = dr.zeros(mi.SurfaceInteraction3f, len(wo))
    si.wi = mi.Vector3f(*np.repeat(np.asarray(wi, float)[None], len(wo), 0).T)
    return np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*np.asarray(wo).T))).T


def test_eval_matches_the_formula():
    td, ts, n = np.array([0.2, 0.4, 0.6]), np.array([0.5, 0.3, 0.1]), 10.0
    bsdf = mi.load_dict(_bsdf(td.tolist(), ts.tolist(), n))
    wi = np.array(_unit([0.3, -0.2, 0.8]))
    rng = np.random.default_rng(0)
    wo = rng.normal(size=(500, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    r = np.array([-wi[0], -wi[1], wi[2]])
    cos_o = wo[:, 2]
    expected = (td[None] / np.pi * cos_o[:, None]
                + ts[None] * (n + 1) / (2 * np.pi) * np.maximum(wo @ r, 0)[:, None] ** n)
    expected[cos_o <= 0] = 0
    np.testing.assert_allclose(_eval(bsdf, wi, wo), expected, rtol=2e-5, atol=1e-7)
    # seen from below: black
    assert np.all(_eval(bsdf, [0, 0, -1], wo) == 0)


def test_white_specular_lobe_conserves_energy_at_normal_incidence():
    # integral over the hemisphere of f cos = 1 for t_s = 1 when the lobe is not cut
    bsdf = mi.load_dict(_bsdf(0.0, 1.0, 10.0))
    n = 1_000_000
    rng = np.random.default_rng(1)
    u = rng.random((n, 2))
    z = u[:, 0]
    r = np.sqrt(1 - z * z)
    wo = np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), z], 1)
    albedo = _eval(bsdf, [0, 0, 1], wo)[:, 0].mean() * 2 * np.pi
    assert albedo == pytest.approx(1.0, abs=0.01)
    # at grazing incidence the horizon cuts the lobe: less than 1
    grazing = _eval(bsdf, _unit([1, 0, 0.2]), wo)[:, 0].mean() * 2 * np.pi
    assert 0.3 < grazing < 0.9


def test_bad_exponent_is_refused():
    with pytest.raises(Exception, match="exponent"):
        mi.load_dict(_bsdf(0.5, 0.5, -1.0))
