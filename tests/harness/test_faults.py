"""The fault model: each fault does what it says, is seeded, recorded, and leaves the test
views clean."""
import json
import os

import numpy as np
import pytest

from estimator.core.camera import Camera, look_at
from estimator.core.data import TriangleMesh
from harness.io.dataset import read_dataset
from harness.scene import faults
from harness.scene.generate import generate
from harness.scene.spec import FaultSpec, SpecError, load_spec
from reports.metrics import srgb_decode, srgb_encode

MICRO = os.path.join(os.path.dirname(os.path.dirname(__file__)), "fixtures", "micro.toml")


def _flat(value=0.5, size=64):
    image = np.zeros((size, size, 4), np.float32)
    image[..., :3] = value
    image[..., 3] = 1.0
    return image


def test_read_noise_has_the_requested_sigma():
    rng = np.random.default_rng(0)
    noisy = faults.add_noise(_flat(0.5), read=0.1, shot=0.0, rng=rng)
    assert np.std(noisy[..., :3] - 0.5) == pytest.approx(0.05, rel=0.05)   # 0.1 x level 0.5
    np.testing.assert_array_equal(noisy[..., 3], 1.0)


def test_shot_noise_variance_grows_with_the_value():
    rng = np.random.default_rng(1)
    image = _flat(0.5)
    image[:32, :, :3] = 0.125                      # level (p99) stays 0.5
    noisy = faults.add_noise(image, read=0.0, shot=0.01, rng=rng)
    diff = noisy[..., :3] - image[..., :3]
    assert np.var(diff[32:]) == pytest.approx(0.01 * 0.5 * 0.5, rel=0.1)
    assert np.var(diff[:32]) == pytest.approx(0.01 * 0.5 * 0.125, rel=0.1)


def test_ldr_round_trip_is_within_one_step_of_255():
    values = np.linspace(0, 1, 1000, dtype=np.float32)
    image = np.ones((1, 1000, 4), np.float32)
    image[0, :, :3] = values[:, None]
    png = faults.to_ldr(image, white=1.0)
    assert np.max(np.abs(png[0, :, 0] - 255 * srgb_encode(values))) <= 0.5 + 1e-6
    np.testing.assert_allclose(srgb_encode(srgb_decode(png[0, :, 0] / 255.0)), png[0, :, 0] / 255.0, atol=1e-9)
    np.testing.assert_array_equal(png[0, :, 3], 255)


def test_pose_error_is_a_rotation_of_the_drawn_angle_and_a_shift_of_the_drawn_length():
    cam = Camera(look_at(np.array([0.0, 0.0, 4.0]), np.zeros(3)), 50.0, 50.0, 32.0, 32.0, 64, 64)
    moved, angle, shift = faults.perturb_pose(cam, 2.0, 0.01, np.zeros(3), np.random.default_rng(3))
    relative = moved.c2w[:3, :3] @ cam.c2w[:3, :3].T
    measured = np.degrees(np.arccos(np.clip((np.trace(relative) - 1) / 2, -1, 1)))
    assert measured == pytest.approx(angle, abs=1e-6)
    assert np.linalg.norm(moved.center - cam.center) == pytest.approx(shift, abs=1e-9)
    np.testing.assert_allclose(moved.c2w[:3, :3] @ moved.c2w[:3, :3].T, np.eye(3), atol=1e-12)


def test_vertex_noise_keeps_faces_and_moves_along_normals():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    mesh = TriangleMesh(v, f)
    moved = faults.displace_vertices(mesh, 0.1, np.random.default_rng(0))
    np.testing.assert_array_equal(moved.faces, f)
    step = moved.vertices - v
    normals = faults.vertex_normals(mesh)
    np.testing.assert_allclose(np.cross(step, normals), 0, atol=1e-12)


def test_patches_land_on_the_object():
    image = np.zeros((40, 40, 4), np.float32)
    image[10:30, 10:30] = [0.2, 0.2, 0.2, 1.0]
    out, (x0, y0, x1, y1) = faults.add_patch(image, 6, 0.5, False, np.random.default_rng(0))
    assert 4 <= x0 <= 30 and 4 <= y0 <= 30 and (x1 - x0, y1 - y0) == (6, 6)
    assert np.allclose(out[y0:y1, x0:x1, :3] - image[y0:y1, x0:x1, :3], 0.5)
    occluded, box = faults.add_patch(image, 4, -0.5, True, np.random.default_rng(0))
    assert np.all(occluded[box[1]:box[3], box[0]:box[2], :3] == -0.5)


