"""Lens distortion: the models' round trip, undistortion of images, and a distorted capture
traced by Mitsuba read back as the pinhole capture."""
import json

import numpy as np
import pytest

from estimator import InputError
from harness.io.dataset import read_dataset
from harness.io.exr import read_exr
from harness.io.lens import Lens, distort, source_pixels, undistort, undistort_image
from harness.scene.generate import generate
from harness.scene.spec import SpecError, load_spec, resolve_scene

LENSES = [Lens("OPENCV", k1=-0.3, k2=0.08, p1=0.002, p2=-0.001), Lens("OPENCV", k1=0.2, k3=0.05),
          Lens("OPENCV_FISHEYE", k1=0.05, k2=-0.01, k3=0.002, k4=-0.0005)]


@pytest.mark.parametrize("lens", LENSES)
def test_undistort_inverts_distort(lens):
    x, y = np.meshgrid(np.linspace(-0.6, 0.6, 41), np.linspace(-0.5, 0.5, 31))
    xd, yd = distort(x, y, lens)
    assert np.max(np.hypot(xd - x, yd - y)) > 1e-3          # the lens does distort
    xu, yu = undistort(xd, yd, lens)
    np.testing.assert_allclose(xu, x, atol=1e-9)
    np.testing.assert_allclose(yu, y, atol=1e-9)


def test_fisheye_follows_the_equidistant_model():
    """Without coefficients a fisheye maps a ray at angle theta to radius theta (not tan theta)."""
    theta = np.radians([5.0, 30.0, 60.0])
    xd, yd = distort(np.tan(theta), np.zeros(3), Lens("OPENCV_FISHEYE"))
    np.testing.assert_allclose(xd, theta, rtol=1e-12)
    assert not Lens("OPENCV_FISHEYE").is_identity and Lens("OPENCV").is_identity


def test_undistorting_through_no_distortion_is_exact():
    image = np.random.default_rng(0).random((12, 17, 4)).astype(np.float32)
    out, inside = undistort_image(image, 20.0, 20.0, 8.5, 6.0, Lens("OPENCV"))
    np.testing.assert_allclose(out, image, atol=1e-6)
    assert inside.all()


def test_pincushion_leaves_the_corners_without_data():
    """k1 > 0 pushes the pinhole image's corners outside the recorded frame: alpha 0 there."""
    image = np.ones((40, 40, 4), np.float32)
    out, inside = undistort_image(image, 30.0, 30.0, 20.0, 20.0, Lens("OPENCV", k1=0.3))
    assert inside[20, 20] and not inside[0, 0] and not inside[-1, -1]
    assert out[0, 0, 3] == 0 and out[20, 20, 3] == pytest.approx(1.0)


@pytest.mark.parametrize("kwargs, needle", [
    ({"model": "OPENCV_FISHEYE", "p1": 0.01}, "p1 and p2 must be 0"),
    ({"k1": float("nan")}, "k1 must be a finite number"),
    ({"model": "FOO"}, "not one of OPENCV"),
])
def test_impossible_lenses_are_refused(kwargs, needle):
    with pytest.raises(InputError, match=needle):
        Lens(**kwargs)


def test_a_folding_distortion_is_refused():
    with pytest.raises(InputError, match="folds over"):
        source_pixels(Lens("OPENCV", k1=-2.0), 64, 64, 40.0, 40.0, 32.0, 32.0)


def test_the_spec_needs_a_lens_model_for_coefficients():
    with pytest.raises(SpecError, match="cameras.lens_model"):
        load_spec(resolve_scene("sparse-colored"), "tiny", {"cameras.k1": -0.1})
    with pytest.raises(SpecError, match="folds over"):
        load_spec(resolve_scene("sparse-colored"), "tiny", {"cameras.lens_model": "OPENCV", "cameras.k1": -1.0,
                                                            "cameras.fov": 100.0})


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """sparse-colored at 96 px, 36 spp: through a pinhole, and through a wide-angle lens
    whose rays Mitsuba traces (as recorded: not undistorted)."""
    root = tmp_path_factory.mktemp("lens")
    common = {"cameras.count": 4, "cameras.test_count": 0, "cameras.distance": 2.6, "render.spp": 36}
    lens = {"cameras.lens_model": "OPENCV", "cameras.k1": -0.3, "cameras.k2": 0.08, "cameras.p1": 0.002}
    for name, extra in (("pinhole", {}), ("opencv", lens)):
        generate(load_spec(resolve_scene("sparse-colored"), "tiny", {**common, **extra}), str(root / name))
    return root


def test_a_distorted_capture_reads_back_as_the_pinhole_capture(captures):
    """The undistorted silhouettes and colours match the pinhole render; the images as the
    lens recorded them do not (the object fills most of the frame, where the lens moves
    pixels by up to ~4 px)."""
    pinhole = read_dataset(captures / "pinhole").data.views
    opencv = read_dataset(captures / "opencv").data.views
    frames = json.loads((captures / "opencv" / "transforms.json").read_text())
    assert frames["camera_model"] == "OPENCV" and frames["k1"] == -0.3
    for k, (a, b) in enumerate(zip(pinhole, opencv)):
        raw = read_exr(str(captures / "opencv" / frames["frames"][k]["file_path"]))
        undistorted = np.abs(a.alpha - b.alpha).sum()
        recorded = np.abs(a.alpha - raw[..., 3]).sum()
        assert undistorted < 0.4 * recorded, (k, undistorted, recorded)
        inner = (a.alpha > 0.999) & (b.alpha > 0.999) & (raw[..., 3] > 0.999)
        level = a.rgb[inner].mean()
        assert np.abs(a.rgb[inner] - b.rgb[inner]).mean() < 0.6 * np.abs(a.rgb[inner] - raw[..., :3][inner]).mean()
        # what remains: bilinear resampling across the regions' sharp edges and 36-spp noise
        assert np.abs(a.rgb[inner] - b.rgb[inner]).mean() < 0.08 * level
