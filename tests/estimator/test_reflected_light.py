"""The light a dielectric coat reflects, fitted with every face's diffuse free: round trip
on synthetic rows, robustness to glints, no light where nothing changes with the view,
the sun cut out of the map, bad inputs, and the faces' elimination against the explicit
projection."""
import numpy as np
import pytest
from scipy import linalg, sparse

from estimator.core import latlong, sh
from estimator.core.errors import InputError
from estimator.light.coat_map import (
    CG_PROBE,
    _conjugate_gradients,
    _face_eliminated_system,
    _reweighted_solve,
    bilinear_rows,
    diffuse_radiance,
    fit_reflected_light,
    map_differences,
)
from estimator.model.reflection import fresnel_dielectric, mirror_directions
from estimator.rays.visibility import Visibility, sphere_sampling


def _rows(true_map, faces=1500, views=24, ior=1.5, seed=0):
    """Synthetic coated observations of a convex object: face normals spread on the sphere,
    cameras all around, rgb = D (1 - F) + F L(r) with L sampled bilinearly from ``true_map``."""
    rng = np.random.default_rng(seed)
    normals = sh.fibonacci_sphere(faces)
    cameras = sh.fibonacci_sphere(views)
    cos = normals @ cameras.T
    face, view = np.nonzero(cos > 0.5)
    view_dir = cameras[view]
    diffuse = rng.uniform(0.03, 0.8, size=(faces, 3))          # a texture: any level per face
    mirror = mirror_directions(normals[face], view_dir)
    f = fresnel_dielectric(np.sum(normals[face] * view_dir, axis=1), ior)[:, None]
    rgb = diffuse[face] * (1 - f) + f * latlong.sample_bilinear(true_map, mirror)
    sampling = sphere_sampling(64)
    everywhere = Visibility(np.full((faces, 8), 255, dtype=np.uint8), 64)   # nothing blocks a mirror ray
    return face, rgb, view_dir, normals, sampling, everywhere, diffuse


def _smooth_map(height=16, width=32):
    coeffs = np.zeros((sh.num_coeffs(2), 3))
    coeffs[0] = [2.0, 1.8, 1.5]
    coeffs[2] = [0.8, 0.7, 0.4]       # brighter above
    coeffs[3] = [0.3, -0.2, 0.1]
    coeffs[5] = [0.2, 0.1, -0.1]
    return sh.to_latlong(coeffs, height, width)


def test_bilinear_rows_sample_like_the_envmap_lookup():
    rng = np.random.default_rng(3)
    image = rng.uniform(size=(9, 16, 3))
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    np.testing.assert_allclose(bilinear_rows(dirs, 9, 16) @ image.reshape(-1, 3),
                               latlong.sample_bilinear(image, dirs), atol=1e-12)


def test_map_differences_vanish_on_a_constant_map():
    d = map_differences(5, 8)
    assert d.shape == (5 * 8 + 4 * 8, 40)
    np.testing.assert_allclose(d @ np.ones(40), 0.0, atol=1e-12)


def test_round_trip_recovers_the_light_and_the_texture():
    """Rows made by the model itself: the map's low orders come back within 2 % (the DC
    too: F's change with the view fixes it against the diffuse), the per-face diffuse within
    1 %, and the model explains the view changes."""
    true_map = _smooth_map()
    face, rgb, view_dir, normals, sampling, vis, diffuse = _rows(true_map)
    fit = fit_reflected_light(face, rgb, view_dir, normals, sampling, vis, height=16, width=32, smoothness=1e-6)
    assert fit.radiance.shape == (16, 32, 3) and fit.diffuse.shape == (len(normals), 3)
    low_true, low_fit = sh.project_latlong(2, true_map), fit.sh(2)
    np.testing.assert_allclose(low_fit, low_true, atol=0.02 * np.abs(low_true[0]).max())
    seen = np.all(np.isfinite(fit.diffuse), axis=1)
    assert seen.mean() > 0.99
    np.testing.assert_allclose(fit.diffuse[seen], diffuse[seen], rtol=0.01, atol=1e-3)
    assert np.all(fit.explained > 0.99)


