"""Interoperability: the NeRF-synthetic export read back frame by frame, and other tools'
results imported (per-face arrays, UV textures + envmap) and scored like any run."""
import json
import os

import numpy as np
import pytest
from PIL import Image

from harness.cli.main import main
from harness.io.dataset import read_dataset
from harness.io.runs import read_run
from reports.metrics import srgb_encode


@pytest.fixture(scope="module")
def exported(tiny_earth, tmp_path_factory):
    out = tmp_path_factory.mktemp("interop") / "nerf"
    assert main(["export", tiny_earth, "--format", "nerf-synthetic", "-o", str(out), "--size", "256"]) == 0
    return str(out)


def test_nerf_synthetic_frames_read_back(tiny_earth, exported):
    ds = read_dataset(tiny_earth)
    for split, views in (("train", ds.data.views), ("test", ds.data.test_views)):
        meta = json.load(open(os.path.join(exported, f"transforms_{split}.json")))
        assert len(meta["frames"]) == len(views)
        assert meta["camera_angle_x"] == pytest.approx(np.radians(views[0].camera.fov_x_deg))
        for frame, view in zip(meta["frames"], views):
            np.testing.assert_allclose(frame["transform_matrix"], view.camera.c2w)
            png = np.asarray(Image.open(os.path.join(exported, frame["file_path"] + ".png")))
            assert png.shape == view.rgb.shape[:2] + (4,)
            expected = 255 * srgb_encode(view.rgb / meta["exposure"])
            assert np.max(np.abs(png[..., :3] - expected)) <= 0.5 + 1e-3
            np.testing.assert_array_equal(png[..., 3] > 0, view.alpha > 0)
    assert os.path.isfile(os.path.join(exported, "ground_truth", "mesh.obj"))


def _report(run, out):
    assert main(["report", str(run), "-o", str(out), "--no-mitsuba"]) == 0
    return json.load(open(os.path.join(out, "metrics.json")))


def test_per_face_import_scores_at_ratio_one(tiny_earth, tmp_path, capsys):
    """The truth imported per face scores at ratio one, and without a warning: earth-specular's
    data are specular only (its estimator's ``components``), so a black diffuse is right."""
    ds = read_dataset(tiny_earth)
    truth = ds.ground_truth
    np.savez(tmp_path / "faces.npz", diffuse=truth.diffuse, specular=truth.specular, radiance_sh=truth.radiance_sh)
    assert main(["import", tiny_earth, "--from", "per-face", "--file", str(tmp_path / "faces.npz"),
                 "--exponent", "10", "-o", str(tmp_path / "run")]) == 0
    assert not np.any(truth.diffuse) and "warning" not in capsys.readouterr().err
    est, meta = read_run(str(tmp_path / "run"))
    assert est.method == "imported-per-face" and "faces.npz" in meta["imported_from"]
    m = _report(tmp_path / "run", tmp_path / "report")
    spec = m["albedo"]["specular"]
    assert spec["dc"]["luminance"]["median_ratio"] == pytest.approx(1.0, abs=1e-6)
    assert spec["dc"]["luminance"]["within_10"] > 0.999
    assert m["illumination"]["relative_l2"] < 1e-6


def test_csv_import_and_its_errors(tiny_earth, tmp_path, capsys):
    f = read_dataset(tiny_earth).data.mesh.num_faces
    rows = ["diffuse_r,diffuse_g,diffuse_b"] + ["0.5,0.4,0.3"] * f
    (tmp_path / "ok.csv").write_text("\n".join(rows))
    assert main(["import", tiny_earth, "--from", "per-face", "--file", str(tmp_path / "ok.csv"),
                 "-o", str(tmp_path / "run")]) == 0
    np.testing.assert_allclose(read_run(str(tmp_path / "run"))[0].diffuse, [[0.5, 0.4, 0.3]] * f)
    (tmp_path / "short.csv").write_text("\n".join(rows[:10]))
    assert main(["import", tiny_earth, "--from", "per-face", "--file", str(tmp_path / "short.csv"),
                 "-o", str(tmp_path / "r2")]) == 2
    assert f"must be ({f}, 3)" in capsys.readouterr().err and not (tmp_path / "r2").exists()
    ragged = rows[:5] + ["0.5,0.4,0.3,0.9"] + rows[6:]     # a cell more than the header: a shifted row
    (tmp_path / "ragged.csv").write_text("\n".join(ragged))
    assert main(["import", tiny_earth, "--from", "per-face", "--file", str(tmp_path / "ragged.csv"),
                 "-o", str(tmp_path / "r4")]) == 2
    assert "line 6 has more cells than the header names" in capsys.readouterr().err
    assert main(["import", tiny_earth, "--from", "uv-textures", "-o", str(tmp_path / "r3")]) == 2
    assert "needs --mesh" in capsys.readouterr().err


