"""The sun as a delta light beside the SH light: exact shading and cast shadows, its
irradiance fitted with the light, its direction found by the pattern search."""
import numpy as np
import pytest

from estimator.config import EstimatorConfig
from estimator.core import sh
from estimator.core.data import TriangleMesh
from estimator.core.errors import InputError
from estimator.light.edge_fit import log_shading_fit
from estimator.light.sun import brightest_direction, find_sun, find_suns, sun_shading, sun_shadings
from estimator.model.reflection import diffuse_matrix, fresnel_dielectric
from estimator.model.reflection_models import reflection_model
from estimator.rays.raycast import ELSEWHERE, MISS, ClusterCaster, RayCaster
from estimator.rays.visibility import compute_visibility, sphere_sampling

from .meshes import lobed, sphere


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_convex_object_shading_is_the_cosine_over_pi():
    mesh = sphere(2)
    d = _unit([0.3, 0.8, -0.2])
    np.testing.assert_allclose(np.pi * sun_shading(mesh, RayCaster(mesh), d), np.maximum(mesh.face_normals @ d, 0),
                               atol=1e-12)


def test_directions_batched_in_one_ray_query_give_each_direction_s_column():
    """sun_shadings of six directions (one ray query, shadows and a coat included) equals
    sun_shading of each alone, (F, 6): the same faces lit (the same shadow rays), the values to
    1e-12 (the cosines' products differ in rounding with the batch's shape)."""
    a, b = sphere(2), sphere(2)
    mesh = TriangleMesh(np.vstack([a.vertices, b.vertices + [0.0, 2.5, 0.0]]),
                        np.vstack([a.faces, b.faces + len(a.vertices)]))
    caster = RayCaster(mesh)
    ring = np.array([_unit(v) for v in ([0, 1, 0], [0.3, 0.9, 0], [1, 0.1, 0], [0, 0.2, -1], [-1, -1, 0.5],
                                        [0, -1, 0])])
    for ior in (None, 1.5):
        both = sun_shadings(mesh, caster, ring, ior)
        assert both.shape == (mesh.num_faces, 6) and np.any(both > 0)
        # the lower sphere's top, turned to a sun overhead, lies in the upper sphere's shadow
        assert np.any((mesh.face_normals @ ring[0] > 0.5) & (both[:, 0] == 0))
        for k, d in enumerate(ring):
            alone = sun_shading(mesh, caster, d, ior)
            np.testing.assert_array_equal(both[:, k] > 0, alone > 0)
            np.testing.assert_allclose(both[:, k], alone, rtol=1e-12, atol=0)

def test_escapes_is_a_miss_of_the_first_hit():
    """RayCaster.escapes (any hit) agrees with first_hit_faces == MISS on 2,000 random rays
    from inside and outside two spheres, both outcomes present."""
    a, b = sphere(2), sphere(2)
    caster = RayCaster(TriangleMesh(np.vstack([a.vertices, b.vertices + [0.0, 2.5, 0.0]]),
                                    np.vstack([a.faces, b.faces + len(a.vertices)])))
    rng = np.random.default_rng(4)
    origins = rng.uniform(-2.0, 4.0, (2000, 3))
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    escaped = caster.escapes(origins, directions)
    np.testing.assert_array_equal(escaped, caster.first_hit_faces(origins, directions) == MISS)
    assert 0 < escaped.mean() < 1


def test_a_blocker_casts_a_full_shadow():
    """A sphere above another: faces of the lower sphere under the upper one are dark for a
    sun overhead, lit for a sun at the horizon."""
    a, b = sphere(2), sphere(2)
    vertices = np.vstack([a.vertices, b.vertices + [0.0, 3.0, 0.0]])
    mesh = TriangleMesh(vertices, np.vstack([a.faces, b.faces + len(a.vertices)]))
    caster = RayCaster(mesh)
    lower_top = (np.arange(mesh.num_faces) < a.num_faces) & (mesh.face_normals[:, 1] > 0.95)
    assert lower_top.sum() >= 3
    assert np.all(sun_shading(mesh, caster, [0.0, 1.0, 0.0])[lower_top] == 0.0)
    side = _unit([1.0, 0.05, 0.0])
    np.testing.assert_allclose(np.pi * sun_shading(mesh, caster, side)[lower_top],
                               np.maximum(mesh.face_normals[lower_top] @ side, 0), atol=1e-12)


