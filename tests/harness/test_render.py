"""Rendering: analytic pixel values and the camera convention against Mitsuba."""
import os

import numpy as np
import pytest

from estimator.core.camera import Camera, look_at
from estimator.core.data import TriangleMesh
from harness.scene.geometry import icosphere
from harness.scene.illumination import Illumination
from harness.scene.render import build_scene, render_views


def _quad(z=0.0, size=1.0):
    v = np.array([[-size, -size, z], [size, -size, z], [size, size, z], [-size, size, z]], float)
    return TriangleMesh(v, np.array([[0, 1, 2], [0, 2, 3]]))


def test_rendered_pixel_matches_the_forward_model():
    mesh = _quad(size=3.0)
    td, ts, n = np.array([0.3, 0.5, 0.7]), np.array([0.4, 0.2, 0.1]), 10.0
    to_light = np.array([0.3, 0.2, 0.9])
    to_light /= np.linalg.norm(to_light)
    e = np.array([2.0, 1.5, 1.0])
    light = Illumination("directional", to_light=to_light[None], irradiance=e[None])
    cam = Camera.from_fov(look_at([-0.8, 0.3, 3.0], [0, 0, 0]), 30.0, 33, 33)
    scene = build_scene(mesh, np.tile(td, (2, 1)), np.tile(ts, (2, 1)), n, light, cam, spp=16)
    image = render_views(scene, [cam], spp=16)[0]
    # analytic value at the centre pixel (16, 16): its ray hits z = 0 at p
    o, d = cam.pixel_rays()
    k = 16 * 33 + 16
    p = o[k] + d[k] * (-o[k, 2] / d[k, 2])
    v = cam.center - p
    v /= np.linalg.norm(v)
    normal = np.array([0.0, 0.0, 1.0])
    r = 2 * (v @ normal) * normal - v
    expected = e * (td / np.pi * (to_light @ normal) + ts * (n + 1) / (2 * np.pi) * max(r @ to_light, 0) ** n)
    np.testing.assert_allclose(image[16, 16, :3], expected, rtol=5e-3)
    assert image[16, 16, 3] == pytest.approx(1.0)


def test_shadowed_point_is_black_with_the_deterministic_integrator():
    # a small quad hovering above the big one shadows it exactly below (light from +Z)
    big, small = _quad(0.0, 2.0), _quad(0.5, 0.4)
    mesh = TriangleMesh(np.vstack([big.vertices, small.vertices]), np.vstack([big.faces, small.faces + 4]))
    light = Illumination("directional", to_light=np.array([[0.0, 0.0, 1.0]]), irradiance=np.ones((1, 3)))
    cam = Camera.from_fov(look_at([0.0, -4.0, 1.5], [0, 0, 0]), 50.0, 41, 41)
    scene = build_scene(mesh, np.full((4, 3), 0.5), np.zeros((4, 3)), 10.0, light, cam, spp=1)
    image = render_views(scene, [cam], spp=1)[0]
    xy, _ = cam.project(np.array([[0.0, 0.2, 0.0], [1.5, 1.5, 0.0]]))
    shadowed = image[int(xy[0, 1]), int(xy[0, 0]), :3]
    lit = image[int(xy[1, 1]), int(xy[1, 0]), :3]
    assert np.all(shadowed < 1e-6)
    np.testing.assert_allclose(lit, 0.5 / np.pi, rtol=1e-4)


@pytest.mark.parametrize("cx,cy", [(32.0, 24.0), (27.5, 20.0)])
def test_projected_point_lands_where_mitsuba_renders_it(cx, cy):
    # a small sphere off the optical axis; its coverage centroid must be its projection
    ball = icosphere(3, 0.05)
    center = np.array([0.35, 0.25, -0.1])
    mesh = TriangleMesh(ball.vertices + center, ball.faces)
    c2w = look_at([0.4, 0.5, 2.5], [0, 0, 0])
    f = 0.5 * 64 / np.tan(np.radians(20.0))
    cam = Camera(c2w, f, f, cx, cy, 64, 48)
    light = Illumination("directional", to_light=np.array([[0.0, 0.0, 1.0]]), irradiance=np.ones((1, 3)))
    scene = build_scene(mesh, np.full((mesh.num_faces, 3), 0.5), np.zeros((mesh.num_faces, 3)), 10.0,
                        light, cam, spp=64)
    alpha = render_views(scene, [cam], spp=64)[0][..., 3]
    rows, cols = np.mgrid[0:48, 0:64] + 0.5
    centroid = np.array([(alpha * cols).sum(), (alpha * rows).sum()]) / alpha.sum()
    xy, _ = cam.project(center[None])
    np.testing.assert_allclose(centroid, xy[0], atol=0.15)


