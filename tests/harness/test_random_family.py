"""The seeded random scene family: deterministic draws that cover every kind, valid specs,
its new spec features (spherical lights, table-top cameras, patterns, mixed materials), and
three seeds rendered and estimated end to end at the tiny size."""
from __future__ import annotations

import numpy as np
import pytest

from estimator import estimate, latlong, sh
from harness.io.dataset import read_dataset
from harness.io.runs import estimator_settings
from harness.scene.generate import generate, prepare
from harness.scene.illumination import spheres_sh
from harness.scene.random_family import ALBEDOS, CAMERAS, GEOMETRIES, LIGHTS, MATERIALS, draw, random_spec
from harness.scene.render import camera_positions


def test_a_seed_draws_the_same_scene_and_the_family_covers_every_kind():
    assert draw(7) == draw(7) and draw(7) != draw(8)
    seen = {k: {draw(s)[1][k] for s in range(200)} for k in ("light", "material", "albedo", "geometry", "cameras")}
    assert seen == {"light": set(LIGHTS), "material": set(MATERIALS), "albedo": set(ALBEDOS),
                    "geometry": set(GEOMETRIES), "cameras": set(CAMERAS)}


@pytest.mark.parametrize("seed", range(0, 100, 7))
def test_drawn_specs_validate(seed):
    spec = random_spec(seed)
    strata = draw(seed)[1]
    assert spec.name == f"random-{seed:04d}" and 12 <= spec.cameras.count <= 40
    assert spec.material.mixed == (strata["material"] == "mixed")


def test_spherical_lights_have_the_sh_of_their_cones():
    """The closed-form SH of spherical lights on an ambient environment against quadrature of
    the radiance map they make (a sphere near the horizon, where the lat-long grid is fine)."""
    spheres = {"positions": [[6.0, 0.5, 1.0], [-2.0, 3.0, -5.0]], "radii": [0.8, 1.0],
               "radiance": [[5.0, 4.0, 3.0], [1.0, 2.0, 6.0]], "ambient": [0.05, 0.05, 0.05]}
    dirs = latlong.directions(1024, 2048)
    image = np.broadcast_to(np.asarray(spheres["ambient"]), (*dirs.shape[:2], 3)).copy()
    for p, r, e in zip(spheres["positions"], spheres["radii"], spheres["radiance"]):
        d = np.asarray(p) / np.linalg.norm(p)
        image[dirs @ d >= np.sqrt(1 - (r / np.linalg.norm(p)) ** 2)] = e
    quadrature = sh.project_latlong(6, image)
    exact = spheres_sh(spheres, 6, np.zeros(3))
    assert np.linalg.norm(exact - quadrature) / np.linalg.norm(exact) < 0.01


def test_table_top_cameras_stay_in_their_band_of_elevations():
    spec = random_spec(1000).cameras
    for test in (False, True):
        elevation = np.degrees(np.arcsin(camera_positions(spec, test)[:, 1] / spec.distance))
        assert np.all(elevation >= spec.min_elevation - 1e-9) and np.all(elevation <= spec.max_elevation + 1e-9)


def test_mixed_materials_keep_each_regions_own_brdf():
    scene = prepare(random_spec(1003))          # mixed materials on the teapot
    truth = scene.ground_truth()
    assert truth.brdf["model"] == "mixed"
    labels = np.asarray(truth.brdf["labels"])
    np.testing.assert_array_equal(labels, scene.regions)
    for k, part in enumerate(truth.brdf["parts"]):
        specular = truth.specular[labels == k]
        if part["model"] == "diffuse":
            assert np.all(specular == 0)
        elif part["model"] in ("plastic", "roughplastic"):
            np.testing.assert_allclose(specular, ((part["int_ior"] - 1) / (part["int_ior"] + 1)) ** 2)


@pytest.mark.parametrize("seed", [1001, 1003, 1005])   # table-top teapot; mixed teapot; bumpy blob of regions
def test_three_seeds_render_and_estimate_at_tiny_size(tmp_path, seed):
    folder = tmp_path / f"random-{seed}"
    summary = generate(random_spec(seed, "tiny"), str(folder))
    ds = read_dataset(str(folder))
    assert len(ds.data.views) == summary["views"]
    assert ds.ground_truth.diffuse.shape == (ds.data.mesh.num_faces, 3)
    assert all(np.all(np.isfinite(v.rgb)) and v.rgb.max() > 0 for v in ds.data.views)
    method, config = estimator_settings(ds.meta)
    est = estimate(ds.data, method, config)
    kept = est.diffuse[est.observed]
    assert est.observed.any() and np.all(np.isfinite(kept))
    level = np.median(kept[kept.sum(axis=1) > 0] @ [0.2126, 0.7152, 0.0722])
    assert np.all(kept.max(axis=1) <= 100 * level)          # no absurd albedo is written
