import numpy as np
import pytest

from estimator.core import camera


def test_conversions_round_trip():
    c2w = camera.look_at([1.0, 2.0, 3.0], [0.0, 0.2, 0.0])
    np.testing.assert_allclose(camera.mitsuba_to_gl(camera.gl_to_mitsuba(c2w)), c2w, atol=1e-12)
    np.testing.assert_allclose(camera.opencv_to_gl(camera.gl_to_opencv(c2w)), c2w, atol=1e-12)
    # OpenGL looks down -Z; OpenCV down +Z; Mitsuba down +Z with +X left.
    forward = np.array([0.0, 0.2, 0.0]) - [1.0, 2.0, 3.0]
    forward /= np.linalg.norm(forward)
    np.testing.assert_allclose(-c2w[:3, 2], forward, atol=1e-12)
    np.testing.assert_allclose(camera.gl_to_opencv(c2w)[:3, 2], forward, atol=1e-12)
    np.testing.assert_allclose(camera.gl_to_mitsuba(c2w)[:3, 2], forward, atol=1e-12)
    np.testing.assert_allclose(camera.gl_to_mitsuba(c2w)[:3, 0], -c2w[:3, 0], atol=1e-12)


def test_look_at_keeps_world_up_and_handles_poles():
    c2w = camera.look_at([0, 0, 5], [0, 0, 0])
    np.testing.assert_allclose(c2w[:3, 1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(c2w[:3, 0], [1, 0, 0], atol=1e-12)
    top = camera.look_at([0, 5, 0], [0, 0, 0])
    assert np.all(np.isfinite(top)) and abs(np.linalg.det(top[:3, :3]) - 1) < 1e-12


def test_pixel_rays_and_projection_are_inverse():
    cam = camera.Camera(camera.look_at([0.5, 1.0, 4.0], [0, 0, 0]), 70.0, 75.0, 30.5, 22.0, 64, 48)
    o, d = cam.pixel_rays()
    pts = o + 3.0 * d
    xy, depth = cam.project(pts)
    cols, rows = np.meshgrid(np.arange(64) + 0.5, np.arange(48) + 0.5)
    np.testing.assert_allclose(xy, np.stack([cols.ravel(), rows.ravel()], 1), atol=1e-9)
    assert np.all(depth > 0)
    # a point up and to the right of the optical axis lands top-right of the principal point
    xy, _ = cam.project(cam.center + (-cam.c2w[:3, 2] + 0.1 * cam.c2w[:3, 0] + 0.1 * cam.c2w[:3, 1])[None])
    assert xy[0, 0] > cam.cx and xy[0, 1] < cam.cy


def test_pixel_directions_are_the_pixel_rays_per_axis():
    cam = camera.Camera(camera.look_at([0.5, 1.0, 4.0], [0, 0, 0]), 70.0, 75.0, 30.5, 22.0, 64, 48)
    d = cam.pixel_directions()
    assert d.shape == (3, 64 * 48)
    # the OpenGL camera's ray through pixel centre (col, row), turned to the world by c2w
    cols, rows = np.meshgrid(np.arange(64) + 0.5, np.arange(48) + 0.5)
    local = np.stack([(cols - 30.5) / 70.0, -(rows - 22.0) / 75.0, -np.ones_like(cols)]).reshape(3, -1)
    world = cam.c2w[:3, :3] @ local
    np.testing.assert_allclose(d, world / np.linalg.norm(world, axis=0), atol=1e-15)
    np.testing.assert_array_equal(d.T, cam.pixel_rays()[1])
    # one sub-pixel sample is the pixel centre: the rays of chosen pixels alone (what the pose
    # refinement and the predicted images take, for the pixels on the mesh)
    pixels = np.array([0, 5, 64 * 47 + 63, 1000])
    np.testing.assert_allclose(cam.subpixel_directions(pixels, 1), d[:, pixels], atol=1e-15)


def test_a_rigid_transform_is_checked_to_numpy_allclose_tolerances():
    """The camera's rigid-transform check has np.allclose's tolerances written out: a bottom
    row within 1e-8 + 1e-5 of (0, 0, 0, 1) and a rotation orthonormal to 1e-3 pass, just
    beyond them fail, and a reflection fails."""
    def make(bottom: float, scale: float, flip: float = 1.0):
        c2w = camera.look_at([0.5, 1.0, 4.0], [0, 0, 0])
        c2w[:3, :3] *= scale
        c2w[:3, 0] *= flip
        c2w[3, 3] = bottom
        return camera.Camera(c2w, 70.0, 70.0, 32.0, 24.0, 64, 48)

    make(1.0 + 0.99e-5, 1.0 + 4.9e-4)   # R^T R = (1 + 4.9e-4)^2 I: within 1e-3 + 1e-5
    for bottom, scale, flip in ((1.0 + 1.01e-5, 1.0, 1.0), (1.0, 1.0 + 5.1e-4, 1.0), (1.0, 1.0, -1.0)):
        with pytest.raises(ValueError, match="rigid"):
            make(bottom, scale, flip)


def test_bad_cameras_are_refused():
    with pytest.raises(ValueError, match="4x4"):
        camera.Camera(np.eye(3), 1, 1, 0, 0, 4, 4)
    with pytest.raises(ValueError, match="focal"):
        camera.Camera(np.eye(4), -1, 1, 0, 0, 4, 4)
    with pytest.raises(ValueError, match="fov"):
        camera.Camera.from_fov(np.eye(4), 190, 4, 4)


@pytest.mark.parametrize("spp", [1, 2, 3, 5, 16, 32, 50, 64, 100, 256, 512])
def test_multijitter_count_is_taken_as_it_is(spp):
    """Mitsuba's multijitter sampler keeps the count we give (it rounds any other up, with a
    console warning: 32 became 35), and that count covers the one asked for."""
    from estimator.rays import backend

    mi = backend.set_variant()
    count = camera.multijitter_count(spp)
    assert spp <= count < spp + 2 * np.sqrt(spp) + 1
    assert mi.load_dict({"type": "multijitter", "sample_count": count}).sample_count() == count