def test_diffuse_mirror_bsdf_under_a_constant_environment():
    # radiance L everywhere: a lone quad returns (t_d + t_s) L (diffuse integral + mirror)
    mesh = _quad(size=3.0)
    td, ts = np.array([0.3, 0.2, 0.1]), np.array([0.1, 0.3, 0.5])
    env = Illumination("envmap", envmap=np.full((16, 32, 3), 2.0))
    cam = Camera.from_fov(look_at([0.3, -0.4, 3.0], [0, 0, 0]), 30.0, 17, 17)
    scene = build_scene(mesh, np.tile(td, (2, 1)), np.tile(ts, (2, 1)), None, env, cam, 256, "path", max_depth=2)
    image = render_views(scene, [cam], spp=256)[0]
    np.testing.assert_allclose(image[6:11, 6:11, :3].mean(axis=(0, 1)), 2.0 * (td + ts), rtol=0.02)


STOCK_RENDER = """
import sys, numpy as np, mitsuba as mi
mi.set_variant(sys.argv[3])
np.save(sys.argv[2], np.array(mi.render(mi.load_file(sys.argv[1]), spp=int(sys.argv[4]))))
"""


def test_exported_estimate_renders_in_stock_mitsuba(tmp_path):
    """The paper model's export uses Mitsuba's own plugins only: a fresh Python that imports
    nothing of pseudolight renders it within 3 % of the forward model (measured on constant
    albedos: 0.1 % for the diffuse part, 0.1 % for the mirror part)."""
    import subprocess
    import sys

    from estimator.config import EstimatorConfig
    from estimator.model.estimate import Estimate
    from estimator.model.forward import Predictor
    from estimator.rays import backend
    from harness.scene.export import export_scene

    mesh = icosphere(3)
    f = mesh.num_faces
    rng = np.random.default_rng(0)
    h = np.zeros((121, 3))
    h[0] = 2 * np.sqrt(np.pi)                         # radiance 1, plus a tilt that stays positive
    h[1:4] = 0.8 * np.sqrt(np.pi / 3) * np.array([[0.4, 0.3, 0.2], [0.6, 0.5, 0.4], [-0.3, -0.2, 0.1]])
    est = Estimate(rng.uniform(0.1, 0.7, (f, 3)), rng.uniform(0.0, 0.3, (f, 3)), h, np.zeros(f, int),
                   np.ones(f, bool), "test", EstimatorConfig())
    cam = Camera.from_fov(look_at([0.5, 1.0, 3.5], [0, 0, 0]), 35, 32, 32)
    path = export_scene(str(tmp_path), mesh, est, cam)
    assert "stock Mitsuba plugins only" in open(path).read()
    image = tmp_path / "stock.npy"
    backend.set_variant()     # finds a libLLVM >= 16 and exports DRJIT_LIBLLVM_PATH for the child
    subprocess.run([sys.executable, "-c", STOCK_RENDER, "scene.xml", str(image), backend.resolve_variant(), "512"],
                   cwd=tmp_path, check=True, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    stock = np.load(image)
    predicted, coverage = Predictor(mesh, est).predict(cam)
    inside = (coverage > 0.999) & (stock[..., 3] > 0.999)
    np.testing.assert_allclose(stock[..., :3][inside].mean(0), predicted[inside].mean(0), rtol=0.03)


def test_sunsky_ground_truth_matches_mitsuba_on_a_white_plane():
    # a white Lambertian plane facing +Y: its radiance is (sky irradiance + sun irradiance cos) / pi
    from estimator.core import sh
    from harness.scene.illumination import sunsky_sh

    to_sun = np.array([0.5, 0.6, 0.3]) / np.linalg.norm([0.5, 0.6, 0.3])
    light = Illumination("sunsky", sunsky={"to_sun": to_sun.tolist(), "turbidity": 3.0, "ground_albedo": 0.3,
                                           "sun_scale": 1.0, "sky_scale": 1.0, "scale": 1.0})
    v = np.array([[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]], float)
    plane = TriangleMesh(v, np.array([[0, 1, 2], [0, 2, 3]]))
    assert np.allclose(plane.face_normals, [0, 1, 0])
    cam = Camera.from_fov(look_at([0.0, 3.0, 0.5], [0, 0, 0]), 20.0, 9, 9)
    scene = build_scene(plane, np.ones((2, 3)), np.zeros((2, 3)), 10.0, light, cam, 1024, "path", max_depth=2)
    pixel = render_views(scene, [cam], spp=1024)[0][3:6, 3:6, :3].mean(axis=(0, 1))
    # the same number from the ground-truth SH (order 12, clamped-cosine filter)
    coeffs = sunsky_sh(light, 12)
    l = np.arange(13)
    a = np.zeros(13)
    a[0], a[1] = np.pi, 2 * np.pi / 3
    even = l[2::2]
    from scipy.special import factorial
    a[2::2] = 2 * np.pi * (-1) ** (even // 2 - 1) / ((even + 2) * (even - 1)) * factorial(even) / (
        2.0 ** even * factorial(even // 2) ** 2)
    expected = (sh.expand_per_degree(a)[:, None] * coeffs).T @ sh.basis(12, np.array([[0.0, 1.0, 0.0]]))[0] / np.pi
    np.testing.assert_allclose(pixel, expected, rtol=0.03)
