"""Reflection models: selection from the configuration, rows, light conversion, Mitsuba material."""
import numpy as np
import pytest

from estimator.config import EstimatorConfig
from estimator.core import sh
from estimator.model.reflection import diffuse_matrix, fresnel_dielectric, mirror_directions
from estimator.model.reflection_models import (
    MODELS,
    DefilteredModel,
    LobeModel,
    NoMitsubaEquivalent,
    PaperModel,
    reflection_model,
)
from estimator.rays.raycast import RayCaster
from estimator.rays.visibility import compute_visibility, sphere_sampling

from .meshes import sphere


@pytest.mark.parametrize("flags, cls", [
    ({}, PaperModel),
    ({"diffuse_light": "defiltered"}, DefilteredModel),
    ({"specular_model": "lobe"}, LobeModel),
    ({"specular_model": "lobe", "diffuse_light": "defiltered"}, LobeModel),
])
def test_configuration_selects_the_model(flags, cls):
    model = reflection_model(EstimatorConfig(sh_order=4, **flags))
    assert type(model) is cls and MODELS[model.name] is cls


def test_light_conversion_and_mitsuba_materials():
    cfg = EstimatorConfig(sh_order=4, phong_exponent=7.0)
    light = np.random.default_rng(0).standard_normal((25, 3))
    assert np.array_equal(PaperModel(cfg).pseudo_from_light(light), light)
    filt = sh.expand_per_degree(sh.phong_filter(4, 7.0))[:, None]
    np.testing.assert_allclose(LobeModel(cfg).pseudo_from_light(light), light * filt)
    assert PaperModel(cfg).mitsuba_material().kind == "diffuse_mirror"
    lobe = LobeModel(cfg).mitsuba_material()
    assert lobe.kind == "phong" and lobe.properties == {"exponent": 7.0}
    with pytest.raises(NoMitsubaEquivalent, match="defiltered"):
        DefilteredModel(cfg).mitsuba_material()
    assert LobeModel(cfg).known_light("h", "L")[0] == "L" and PaperModel(cfg).known_light("h", "L")[0] == "h"


def test_rows_of_the_three_models_agree_where_they_should():
    # an unshadowed convex sphere: the paper's and the lobe model's diffuse rows are identical,
    # the defiltered model's differ by 1 / Phong filter in degrees <= defilter_order only
    mesh = sphere(1)
    sampling = sphere_sampling(400)
    vis = compute_visibility(RayCaster(mesh), sampling)
    cfg = EstimatorConfig(sh_order=4, directions=400, diffuse_light="defiltered", defilter_order=2)
    c_paper = PaperModel(cfg).diffuse_matrix(mesh, sampling, vis)
    np.testing.assert_array_equal(LobeModel(cfg).diffuse_matrix(mesh, sampling, vis), c_paper)
    gains = DefilteredModel(cfg).diffuse_matrix(mesh, sampling, vis) / np.where(c_paper == 0, 1, c_paper)
    filt = sh.phong_filter(4, cfg.phong_exponent)
    band = sh.degrees(4)
    big = np.abs(c_paper) > 1e-9
    np.testing.assert_allclose(
        gains[big & (band[None] <= 2)], (1 / filt[band])[None].repeat(len(c_paper), 0)[big & (band[None] <= 2)]
    )
    np.testing.assert_allclose(gains[big & (band[None] > 2)], 1.0)
    # predict is the bilinear form
    faces = np.arange(5)
    view = mesh.face_normals[faces]
    d_rows = PaperModel(cfg).specular_rows(faces, mirror_directions(mesh.face_normals[faces], view), sampling, vis)
    light = np.random.default_rng(1).standard_normal((25, 3))
    td, ts = np.full((5, 3), 0.3), np.full((5, 3), 0.2)
    np.testing.assert_allclose(PaperModel.predict(td, ts, c_paper[faces] @ light, d_rows @ light),
                               td * (c_paper[faces] @ light) + ts * (d_rows @ light))
    # each model's specular shading is its rows times the light (the paper's without the rows)
    rng = np.random.default_rng(2)
    faces = rng.integers(0, mesh.num_faces, 300)
    view = rng.standard_normal((300, 3))
    mirror = mirror_directions(mesh.face_normals[faces], view / np.linalg.norm(view, axis=1, keepdims=True))
    for model in (PaperModel(cfg), DefilteredModel(cfg), LobeModel(cfg)):
        np.testing.assert_allclose(model.specular_shading(faces, mirror, sampling, vis, light),
                                   model.specular_rows(faces, mirror, sampling, vis) @ light, rtol=0, atol=1e-12)


