import json
import os

import numpy as np
import OpenEXR
import pytest

import harness.scene.generate as generate_module
from estimator.core.camera import Camera, look_at
from estimator.core.data import TriangleMesh
from harness.io.atomic import OutputExistsError, atomic_directory
from harness.io.dataset import DatasetError, read_dataset, write_dataset, write_ground_truth
from harness.io.exr import read_exr, write_exr
from harness.scene.generate import generate
from harness.scene.spec import load_spec, resolve_scene
from reports.ground_truth import GroundTruth


def test_exr_round_trip(tmp_path):
    image = np.random.default_rng(0).random((5, 7, 4)).astype(np.float32) * 100
    write_exr(tmp_path / "a.exr", image)
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr"), image)
    write_exr(tmp_path / "b.exr", image[..., :3], half=True)
    np.testing.assert_allclose(read_exr(tmp_path / "b.exr"), image[..., :3], rtol=1e-3)
    with pytest.raises(ValueError, match="NaN"):
        write_exr(tmp_path / "c.exr", np.full((2, 2, 3), np.nan))
    (tmp_path / "d.exr").write_bytes(b"not an exr")
    with pytest.raises(ValueError, match="cannot read EXR"):
        read_exr(tmp_path / "d.exr")


def test_a_truncated_exr_is_one_error_and_the_library_prints_nothing(tmp_path, capfd):
    """OpenEXR prints its own lines (to the process's stdout and stderr) on a corrupt file
    before it raises: they are held, and the first of them joins the one error."""
    write_exr(tmp_path / "a.exr", np.ones((64, 64, 3), np.float32))
    data = (tmp_path / "a.exr").read_bytes()
    (tmp_path / "t.exr").write_bytes(data[: int(len(data) * 0.9)])   # the header whole, the pixels cut
    capfd.readouterr()
    with pytest.raises(ValueError, match=r"cannot read EXR file .*t\.exr \(truncated or not an EXR\?\).*OpenEXR: "):
        read_exr(tmp_path / "t.exr")
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr"), 1.0)   # the streams are back: a good file reads
    print("after")
    assert capfd.readouterr().out == "after\n"


def _toy(tmp_path):
    rng = np.random.default_rng(1)
    v = rng.normal(size=(30, 3))
    f = rng.integers(0, 30, size=(40, 3))  # arbitrary order, even degenerate faces: kept as is
    mesh = TriangleMesh(v, f)
    cams = [Camera.from_fov(look_at(p, [0, 0, 0]), 40, 8, 6) for p in ([0, 0, 5], [5, 0, 0], [0, 5, 1])]
    images = [rng.random((6, 8, 4)).astype(np.float32) for _ in cams]
    return mesh, cams, images


def test_dataset_round_trip_keeps_face_order_and_cameras(tmp_path):
    mesh, cams, images = _toy(tmp_path)
    write_dataset(str(tmp_path), mesh, list(zip(cams[:2], images[:2])), [(cams[2], images[2])], {"scene": "toy"})
    rng = np.random.default_rng(0)
    truth = GroundTruth(rng.random((40, 3)), rng.random((40, 3)), rng.random((121, 3)),
                        {"model": "phong", "exponent": 10.0}, {"kind": "directional", "lights": []},
                        np.arange(40) % 3)
    write_ground_truth(str(tmp_path), truth)
    ds = read_dataset(tmp_path)
    np.testing.assert_array_equal(ds.data.mesh.faces, mesh.faces)
    np.testing.assert_allclose(ds.data.mesh.vertices, mesh.vertices, rtol=1e-6)
    assert len(ds.data.views) == 2 and len(ds.data.test_views) == 1
    for view, cam, image in zip(ds.data.views + ds.data.test_views, cams, images):
        np.testing.assert_allclose(view.camera.c2w, cam.c2w, atol=1e-12)
        assert (view.camera.fx, view.camera.cx, view.camera.width) == (cam.fx, cam.cx, cam.width)
        np.testing.assert_array_equal(view.rgb, image[..., :3])
        np.testing.assert_array_equal(view.alpha, image[..., 3])
    np.testing.assert_array_equal(ds.ground_truth.diffuse, truth.diffuse)
    np.testing.assert_array_equal(ds.ground_truth.regions, truth.regions)
    assert ds.ground_truth.sh_order == 10 and ds.meta["scene"] == "toy"
    t = json.load(open(tmp_path / "transforms.json"))
    assert t["world_up"] == [0.0, 1.0, 0.0] and t["color_space"] == "linear_rec709"
    assert "camera_angle_x" in t and t["frames"][0]["file_path"].startswith("images/")


