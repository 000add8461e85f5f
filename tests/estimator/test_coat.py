"""The coat term: Fresnel reflectance, the rows' shapes, and the fitted weight."""
import numpy as np
import pytest

from estimator.core import latlong, sh
from estimator.light.coat import (
    LOBE_EXPONENTS,
    admissible_scale,
    coat_rows,
    fit_coat,
    grey_weights,
    lobe_rows,
    mirror_escapes,
    unexplained_cost,
)
from estimator.model.reflection import fresnel_dielectric, mirror_directions
from estimator.rays.visibility import Visibility, sphere_sampling


def test_fresnel_limits():
    np.testing.assert_allclose(fresnel_dielectric(np.array([1.0]), 1.5), ((1.5 - 1) / 2.5) ** 2, rtol=1e-12)
    # an index far beyond any dielectric (a user's setting) reflects everything and does not overflow
    np.testing.assert_allclose(fresnel_dielectric(np.array([1.0, 0.5, 1e-6]), 1e200), 1.0, rtol=1e-12)
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


def _views_of_upward_faces(count, seed):
    """``count`` observations of faces facing +Y seen from random directions above them."""
    rng = np.random.default_rng(seed)
    n = np.tile([[0.0, 1.0, 0.0]], (count, 1))
    v = rng.normal(size=(count, 3))
    v[:, 1] = np.abs(v[:, 1]) + 0.5
    return n, v / np.linalg.norm(v, axis=1, keepdims=True)


def test_rows_vanish_where_the_object_blocks_the_mirror_direction():
    n, v = _views_of_upward_faces(6, 4)
    light = np.zeros((sh.num_coeffs(0), 3))
    light[0] = [1.0, 2.0, 3.0]
    escapes = np.array([1.0, 0.0, 1.0, 0.0, 1.0, 1.0])
    rows = coat_rows(n, v, light, 0, 1.5, escapes)
    np.testing.assert_allclose(rows, coat_rows(n, v, light, 0, 1.5) * escapes[:, None], rtol=1e-12)
    assert np.all(rows[escapes == 0] == 0) and np.all(rows[escapes == 1] > 0)


def test_mirror_escapes_reads_the_shadow_function_at_the_nearest_direction():
    """Face 0 sees every direction, face 1 only those above 60 degrees elevation: an
    observation escapes where its face sees the sample direction nearest its mirror direction."""
    sampling = sphere_sampling(300)
    sees = np.stack([np.ones(300, bool), sampling.directions[:, 1] > np.sin(np.radians(60))])
    visibility = Visibility(np.packbits(sees, axis=1), 300)
    n, v = _views_of_upward_faces(400, 5)
    face = np.arange(400) % 2
    out = mirror_escapes(face, n, v, sampling, visibility)
    nearest = sampling.directions[sampling.nearest(mirror_directions(n, v))]
    expected = np.where(face == 0, 1.0, nearest[:, 1] > np.sin(np.radians(60)))
    np.testing.assert_array_equal(out, expected)
    assert 0 < out[face == 1].mean() < 1                        # both cases occur


def test_the_mean_levels_reflection_is_recovered_beside_any_diffuse():
    """A coat reflecting an even environment of level k where the object does not block the
    mirror direction: the degree-0 rows (the Fresnel factor times the escape) give k back,
    whatever each face's diffuse level."""
    rng = np.random.default_rng(6)
    faces, views, level = 300, 10, 0.4
    face = np.repeat(np.arange(faces), views)
    n, v = _views_of_upward_faces(faces * views, 7)
    escapes = (rng.uniform(size=faces * views) > 0.2).astype(float)
    reflection = level * fresnel_dielectric(v[:, 1], 1.5) * escapes
    rgb = rng.uniform(0.02, 0.8, size=(faces, 3))[face] + reflection[:, None]
    unit = np.zeros((1, 3))
    unit[0] = 1.0 / sh.basis(0, v[:1])[0, 0]                  # a light of radiance 1 in every direction
    k = fit_coat(face, rgb, coat_rows(n, v, unit, 0, 1.5, escapes), faces)
    np.testing.assert_allclose(k, level, rtol=1e-6)


def _smooth_light(order, seed):
    """(M, 3) SH radiance: a positive mean and random coefficients falling with the degree."""
    rng = np.random.default_rng(seed)
    degree = np.concatenate([np.full(2 * l + 1, l) for l in range(order + 1)])
    light = rng.normal(size=(sh.num_coeffs(order), 3)) * 0.3 / (1.0 + degree[:, None]) ** 2
    light[0] = [1.0, 0.8, 0.6]
    return light


@pytest.mark.parametrize("exponent", [5.0, 20.0, 80.0])
def test_lobe_rows_integrate_the_light_over_the_normalised_phong_lobe(exponent):
    """The lobe's row is the light's radiance integrated against (n + 1) / (2 pi) max(0, r . w)^n
    around the mirror direction r: checked by quadrature over a fine lat-long grid."""
    light = _smooth_light(6, 8)
    n, v = _views_of_upward_faces(4, 9)
    rows = lobe_rows(n, v, light, [exponent])
    assert rows.shape == (1, 4, 3)
    dirs = latlong.directions(400, 800).reshape(-1, 3)
    radiance = sh.basis(6, dirs) @ light                                            # (K, 3)
    weight = latlong.solid_angles(400, 800).reshape(-1)
    lobe = (exponent + 1) / (2 * np.pi) * np.maximum(mirror_directions(n, v) @ dirs.T, 0.0) ** exponent
    expected = (lobe * weight) @ radiance                                           # (4, 3)
    np.testing.assert_allclose(rows[0], expected, rtol=2e-3)