def test_faces_outside_the_clusters_still_cast_their_shadow():
    """The lower sphere's faces as clusters of one face each, traced against both spheres:
    their sun column equals the whole mesh's, the upper sphere's shadow included, and a ray
    reports the cluster it hits, ELSEWHERE for the upper sphere and MISS for nothing."""
    a, b = sphere(2), sphere(2)
    mesh = TriangleMesh(np.vstack([a.vertices, b.vertices + [0.0, 3.0, 0.0]]),
                        np.vstack([a.faces, b.faces + len(a.vertices)]))
    whole = RayCaster(mesh)
    cluster = np.where(np.arange(mesh.num_faces) < a.num_faces, np.arange(mesh.num_faces), -1)
    clusters = ClusterCaster(whole, cluster, a)
    faces = np.arange(a.num_faces)
    for d in ([0.0, 1.0, 0.0], _unit([1.0, 0.05, 0.0]), _unit([0.3, 0.8, -0.2])):
        np.testing.assert_array_equal(sun_shading(a, clusters, d), sun_shading(mesh, whole, d)[faces])
    assert np.all(sun_shading(a, clusters, [0.0, 1.0, 0.0])[a.face_normals[:, 1] > 0.95] == 0.0)
    origins = np.array([[0.0, -5.0, 0.0], [0.0, 1.5, 0.0], [5.0, 0.0, 0.0]])
    hit = clusters.first_hit_faces(origins, np.array([[0.0, 1.0, 0.0]] * 3))
    assert 0 <= hit[0] < a.num_faces and a.face_normals[hit[0], 1] < -0.9      # the lower sphere's bottom
    assert hit[1] == ELSEWHERE and hit[2] == MISS
    # a shadow ray escapes only where it hits nothing, a face in no cluster included
    np.testing.assert_array_equal(clusters.escapes(origins, np.array([[0.0, 1.0, 0.0]] * 3)), [False, False, True])
    assert clusters.escapes(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)
    # two faces in one cluster: a ray hitting either reports it
    pair = np.where(np.arange(mesh.num_faces) == hit[0], 7, cluster)
    assert ClusterCaster(whole, pair, a).first_hit_faces(origins[:1], np.array([[0.0, 1.0, 0.0]]))[0] == 7
    with pytest.raises(InputError, match="indices below 80"):
        ClusterCaster(whole, np.full(mesh.num_faces, 80), sphere(1))


def test_brightest_direction_of_a_delta_light():
    d = _unit([-0.4, 0.5, 0.7])
    light = sh.project_directional(6, d[None, :], np.array([[1.0, 1.0, 1.0]]))
    directions = sh.fibonacci_sphere(2000)
    assert np.degrees(np.arccos(brightest_direction(light, directions) @ d)) < 4.0


@pytest.fixture(scope="module")
def scene():
    mesh = lobed(3)
    caster = RayCaster(mesh)
    sampling = sphere_sampling(600)
    c_matrix = diffuse_matrix(mesh, sampling, compute_visibility(caster, sampling), 2)
    rng = np.random.default_rng(3)
    albedo = np.array([[0.7, 0.5, 0.1], [0.2, 0.6, 0.8], [0.8, 0.8, 0.8]])[
        (mesh.centroids[:, 0] > 0).astype(int) + (mesh.centroids[:, 1] > 0.3)]
    albedo = albedo * np.exp(0.02 * rng.normal(size=albedo.shape))          # a little texture
    sky = np.array([[1.0, 1.1, 1.4], [0.3, 0.35, 0.5], [0.1, 0.1, 0.1], [0.05, 0.05, 0.0]] + [[0.0] * 3] * 5)
    return mesh, caster, c_matrix, albedo, sky


def test_find_sun_recovers_the_direction_and_its_irradiance(scene):
    """Noise-free radiance under a sky (SH order 2) plus a sun with exact shadows: started
    9 degrees off, the search lands within 1.5 degrees; the fit with its column gives the
    sun's irradiance relative to the sky's DC within 5 %."""
    mesh, caster, c_matrix, albedo, sky = scene
    to_sun, e_sun = _unit([0.5, 0.7, 0.3]), np.array([3.0, 2.5, 1.5])
    radiance = albedo * (c_matrix @ sky + sun_shading(mesh, caster, to_sun)[:, None] * e_sun)
    usable = np.ones(mesh.num_faces, dtype=bool)
    start = _unit(to_sun + [0.15, -0.1, 0.0])
    assert np.degrees(np.arccos(start @ to_sun)) > 8
    found = find_sun(radiance, c_matrix, mesh.face_adjacency, usable, mesh, caster, sh.fibonacci_sphere(500), start)
    assert np.degrees(np.arccos(np.clip(found.direction @ to_sun, -1, 1))) < 1.5
    assert found.cost_ratio < 0.8                                      # the 2 % texture stays
    columns = np.hstack([c_matrix, sun_shading(mesh, caster, found.direction)[:, None]])
    light, _ = log_shading_fit(radiance, columns, mesh.face_adjacency, usable)
    assert light.shape == (10, 3)
    np.testing.assert_allclose(light[-1], e_sun / sky[0], rtol=0.05)


def test_no_sun_gives_no_gain(scene):
    """Under the sky alone the best sun lowers the edge cost by under 10 %, less than its
    BIC price: the search does not invent one."""
    mesh, caster, c_matrix, albedo, sky = scene
    radiance = albedo * (c_matrix @ sky)
    found = find_sun(radiance, c_matrix, mesh.face_adjacency, np.ones(mesh.num_faces, dtype=bool), mesh, caster,
                     sh.fibonacci_sphere(500))                                # started at the sky's brightest
    assert found.cost_ratio > 0.9
    assert found.penalty > 0 and not found.explains


