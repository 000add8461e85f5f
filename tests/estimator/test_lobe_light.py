"""The light a shared Phong lobe reflects, fitted with every face's diffuse free: round trip
on synthetic rows (the light but its DC, each face's diffuse), the DC from the albedo
edges, and bad inputs."""
import numpy as np
import pytest

from estimator.core import sh
from estimator.core.errors import InputError
from estimator.light.lobe_light import dc_from_edges, fit_lobe_light
from estimator.model.reflection import diffuse_matrix, lobe_matrix, mirror_directions
from estimator.rays.visibility import Visibility, sphere_sampling

from .meshes import sphere

EXPONENT = 10.0
SPECULAR = 0.2


def _light():
    """(9, 3) radiance SH: a sky brighter above, a warm side light."""
    light = np.zeros((9, 3))
    light[0] = [2.0, 1.8, 1.5]
    light[1] = [0.5, 0.4, 0.2]
    light[2] = [0.9, 0.8, 0.6]
    light[3] = [-0.6, -0.4, -0.3]
    light[6] = [0.3, 0.2, 0.1]
    return light


def _scene(albedo, views=24):
    """A sphere of 1280 faces seen from cameras all around: rgb = t_d (C . L) + t_s (E . L)
    with the Phong lobe E of :data:`EXPONENT`, a white specular :data:`SPECULAR`, nothing
    blocking (so the lobe's DC reflects alike into every view)."""
    mesh = sphere(3)
    normals = mesh.face_normals
    cameras = sh.fibonacci_sphere(views)
    face, view = np.nonzero(normals @ cameras.T > 0.3)
    view_dir = cameras[view]
    sampling = sphere_sampling(400)
    everywhere = Visibility(np.full((mesh.num_faces, (len(sampling.directions) + 7) // 8), 255, np.uint8),
                            len(sampling.directions))
    rows = lobe_matrix(face, mirror_directions(normals[face], view_dir), sampling, everywhere, 2, EXPONENT)
    c_matrix = diffuse_matrix(mesh, sampling, everywhere, 2)
    light = _light()
    rgb = albedo(mesh)[face] * (c_matrix @ light)[face] + SPECULAR * rows @ light
    return mesh, face, rgb, rows, c_matrix, light


def _patches(mesh):
    """(F, 3) piecewise-constant albedo: four bands of latitude, a dark one among them."""
    y = mesh.vertices[mesh.faces].mean(axis=1)[:, 1]
    levels = np.array([[0.7, 0.5, 0.1], [0.05, 0.06, 0.08], [0.3, 0.6, 0.2], [0.8, 0.8, 0.8]])
    return levels[np.digitize(y, [-0.5, 0.0, 0.5])]


def test_round_trip_recovers_the_light_but_its_dc_and_the_texture():
    """A texture (any albedo per face): the light's orders above the DC come back times the
    specular albedo within 1 %, the DC stays zero, and with the true DC each face's diffuse
    radiance comes back within 1 %."""
    rng = np.random.default_rng(0)
    texture = rng.uniform(0.03, 0.8, size=(1280, 3))
    mesh, face, rgb, rows, c_matrix, light = _scene(lambda m: texture)
    fit = fit_lobe_light(face, rgb, rows, mesh.num_faces, ridge=1e-9)
    assert fit.light.shape == (9, 3) and fit.diffuse.shape == (1280, 3) and fit.rows == len(face)
    np.testing.assert_allclose(fit.light[0], 0.0)
    np.testing.assert_allclose(fit.light[1:], SPECULAR * light[1:], atol=0.01 * SPECULAR * light[0].max())
    assert np.all(fit.explained > 0.999)
    _, diffuse = fit.with_dc(SPECULAR * light[0])
    seen = np.all(np.isfinite(diffuse), axis=1)
    assert seen.mean() > 0.99
    true = (texture * (c_matrix @ light))[seen]
    np.testing.assert_allclose(diffuse[seen], true, rtol=0.01, atol=1e-4)


def test_the_dc_is_where_the_albedos_vary_least_across_edges():
    """Uniform bands: any DC but the true one makes the albedo follow the shading inside a
    band. The DC comes back within 2 %, and the albedos in the least-squares gauge within 2 %."""
    mesh, face, rgb, rows, c_matrix, light = _scene(_patches)
    fit = fit_lobe_light(face, rgb, rows, mesh.num_faces, ridge=1e-9)
    usable = np.all(np.isfinite(fit.diffuse), axis=1)
    dc = dc_from_edges(fit, c_matrix, mesh.face_adjacency, usable)
    np.testing.assert_allclose(dc, SPECULAR * light[0], rtol=0.02)
    full, diffuse = fit.with_dc(dc)
    albedo = diffuse / (c_matrix @ full)
    true = _patches(mesh)
    lit = usable & np.all(c_matrix @ light > 0.05 * (c_matrix @ light).max(axis=0), axis=1)
    scale = np.sum(albedo[lit] * true[lit], axis=0) / np.sum(albedo[lit] ** 2, axis=0)
    np.testing.assert_allclose(albedo[lit] * scale, true[lit], rtol=0.02, atol=0.002)


def test_no_lobe_explains_nothing():
    """A bare diffuse texture (no specular): the view changes are noise, the lobe explains
    almost none of them (the method's gate then refuses it)."""
    rng = np.random.default_rng(1)
    texture = rng.uniform(0.03, 0.8, size=(1280, 3))
    mesh, face, rgb, rows, c_matrix, light = _scene(lambda m: texture)
    diffuse_only = rgb - SPECULAR * rows @ light
    noisy = diffuse_only * (1 + 0.01 * rng.standard_normal(diffuse_only.shape))
    fit = fit_lobe_light(face, noisy, rows, mesh.num_faces)
    assert np.all(fit.explained < 0.2)


@pytest.mark.parametrize("case, message", [
    ("rgb", "one row per observation"), ("rows", "one row per observation"),
    ("empty", "no observation"), ("face", "must lie in"),
])
def test_bad_inputs_are_named(case, message):
    face, rgb, rows = np.array([0, 1, 1]), np.ones((3, 3)), np.ones((3, 4))
    if case == "rgb":
        rgb = np.ones((2, 3))
    elif case == "rows":
        rows = np.ones((2, 4))
    elif case == "empty":
        face, rgb, rows = face[:0], rgb[:0], rows[:0]
    elif case == "face":
        face = np.array([0, 1, 5])
    with pytest.raises(InputError, match=message):
        fit_lobe_light(face, rgb, rows, 2)