def test_a_fitted_map_gives_the_diffuse_of_faces_it_was_not_fitted_on():
    """The map fitted on the observations of half the faces, then held fixed: the other half's
    diffuse comes back within 1 % as the fit's own faces' does, and a glint on 1 % of their
    rows is downweighted."""
    true_map = _smooth_map()
    face, rgb, view_dir, normals, sampling, vis, diffuse = _rows(true_map, seed=4)
    half = face % 2 == 0
    fit = fit_reflected_light(face[half], rgb[half], view_dir[half], normals, sampling, vis, height=16, width=32,
                              smoothness=1e-6)
    rgb = rgb.copy()
    rgb[np.nonzero(~half)[0][::100]] += 40.0
    out = diffuse_radiance(fit, face[~half], rgb[~half], view_dir[~half], normals, sampling, vis)
    odd = np.arange(len(normals)) % 2 == 1
    seen = np.all(np.isfinite(out), axis=1)
    np.testing.assert_array_equal(seen, odd & np.isin(np.arange(len(normals)), face))   # only the other half
    np.testing.assert_allclose(out[seen], diffuse[seen], rtol=0.01, atol=1e-3)


def test_glints_are_downweighted():
    """1 % of the rows carry a glint 20 x the light (a sun narrower than a cell): the low
    orders still come back within 3 %."""
    true_map = _smooth_map()
    face, rgb, view_dir, normals, sampling, vis, _ = _rows(true_map, seed=1)
    rgb = rgb.copy()
    rgb[::100] += 40.0
    fit = fit_reflected_light(face, rgb, view_dir, normals, sampling, vis, height=16, width=32, smoothness=1e-6)
    low_true = sh.project_latlong(2, true_map)
    np.testing.assert_allclose(fit.sh(2), low_true, atol=0.03 * np.abs(low_true[0]).max())


