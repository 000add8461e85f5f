import numpy as np
import pytest
from scipy import integrate, special

from estimator.core import latlong, sh
from estimator.core.errors import InputError


def test_basis_matches_scipy_complex_sph_harm():
    d = sh.fibonacci_sphere(200)
    y = sh.basis(10, d)
    theta, phi = np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0])
    for l in range(11):
        for m in range(-l, l + 1):
            c = special.sph_harm_y(l, abs(m), theta, phi)
            ref = c.real if m == 0 else np.sqrt(2) * (-1) ** m * (c.real if m > 0 else c.imag)
            np.testing.assert_allclose(y[:, sh.index(l, m)], ref, atol=1e-12)


def test_basis_in_blocks_equals_the_basis_of_each_direction_alone():
    # more directions than one block: every row must be the basis of its own direction
    d = sh.fibonacci_sphere(sh.BASIS_BLOCK + 37)
    y = sh.basis(6, d)
    assert y.shape == (len(d), 49) and y.flags.c_contiguous
    rows = [0, sh.BASIS_BLOCK - 1, sh.BASIS_BLOCK, len(d) - 1]
    np.testing.assert_allclose(y[rows], np.concatenate([sh.basis(6, d[[k]]) for k in rows]), atol=1e-14)
    assert sh.basis(3, np.zeros((0, 3))).shape == (0, 16)


def test_evaluate_is_the_basis_times_the_coefficients_without_the_basis():
    # across a block seam, several functions at once; shapes are checked
    d = sh.fibonacci_sphere(sh.BASIS_BLOCK + 37)
    coeffs = np.random.default_rng(0).standard_normal((49, 3))
    np.testing.assert_allclose(sh.evaluate(6, d, coeffs), sh.basis(6, d) @ coeffs, rtol=0, atol=1e-12)
    assert sh.evaluate(6, np.zeros((0, 3)), coeffs).shape == (0, 3)
    with pytest.raises(InputError, match=r"coeffs must have shape \(49, C\)"):
        sh.evaluate(6, d, coeffs[:16])
    with pytest.raises(InputError, match="dirs must have shape"):
        sh.evaluate(6, d[:, :2], coeffs)


def test_order_one_sign_convention():
    c = np.sqrt(3 / (4 * np.pi))
    y = sh.basis(1, np.eye(3))
    assert y[0, sh.index(1, 1)] == pytest.approx(c)   # +x
    assert y[1, sh.index(1, -1)] == pytest.approx(c)  # +y
    assert y[2, sh.index(1, 0)] == pytest.approx(c)   # +z


def test_basis_is_orthonormal_under_latlong_quadrature():
    h, w = 400, 800
    weights = latlong.solid_angles(h, w).reshape(-1)
    assert weights.sum() == pytest.approx(4 * np.pi, rel=1e-12)
    y = sh.basis(6, latlong.directions(h, w).reshape(-1, 3))
    gram = (y * weights[:, None]).T @ y
    np.testing.assert_allclose(gram, np.eye(49), atol=2e-3)


def test_shapes_and_errors():
    assert sh.basis(10, np.zeros((0, 3)) + 1).shape == (0, 121)
    with pytest.raises(ValueError, match="shape"):
        sh.basis(2, np.ones((4, 2)))
    with pytest.raises(ValueError, match="order"):
        sh.num_coeffs(-1)
    with pytest.raises(ValueError, match="orthogonal"):
        sh.rotation_matrix(2, np.ones((3, 3)))


@pytest.mark.parametrize("axis,angle", [("y", 37.0), ("x", -80.0), ([1.0, 2.0, 3.0], 123.0)])
def test_rotation_round_trip_and_against_rotated_directions(axis, angle):
    rng = np.random.default_rng(0)
    rot = sh.axis_angle_matrix(axis, angle)
    m = sh.rotation_matrix(10, rot)
    c = rng.normal(size=121)
    d = sh.fibonacci_sphere(300)
    # f_rot(w) = f(R^T w)
    np.testing.assert_allclose(sh.basis(10, d) @ (m @ c), sh.basis(10, d @ rot) @ c, atol=1e-10)
    np.testing.assert_allclose(sh.rotation_matrix(10, rot.T) @ m, np.eye(121), atol=1e-10)


@pytest.mark.parametrize("n", [1.0, 4.0, 10.0, 33.3, 200.0])
def test_phong_filter_closed_form_against_quadrature(n):
    f = sh.phong_filter(10, n)
    for l in range(11):
        ref = (n + 1) * integrate.quad(lambda x, l=l: x ** n * special.eval_legendre(l, x), 0, 1, limit=200)[0]
        assert f[l] == pytest.approx(ref, rel=1e-7, abs=1e-12)
    assert f[0] == pytest.approx(1.0)


def test_phong_filter_equals_convolution_of_a_delta_light():
    # The pseudo illumination of one delta light is the Phong lobe around it.
    n, order = 10.0, 10
    to_light = np.array([[0.3, 0.8, -0.52]])
    to_light /= np.linalg.norm(to_light)
    filtered = sh.expand_per_degree(sh.phong_filter(order, n))[:, None] * sh.project_directional(
        order, to_light, [[1.0]]
    )
    r = sh.fibonacci_sphere(500)
    lobe = (n + 1) / (2 * np.pi) * np.maximum(r @ to_light[0], 0) ** n
    # order 10 truncation of a cos^10 lobe: small but nonzero residual
    err = np.abs(sh.basis(order, r) @ filtered[:, 0] - lobe).max() / lobe.max()
    assert err < 0.02


def test_projection_of_directional_lights_against_monte_carlo():
    # A narrow cap of radiance approaches a delta light with the same irradiance.
    rng = np.random.default_rng(1)
    axis = np.array([0.0, 0.6, 0.8])
    w = rng.normal(size=(400000, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    cap = w @ axis > np.cos(np.radians(2.0))
    cap_solid_angle = 2 * np.pi * (1 - np.cos(np.radians(2.0)))
    radiance = 5.0 / cap_solid_angle  # irradiance 5 at normal incidence
    mc = 4 * np.pi * (sh.basis(4, w) * (cap * radiance)[:, None]).mean(axis=0)
    exact = sh.project_directional(4, axis[None], [[5.0]])[:, 0]
    np.testing.assert_allclose(mc, exact, atol=0.05 * np.abs(exact).max())


def test_latlong_projection_against_monte_carlo_and_back():
    rng = np.random.default_rng(2)
    coeffs = rng.normal(size=(16, 3))
    image = sh.to_latlong(coeffs, 256, 512)
    np.testing.assert_allclose(sh.project_latlong(3, image), coeffs, atol=2e-3)
    w = rng.normal(size=(200000, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    values = latlong.sample_bilinear(image, w)
    mc = 4 * np.pi * (sh.basis(3, w)[:, :, None] * values[:, None, :]).mean(axis=0)
    np.testing.assert_allclose(mc, coeffs, atol=0.05 * np.abs(coeffs).max())


def test_phong_filter_of_huge_exponents_tends_to_one_from_below():
    from estimator.core.sh import LARGE_EXPONENT, phong_filter

    l = np.arange(11.0)
    closed = phong_filter(10, LARGE_EXPONENT)                      # the closed form, at the switch
    np.testing.assert_allclose(closed, np.exp(-l * (l + 1) / (2 * (LARGE_EXPONENT + 2))), atol=1e-8)
    for n in (1e6, 1e12, 1e300):
        f = phong_filter(10, n)
        assert np.all(np.isfinite(f)) and np.all(f <= 1.0) and np.all(np.diff(f) <= 0) and f[0] == 1.0
