import numpy as np
import pytest

from estimator.solvers.bilinear import solve_bilinear


def _problem(rng, components, groups=30, per_group=40, m=16):
    n = groups * per_group
    group = np.repeat(np.arange(groups), per_group)
    c_face = rng.normal(size=(groups * 4, m)) * 0.3
    c_face[:, 0] = 1.0
    face = group * 4 + rng.integers(0, 4, n)
    c_rows = c_face[face]
    d_rows = rng.normal(size=(n, m)) * 0.5
    d_rows[:, 0] = 1.0
    h = rng.normal(size=(m, 3)) * 0.2
    h[0] = 1.0
    td = rng.uniform(0.2, 1.0, (groups, 3)) * (components != "specular")
    ts = rng.uniform(0.2, 1.0, (groups, 3)) * (components != "diffuse")
    rgb = td[group] * (c_rows @ h) + ts[group] * (d_rows @ h)
    return rgb, group, c_rows, d_rows, h, td, ts


@pytest.mark.parametrize("shuffled", [False, True])
@pytest.mark.parametrize("components", ["both", "specular", "diffuse"])
def test_noise_free_bilinear_problem_is_solved_exactly(components, shuffled):
    """Exact recovery, whatever order the observations come in (the solver sums per group),
    to float64 precision although the steps' normal matrix is float32 (measured errors 1e-16)."""
    rng = np.random.default_rng(3)
    rgb, group, c_rows, d_rows, h, td, ts = _problem(rng, components)
    if shuffled:
        order = rng.permutation(len(group))
        rgb, group, c_rows, d_rows = rgb[order], group[order], c_rows[order], d_rows[order]
    res = solve_bilinear(rgb, group, c_rows, d_rows, 30, components, iterations=50, tol=1e-14)
    np.testing.assert_allclose(res.light[0], 1.0)                      # the gauge
    np.testing.assert_allclose(res.light, h, atol=1e-10)
    np.testing.assert_allclose(res.diffuse, td, atol=1e-10)
    np.testing.assert_allclose(res.specular, ts, atol=1e-10)
    assert res.residuals[-1] < 1e-10 and res.residuals[-1] <= res.residuals[0]
    # a normal matrix whose rows and albedos are out of step still reaches the optimum
    # (the gradient is exact), only slowly: measured 4-17 steps, 29-50 on shuffled rows with such a mismatch
    assert max(len(r) for r in res.lm_residuals) <= 20


def test_known_illumination_is_one_linear_solve():
    rng = np.random.default_rng(4)
    rgb, group, c_rows, d_rows, h, td, ts = _problem(rng, "both")
    res = solve_bilinear(rgb, group, c_rows, d_rows, 30, "both", fixed_light=h)
    np.testing.assert_allclose(res.diffuse, td, atol=1e-8)
    np.testing.assert_allclose(res.light, h)
    assert len(res.residuals) == 1


def test_albedos_stay_non_negative_and_shapes_are_checked():
    rng = np.random.default_rng(5)
    rgb, group, c_rows, d_rows, *_ = _problem(rng, "both")
    res = solve_bilinear(rgb + rng.normal(size=rgb.shape), group, c_rows, d_rows, 30, "both")
    assert res.diffuse.min() >= 0 and res.specular.min() >= 0
    with pytest.raises(ValueError, match="components"):
        solve_bilinear(rgb, group, c_rows, d_rows, 30, "glossy")
    with pytest.raises(ValueError, match="must agree"):
        solve_bilinear(rgb[:-1], group, c_rows, d_rows, 30)