@pytest.mark.parametrize("rounds", [0, 1, 2, 4])
def test_each_channel_is_fitted_as_if_alone(rounds):
    """The channels share their first (unweighted) round's system, then each is reweighted on
    its own residuals: a channel's map, diffuse and explained share are those of a fit whose
    three channels are all that channel. Glints in one channel only, so the channels' weights
    differ from the second round on."""
    face, rgb, view_dir, normals, sampling, vis, _ = _rows(_smooth_map(), faces=600, seed=2)
    rgb = rgb.copy()
    rgb[::50, 1] += 40.0
    fit = fit_reflected_light(face, rgb, view_dir, normals, sampling, vis, height=8, width=16, rounds=rounds)
    for c in range(3):
        alone = fit_reflected_light(face, np.repeat(rgb[:, c:c + 1], 3, axis=1), view_dir, normals, sampling, vis,
                                    height=8, width=16, rounds=rounds)
        np.testing.assert_allclose(fit.radiance[..., c], alone.radiance[..., 0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(fit.diffuse[:, c], alone.diffuse[:, 0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(fit.explained[c], alone.explained[0], rtol=1e-9)


def test_view_independent_colours_are_not_explained_by_a_reflection():
    """A bare diffuse texture with 1 % noise: nothing changes with the view but the noise.
    A uniform reflected light L = D would explain a uniform diffuse exactly (D = D (1 - F) +
    F D), so part of each face's level is explained (measured 0.62 here), far less than on
    coated scenes (0.974-0.999 on the shipped coated textures)."""
    face, _, view_dir, normals, sampling, vis, diffuse = _rows(_smooth_map(), seed=2)
    rng = np.random.default_rng(5)
    rgb = diffuse[face] * (1 + 0.01 * rng.normal(size=(len(face), 3)))
    fit = fit_reflected_light(face, rgb, view_dir, normals, sampling, vis, height=16, width=32)
    assert np.all(fit.explained < 0.8)


def test_blocked_mirror_directions_are_left_out():
    true_map = _smooth_map()
    face, rgb, view_dir, normals, sampling, vis, _ = _rows(true_map)
    blocked = Visibility(np.zeros_like(vis.bits), vis.num_directions)
    with pytest.raises(InputError, match="blocked"):
        fit_reflected_light(face, rgb, view_dir, normals, sampling, blocked)


def test_the_determined_flag_needs_rows_per_vertex():
    """A map the rows cannot determine is not fitted (its dense system, nearly singular, failed
    to factor on 4-6 views): radiance 0, diffuse NaN, nothing explained."""
    face, rgb, view_dir, normals, sampling, vis, _ = _rows(_smooth_map(), faces=300, views=12)
    few = fit_reflected_light(face, rgb, view_dir, normals, sampling, vis)     # 32 x 64: too few rows
    assert not few.determined
    assert not few.radiance.any() and np.isnan(few.diffuse).all() and not few.explained.any()
    fitted = fit_reflected_light(face, rgb, view_dir, normals, sampling, vis, height=4, width=8)
    assert fitted.determined and fitted.explained.min() > 0.5


def _small_round(seed: int, rows: int = 300, faces: int = 30, cells: int = 20):
    """A small reweighted round's inputs: sparse rows a (N, K), one transmission per row b (N, F),
    a ridge, values and weights (N, 3), the Cholesky factor of the evenly weighted system and K."""
    rng = np.random.default_rng(seed)
    face = rng.integers(0, faces, rows)
    a = sparse.csr_matrix(rng.random((rows, cells)) * (rng.random((rows, cells)) < 0.3))
    b = sparse.csr_matrix((0.5 + rng.random(rows), (np.arange(rows), face)), shape=(rows, faces))
    ridge = 1e-2 * sparse.identity(cells)
    values, weights = rng.normal(size=(rows, 3)), rng.uniform(0.05, 1.0, size=(rows, 3))
    system, _, _ = _face_eliminated_system(a, b, values, np.ones(rows))
    first = linalg.cho_factor(system + np.trace(system) / cells * ridge.toarray())
    return a, b, ridge, values, weights, first, system, cells


def test_a_channel_whose_dense_factorisation_fails_is_solved_by_least_squares(monkeypatch):
    """Where the dense fallback's Cholesky fails (rows whose weights nearly vanish), that channel's
    map is the least-squares solution of the same system, not an error."""
    a, b, ridge, values, weights, first, _, cells = _small_round(11)
    monkeypatch.setattr("estimator.light.coat_map.CG_ITERATIONS", 1)

    def failing(system, ridge):
        raise np.linalg.LinAlgError("1-th leading minor of the array is not positive definite")

    monkeypatch.setattr("estimator.light.coat_map._factored", failing)
    light, _, _ = _reweighted_solve(a, b, values, weights, ridge, first, np.zeros((cells, 3)))
    for c in range(3):
        dense, right, _ = _face_eliminated_system(a, b, values[:, c], weights[:, c])
        expected = np.linalg.solve(dense + np.trace(dense) / cells * ridge.toarray(), right)
        np.testing.assert_allclose(light[:, c], expected, rtol=1e-8, atol=1e-11 * np.abs(expected).max())


def test_sky_and_sun_cuts_the_brightest_compact_source():
    height, width = 32, 64
    sun_dir = np.array([0.5, 0.6, -0.62])
    sun_dir /= np.linalg.norm(sun_dir)
    dirs = latlong.directions(height, width)
    sky = _smooth_map(height, width)
    spot = np.exp(-(np.degrees(np.arccos(np.clip(dirs @ sun_dir, -1, 1))) / 4.0) ** 2)[..., None] * 200.0
    from estimator.light.coat_map import ReflectedLight
    light = ReflectedLight(sky + spot, np.zeros((1, 3)), np.ones(3), 1, True)
    cut, direction = light.sky_and_sun()
    assert np.degrees(np.arccos(np.clip(direction @ sun_dir, -1, 1))) < 3.0
    assert cut.max() < 1.5 * sky.max()
    far = np.degrees(np.arccos(np.clip(dirs @ sun_dir, -1, 1))) > 20
    np.testing.assert_array_equal(cut[far], (sky + spot)[far])


@pytest.mark.parametrize("change, message", [
    (dict(rgb=np.zeros((3, 3))), "rgb and view_dir"),
    (dict(ior=1.0), "ior"),
    (dict(height=2), "3 x 2"),
    (dict(face=np.array([0, 1, 99999])), "faces must lie"),
])
def test_bad_inputs_name_the_problem(change, message):
    face, rgb, view_dir, normals, sampling, vis, _ = _rows(_smooth_map(), faces=50, views=6)
    args = dict(face=face, rgb=rgb, view_dir=view_dir, normals=normals, sampling=sampling, visibility=vis)
    if "face" in change:
        args["face"] = np.resize(change.pop("face"), len(face))
    args.update(change)
    with pytest.raises(InputError, match=message):
        fit_reflected_light(**args)


def test_face_eliminated_system_is_the_projected_rows_normal_equations():
    """The Schur-complement system equals the normal equations of the rows with each face's
    transmission column projected off (weighted), to 1e-10 relative, a face without weight and
    an unseen face included; the residual function refits each face's diffuse under a map."""
    rng = np.random.default_rng(5)
    rows, faces, cells = 60, 9, 7
    face = rng.integers(0, faces - 1, rows)                       # face faces-1 is unseen
    a = sparse.csr_matrix(rng.random((rows, cells)) * (rng.random((rows, cells)) < 0.4))
    b = sparse.csr_matrix((0.5 + rng.random(rows), (np.arange(rows), face)), shape=(rows, faces))
    y, weights = rng.normal(size=rows), rng.random(rows)
    weights[face == 2] = 0.0                                      # face 2 carries no weight
    system, right, faces_fit = _face_eliminated_system(a, b, y, weights)
    w, bd = np.diag(weights), b.toarray()
    column = np.einsum("nf,nf->f", bd, weights[:, None] * bd)
    inverse = np.diag(np.where(column > 0, 1.0 / np.where(column > 0, column, 1.0), 0.0))
    project = np.eye(rows) - bd @ inverse @ bd.T @ w
    a_c, y_c = project @ a.toarray(), project @ y
    np.testing.assert_allclose(system, a_c.T @ w @ a_c, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(right, a_c.T @ w @ y_c, rtol=1e-10, atol=1e-12)
    light = rng.normal(size=cells)
    np.testing.assert_allclose(faces_fit(light), y_c - a_c @ light, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(faces_fit(np.zeros(cells)), y_c, rtol=1e-10, atol=1e-12)
    # three channels under the same weights: one system, a right side and residuals per channel
    ys, lights = np.column_stack([y, rng.normal(size=(rows, 2))]), rng.normal(size=(cells, 3))
    system3, right3, faces_fit3 = _face_eliminated_system(a, b, ys, weights)
    np.testing.assert_array_equal(system3, system)
    for c in range(3):
        one_system, one_right, one_fit = _face_eliminated_system(a, b, ys[:, c], weights)
        np.testing.assert_allclose(right3[:, c], one_right, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(faces_fit3(lights)[:, c], one_fit(lights[:, c]), rtol=1e-12, atol=1e-14)


def test_reweighted_rounds_solve_the_dense_systems():
    """A reweighted round's conjugate gradients, preconditioned by the first round's factor,
    give each channel's map of the dense system (Schur complement plus its mean diagonal times
    the ridge) to 1e-6 relative, with the channels under different weights; the residuals and
    projections are those of the dense solve's map."""
    rng = np.random.default_rng(7)
    rows, faces, cells = 400, 40, 24
    face = rng.integers(0, faces, rows)
    a = sparse.csr_matrix(rng.random((rows, cells)) * (rng.random((rows, cells)) < 0.3))
    b = sparse.csr_matrix((0.5 + rng.random(rows), (np.arange(rows), face)), shape=(rows, faces))
    ridge = 1e-2 * sparse.identity(cells) + sparse.diags(np.full(cells - 1, -5e-3), 1) \
        + sparse.diags(np.full(cells - 1, -5e-3), -1)
    values, weights = rng.normal(size=(rows, 3)), rng.uniform(0.05, 1.0, size=(rows, 3))
    system, _, _ = _face_eliminated_system(a, b, values, np.ones(rows))
    first = linalg.cho_factor(system + np.trace(system) / cells * ridge.toarray())
    light, residuals, projections = _reweighted_solve(a, b, values, weights, ridge, first, np.zeros((cells, 3)))
    for c in range(3):
        dense, right, faces_fit = _face_eliminated_system(a, b, values[:, c], weights[:, c])
        expected = np.linalg.solve(dense + np.trace(dense) / cells * ridge.toarray(), right)
        np.testing.assert_allclose(light[:, c], expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
        np.testing.assert_allclose(residuals[:, c], faces_fit(light[:, c]), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(projections[:, c], faces_fit(np.zeros(cells)), rtol=1e-12, atol=1e-12)


def test_conjugate_gradients_solve_several_systems_side_by_side():
    """Three different symmetric positive definite systems, one preconditioner (the first
    system's inverse), one column each: each comes back as np.linalg.solve gives it."""
    rng = np.random.default_rng(8)
    k = 30
    matrices = []
    for _ in range(3):
        m = rng.normal(size=(k, k))
        matrices.append(m @ m.T + k * np.eye(k))
    right = rng.normal(size=(k, 3))
    inverse = np.linalg.inv(matrices[0])
    x, converged = _conjugate_gradients([lambda v, m=m: m @ v for m in matrices], lambda r: inverse @ r, right,
                                        np.zeros((k, 3)))
    assert converged.all()
    for c, m in enumerate(matrices):
        np.testing.assert_allclose(x[:, c], np.linalg.solve(m, right[:, c]), rtol=1e-6)

def test_a_column_converging_too_slowly_is_left_at_the_probe():
    """A system whose spectrum spans six decades, unpreconditioned, would need hundreds of
    iterations: after CG_PROBE its rate says more than CG_DENSE_ITERATIONS, so it stops there
    unconverged (the dense solve takes over); a column the preconditioner solves exactly
    converges beside it."""
    k = 200
    slow = np.diag(np.logspace(0, 6, k))
    rng = np.random.default_rng(10)
    m = rng.normal(size=(k, k))
    fast = m @ m.T + k * np.eye(k)
    inverse = np.linalg.inv(fast)
    calls = [0, 0]

    def times(c, matrix):
        def product(v):
            calls[c] += 1
            return matrix @ v
        return product

    right = rng.normal(size=(k, 2))
    x, converged = _conjugate_gradients([times(0, slow), times(1, fast)],
                                        lambda r: np.column_stack([r[:, 0], inverse @ r[:, 1]]), right,
                                        np.zeros((k, 2)))
    assert converged.tolist() == [False, True]
    assert calls[0] == 1 + CG_PROBE                      # the first residual, then the probe's iterations
    np.testing.assert_allclose(x[:, 1], np.linalg.solve(fast, right[:, 1]), rtol=1e-6)


def test_a_channel_the_iterations_leave_short_is_solved_densely(monkeypatch):
    """With one iteration allowed, the conjugate gradients say no column converged, and the
    reweighted round solves those channels by their dense systems: the maps still equal the
    dense solve's."""
    a, b, ridge, values, weights, first, system, cells = _small_round(9)
    monkeypatch.setattr("estimator.light.coat_map.CG_ITERATIONS", 1)
    _, converged = _conjugate_gradients([lambda v: system @ v] * 3, lambda r: r, values[:cells], np.zeros((cells, 3)))
    assert not converged.any()
    light, _, _ = _reweighted_solve(a, b, values, weights, ridge, first, np.zeros((cells, 3)))
    for c in range(3):
        dense, right, _ = _face_eliminated_system(a, b, values[:, c], weights[:, c])
        expected = np.linalg.solve(dense + np.trace(dense) / cells * ridge.toarray(), right)
        np.testing.assert_allclose(light[:, c], expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