def test_coated_diffuse_rows_weight_the_cosine_by_the_coats_transmission():
    # under a uniform light, the irradiance through a smooth coat is the bare irradiance
    # times 1 - (hemispherical average of F): 2 int_0^1 F(mu) mu dmu = 0.0918 for ior 1.5
    mesh = sphere(1)
    sampling = sphere_sampling(1164)
    vis = compute_visibility(RayCaster(mesh), sampling)
    bare = diffuse_matrix(mesh, sampling, vis, 2)
    coated = diffuse_matrix(mesh, sampling, vis, 2, coat_ior=1.5)
    mu = (np.arange(20000) + 0.5) / 20000
    expected = 1.0 - 2.0 * np.mean(fresnel_dielectric(mu, 1.5) * mu)
    np.testing.assert_allclose(coated[:, 0] / bare[:, 0], expected, rtol=0.01)
    assert 0.90 < expected < 0.92
    # the models pass the coat through (the defiltered model keeps its gains)
    cfg = EstimatorConfig(sh_order=2, directions=1164)
    np.testing.assert_array_equal(PaperModel(cfg).diffuse_matrix(mesh, sampling, vis, coat_ior=1.5), coated)


def test_every_faces_diffuse_rows_are_kept_on_the_shadow_function_read_only():
    """A pose refinement asks for the same rows once per held-out estimate and prediction: the
    first call's are kept (read-only) and returned again; another order, coat or mesh gets its own."""
    import dataclasses

    mesh = sphere(1)
    sampling = sphere_sampling(300)
    vis = compute_visibility(RayCaster(mesh), sampling)
    rows = diffuse_matrix(mesh, sampling, vis, 2)
    assert diffuse_matrix(mesh, sampling, vis, 2) is rows and not rows.flags.writeable
    np.testing.assert_allclose(rows[[3, 7]], diffuse_matrix(mesh, sampling, vis, 2, faces=np.array([3, 7])), atol=1e-15)
    assert diffuse_matrix(mesh, sampling, vis, 1).shape == (mesh.num_faces, 4)
    assert not np.array_equal(diffuse_matrix(mesh, sampling, vis, 2, coat_ior=1.5), rows)
    turned = dataclasses.replace(mesh, vertices=mesh.vertices[:, [1, 2, 0]])   # same faces, other normals
    assert not np.array_equal(diffuse_matrix(turned, sampling, vis, 2), rows)


@pytest.mark.parametrize("flags", [{}, {"diffuse_light": "defiltered"}, {"specular_model": "lobe"}])
def test_unshadowed_reflection_is_the_pseudo_illumination_at_the_mirror_direction(flags):
    """h(r) = Y(r) . pseudo(x) for every model; the pseudo models' reflection is h(r) times
    the visibility along r: with every direction visible it is h(r) itself, with none zero."""
    from estimator.rays.visibility import Visibility

    model = reflection_model(EstimatorConfig(sh_order=4, phong_exponent=7.0, **flags))
    rng = np.random.default_rng(1)
    mirror = rng.standard_normal((50, 3))
    mirror /= np.linalg.norm(mirror, axis=1, keepdims=True)
    light = rng.standard_normal((25, 3))
    unshadowed = model.unshadowed_specular_shading(mirror, light)
    np.testing.assert_allclose(unshadowed, sh.basis(4, mirror) @ model.pseudo_from_light(light), atol=1e-12)
    assert unshadowed.shape == (50, 3) and np.abs(unshadowed).max() > 0.1
    assert model.shadow_along_mirror == (not isinstance(model, LobeModel))
    if model.shadow_along_mirror:
        sampling = sphere_sampling(162)
        faces = np.zeros(50, dtype=np.int64)
        nbytes = (sampling.directions.shape[0] + 7) // 8
        seen = Visibility(np.full((1, nbytes), 255, np.uint8), sampling.directions.shape[0])
        hidden = Visibility(np.zeros((1, nbytes), np.uint8), sampling.directions.shape[0])
        np.testing.assert_allclose(model.specular_shading(faces, mirror, sampling, seen, light), unshadowed,
                                   atol=1e-12)
        np.testing.assert_allclose(model.specular_shading(faces, mirror, sampling, hidden, light), 0.0)