def test_exposure_and_white_balance_jitter_scale_each_view_by_its_recorded_gains():
    """Auto-exposure: one log-normal gain per view (sigma 0.3) and a per-channel one on top
    (sigma 0.05); the record holds the gains applied, alpha is untouched."""
    mesh = TriangleMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    camera = Camera(look_at([0, 0, 3], [0, 0, 0]), 64, 64, 32, 32, 64, 64)
    train = [(camera, _flat(0.25)) for _ in range(200)]
    _, out, _, _, record = faults.apply_faults(FaultSpec(exposure_jitter=0.3, white_balance_jitter=0.05), 0, mesh,
                                               train, [])
    gains = np.array(record["view_gains"])
    assert gains.shape == (200, 3)
    for (_, image), gain in zip(out, gains):
        np.testing.assert_allclose(image[0, 0, :3], 0.25 * gain, rtol=1e-6)
        assert image[0, 0, 3] == 1.0
    logs = np.log(gains)
    assert abs(np.std(logs.mean(axis=1)) - 0.3) < 0.05                 # the exposure, every channel alike
    assert abs(np.std(logs - logs.mean(axis=1, keepdims=True)) - 0.05 * np.sqrt(2 / 3)) < 0.01   # white balance


def test_spec_validates_fault_keys():
    with pytest.raises(SpecError, match="faults.noise_read"):
        load_spec(MICRO, overrides={"faults.noise_read": -0.1})
    with pytest.raises(SpecError, match="faults.colour"):
        load_spec(MICRO, overrides={"faults.colour": 1})
    assert not FaultSpec().active and FaultSpec(glare_views=1).active


@pytest.fixture(scope="module")
def micro_pair(tmp_path_factory):
    root = tmp_path_factory.mktemp("faults")
    clean = str(root / "clean")
    generate(load_spec(MICRO), clean)
    setting = {"faults.noise_read": 0.05, "faults.ldr": True, "faults.pose_rotation": 1.0,
               "faults.pose_translation": 0.01, "faults.glare_views": 1, "faults.glare_size": 6,
               "faults.focal_error": 0.02, "faults.vertex_noise": 0.05}
    folders = []
    for name in ("faulty", "again"):
        generate(load_spec(MICRO, overrides=setting), str(root / name))
        folders.append(str(root / name))
    return clean, *folders


def test_generate_records_faults_and_keeps_test_views_clean(micro_pair):
    clean, faulty, again = micro_pair
    meta = json.load(open(os.path.join(faulty, "transforms.json")))
    record = meta["faults"]
    assert record["spec"]["noise_read"] == 0.05 and len(record["pose_errors"]) == 6
    assert [p["kind"] for p in record["patches"]] == ["glare"]
    assert meta["frames"][0]["file_path"].endswith(".png") and meta["frames"][0]["hdr_file_path"].endswith(".exr")
    assert meta["fl_x"] == pytest.approx(json.load(open(os.path.join(clean, "transforms.json")))["fl_x"] * 1.02)
    a, b = read_dataset(clean), read_dataset(faulty)
    np.testing.assert_array_equal(a.data.test_views[0].rgb, b.data.test_views[0].rgb)
    assert not np.allclose(a.data.views[0].rgb, b.data.views[0].rgb, atol=1e-3)
    assert not np.allclose(a.data.mesh.vertices, b.data.mesh.vertices)
    np.testing.assert_array_equal(a.data.mesh.faces, b.data.mesh.faces)
    assert b.data.views[0].rgb.max() <= 1.0 + 1e-6       # an 8-bit frame reads as [0, 1]


def test_faults_are_reproducible_from_the_seed(micro_pair):
    _, faulty, again = micro_pair
    x, y = read_dataset(faulty), read_dataset(again)
    for u, v in zip(x.data.views, y.data.views):
        np.testing.assert_array_equal(u.rgb, v.rgb)
        np.testing.assert_array_equal(u.camera.c2w, v.camera.c2w)


def test_corrupt_dataset_applies_faults_to_a_copy(micro_pair, tmp_path):
    clean, _, _ = micro_pair
    out = str(tmp_path / "corrupt")
    record = faults.corrupt_dataset(clean, out, FaultSpec(occluder_views=2, occluder_size=5, occluder_value=-0.5))
    a, b = read_dataset(clean), read_dataset(out)
    assert [p["kind"] for p in record["patches"]] == ["occluder", "occluder"]
    changed = [i for i, (u, v) in enumerate(zip(a.data.views, b.data.views)) if not np.array_equal(u.rgb, v.rgb)]
    assert sorted(changed) == sorted(p["view"] for p in record["patches"])
    np.testing.assert_array_equal(a.ground_truth.diffuse, b.ground_truth.diffuse)
    np.testing.assert_array_equal(a.data.test_views[0].rgb, b.data.test_views[0].rgb)
    assert json.load(open(os.path.join(out, "transforms.json")))["faults"]["source"] == os.path.abspath(clean)


