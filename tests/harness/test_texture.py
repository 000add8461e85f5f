"""export-texture: the baked textures give back the per-face albedo, the meshes load."""
import json
import os

import numpy as np
import trimesh
from PIL import Image

from estimator import uv_atlas
from harness.cli.main import main
from harness.io.exr import read_exr
from harness.io.runs import read_run
from harness.io.texture import bake, sample, srgb8
from harness.scene.geometry import icosphere

from .test_hostile_inputs import micro  # noqa: F401  (module fixture: dataset, run, report)


def test_bake_is_exact_at_face_centroids():
    mesh = icosphere(3)
    vertices, faces, uv = uv_atlas(mesh)
    np.testing.assert_array_equal(vertices[faces], mesh.vertices[mesh.faces])   # same faces, same order
    assert uv.min() >= 0 and uv.max() <= 1
    values = np.random.default_rng(0).random((mesh.num_faces, 3))
    texture, covered = bake(faces, uv, values, 512)
    centroids = uv[faces].mean(axis=1)
    np.testing.assert_array_equal(sample(texture, centroids), values.astype(np.float32))
    assert covered.mean() > 0.3 and np.isfinite(texture).all()


def test_export_texture_command(micro, tmp_path):  # noqa: F811
    ds, run, _ = micro
    out = tmp_path / "tex"
    assert main(["export-texture", str(run), "-o", str(out), "--size", "256"]) == 0
    est, _ = read_run(str(run))
    meta = json.load(open(out / "texture.json"))
    assert meta["faces"] == 80 and meta["size"] == 256 and meta["uv_source"] == "xatlas"
    glb = trimesh.load(out / "mesh.glb", force="mesh", process=False)
    assert len(glb.faces) == 80
    uv = np.asarray(glb.visual.uv)
    assert uv.min() >= 0 and uv.max() <= 1
    image = glb.visual.material.baseColorTexture
    assert image.size == (256, 256)
    # the EXR gives the linear albedo exactly, the PNG within 1/255 in sRGB, at each face centroid
    centroids = uv[np.asarray(glb.faces)].mean(axis=1)
    exr = read_exr(out / "diffuse.exr")
    assert exr.shape == (256, 256, 4)
    observed = est.observed
    np.testing.assert_allclose(sample(exr, centroids)[observed, :3], est.diffuse[observed], rtol=1e-6)
    png = np.asarray(Image.open(out / "diffuse.png"), dtype=np.float64)[..., :3]
    expected = srgb8(est.diffuse * meta["png_scale"]["diffuse"]).astype(np.float64)
    assert np.abs(sample(png, centroids)[observed] - expected[observed]).max() <= 1.0
    obj = trimesh.load(out / "mesh.obj", force="mesh", process=False)
    assert len(obj.faces) == 80
    assert os.path.isfile(out / "radiance.exr") and not os.path.exists(out / "estimate.png")
    # the OBJ's material names both maps, with factors that undo each PNG's scale
    mtl = dict(line.split(" ", 1) for line in (out / "material.mtl").read_text().splitlines()
               if line and not line.startswith("#"))
    assert mtl["map_Kd"] == "diffuse.png" and mtl["map_Ks"] == "specular.png"
    for key, name in (("Kd", "diffuse"), ("Ks", "specular")):
        np.testing.assert_allclose([float(v) for v in mtl[key].split()], 1.0 / meta["png_scale"][name], rtol=1e-5)
    assert float(mtl["Ns"]) == min(est.config.phong_exponent, 1000.0)


def test_uvs_outside_the_unit_square_are_unwrapped_not_clamped(tmp_path):
    """A mesh whose own UVs lie on a UDIM tile (u in [1, 2]) cannot share one [0, 1] texture:
    the export unwraps it instead, and every face reads its own albedo back."""
    from estimator import Estimate, EstimatorConfig, TriangleMesh
    from harness.io.texture import export_textures

    mesh = icosphere(2)
    _, _, unit = uv_atlas(mesh)                    # per corner in xatlas's vertex order
    vertices, faces, _ = uv_atlas(mesh)
    f = mesh.num_faces
    values = np.random.default_rng(1).random((f, 3))
    est = Estimate(values, np.zeros((f, 3)), np.eye(9, 3), np.arange(f), np.ones(f, bool), "t", EstimatorConfig())
    split = TriangleMesh(vertices, faces)          # vertices split along the seams: one UV per vertex
    summary = export_textures(str(tmp_path), split, est, unit + [1.0, 0.0], size=512)
    assert summary["uv_source"].startswith("xatlas")
    glb = trimesh.load(tmp_path / "mesh.glb", force="mesh", process=False)
    uv = np.asarray(glb.visual.uv)
    assert uv.min() >= 0 and uv.max() <= 1
    texture = read_exr(tmp_path / "diffuse.exr")[..., :3]
    np.testing.assert_allclose(sample(texture, uv[np.asarray(glb.faces)].mean(axis=1)), values, rtol=1e-6)


def test_unestimated_faces_are_transparent_in_the_maps_and_come_back_unestimated(tmp_path):
    """A face the estimate left unestimated is written with alpha 0 (its colour 0 is no albedo)
    in both maps, EXR and PNG, and counted in texture.json; reading the maps back
    (``import --from uv-textures``) leaves exactly those faces unestimated, in both albedos, and
    gives every other face its albedo."""
    from estimator import Estimate, EstimatorConfig
    from harness.io.imports import imported_estimate, read_uv_textures
    from harness.io.texture import export_textures

    mesh = icosphere(2)
    f = mesh.num_faces
    values = 0.1 + 0.8 * np.random.default_rng(2).random((f, 3))
    observed = np.ones(f, bool)
    observed[[3, 17, 40, 41]] = False
    est = Estimate(np.where(observed[:, None], values, 0.0), 0.5 * np.where(observed[:, None], values, 0.0),
                   np.eye(9, 3), np.where(observed, np.arange(f), -1), observed, "t", EstimatorConfig())
    summary = export_textures(str(tmp_path), mesh, est, size=512)
    assert summary["unestimated_faces"] == 4
    glb = trimesh.load(tmp_path / "mesh.glb", force="mesh", process=False)
    centroids = np.asarray(glb.visual.uv)[np.asarray(glb.faces)].mean(axis=1)
    for name in ("diffuse", "specular"):
        assert read_exr(tmp_path / f"{name}.exr")[..., 3].min() == 0.0
        np.testing.assert_array_equal(sample(read_exr(tmp_path / f"{name}.exr"), centroids)[:, 3], observed)
        png = np.asarray(Image.open(tmp_path / f"{name}.png"))
        np.testing.assert_array_equal(sample(png, centroids)[:, 3], 255 * observed)
    back = read_uv_textures(mesh, str(tmp_path / "mesh.obj"), str(tmp_path / "diffuse.exr"),
                            str(tmp_path / "specular.exr"))
    for name, scale in (("diffuse", 1.0), ("specular", 0.5)):
        np.testing.assert_array_equal(np.isnan(back[name]).any(axis=1), ~observed)
        np.testing.assert_allclose(back[name][observed], scale * values[observed], rtol=0.05)
    imported = imported_estimate(back, f, "uv-textures")      # what import writes as a run
    np.testing.assert_array_equal(imported.observed, observed)
    assert np.all(np.isfinite(imported.diffuse)) and np.all(imported.diffuse[~observed] == 0)