def test_lobe_rows_of_several_exponents_and_their_escape():
    light = _smooth_light(4, 10)
    n, v = _views_of_upward_faces(7, 11)
    escapes = np.array([1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0])
    both = lobe_rows(n, v, light, [7.0, 40.0], escapes)
    for k, exponent in enumerate([7.0, 40.0]):
        np.testing.assert_allclose(both[k], lobe_rows(n, v, light, [exponent])[0] * escapes[:, None], rtol=1e-12)
    assert np.all(both[:, escapes == 0] == 0)


def test_the_lobes_exponent_is_the_one_that_explains_the_changes_across_views():
    """Colours of a glossy lobe of exponent 14 beside any diffuse level: of the candidate
    exponents, 14's rows leave the least of the changes across views unexplained."""
    rng = np.random.default_rng(12)
    faces, views = 200, 12
    face = np.repeat(np.arange(faces), views)
    n, v = _views_of_upward_faces(faces * views, 13)
    light = _smooth_light(8, 14)
    rows = lobe_rows(n, v, light, LOBE_EXPONENTS)
    truth = LOBE_EXPONENTS.index(14.0)
    rgb = rng.uniform(0.05, 0.8, size=(faces, 3))[face] + 0.2 * rows[truth]
    fitted = [fit_coat(face, rgb, r, faces)[0] * r for r in rows]
    costs = unexplained_cost(face, rgb, fitted, faces)
    assert int(np.argmin(costs)) == truth
    np.testing.assert_allclose(fit_coat(face, rgb, rows[truth], faces), 0.2, rtol=1e-6)


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


def test_fit_gives_each_group_its_own_weight():
    """An object that mixes a matte part (no coat) with a coated one: each part's weight is its own."""
    rng = np.random.default_rng(3)
    faces, views = 400, 10
    face = np.repeat(np.arange(faces), views)
    group = (face >= 150).astype(np.int64)                              # faces 0-149 matte, the rest coated
    x = rng.uniform(0.0, 1.0, size=(faces * views, 3))
    true_k = np.array([[0.0, 0.0, 0.0], [0.08, 0.05, 0.03]])
    rgb = rng.uniform(0.05, 0.8, size=(faces, 3))[face] + true_k[group] * x
    k = fit_coat(face, rgb, x, faces, group=group, num_groups=2)
    assert k.shape == (2, 3)
    np.testing.assert_allclose(k, true_k, atol=2e-3)
    one = fit_coat(face, rgb, x, faces)                                 # one shared weight sits between the two
    assert np.all(one[0] < true_k[1]) and np.all(one[0] > 0.01)


def test_admissible_scale_caps_what_turns_negative():
    rgb = np.full((1000, 3), 0.1)
    coat = np.zeros((1000, 3))
    coat[:, 0] = np.linspace(0.0, 0.2, 1000)        # subtracting all of it makes half the rows <= 0
    t = admissible_scale(rgb, coat, 0.01)
    share = np.mean(np.any(rgb - t * coat <= 0, axis=1))
    assert share <= 0.01 and 0.49 < t < 0.51     # rows turn <= 0 where coat >= 0.1 / t: t ~ 0.505 at 1 %
    assert admissible_scale(rgb, np.full_like(rgb, 0.05), 0.0) == 1.0          # harmless: the whole weight


def test_admissible_scale_per_group_caps_only_the_group_that_overreaches():
    rgb = np.full((2000, 3), 0.1)
    coat = np.zeros((2000, 3))
    coat[:1000, 0] = np.linspace(0.0, 0.2, 1000)      # group 0 as above; group 1's coat is harmless
    coat[1000:, 0] = 0.05
    group = np.repeat([0, 1], 1000)
    t = admissible_scale(rgb, coat, 0.01, group=group, num_groups=2)
    assert t.shape == (2,) and 0.49 < t[0] < 0.51 and t[1] == 1.0


def test_coat_groups_are_the_regions_and_one_for_every_other_face():
    """Region labels 0..R-1 are groups; a texture's own faces (labels >= R) and unestimated
    faces (-1) share group R; without per-region weights there is one group."""
    from types import SimpleNamespace

    from estimator.methods.retinex_segmented.method import coat_groups

    est = SimpleNamespace(labels=np.array([0, 1, 1, 2, 3, 4, -1]), info={"uniform_regions": 2})
    group, groups = coat_groups(est, per_region=True)
    assert groups == 3
    np.testing.assert_array_equal(group, [0, 1, 1, 2, 2, 2, 2])
    group, groups = coat_groups(est, per_region=False)
    assert groups == 1 and np.all(group == 0)


def test_grey_weights_share_one_colour_across_groups():
    """A grey coat under a light whose per-channel scale is off by c: every group's weights are
    its strength times c, even where a group's own sums are noisy in one channel."""
    colour = np.array([1.0, 0.8, 0.5])
    strength = np.array([0.0, 0.3, 1.0, 2.0])
    xx = np.array([[5.0, 5, 5], [4, 4, 4], [6, 6, 6], [0.01, 0.01, 0.01]])    # the last group is weakly seen
    xy = xx * strength[:, None] * colour
    xy[3, 2] *= 3.0                                                           # ...and off in blue
    s, w = grey_weights(xy, xx)
    k = s[:, None] * w
    np.testing.assert_allclose(k[:3], strength[:3, None] * colour, rtol=0.03)
    np.testing.assert_allclose(k[3] / k[3, 0], colour, rtol=0.05)            # its colour is the others'