def test_corrupt_dataset_writes_the_faulted_focal_length(micro_pair, tmp_path):
    # regression: the source's fl_x/fl_y/camera_angle_x once overrode the faulted cameras
    clean, _, _ = micro_pair
    faults.corrupt_dataset(clean, str(tmp_path / "focal"), FaultSpec(focal_error=0.03))
    a, b = read_dataset(clean), read_dataset(str(tmp_path / "focal"))
    for u, v in zip(a.data.views + a.data.test_views, b.data.views + b.data.test_views):
        assert v.camera.fx == pytest.approx(1.03 * u.camera.fx, rel=1e-9)
        assert v.camera.fy == pytest.approx(1.03 * u.camera.fy, rel=1e-9)


def test_generate_set_flag_adds_faults(tmp_path, capsys):
    from harness.cli.main import main

    out = tmp_path / "cli"
    assert main(["generate", MICRO, "-o", str(out), "--set", "faults.noise_read=0.1",
                 "--set", "faults.ldr=true"]) == 0
    record = json.load(open(out / "transforms.json"))["faults"]
    assert record["spec"]["noise_read"] == 0.1 and record["spec"]["ldr"] is True
    assert main(["generate", MICRO, "-o", str(tmp_path / "bad"), "--set", "faults.noise_read"]) == 2
    assert "--set needs KEY=VALUE" in capsys.readouterr().err


def test_more_patch_views_than_views_are_recorded_as_applied():
    cam = Camera.from_fov(look_at([0, 0, 4], [0, 0, 0]), 30, 64, 64)
    mesh = TriangleMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    spec = FaultSpec(glare_views=9, glare_size=8)
    _, out, _, _, record = faults.apply_faults(spec, 0, mesh, [(cam, _flat()) for _ in range(3)], [cam])
    assert record["spec"]["glare_views"] == 3 and record["clamped"] == {"glare_views": {"requested": 9, "applied": 3}}
    assert sorted(p["view"] for p in record["patches"]) == [0, 1, 2]


def test_decimation_keeps_about_the_asked_share_and_carries_the_truth(micro_pair, tmp_path):
    from harness.scene.geometry import icosphere

    sphere = icosphere(4)
    half = faults.decimate(sphere, 0.5)
    assert abs(half.num_faces - 0.5 * sphere.num_faces) <= 0.05 * 0.5 * sphere.num_faces
    assert np.all(np.abs(np.linalg.norm(half.vertices, axis=1) - 1.0) < 0.05)   # still the sphere's surface
    source = faults.nearest_faces(sphere, half)
    assert source.shape == (half.num_faces,) and source.max() < sphere.num_faces
    # a decimated copy of a dataset: mesh and ground truth agree face for face
    clean = micro_pair[0]
    record = faults.corrupt_dataset(clean, str(tmp_path / "d"), FaultSpec(decimate=0.5), seed=1)
    ds = read_dataset(str(tmp_path / "d"))
    assert record["decimated"]["faces_written"] == ds.data.mesh.num_faces < record["decimated"]["faces_rendered"]
    assert ds.ground_truth.diffuse.shape == (ds.data.mesh.num_faces, 3)
    assert "face_source" not in json.load(open(tmp_path / "d" / "transforms.json"))["faults"]


def test_decimation_past_what_clustering_reaches_keeps_a_mesh():
    """Asked for 2 % of 80 faces (target 4), the clustering never empties the mesh: the coarsest
    mesh it finds has at least 4 faces."""
    from harness.scene.geometry import icosphere

    small = faults.decimate(icosphere(1), 0.02)
    assert 4 <= small.num_faces < 80


def test_generate_writes_a_decimated_mesh_with_its_truth(tmp_path):
    generate(load_spec(MICRO, overrides={"faults.decimate": 0.5}), str(tmp_path / "d"))
    ds = read_dataset(str(tmp_path / "d"))
    assert ds.data.mesh.num_faces < 80 and ds.ground_truth.diffuse.shape == (ds.data.mesh.num_faces, 3)
    np.testing.assert_allclose(ds.ground_truth.diffuse, [[0.5, 0.4, 0.3]] * ds.data.mesh.num_faces)