def test_reader_errors_name_the_problem(tmp_path):
    mesh, cams, images = _toy(tmp_path)
    with pytest.raises(DatasetError, match="not found"):
        read_dataset(tmp_path / "missing")
    with pytest.raises(DatasetError, match="transforms.json"):
        read_dataset(tmp_path)
    write_dataset(str(tmp_path), mesh, list(zip(cams, images)), [])
    t = json.load(open(tmp_path / "transforms.json"))
    json.dump({**t, "w": 9}, open(tmp_path / "transforms.json", "w"))
    with pytest.raises(DatasetError, match="intrinsics say 9x6"):
        read_dataset(tmp_path)
    json.dump({**t, "frames": []}, open(tmp_path / "transforms.json", "w"))
    with pytest.raises(DatasetError, match="no frames"):
        read_dataset(tmp_path)
    json.dump(t, open(tmp_path / "transforms.json", "w"))
    bad = images[1].copy()
    bad[2, 3, 1] = np.nan
    with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"RGBA": bad}) as f:
        f.write(str(tmp_path / "images" / "train_001.exr"))
    with pytest.raises(DatasetError, match="NaN"):
        read_dataset(tmp_path)
    os.remove(tmp_path / "mesh.ply")
    with pytest.raises(DatasetError, match="no mesh"):
        read_dataset(tmp_path)


def test_atomic_directory(tmp_path):
    target = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with atomic_directory(target) as tmp:
            open(os.path.join(tmp, "x"), "w").write("half")
            raise RuntimeError("boom")
    assert not target.exists() and os.listdir(tmp_path) == []
    with atomic_directory(target) as tmp:
        open(os.path.join(tmp, "x"), "w").write("one")
    with pytest.raises(OutputExistsError, match="--overwrite"):
        with atomic_directory(target):
            pass
    with atomic_directory(target, overwrite=True) as tmp:
        open(os.path.join(tmp, "x"), "w").write("two")
    assert open(target / "x").read() == "two" and sorted(os.listdir(tmp_path)) == ["out"]


def test_interrupted_generation_leaves_no_dataset(tmp_path, monkeypatch):
    spec = load_spec(resolve_scene("earth-specular"), profile="tiny", overrides={"cameras.count": 4})
    calls = []

    def interrupted(scene, cameras, spp, seed=0, desc=""):
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(generate_module, "render_views", interrupted)
    with pytest.raises(KeyboardInterrupt):
        generate(spec, str(tmp_path / "ds"))
    assert calls and os.listdir(tmp_path) == []


def test_generated_tiny_dataset_is_complete(tiny_earth):
    ds = read_dataset(tiny_earth)
    assert ds.meta["scene"] == "earth-specular" and len(ds.data.views) == 16 and len(ds.data.test_views) == 2
    gt = ds.ground_truth
    assert gt.brdf == {"model": "phong", "exponent": 10.0}
    assert np.all(gt.diffuse == 0) and gt.specular.shape == (1280, 3) and gt.specular.max() > 0.2
    assert gt.sh_order >= 10 and len(gt.illumination["lights"]) == 40
    coverage = np.mean([v.alpha.mean() for v in ds.data.views])
    assert 0.2 < coverage < 0.8


def test_16_bit_png_frames_keep_their_depth(tmp_path):
    """16-bit PNG frames are read as 16-bit (Pillow's conversion turned grey ones into 0/1 masks
    and RGB ones into 8 bits), sRGB-decoded as 8-bit ones are."""
    import mitsuba as mi

    from estimator import backend
    from harness.io.dataset import read_frame_image
    from reports.metrics import srgb_decode

    backend.set_variant()
    ramp = np.linspace(0, 65535, 32 * 32 * 3).reshape(32, 32, 3).astype(np.uint16)
    mi.Bitmap(ramp, pixel_format=mi.Bitmap.PixelFormat.RGB).write(str(tmp_path / "rgb16.png"))
    mi.Bitmap(ramp[..., 0], pixel_format=mi.Bitmap.PixelFormat.Y).write(str(tmp_path / "grey16.png"))
    rgb = read_frame_image(str(tmp_path / "rgb16.png"))
    grey = read_frame_image(str(tmp_path / "grey16.png"))
    np.testing.assert_allclose(rgb, srgb_decode(ramp / 65535.0), atol=1e-5)
    np.testing.assert_allclose(grey[..., 0], srgb_decode(ramp[..., 0] / 65535.0), atol=1e-5)
    assert len(np.unique(rgb)) > 2000          # not 256 levels, not a mask