def test_uv_texture_round_trip_scores_at_ratio_one(tiny_earth, exported, tmp_path):
    """Ground truth baked as UV textures + envmap by the export, imported back: the
    per-face area average of the baked texture gives the albedo back."""
    gt = os.path.join(exported, "ground_truth")
    assert main(["import", tiny_earth, "--from", "uv-textures", "--mesh", os.path.join(gt, "mesh.obj"),
                 "--diffuse", os.path.join(gt, "diffuse.exr"), "--specular", os.path.join(gt, "specular.exr"),
                 "--envmap", os.path.join(gt, "radiance.exr"), "--exponent", "10", "-o", str(tmp_path / "run")]) == 0
    m = _report(tmp_path / "run", tmp_path / "report")
    lstsq = m["albedo"]["specular"]["lstsq"]["luminance"]
    assert lstsq["median_ratio"] == pytest.approx(1.0, abs=0.02) and lstsq["within_10"] > 0.95


def test_import_refuses_strings_and_broken_archives(tiny_earth, tmp_path, capsys):
    f = read_dataset(tiny_earth).data.mesh.num_faces
    np.savez(tmp_path / "str.npz", diffuse=np.array([["a", "b", "c"]] * f))
    raw = (tmp_path / "str.npz").read_bytes()
    (tmp_path / "trunc.npz").write_bytes(raw[: len(raw) // 2])
    for name, needle in (("str.npz", "must hold real numbers"), ("trunc.npz", "unreadable")):
        assert main(["import", tiny_earth, "--from", "per-face", "--file", str(tmp_path / name),
                     "-o", str(tmp_path / f"r-{name}")]) == 2
        assert needle in capsys.readouterr().err


def test_uv_textures_on_another_mesh_take_the_nearest_face(tiny_earth, exported, tmp_path):
    import trimesh

    gt = os.path.join(exported, "ground_truth")
    other = trimesh.load(os.path.join(gt, "mesh.obj"), process=False, force="mesh")
    keep = np.arange(0, len(other.faces), 2)            # another mesh: every second face
    sub = trimesh.Trimesh(other.vertices, other.faces[keep], process=False,
                          visual=trimesh.visual.TextureVisuals(uv=other.visual.uv))
    sub.export(str(tmp_path / "half.obj"))
    assert main(["import", tiny_earth, "--from", "uv-textures", "--mesh", str(tmp_path / "half.obj"),
                 "--specular", os.path.join(gt, "specular.exr"), "--diffuse", os.path.join(gt, "diffuse.exr"),
                 "-o", str(tmp_path / "run")]) == 0
    est, _ = read_run(str(tmp_path / "run"))
    truth = read_dataset(tiny_earth).ground_truth
    ratio = (est.specular @ [0.2126, 0.7152, 0.0722]) / (truth.specular @ [0.2126, 0.7152, 0.0722])
    assert np.median(ratio / np.median(ratio)) == pytest.approx(1.0, abs=0.02)


def test_uv_textures_on_a_mesh_elsewhere_are_refused(tiny_earth, exported, tmp_path, capsys):
    """A textured mesh that does not lie on the dataset's (here moved by 3 object sizes) gave
    every face one of two texels, with exit 0; now it is refused naming the mesh."""
    import trimesh

    gt = os.path.join(exported, "ground_truth")
    other = trimesh.load(os.path.join(gt, "mesh.obj"), process=False, force="mesh")
    moved = trimesh.Trimesh(other.vertices + [6.0, 0.0, 0.0], other.faces, process=False,
                            visual=trimesh.visual.TextureVisuals(uv=other.visual.uv))
    moved.export(str(tmp_path / "moved.obj"))
    assert main(["import", tiny_earth, "--from", "uv-textures", "--mesh", str(tmp_path / "moved.obj"),
                 "--diffuse", os.path.join(gt, "diffuse.exr"), "-o", str(tmp_path / "run")]) == 2
    assert "does not lie on the dataset's mesh" in capsys.readouterr().err and not (tmp_path / "run").exists()


STOCK_RENDER = """
import sys, numpy as np, mitsuba as mi
mi.set_variant(sys.argv[3])
np.save(sys.argv[2], np.array(mi.render(mi.load_file(sys.argv[1]), spp=int(sys.argv[4]))))
"""


@pytest.fixture(scope="module")
def stock_export(tmp_path_factory):
    """A tiny real-light (plastic, envmap) dataset and its --format mitsuba export."""
    from harness.scene.generate import generate
    from harness.scene.spec import load_spec, resolve_scene

    root = tmp_path_factory.mktemp("stock")
    folder, out = root / "rl", root / "mitsuba"
    generate(load_spec(resolve_scene("real-light"), "tiny", {"material.model": "plastic"}), str(folder))
    assert main(["export", str(folder), "--format", "mitsuba", "-o", str(out)]) == 0
    return folder, out


def test_mitsuba_export_renders_the_dataset_in_stock_mitsuba(stock_export, tmp_path):
    """Every frame's scene XML has the frame's camera; a fresh Python with only Mitsuba
    renders a frame to the dataset's image (measured: means within 0.2 %, 99.9 % of the
    silhouette pixels agree)."""
    import subprocess
    import sys
    import xml.etree.ElementTree as ET

    from estimator.core.camera import gl_to_mitsuba

    folder, out = stock_export
    ds = read_dataset(str(folder))
    frames = [("train", k, v) for k, v in enumerate(ds.data.views)] + [
        ("test", k, v) for k, v in enumerate(ds.data.test_views)
    ]
    assert sorted(p for p in os.listdir(out) if p.endswith(".xml")) == sorted(f"{s}_{k:03d}.xml" for s, k, _ in frames)
    for split, k, view in frames:
        sensor = ET.parse(out / f"{split}_{k:03d}.xml").getroot().find("sensor")
        matrix = np.array(sensor.find("transform/matrix").get("value").split(), float).reshape(4, 4)
        np.testing.assert_allclose(matrix, gl_to_mitsuba(view.camera.c2w), atol=1e-7)
        assert int(sensor.find("film/integer[@name='width']").get("value")) == view.camera.width
    image = tmp_path / "stock.npy"
    variant = ds.meta["variant"]      # generate() set it, and DRJIT_LIBLLVM_PATH for the child
    subprocess.run([sys.executable, "-c", STOCK_RENDER, "train_000.xml", str(image), variant, "128"], cwd=out,
                   check=True, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    stock, view = np.load(image), ds.data.views[0]
    both = (view.alpha > 0.999) & (stock[..., 3] > 0.999)
    assert np.mean((view.alpha > 0.5) == (stock[..., 3] > 0.5)) > 0.99
    np.testing.assert_allclose(stock[..., :3][both].mean(0), view.rgb[both].mean(0), rtol=0.02)


def test_mitsuba_xml_import_round_trip(stock_export, tmp_path, capsys):
    """The exported frame XML imported back: the true albedos exactly (nearest-filtered atlas
    on a PLY; the plastic's specular its coat's Fresnel reflectance at normal incidence, as the
    ground truth records it), the true light (its envmap turned by to_world) and the true
    regions (faces of one albedo are one group), without a warning."""
    folder, out = stock_export
    assert main(["import", str(folder), "--from", "mitsuba-xml", "--file", str(out / "test_000.xml"),
                 "-o", str(tmp_path / "run")]) == 0
    assert "warning" not in capsys.readouterr().err
    m = _report(tmp_path / "run", tmp_path / "report")
    for part in ("diffuse", "specular"):
        scores = m["albedo"][part]["lstsq"]["luminance"]
        assert scores["median_ratio"] == pytest.approx(1.0, abs=1e-6) and scores["within_5"] == 1.0
    assert m["illumination"]["relative_l2"] < 1e-6
    assert m["clusters"]["ari"] == pytest.approx(1.0)


def test_estimate_export_imports_back(stock_export, tmp_path):
    """The estimate's stock export (blendbsdf of diffuse and mirror, albedos x 2 at weight
    1/2) read by the XML import gives the estimate's albedos back."""
    from estimator.config import EstimatorConfig
    from estimator.model.estimate import Estimate
    from harness.io.imports import read_mitsuba_xml
    from harness.scene.export import export_scene

    mesh = read_dataset(str(stock_export[0]), load_truth=False).data.mesh
    f = mesh.num_faces
    rng = np.random.default_rng(4)
    h = np.zeros((121, 3))
    h[0] = 1.0
    est = Estimate(rng.uniform(0.05, 0.9, (f, 3)), rng.uniform(0.0, 0.4, (f, 3)), h, np.zeros(f, int),
                   np.ones(f, bool), "test", EstimatorConfig())
    arrays = read_mitsuba_xml(mesh, export_scene(str(tmp_path), mesh, est))
    np.testing.assert_allclose(arrays["diffuse"], est.diffuse, rtol=1e-6)
    np.testing.assert_allclose(arrays["specular"], est.specular, rtol=1e-6)


def test_mitsuba_export_reads_the_envmap_it_copies(stock_export, tmp_path, capsys):
    """A truncated ground-truth envmap is named, not copied into an export that Mitsuba cannot
    load; nothing is left behind."""
    import shutil

    folder, _ = stock_export
    broken = tmp_path / "rl"
    shutil.copytree(folder, broken)
    envmap = broken / "ground_truth" / "envmap.exr"
    envmap.write_bytes(envmap.read_bytes()[:3000])
    assert main(["export", str(broken), "--format", "mitsuba", "-o", str(tmp_path / "m")]) == 2
    assert "envmap.exr" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()
    import mitsuba as mi

    image = np.full((8, 16, 3), 0.5, np.float32)
    image[2, 3, 1] = np.nan
    mi.Bitmap(image).write(str(envmap))
    assert main(["export", str(broken), "--format", "mitsuba", "-o", str(tmp_path / "m")]) == 2
    assert "envmap.exr: the envmap holds NaN or Inf" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


def test_mitsuba_export_refuses_a_phong_dataset(tiny_earth, tmp_path, capsys):
    assert main(["export", tiny_earth, "--format", "mitsuba", "-o", str(tmp_path / "m")]) == 2
    assert "stock Mitsuba 3 has no such BSDF" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


@pytest.mark.parametrize("text, needle", [
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='x.ply'/></shape></scene>",
     "no <shape type='ply'|'obj'> with a BSDF"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/>"
     "<bsdf type='dielectric'/></shape></scene>", "BSDF type 'dielectric' is not read"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/>"
     "<bsdf type='plastic'><string name='int_ior' value='bk7'/></bsdf></shape></scene>",
     "plastic.int_ior is a material name; give it as a <float>"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/>"
     "<bsdf type='roughplastic'><float name='int_ior' value='1.0'/></bsdf></shape></scene>",
     "roughplastic needs int_ior and ext_ior > 0 and unequal"),
    ("<sensor/>", "not a Mitsuba <scene>"),
    ("<scene", "not a readable XML file"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/>"
     "<bsdf type='blendbsdf'><float name='weight' value='abc'/><bsdf type='diffuse'/><bsdf type='diffuse'/></bsdf>"
     "</shape></scene>", "<float name='weight'> must hold 1 finite numbers"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/><bsdf type='diffuse'/>"
     "</shape><emitter type='envmap'><string name='filename' value='env.exr'/><float name='scale' value='abc'/>"
     "</emitter></scene>", "<float name='scale'> must hold 1 finite numbers"),
    ("<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/><bsdf type='diffuse'/>"
     "</shape><emitter type='envmap'><string name='filename' value='env.exr'/><float name='scale' value='1e308'/>"
     "</emitter></scene>", "scale'> of the envmap must lie in [0, 1e+12]"),
])
def test_mitsuba_xml_import_errors(stock_export, tmp_path, capsys, text, needle):
    import shutil

    from harness.io.exr import write_exr

    folder, out = stock_export
    shutil.copy(out / "object.ply", tmp_path / "object.ply")
    write_exr(tmp_path / "env.exr", np.ones((8, 16, 3), np.float32))
    (tmp_path / "scene.xml").write_text(text)
    assert main(["import", str(folder), "--from", "mitsuba-xml", "--file", str(tmp_path / "scene.xml"),
                 "-o", str(tmp_path / "run")]) == 2
    assert needle in capsys.readouterr().err and not (tmp_path / "run").exists()


def test_import_never_overwrites_the_files_its_xml_names(stock_export, tmp_path, capsys):
    """``import --from mitsuba-xml -o X --overwrite`` where X holds the mesh, textures and envmap
    the XML names: they are inputs, so the output is refused and X stays as it was."""
    import re
    import shutil

    _, out = stock_export
    target = tmp_path / "export"
    shutil.copytree(out, target)                      # a folder pseudolight wrote (it has the marker)
    xml = (out / "test_000.xml").read_text()
    (tmp_path / "scene.xml").write_text(re.sub(r"name=\"filename\" value=\"", 'name="filename" value="export/', xml))
    before = sorted(p.name for p in target.iterdir())
    assert main(["import", str(stock_export[0]), "--from", "mitsuba-xml", "--file", str(tmp_path / "scene.xml"),
                 "-o", str(target), "--overwrite"]) == 2
    assert "Traceback" not in capsys.readouterr().err
    assert sorted(p.name for p in target.iterdir()) == before