@pytest.mark.parametrize("model", [dict(), dict(diffuse_light="defiltered", defilter_order=2)])
def test_the_column_is_the_diffuse_rows_times_the_sun_as_sh(model):
    """Units: C @ x(E Y(d)) (the sun projected to order 10, in the model's light unknown,
    through the quadrature) matches E x the sun's column on a convex object to within the
    truncation's ringing, for the paper model and the defiltered one (whose rows carry
    1 / Phong filter at the low degrees)."""
    mesh = sphere(2)
    caster = RayCaster(mesh)
    sampling = sphere_sampling()
    reflection = reflection_model(EstimatorConfig(sh_order=10, **model))
    assert reflection.name == ("defiltered" if model else "paper")
    c_matrix = reflection.diffuse_matrix(mesh, sampling, compute_visibility(caster, sampling))
    d = _unit([0.2, 0.9, 0.4])
    through_sh = c_matrix @ reflection.unknown_from_radiance(sh.project_directional(10, d[None, :], np.array([[2.0]])))
    exact = 2.0 * sun_shading(mesh, caster, d)
    assert np.abs(through_sh[:, 0] - exact).max() < 0.03 * exact.max()


def test_through_a_coat_the_sun_loses_its_fresnel_reflection():
    mesh = sphere(2)
    caster = RayCaster(mesh)
    d = _unit([0.3, 0.8, -0.2])
    bare, coated = sun_shading(mesh, caster, d), sun_shading(mesh, caster, d, coat_ior=1.5)
    cosine = np.maximum(mesh.face_normals @ d, 0)
    np.testing.assert_allclose(coated, bare * (1 - fresnel_dielectric(cosine, 1.5)), atol=1e-12)
    facing = cosine > 0.99
    np.testing.assert_allclose(coated[facing] / bare[facing], 0.96, atol=0.002)   # ((1.5 - 1) / 2.5)^2 = 0.04
    grazing = (cosine > 0) & (cosine < 0.1)
    assert np.all(coated[grazing] < 0.6 * bare[grazing])


@pytest.mark.parametrize("coated", [False, True])
def test_find_sun_tells_a_coated_surface_from_a_bare_one(scene, coated):
    """Rendered with or without the coat's transmission, the search picks that column."""
    mesh, caster, c_matrix, albedo, sky = scene
    to_sun = _unit([0.5, 0.7, 0.3])
    radiance = albedo * (c_matrix @ sky + 3.0 * sun_shading(mesh, caster, to_sun, 1.5 if coated else None)[:, None])
    found = find_sun(radiance, c_matrix, mesh.face_adjacency, np.ones(mesh.num_faces, dtype=bool), mesh, caster,
                     sh.fibonacci_sphere(500), coat_ior=1.5)
    assert found.coat_ior == (1.5 if coated else None)
    assert found.explains
    assert np.degrees(np.arccos(np.clip(found.direction @ to_sun, -1, 1))) < 2.0


def test_a_dark_patch_shaped_like_a_sun_is_no_sun(scene):
    """No sun, but an albedo darker where a sun's column would be bright: a fit would take it
    for a sun of negative irradiance; such trials cost infinity, so none is kept."""
    mesh, caster, c_matrix, albedo, sky = scene
    column = sun_shading(mesh, caster, _unit([0.5, 0.7, 0.3]))
    radiance = 0.6 * (1 - 0.6 * column / column.max())[:, None] * (c_matrix @ sky)
    found = find_sun(radiance, c_matrix, mesh.face_adjacency, np.ones(mesh.num_faces, dtype=bool), mesh, caster,
                     sh.fibonacci_sphere(500), start=_unit([0.5, 0.7, 0.3]))
    assert not found.explains


def test_find_suns_finds_a_second_lamp_of_another_colour(scene):
    """Two suns of different colours with exact shadows beside the sky: with ``max_suns`` 3 the
    search keeps both (each within 2 degrees; the first the brighter) and no third (its BIC
    price is not paid); with the default of one it keeps one, as :func:`find_sun` does."""
    mesh, caster, c_matrix, albedo, sky = scene
    to_a, to_b = _unit([0.5, 0.7, 0.3]), _unit([-0.6, 0.3, -0.5])
    columns = sun_shadings(mesh, caster, np.array([to_a, to_b]))
    radiance = albedo * (c_matrix @ sky + columns @ np.array([[3.0, 2.5, 1.5], [0.6, 1.2, 2.0]]))
    usable = np.ones(mesh.num_faces, dtype=bool)
    args = (radiance, c_matrix, mesh.face_adjacency, usable, mesh, caster, sh.fibonacci_sphere(500))
    found = find_suns(*args, max_suns=3)
    assert found.explains and found.directions.shape == (2, 3)
    assert np.degrees(np.arccos(np.clip(found.directions @ to_a, -1, 1)))[0] < 2.0
    assert np.degrees(np.arccos(np.clip(found.directions @ to_b, -1, 1)))[1] < 2.0
    one = find_suns(*args)
    assert one.directions.shape == (1, 3)
    np.testing.assert_allclose(one.direction, find_sun(*args).direction)

