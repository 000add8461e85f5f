"""Every failure the hostile-input run found, reproduced: exit code, one line naming the
file, key or flag, no output left behind, and no input changed.

Each case runs the real command line on the micro scene (80 faces, 6 views of 24x24).
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from harness.cli.main import main
from harness.io.atomic import MARKER

MICRO = os.path.join(os.path.dirname(os.path.dirname(__file__)), "fixtures", "micro.toml")


def snapshot(*paths) -> dict:
    """{path: sha256} of every file under the given files and folders."""
    out = {}
    for root in paths:
        root = str(root)
        if os.path.isfile(root):
            out[root] = hashlib.sha256(open(root, "rb").read()).hexdigest()
            continue
        for folder, _, files in os.walk(root):
            for name in files:
                path = os.path.join(folder, name)
                out[path] = hashlib.sha256(open(path, "rb").read()).hexdigest()
    return out


def expect_error(capsys, argv, *needles, inputs=(), absent=(), code=2):
    """Run the CLI; assert the exit code, exactly one error line holding every needle,
    no traceback, no temporary-folder name, unchanged inputs and absent outputs."""
    before = snapshot(*inputs)
    assert main([str(a) for a in argv]) == code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("pseudolight")]
    assert len(lines) == 1, err
    assert "Traceback" not in err and "-partial-" not in lines[0], err
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert snapshot(*inputs) == before
    for path in absent:
        assert not os.path.exists(path), path
    return lines[0]


@pytest.fixture(scope="module")
def micro(tmp_path_factory):
    """A micro dataset, a run of it and a report of the run (no Mitsuba cross-check)."""
    root = tmp_path_factory.mktemp("micro")
    ds, run, rep = root / "dataset", root / "run", root / "report"
    assert main(["generate", MICRO, "-o", str(ds)]) == 0
    assert main(["estimate", str(ds), "-o", str(run)]) == 0
    assert main(["report", str(run), "-o", str(rep), "--no-mitsuba"]) == 0
    return ds, run, rep


@pytest.fixture
def copy(micro, tmp_path):
    """A fresh copy of the micro dataset, run and report for a case that mutates them."""
    ds, run, rep = (tmp_path / name for name in ("dataset", "run", "report"))
    for src, dst in zip(micro, (ds, run, rep)):
        shutil.copytree(src, dst)
    meta = json.load(open(run / "run.json"))
    meta["dataset"] = str(ds)
    json.dump(meta, open(run / "run.json", "w"))
    return ds, run, rep


# ---------------------------------------------------------------- data loss

def test_overwrite_never_destroys_an_input(copy, tmp_path, capsys):
    ds, run, rep = copy
    expect_error(capsys, ["estimate", ds, "-o", ds, "--overwrite"], "is the input", str(ds), inputs=[ds])
    expect_error(capsys, ["estimate", ds, "-o", tmp_path, "--overwrite"], "contains the input", inputs=[ds])
    expect_error(capsys, ["report", run, "-o", run, "--overwrite", "--no-mitsuba"], "is the input", inputs=[run, ds])
    spec_dir = tmp_path / "specs"
    spec_dir.mkdir()
    shutil.copy(MICRO, spec_dir / "micro.toml")
    (spec_dir / "notes.txt").write_text("keep me")
    expect_error(capsys, ["generate", spec_dir / "micro.toml", "-o", spec_dir, "--overwrite"], "contains the input",
                 inputs=[spec_dir])


def test_overwrite_replaces_only_what_pseudolight_wrote(copy, tmp_path, capsys):
    ds, _, _ = copy
    foreign = tmp_path / "photos"
    foreign.mkdir()
    (foreign / "holiday.jpg").write_bytes(b"\xff\xd8 not really")
    expect_error(capsys, ["estimate", ds, "-o", foreign, "--overwrite"], "not written by pseudolight", str(foreign),
                 inputs=[ds, foreign])
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["estimate", str(ds), "-o", str(empty), "--overwrite"]) == 0
    assert (empty / MARKER).is_file()
    assert main(["estimate", str(ds), "-o", str(empty), "--overwrite"]) == 0   # its own output: replaced
    capsys.readouterr()


def test_overwrite_never_replaces_another_kind_of_output(copy, micro, tmp_path, capsys):
    """A dataset (or a report) pseudolight wrote is not a run: --overwrite of a run there is
    refused before the estimate starts, and the folder keeps every file."""
    ds, run, rep = copy
    other = tmp_path / "other-dataset"
    shutil.copytree(micro[0], other)
    expect_error(capsys, ["estimate", ds, "-o", other, "--overwrite"], "holds pseudolight output of kind 'dataset'",
                 "writes kind 'run'", str(other), inputs=[ds, other])
    expect_error(capsys, ["estimate", ds, "-o", rep, "--overwrite"], "of kind 'report'", inputs=[ds, rep])
    expect_error(capsys, ["report", run, "-o", other, "--overwrite", "--no-mitsuba"], "of kind 'dataset'",
                 "writes kind 'report'", inputs=[run, ds, other])
    (other / MARKER).write_text("{not json")
    expect_error(capsys, ["estimate", ds, "-o", other, "--overwrite"], "unknown kind", MARKER, inputs=[ds, other])
    # each command replaces its own earlier output
    for argv in (["render", run, "-o", tmp_path / "rendered", "--frames", "test"],
                 ["export-texture", run, "-o", tmp_path / "texture"]):
        assert main([str(a) for a in argv]) == 0
        assert main([str(a) for a in argv] + ["--overwrite"]) == 0, capsys.readouterr().err
    capsys.readouterr()


def test_an_output_in_a_folder_that_refuses_writes_is_refused_before_the_work(copy, tmp_path, capsys, monkeypatch):
    """The parent folder is tried, not judged by its permission bits (root passes those where a
    read-only file system refuses): the estimate and a report's --write-baseline fail at once."""
    import harness.io.atomic as atomic

    ds, run, _ = copy
    locked = tmp_path / "locked"
    locked.mkdir()
    real = atomic.tempfile.mkdtemp

    def refuse(*args, **kwargs):
        if os.path.realpath(str(kwargs.get("dir", ""))) == os.path.realpath(locked):
            raise PermissionError(1, "Operation not permitted")
        return real(*args, **kwargs)

    monkeypatch.setattr(atomic.tempfile, "mkdtemp", refuse)
    monkeypatch.setattr("estimator.estimate", lambda *a, **k: pytest.fail("the estimate ran before the check"))
    expect_error(capsys, ["estimate", ds, "-o", locked / "run"], "cannot write", "not writable", inputs=[ds],
                 absent=[locked / "run"])
    report = tmp_path / "report2"
    expect_error(capsys, ["report", run, "-o", report, "--no-mitsuba", "--write-baseline", locked / "b.json"],
                 "cannot write", str(locked / "b.json"), inputs=[run, ds], absent=[report, locked / "b.json"])


# ------------------------------------------------------------ silent garbage

def test_non_finite_estimate_is_refused_and_nan_is_a_regression(copy, capsys):
    ds, run, rep = copy
    data = dict(np.load(run / "estimate.npz"))
    data["pseudo_sh"][3, 1] = np.nan
    np.savez(run / "estimate.npz", **data)
    out = run.parent / "rep2"
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "estimate.npz", "pseudo_sh", "NaN",
                 inputs=[run, ds], absent=[out])
    data["pseudo_sh"][3, 1] = 0.0
    data["diffuse"] = data["diffuse"] * 1e300    # finite, beyond float32: the textures would hold Inf
    np.savez(run / "estimate.npz", **data)
    expect_error(capsys, ["export-texture", run, "-o", out, "--size", "64"], "estimate.npz", "diffuse", "float32",
                 inputs=[run, ds], absent=[out])

    from reports.regression import check

    rows = check({"illumination": {"relative_l2": float("nan")}},
                 {"metrics": {"illumination.relative_l2": 0.1}})
    assert rows[0]["status"] == "missing" and rows[0]["current"] is None


def test_metrics_json_is_strict(tmp_path):
    from harness.io.jsonio import dump_json

    dump_json(str(tmp_path / "m.json"), {"a": {"b": float("nan")}, "c": [1.0, float("inf")]})
    text = (tmp_path / "m.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    loaded = json.loads(text)
    assert loaded["a"]["b"] is None and loaded["c"][1] is None
    assert set(loaded["null_reasons"]) == {"a.b", "c[1]"}


def test_report_against_another_dataset_is_refused(copy, tmp_path, capsys):
    ds, run, _ = copy
    other = tmp_path / "other"
    shutil.copytree(ds, other)
    from harness.io.exr import read_exr, write_exr

    image = read_exr(other / "images" / "train_000.exr")
    image[..., :3] *= 2.0
    write_exr(other / "images" / "train_000.exr", image)
    out = tmp_path / "rep"
    expect_error(capsys, ["report", run, "--dataset", other, "-o", out, "--no-mitsuba"], "images", str(ds),
                 str(other), inputs=[run, other], absent=[out])


@pytest.mark.parametrize("command", [["render"], ["export-texture"], ["report", "--no-mitsuba"]])
def test_a_mesh_with_its_faces_reordered_is_refused_by_every_reader_of_a_run(copy, tmp_path, capsys, command):
    """Same face count, another face order: each albedo would land on the wrong face."""
    from harness.io.mesh import load_mesh_file, save_mesh_ply

    ds, run, _ = copy
    other = tmp_path / "reordered"
    shutil.copytree(ds, other)
    mesh = load_mesh_file(str(other / "mesh.ply"))
    save_mesh_ply(type(mesh)(mesh.vertices, mesh.faces[::-1]), str(other / "mesh.ply"))
    out = tmp_path / "out"
    expect_error(capsys, [command[0], run, "--dataset", other, "-o", out, *command[1:]], "mesh", "differ",
                 inputs=[run, other], absent=[out])


def test_a_run_without_a_fingerprint_needs_the_flag(copy, tmp_path, capsys):
    ds, run, _ = copy
    bare = tmp_path / "bare-run"
    shutil.copytree(run, bare)
    record = json.loads((bare / "run.json").read_text())
    del record["fingerprint"]
    (bare / "run.json").write_text(json.dumps(record))
    out = tmp_path / "tex"
    expect_error(capsys, ["export-texture", bare, "-o", out], "no (or an incomplete) fingerprint",
                 "--no-fingerprint-check", inputs=[bare, ds], absent=[out])
    assert main(["export-texture", str(bare), "-o", str(out), "--no-fingerprint-check", "--size", "64"]) == 0
    capsys.readouterr()
    record["fingerprint"] = {"cameras": "x", "images": "y"}    # the mesh's hash alone removed
    (bare / "run.json").write_text(json.dumps(record))
    expect_error(capsys, ["export-texture", bare, "-o", tmp_path / "tex2"], "incomplete) fingerprint",
                 "--no-fingerprint-check", inputs=[bare, ds], absent=[tmp_path / "tex2"])


def test_nan_ground_truth_is_refused(copy, capsys):
    ds, run, _ = copy
    mats = dict(np.load(ds / "ground_truth" / "materials.npz"))
    mats["diffuse"][:10] = np.nan
    np.savez(ds / "ground_truth" / "materials.npz", **mats)
    out = run.parent / "rep2"
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "materials.npz", "diffuse", "10 rows",
                 inputs=[run, ds], absent=[out])


@pytest.mark.parametrize("edit, key", [
    ('specular = { value = [0.2, 0.2, 0.2], scale = nan }', "material.specular.scale"),
    ('exponent = nan', "material.exponent"),
    ('exponent = inf', "material.exponent"),
])
def test_non_finite_spec_values_name_the_key(tmp_path, capsys, edit, key):
    text = open(MICRO).read()
    target = "exponent = 10.0" if edit.startswith("exponent") else 'specular = { value = [0.2, 0.2, 0.2] }'
    spec = tmp_path / "bad.toml"
    spec.write_text(text.replace(target, edit))
    expect_error(capsys, ["generate", spec, "-o", tmp_path / "out"], key, "finite", inputs=[spec],
                 absent=[tmp_path / "out"])


def test_negative_pixels_are_dropped_and_reported(copy, tmp_path, capsys):
    ds, _, _ = copy
    from harness.io.exr import read_exr, write_exr

    image = read_exr(ds / "images" / "train_002.exr")
    image[4:14, 4:14, :3] = -0.5
    write_exr(ds / "images" / "train_002.exr", image)
    assert main(["estimate", str(ds), "-o", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if line.startswith("warning:") and "negative" in line]
    assert len(warning) == 1 and "train_002" in warning[0] and "negative" in warning[0]
    assert int(warning[0].split(": ")[2].split()[0]) > 0
    meta = json.load(open(tmp_path / "r" / "run.json"))
    assert list(meta["rejected_pixels"]) == ["images/train_002.exr"]


# ----------------------------------------------- one line, exit 2, names it

def test_malformed_transforms_json(copy, tmp_path, capsys):
    ds, _, _ = copy
    t = json.load(open(ds / "transforms.json"))
    out = tmp_path / "r"
    for value, needles in [
        ([1, 2, 3], ["transforms.json", "JSON object"]),
        ({**t, "format_version": 99}, ["format_version 99"]),
        ({**t, "frames": [{**t["frames"][0], "transform_matrix": "eye(4)"}]}, ["frames[0]", "4x4 array of numbers"]),
        ({**t, "frames": [{**t["frames"][0], "transform_matrix": [[float("nan")] * 4] * 4}]}, ["frames[0]", "NaN"]),
        ({**t, "frames": [{**t["frames"][0], "transform_matrix": [[str(v) for v in row] for row in np.eye(4)]}]},
         ["frames[0]", "4x4 array of numbers"]),
        ({**t, "frames": [{**t["frames"][0], "transform_matrix": [[10 ** 400] * 4] * 4}]},
         ["frames[0]", "4x4 array of numbers"]),
        ({**t, "frames": [{**t["frames"][0], "transform_matrix": np.diag([1, 1, 0, 1.0]).tolist()}]},
         ["frames[0]", "not a rigid"]),
        ({**t, "fl_x": "wide"}, ["fl_x", "finite number"]),
    ]:
        (ds / "transforms.json").write_text(json.dumps(value))
        expect_error(capsys, ["estimate", ds, "-o", out], *needles, inputs=[ds], absent=[out])


def test_missing_ground_truth_keys_and_files(copy, capsys):
    ds, run, _ = copy
    gt = ds / "ground_truth"
    out = run.parent / "rep2"
    mats = dict(np.load(gt / "materials.npz"))
    np.savez(gt / "materials.npz", diffuse=mats["diffuse"])
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "materials.npz", "'specular'", inputs=[run, ds],
                 absent=[out])
    (gt / "materials.npz").write_text("diffuse,specular\n1,2\n")
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "materials.npz", "not a .npz archive",
                 inputs=[run, ds], absent=[out])
    np.savez(gt / "materials.npz", **mats)
    info = json.load(open(gt / "illumination.json"))
    del info["brdf"]
    json.dump(info, open(gt / "illumination.json", "w"))
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "illumination.json", "'brdf'", inputs=[run, ds],
                 absent=[out])
    os.remove(gt / "illumination.json")
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "illumination.json", "not found",
                 inputs=[run, ds], absent=[out])
    # estimation never reads ground truth: an incomplete ground_truth/ does not matter to it
    assert main(["estimate", str(ds), "-o", str(run.parent / "r2")]) == 0
    capsys.readouterr()


def test_malformed_baseline_metrics_and_run_json(copy, tmp_path, capsys):
    ds, run, rep = copy
    out = tmp_path / "rep2"
    bad = tmp_path / "baseline.json"
    bad.write_text(json.dumps({"metrics": {"illumination.relative_l2": "low"}}))
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba", "--baseline", bad], str(bad),
                 "illumination.relative_l2", inputs=[run, ds, bad], absent=[out])
    bad.write_text("{not json")
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba", "--baseline", bad], str(bad), "not valid JSON",
                 inputs=[run, ds, bad], absent=[out])
    good = json.loads((rep / "metrics.json").read_text())
    (rep / "metrics.json").write_text("[1, 2")
    expect_error(capsys, ["compare", rep, "-o", out], "metrics.json", "not valid JSON", inputs=[rep], absent=[out])
    wrong = [{**good, "scene": [1]}, {**good, "albedo": "x"}, {**good, "novel_views": 5},
             {**good, "novel_views": {**(good["novel_views"] or {}), "psnr_srgb": "x"}}, {**good, "parameters": [1]},
             {**good, "albedo": {**good["albedo"], "diffuse": {**good["albedo"]["diffuse"], "psnr_history": [1, 2]}}}]
    for text, needle in (("[1, 2]", "JSON object"), ('{"schema_version": 99}', "schema_version 99"),
                         ('{"schema": "other"}', "schema 'other'"), ("{}", "'method'"),
                         *zip(map(json.dumps, wrong), ("'scene'", "'albedo'", "'novel_views'", "novel_views.psnr_srgb",
                                                       "'parameters'", "psnr_history"))):
        (rep / "metrics.json").write_text(text)
        expect_error(capsys, ["compare", rep, "-o", out], "metrics.json", needle, inputs=[rep], absent=[out])
    (rep / "metrics.json").write_text(json.dumps({**good, "scene": 42}))   # a dataset may name its scene so
    assert main(["compare", str(rep), "-o", str(tmp_path / "compared")]) == 0
    capsys.readouterr()
    (run / "run.json").write_text("NaN")
    expect_error(capsys, ["render", run, "-o", out], "run.json", inputs=[run, ds], absent=[out])


def test_bad_spec_files_name_the_file(tmp_path, capsys):
    binary = tmp_path / "binary.toml"
    binary.write_bytes(bytes(range(256)))
    expect_error(capsys, ["generate", binary, "-o", tmp_path / "o"], str(binary), inputs=[binary])
    probe = tmp_path / "ldr.toml"
    png = tmp_path / "probe.png"
    import mitsuba as mi

    mi.Bitmap(np.full((16, 32, 3), 0.5, np.float32)).convert(
        mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(str(png))
    probe.write_text(
        open(MICRO)
        .read()
        .replace(
            '[illumination]\ntype = "directional"\n'
            "lights = [{ to_light = [0.4, 0.8, 0.45], irradiance = [3.0, 3.0, 3.0] }]",
            '[illumination]\ntype = "probe-clustered"\nfile = "probe.png"\ncount = 4',
        )
    )
    assert main(["generate", str(probe), "-o", str(tmp_path / "ldr")]) == 0
    assert "low-dynamic-range" in capsys.readouterr().err


def test_black_or_negated_images_name_the_cause(copy, tmp_path, capsys):
    ds, _, _ = copy
    from harness.io.exr import read_exr, write_exr

    for name in os.listdir(ds / "images"):
        image = read_exr(ds / "images" / name)
        image[..., :3] = 0.0
        write_exr(ds / "images" / name, image)
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "every view shows the mesh black", inputs=[ds],
                 absent=[tmp_path / "r"])


def test_degenerate_mesh_and_flags(copy, tmp_path, capsys):
    ds, run, _ = copy
    import trimesh

    mesh = trimesh.load(ds / "mesh.ply", process=False)
    flat = trimesh.Trimesh(np.zeros_like(mesh.vertices), mesh.faces, process=False)
    flat.export(ds / "mesh.ply")
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "mesh.ply", "no face with non-zero area",
                 inputs=[ds], absent=[tmp_path / "r"])
    expect_error(capsys, ["render", run, "-o", tmp_path / "p", "--rotate-illumination", "y", "nan"],
                 "--rotate-illumination", inputs=[run], absent=[tmp_path / "p"])
    expect_error(capsys, ["generate", MICRO, "-o", tmp_path / "g", "--resolution", "0"], "--resolution", ">= 1",
                 absent=[tmp_path / "g"])
    expect_error(capsys, ["generate", MICRO, "-o", tmp_path / "g", "--set", "seed=3\nrender.spp=5"], "--set",
                 "one line", absent=[tmp_path / "g"])


def test_filesystem_errors_are_one_line(copy, tmp_path, capsys, monkeypatch):
    ds, _, _ = copy
    blocker = tmp_path / "file"
    blocker.write_text("x")
    expect_error(capsys, ["estimate", ds, "-o", blocker / "sub"], "is a file", inputs=[ds])
    expect_error(capsys, ["estimate", ds, "-o", "/proc/pseudolight/run"], "/proc/pseudolight/run", inputs=[ds])
    import harness.io.runs as runs

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runs.np, "savez", disk_full)
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "No space left", str(tmp_path / "r"),
                 inputs=[ds], absent=[tmp_path / "r"])
    assert not [n for n in os.listdir(tmp_path) if "-partial-" in n]


def test_a_random_family_seed_out_of_range_names_the_flag(tmp_path, capsys):
    expect_error(capsys, ["generate", "random", "--seed", "4294967296", "-o", tmp_path / "d"], "--seed",
                 "[0, 2147483647]", absent=[tmp_path / "d"])


def test_every_camera_inside_the_mesh_is_refused(tmp_path, capsys):
    """Cameras that all lie inside a closed mesh would record only its inside (black images
    the estimate refuses much later): generation refuses, names the key and writes nothing."""
    spec = tmp_path / "inside.toml"
    spec.write_text(open(MICRO).read().replace("distance = 4.0", "distance = 0.5"))
    expect_error(capsys, ["generate", spec, "-o", tmp_path / "d"], "cameras.distance 0.5",
                 "every camera inside the mesh", absent=[tmp_path / "d"])


def test_a_region_that_covers_no_face_is_warned(tmp_path, capsys):
    """A region whose bands hold no face centroid (or whose faces later regions take) is named,
    and the dataset is written."""
    spec = tmp_path / "sliver.toml"
    spec.write_text(open(MICRO).read().replace(
        'diffuse = { value = [0.5, 0.4, 0.3] }\nspecular = { value = [0.2, 0.2, 0.2] }',
        '[[material.regions]]\nname = "base"\ndiffuse = [0.5, 0.4, 0.3]\n\n[[material.regions]]\nname = "sliver"\n'
        'diffuse = [0.2, 0.2, 0.2]\nranges = [[0.99999, 1.0]]'))
    assert main(["generate", str(spec), "-o", str(tmp_path / "d")]) == 0
    assert "material.regions[1] (sliver) covers no face" in capsys.readouterr().err
    assert os.path.exists(tmp_path / "d" / "transforms.json")


def test_views_that_show_nothing_of_the_object_warn_and_estimate_names_the_framing(tmp_path, capsys):
    """An object far smaller than a pixel (or outside the frame) renders nothing: generate says
    so, and estimate's refusal names the framing beside the alpha channel."""
    spec = tmp_path / "speck.toml"
    spec.write_text(open(MICRO).read().replace("subdivisions = 1", "subdivisions = 1\nradius = 1e-5"))
    assert main(["generate", str(spec), "-o", str(tmp_path / "d")]) == 0
    assert "6 of 6 training views show no pixel wholly covered by the object" in capsys.readouterr().err
    expect_error(capsys, ["estimate", str(tmp_path / "d"), "-o", str(tmp_path / "r")],
                 "outside their frame", "position and scale", inputs=[tmp_path / "d"], absent=[tmp_path / "r"])


def test_an_open_mesh_has_no_inside():
    """A camera looking into an open shell sees a back face from outside: only a closed mesh
    has an inside to warn about."""
    import trimesh

    from estimator import Camera, TriangleMesh, look_at
    from harness.scene.generate import cameras_inside
    sphere = trimesh.creation.icosphere(subdivisions=2)
    closed = TriangleMesh(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    upper = sphere.faces[np.asarray(sphere.vertices)[sphere.faces].mean(axis=1)[:, 1] > 0]   # an open cap
    shell = TriangleMesh(np.asarray(sphere.vertices), upper)
    below = Camera(look_at([0.0, -3.0, 0.01], [0.0, 0.0, 0.0]), 20.0, 20.0, 8.0, 8.0, 16, 16)   # into the open side
    centre = Camera(look_at([0.0, 0.0, 0.01], [0.0, 1.0, 0.0]), 20.0, 20.0, 8.0, 8.0, 16, 16)
    assert cameras_inside(closed, [below, centre]) == [1]
    assert cameras_inside(shell, [below, centre]) == []
    # closed all the same: every face with its own copies of its vertices (as an STL file), a face twice
    corners = np.asarray(sphere.vertices)[np.asarray(sphere.faces)].reshape(-1, 3)
    unshared = TriangleMesh(corners, np.vstack([np.arange(len(corners)).reshape(-1, 3), [[0, 1, 2]]]))
    assert cameras_inside(unshared, [below, centre]) == [1]


def test_stale_partial_folders_are_removed(copy, tmp_path, capsys):
    ds, _, _ = copy
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".r.pseudolight-partial-{dead.pid}-abcd"
    user = tmp_path / ".my notes.old-4000000-keep"   # a user folder that merely looks similar
    user.mkdir()
    (user / "file").write_text("keep")
    odd = tmp_path / ".x.pseudolight-partial-99999999999999999999-a"
    odd.mkdir()
    stale.mkdir()
    (stale / "estimate.npz").write_bytes(b"half")
    old = time.time() - 120                          # an older version's folder: no lock, unchanged for 2 min
    os.utime(stale, (old, old))
    assert main(["estimate", str(ds), "-o", str(tmp_path / "r")]) == 0
    assert not stale.exists() and (user / "file").read_text() == "keep" and odd.exists()
    capsys.readouterr()


LOCK_HOLDER = """
import fcntl, os, sys, time
fd = os.open(sys.argv[1], os.O_CREAT | os.O_RDWR)
fcntl.lockf(fd, fcntl.LOCK_EX)
print("locked", flush=True)
time.sleep(float(sys.argv[2]))
"""


def test_a_live_partial_folder_of_another_namespace_is_kept_and_a_dead_ones_removed(copy, tmp_path, capsys):
    """The writer's lock decides, not its PID: a folder named with a PID this host does not run
    (another container or host) but locked by a live process stays; a locked folder whose
    writer died (the OS released its lock) goes, however new."""
    ds, _, _ = copy
    live = tmp_path / ".r.pseudolight-partial-4000000-live"
    gone = tmp_path / ".r.pseudolight-partial-4000001-gone"
    for folder in (live, gone):
        folder.mkdir()
        (folder / "images").mkdir()
    holder = subprocess.Popen([sys.executable, "-c", LOCK_HOLDER, str(live / ".pseudolight-lock"), "60"],
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    dead = subprocess.Popen([sys.executable, "-c", LOCK_HOLDER, str(gone / ".pseudolight-lock"), "0"],
                            stdout=subprocess.PIPE, text=True)
    dead.wait()
    try:
        assert main(["estimate", str(ds), "-o", str(tmp_path / "r")]) == 0
        assert live.exists() and not gone.exists()
    finally:
        holder.kill()
        holder.wait()
    capsys.readouterr()


def test_sigterm_leaves_no_partial_output(tmp_path):
    spec = tmp_path / "slow.toml"
    spec.write_text(open(MICRO).read().replace("count = 6", "count = 3000").replace("width = 24", "width = 96")
                    .replace("height = 24", "height = 96").replace("spp = 1", "spp = 4"))
    out = tmp_path / "d"
    proc = subprocess.Popen([sys.executable, "-m", "harness.cli", "generate", str(spec), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    deadline = time.time() + 60
    while time.time() < deadline and not [n for n in os.listdir(tmp_path) if "-partial-" in n]:
        time.sleep(0.1)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert not out.exists() and not [n for n in os.listdir(tmp_path) if "-partial-" in n]


def test_internal_errors_keep_their_traceback(copy, tmp_path, monkeypatch):
    ds, _, _ = copy
    import estimator as methods

    def bug(*args, **kwargs):
        raise ValueError("a bug, not bad input")

    monkeypatch.setattr(methods, "estimate", bug)
    with pytest.raises(ValueError, match="a bug"):
        main(["estimate", str(ds), "-o", str(tmp_path / "r")])
    assert not (tmp_path / "r").exists()


def test_underdetermined_estimates_warn_and_fail_under_strict(tmp_path, capsys):
    ds = tmp_path / "one-view"
    assert main(["generate", MICRO, "-o", str(ds), "--views", "1"]) == 0
    assert main(["estimate", str(ds), "-o", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "warning: underdetermined" in err
    assert main(["estimate", str(ds), "-o", str(tmp_path / "r2"), "--strict"]) == 3
    assert "--strict" in capsys.readouterr().err and (tmp_path / "r2" / "run.json").is_file()
    many = tmp_path / "many"
    assert main(["generate", MICRO, "-o", str(many)]) == 0
    # 6 views: per face (72 x 2 albedos + light) is still underdetermined, one cluster is not
    assert main(["estimate", str(many), "-o", str(tmp_path / "r3"), "--method", "bilinear-clustered"]) == 0
    assert "warning: underdetermined" not in capsys.readouterr().err


def test_files_read_from_outside_the_dataset_are_inputs_too(copy, tmp_path, capsys):
    ds, run, _ = copy
    other = tmp_path / "other"
    shutil.copytree(ds, other)
    t = json.load(open(ds / "transforms.json"))
    t["mesh_file_path"] = "../other/mesh.ply"
    for frame in t["frames"]:
        frame["file_path"] = "../other/" + frame["file_path"]
    json.dump(t, open(ds / "transforms.json", "w"))
    expect_error(capsys, ["estimate", ds, "-o", other, "--overwrite"], "the input", inputs=[ds, other])
    # a baseline written over an input file is refused too
    expect_error(capsys, ["report", run, "-o", tmp_path / "rep", "--no-mitsuba", "--write-baseline",
                          run / "run.json"], "run.json", inputs=[run], absent=[tmp_path / "rep"])


def test_write_baseline_replaces_a_baseline_but_no_other_file_without_overwrite(copy, tmp_path, capsys):
    """Updating a baseline is what --write-baseline is for; an existing file that is no baseline
    is kept unless --overwrite; a folder that does not exist is named as such."""
    _, run, _ = copy
    other = tmp_path / "notes.json"
    other.write_text('{"mine": 1}')
    expect_error(capsys, ["report", run, "-o", tmp_path / "rep", "--no-mitsuba", "--no-figures", "--write-baseline",
                          other], "--write-baseline", "is not a baseline", "--overwrite", inputs=[other],
                 absent=[tmp_path / "rep"])
    baseline = tmp_path / "baseline.json"
    argv = ["report", str(run), "--no-mitsuba", "--no-figures", "--write-baseline", str(baseline)]
    assert main(argv[:2] + ["-o", str(tmp_path / "r1")] + argv[2:]) == 0
    first = baseline.read_text()
    assert main(argv[:2] + ["-o", str(tmp_path / "r2")] + argv[2:]) == 0   # a baseline is replaced
    assert json.loads(baseline.read_text())["metrics"] == json.loads(first)["metrics"]
    assert main(argv[:2] + ["-o", str(tmp_path / "r3"), "--overwrite"] + argv[2:-1] + [str(other)]) == 0
    assert "metrics" in json.loads(other.read_text())
    expect_error(capsys, ["report", run, "-o", tmp_path / "r4", "--no-mitsuba", "--write-baseline",
                          tmp_path / "nowhere" / "b.json"], "nowhere does not exist", absent=[tmp_path / "r4"])
    capsys.readouterr()


def test_rendering_a_run_whose_light_is_beyond_any_image_names_the_run(copy, tmp_path, capsys):
    """A light and albedos each within float32 whose predicted pixels overflow an EXR's float32:
    the run's estimate is named as the cause, not the output folder, and nothing is written."""
    ds, run, _ = copy
    data = dict(np.load(run / "estimate.npz"))
    data["pseudo_sh"] = data["pseudo_sh"] * 1e30
    data["diffuse"] = data["diffuse"] * 1e15
    np.savez(run / "estimate.npz", **data)
    out = tmp_path / "predicted"
    line = expect_error(capsys, ["render", run, "-o", out], str(run), "estimate.npz", "beyond any image's range",
                        inputs=[run, ds], absent=[out])
    assert str(out) not in line


def test_malformed_estimate_and_regions_arrays(copy, capsys):
    ds, run, _ = copy
    out = run.parent / "rep2"
    good = dict(np.load(run / "estimate.npz"))
    for key, value, needle in (("diffuse", np.array(3.0), "disagree in shape"),
                               ("pseudo_sh", np.ones((8, 3)), "pseudo_sh"),
                               ("labels", np.full(80, np.nan), "labels must be integers"),
                               ("observed", np.array(["a"] * 80), "observed")):
        np.savez(run / "estimate.npz", **{**good, key: value})
        expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "estimate.npz", needle,
                     inputs=[run, ds], absent=[out])
    np.savez(run / "estimate.npz", **good)
    mats = dict(np.load(ds / "ground_truth" / "materials.npz"))
    for regions in (np.full(80, np.nan), np.full(80, 10 ** 12)):
        np.savez(ds / "ground_truth" / "materials.npz", **{**mats, "regions": regions})
        expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "materials.npz", "regions",
                     inputs=[run, ds], absent=[out])


def test_holdout_views_and_trust_are_recorded_and_read_back(tmp_path, capsys):
    from harness.io.runs import read_run

    ds = tmp_path / "micro"
    assert main(["generate", MICRO, "-o", str(ds)]) == 0
    run = tmp_path / "r"
    assert main(["estimate", str(ds), "-o", str(run), "--method", "bilinear-clustered", "--holdout-views", "2"]) == 0
    err = capsys.readouterr().err
    assert "cross-validation: 2 views held out" in err and "trust:" in err
    est, meta = read_run(str(run))
    assert len(meta["cross_validation"]["views"]) == 2 and meta["cross_validation"]["psnr"] > 0
    assert len(meta["trust"]["views"]) == 6 and "degrees_of_freedom" in meta
    assert est.face_stats["observations"].shape == (80,) and est.face_stats["albedo_se"].shape == (80, 3)
    expect_error(capsys, ["estimate", str(ds), "-o", str(tmp_path / "r2"), "--holdout-views", "5"],
                 "--holdout-views: the number of held-out views must lie in [1, 4]")


def test_report_without_ground_truth_is_the_self_check(tmp_path, capsys):
    ds = tmp_path / "micro"
    assert main(["generate", MICRO, "-o", str(ds)]) == 0
    run = tmp_path / "run"
    assert main(["estimate", str(ds), "-o", str(run), "--method", "bilinear-clustered", "--holdout-views", "2"]) == 0
    assert main(["report", str(run), "-o", str(tmp_path / "with-truth"), "--no-mitsuba"]) == 0
    with_truth = json.load(open(tmp_path / "with-truth" / "metrics.json"))["novel_views"]
    shutil.rmtree(ds / "ground_truth")
    assert main(["report", str(run), "-o", str(tmp_path / "rep"), "--no-mitsuba"]) == 0
    assert "writing the self-check report and scoring its 1 test frame(s)" in capsys.readouterr().err
    m = json.load(open(tmp_path / "rep" / "metrics.json"))
    assert m["ground_truth"] is None and m["self_check"]["cross_validation_psnr"] > 0
    # the held-out test frame is scored as the report with ground truth scores it
    assert m["novel_views"]["views"] == 1
    for key in ("psnr_linear", "psnr_srgb", "relative_l2", "unestimated_pixel_share"):
        assert m["novel_views"][key] == pytest.approx(with_truth[key], rel=1e-12)
    assert m["self_check"]["degrees_of_freedom"]["observations"] > 0
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "self-check report" in html and html.count("<img") == 3
    assert not (tmp_path / "rep" / "ratios.npz").exists()
    # such a report compares beside one with ground truth (no ratios of its own); ratios of another shape are named
    assert main(["compare", str(tmp_path / "rep"), str(tmp_path / "with-truth"), "-o", str(tmp_path / "cmp")]) == 0
    np.savez(tmp_path / "with-truth" / "ratios.npz", diffuse=np.ones(5))
    expect_error(capsys, ["compare", tmp_path / "with-truth", "-o", tmp_path / "cmp2"], "ratios.npz", "(n, 4)",
                 inputs=[tmp_path / "with-truth"], absent=[tmp_path / "cmp2"])


def test_report_with_ground_truth_holds_the_self_check_too(copy, tmp_path):
    _, run, _ = copy
    assert main(["report", str(run), "-o", str(tmp_path / "rep"), "--no-mitsuba"]) == 0
    m = json.load(open(tmp_path / "rep" / "metrics.json"))
    assert "albedo" in m and m["self_check"]["residual"]["median_relative"] >= 0


def test_flags_for_another_method_or_executor_are_refused(micro, tmp_path, capsys):
    ds = micro[0]
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r1", "--method", "median-color", "--time-budget", "5"],
                 "--time-budget applies to mitsuba-ad", inputs=[ds], absent=[tmp_path / "r1"])
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r2", "--method", "mitsuba-ad", "--robust-loss", "huber"],
                 "--robust-loss applies to", inputs=[ds], absent=[tmp_path / "r2"])
    expect_error(capsys, ["bench", "smoke", "-o", tmp_path / "s", "--scheduler", "tcp://127.0.0.1:1"],
                 "it needs --executor dask", absent=[tmp_path / "s"])


def test_resource_settings_are_bounded_before_anything_is_allocated(micro, tmp_path, capsys):
    """--directions 100000000 grew past 6 GB and ignored SIGTERM; now it is refused at once."""
    ds, _, _ = micro
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r", "--directions", "100000000"],
                 "directions must lie in [12, 65536]", inputs=[ds], absent=[tmp_path / "r"])


def test_the_shadow_function_is_refused_when_it_would_not_fit(monkeypatch):
    import numpy as np

    from estimator import InputError, RayCaster, TriangleMesh, compute_visibility, sphere_sampling
    from estimator.rays import visibility

    mesh = TriangleMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    monkeypatch.setattr(visibility, "MAX_SHADOW_BYTES", 10)    # one face x 200 directions: 25 bytes
    with pytest.raises(InputError, match="lower directions"):
        compute_visibility(RayCaster(mesh), sphere_sampling(200))


def test_a_dataset_missing_a_frame_is_never_published(tmp_path, capsys, monkeypatch):
    """A frame's image that vanishes while the dataset is written (another process's clean-up, a
    full disk) fails the write: nothing is published, one line names the output."""
    from harness.io import dataset

    write = dataset.write_exr

    def lose_one(path, *args, **kwargs):
        write(path, *args, **kwargs)
        if path.endswith("train_002.exr"):
            os.remove(path)

    monkeypatch.setattr(dataset, "write_exr", lose_one)
    out = tmp_path / "ds"
    expect_error(capsys, ["generate", MICRO, "-o", out], "images vanished", absent=[out])
    assert not [n for n in os.listdir(tmp_path) if "-partial-" in n]


def test_nerf_synthetic_export_refuses_frames_with_their_own_intrinsics(copy, tmp_path, capsys):
    """The layout holds one camera: a frame with another focal length is refused (it was written
    with the first frame's), not exported wrong."""
    ds, _, _ = copy
    other = tmp_path / "per-frame"
    shutil.copytree(ds, other)
    record = json.loads((other / "transforms.json").read_text())
    record["frames"][1]["fl_x"] = record["fl_x"] * 1.2
    (other / "transforms.json").write_text(json.dumps(record))
    out = tmp_path / "nerf"
    expect_error(capsys, ["export", other, "--format", "nerf-synthetic", "-o", out], "train_001",
                 "--format mitsuba", inputs=[other], absent=[out])


def test_nerf_synthetic_export_writes_train_val_and_test(copy, tmp_path):
    ds, _, _ = copy
    out = tmp_path / "nerf"
    assert main(["export", str(ds), "--format", "nerf-synthetic", "-o", str(out), "--size", "64"]) == 0
    val = json.loads((out / "transforms_val.json").read_text())
    assert val == json.loads((out / "transforms_test.json").read_text()) and val["frames"]


@pytest.mark.parametrize("keys, needle", [
    ({"camera_model": "PINHOLE", "k1": 0.2}, "camera_model 'PINHOLE' has no lens distortion, but k1 = 0.2"),
    ({"camera_model": "OPENCV", "p2": "x"}, "lens distortion p2 must be a finite number"),
    ({"camera_model": "OPENCV_FISHEYE", "p1": 0.01}, "p1 and p2 must be 0"),
    ({"camera_model": "OPENCV", "k1": -5.0}, "folds over"),
    ({"camera_model": "EQUIRECTANGULAR"}, "camera_model 'EQUIRECTANGULAR' is not supported"),
])
def test_unsupported_or_impossible_lenses_are_refused(copy, tmp_path, capsys, keys, needle):
    """A real capture's transforms.json with distortion was estimated without a word; the
    supported models are undistorted on reading (tests/harness/test_lens.py), the rest refused."""
    ds, _, _ = copy
    other = tmp_path / "distorted"
    shutil.copytree(ds, other)
    record = json.loads((other / "transforms.json").read_text())
    record.update(keys)
    (other / "transforms.json").write_text(json.dumps(record))
    expect_error(capsys, ["estimate", other, "-o", tmp_path / "r"], needle, "transforms.json", inputs=[other],
                 absent=[tmp_path / "r"])


def test_an_undistorted_opencv_camera_is_a_pinhole(copy, tmp_path):
    ds, _, _ = copy
    other = tmp_path / "opencv"
    shutil.copytree(ds, other)
    record = json.loads((other / "transforms.json").read_text())
    record.update({"camera_model": "OPENCV", "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0})
    (other / "transforms.json").write_text(json.dumps(record))
    assert main(["estimate", str(other), "-o", str(tmp_path / "r")]) == 0


def test_truncated_archives_are_one_line_errors(copy, tmp_path, capsys):
    """A truncated estimate.npz or materials.npz raised a BadZipFile traceback."""
    ds, run, _ = copy
    broken_run = tmp_path / "broken-run"
    shutil.copytree(run, broken_run)
    data = (broken_run / "estimate.npz").read_bytes()
    (broken_run / "estimate.npz").write_bytes(data[: len(data) // 2])
    expect_error(capsys, ["export-texture", broken_run, "-o", tmp_path / "t"], "estimate.npz", "unreadable",
                 inputs=[broken_run], absent=[tmp_path / "t"])
    broken_ds = tmp_path / "broken-ds"
    shutil.copytree(ds, broken_ds)
    data = (broken_ds / "ground_truth" / "materials.npz").read_bytes()
    (broken_ds / "ground_truth" / "materials.npz").write_bytes(data[: len(data) // 3])
    expect_error(capsys, ["report", run, "--dataset", broken_ds, "-o", tmp_path / "r", "--no-mitsuba",
                          "--no-fingerprint-check"], "materials.npz", "unreadable", inputs=[run, broken_ds],
                 absent=[tmp_path / "r"])


def test_flag_messages_name_their_flag_or_variable(copy, tmp_path, capsys, monkeypatch):
    ds, run, _ = copy
    expect_error(capsys, ["import", ds, "--from", "per-face", "--file", run / "estimate.npz", "--exponent", "auto",
                          "-o", tmp_path / "i"], "--exponent must be a number, got 'auto'", inputs=[ds])
    expect_error(capsys, ["bench", "smoke", "-o", tmp_path / "b", "--jobs", "100000"], "--jobs", "[1, 256]",
                 absent=[tmp_path / "b"])
    monkeypatch.setenv("PSEUDOLIGHT_VARIANT", "bogus")
    from estimator import InputError
    from estimator.rays import backend

    with pytest.raises(InputError, match=r"\$PSEUDOLIGHT_VARIANT 'bogus'"):
        backend.resolve_variant()


# ---------------------------------------------------------------- issue 26, second run

@pytest.mark.parametrize("extra, needle", [("frames", "lists 'images/train_000.exr' again (frames[0])"),
                                           ("test_frames", "test_frames[0] lists")])
def test_a_frame_listed_twice_or_a_test_frame_in_training_is_refused(copy, tmp_path, capsys, extra, needle):
    ds, _, _ = copy
    record = json.loads((ds / "transforms.json").read_text())
    if extra == "frames":
        record["frames"].append(record["frames"][0])
    else:
        record["frames"].append(record["test_frames"][0])
        needle = f"{needle} {record['test_frames'][0]['file_path']!r} again (frames["
    (ds / "transforms.json").write_text(json.dumps(record))
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], needle, inputs=[ds], absent=[tmp_path / "r"])


def test_a_dataset_mesh_of_quads_is_refused(copy, tmp_path, capsys):
    """Loading splits each quad into two triangles, which renumbers the faces (their identity)."""
    ds, _, _ = copy
    quads = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nf 1 2 3 4\nf 1 2 5\n"
    (ds / "quads.obj").write_text(quads)
    record = json.loads((ds / "transforms.json").read_text())
    record["mesh_file_path"] = "quads.obj"
    (ds / "transforms.json").write_text(json.dumps(record))
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "declares 2 faces, which load as 3 triangles",
                 "triangulate it first", inputs=[ds], absent=[tmp_path / "r"])


@pytest.mark.parametrize("value, needle", [(-0.2, "is [-0.2"), (1e308, "is [1e+308")])
def test_imported_albedos_that_are_no_reflectance_are_refused(copy, tmp_path, capsys, value, needle):
    ds, run, _ = copy
    arrays = dict(np.load(run / "estimate.npz"))
    arrays["diffuse"][3] = value
    np.savez(tmp_path / "faces.npz", diffuse=arrays["diffuse"], specular=arrays["specular"])
    expect_error(capsys, ["import", ds, "--from", "per-face", "--file", tmp_path / "faces.npz", "-o", tmp_path / "x"],
                 "diffuse albedo of face 3", needle, "an albedo is a reflectance", inputs=[ds],
                 absent=[tmp_path / "x"])


def test_an_image_above_the_pixel_limit_is_refused_before_decoding(copy, tmp_path, capsys, monkeypatch):
    from harness.io import images

    ds, _, _ = copy
    monkeypatch.setattr(images, "MAX_IMAGE_PIXELS", 100)     # the micro frames are 24 x 24
    png = tmp_path / "albedo.png"
    from PIL import Image
    Image.new("RGB", (40, 20)).save(png)
    with pytest.raises(Exception, match=r"albedo.png is 40x20 pixels, above the limit of 100"):
        images.read_linear_rgb(png)


def test_a_full_disk_during_an_exr_write_names_the_output(copy, tmp_path, capsys, monkeypatch):
    """OpenEXR's RuntimeError named the temporary folder and came out as a traceback."""
    import OpenEXR

    ds, _, _ = copy

    def full(self, path):
        raise RuntimeError(f'Failed to write pixel data to image file "{path}". No space left on device.')

    monkeypatch.setattr(OpenEXR.File, "write", full)
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], f"cannot write {tmp_path / 'r'}",
                 "illumination.exr: No space left on device", inputs=[ds], absent=[tmp_path / "r"])


def test_known_light_from_another_scene_is_refused(copy, tmp_path, capsys):
    """``--truth`` pointing at another scene's dataset silently used that scene's light."""
    ds, _, _ = copy
    other = tmp_path / "other"
    shutil.copytree(ds, other)
    record = json.loads((other / "transforms.json").read_text())
    record["scene"] = "another-scene"
    (other / "transforms.json").write_text(json.dumps(record))
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r", "--method", "known-illumination", "--truth", other],
                 "is a dataset of scene 'another-scene'", "the known light must be this scene's",
                 inputs=[ds, other], absent=[tmp_path / "r"])
    # a method that is not given the light has no use for it: the flag is a mistake, not ignored
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r", "--truth", tmp_path / "nowhere"], "--truth",
                 "known-illumination", inputs=[ds], absent=[tmp_path / "r"])


def test_import_warns_about_a_black_or_one_colour_albedo_and_no_light(copy, tmp_path, capsys):
    ds, run, _ = copy
    f = len(np.load(run / "estimate.npz")["diffuse"])
    for values, needle in ((np.zeros((f, 3)), "black on every face"),
                           (np.tile([0.2, 0.3, 0.4], (f, 1)), "one colour on every face")):
        np.savez(tmp_path / "faces.npz", diffuse=values)
        assert main(["import", str(ds), "--from", "per-face", "--file", str(tmp_path / "faces.npz"), "-o",
                     str(tmp_path / "x"), "--overwrite"]) == 0
        err = capsys.readouterr().err
        assert f"diffuse albedo is {needle}" in err and "no light imported" in err


def test_estimate_set_reaches_every_estimator_setting(copy, tmp_path, capsys):
    """Only 13 settings had flags; ``--set KEY=VALUE`` takes any, validated, the key named."""
    ds, _, _ = copy
    assert main(["estimate", str(ds), "-o", str(tmp_path / "r"), "--set", "estimator.sh_order=3",
                 "--set", "min_cos_view=0.4"]) == 0
    capsys.readouterr()
    parameters = json.loads((tmp_path / "r" / "run.json").read_text())["parameters"]
    assert parameters["sh_order"] == 3 and parameters["min_cos_view"] == 0.4
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "x", "--set", "sh_ordr=4"],
                 "--set sh_ordr: not an estimator setting (did you mean sh_order?)", inputs=[ds],
                 absent=[tmp_path / "x"])
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "x", "--set", "sh_order=many"],
                 "--set sh_order:", "sh_order must be int", inputs=[ds], absent=[tmp_path / "x"])


def test_a_bad_flag_value_is_refused_naming_the_flag(copy, tmp_path, capsys):
    """A flag that sets an estimator setting under another name (``--time-budget`` sets
    ``ad_time_budget``) is named in the refusal, beside the setting."""
    ds, _, _ = copy
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "x", "--method", "mitsuba-ad", "--time-budget", "-1"],
                 "--time-budget: estimator config: ad_time_budget must be > 0", inputs=[ds],
                 absent=[tmp_path / "x"])
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "x", "--sh-order", "99"],
                 "--sh-order: estimator config: sh_order must lie in", inputs=[ds], absent=[tmp_path / "x"])
    for setting, needle in (("variant=foo", "--set variant: estimator config: variant must be one of"),
                            ("bandwidth=-1", "--set bandwidth: estimator config: bandwidth and split_bandwidth")):
        expect_error(capsys, ["estimate", ds, "-o", tmp_path / "x", "--set", setting], needle, inputs=[ds],
                     absent=[tmp_path / "x"])


def test_baseline_dataset_size_and_run_warnings_are_checked(copy, tmp_path, capsys):
    """A baseline's dataset_size must be a table of integers, a run's warnings a list of strings."""
    ds, run, rep = copy
    out = tmp_path / "rep2"
    bad = tmp_path / "baseline.json"
    metrics = json.load(open(rep / "metrics.json"))
    from reports.regression import make_baseline
    for size in ("big", {"faces": "many", "views": 6, "width": 24, "height": 24}):
        bad.write_text(json.dumps({**make_baseline(metrics), "dataset_size": size}))
        expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba", "--baseline", bad], str(bad), "dataset_size",
                     inputs=[run, ds, bad], absent=[out])
    archive = dict(np.load(run / "estimate.npz"))
    np.savez(run / "estimate.npz", **{k: v for k, v in archive.items() if k != "pseudo_sh"})
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "estimate.npz", "'pseudo_sh' missing",
                 inputs=[run, ds], absent=[out])
    np.savez(run / "estimate.npz", **archive)
    meta = json.load(open(run / "run.json"))
    meta["warnings"] = 5
    json.dump(meta, open(run / "run.json", "w"))
    expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "run.json", "'warnings'",
                 inputs=[run, ds], absent=[out])


def test_an_unreadable_mesh_is_one_line(copy, tmp_path, capsys, monkeypatch):
    """The mesh's header is read before the mesh: an OSError there names the file."""
    ds, _, _ = copy
    import harness.io.dataset as dataset

    def denied(path):
        raise PermissionError(13, "Permission denied", str(path))
    monkeypatch.setattr(dataset, "polygon_count", denied)
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "o"], "mesh.ply", "Permission denied", inputs=[ds],
                 absent=[tmp_path / "o"])


def test_fl_y_defaults_to_the_fl_x_derived_from_the_field_of_view(copy):
    """With neither focal length given, both come from camera_angle_x (square pixels)."""
    ds, _, _ = copy
    from harness.io.dataset import read_dataset
    meta = json.load(open(ds / "transforms.json"))
    want = read_dataset(str(ds)).data.views[0].camera
    for key in ("fl_x", "fl_y"):
        meta.pop(key, None)
        for frame in meta["frames"]:
            frame.pop(key, None)
    meta["camera_angle_x"] = float(2 * np.arctan(0.5 * want.width / want.fx))
    json.dump(meta, open(ds / "transforms.json", "w"))
    got = read_dataset(str(ds)).data.views[0].camera
    np.testing.assert_allclose([got.fx, got.fy], [want.fx, want.fx], rtol=1e-9)


INTERRUPT_DURING_IMPORT = """
import importlib.abc, os, signal, sys
class Interrupt(importlib.abc.MetaPathFinder):   # Ctrl-C as trimesh's optional imports run
    def find_spec(self, name, path, target=None):
        if name == "trimesh.path":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Interrupt())
from harness.cli.entry import run
sys.exit(run(sys.argv[1:]))
"""


def test_ctrl_c_while_the_command_line_imports_is_honoured(micro, tmp_path):
    """trimesh catches BaseException around its optional imports; the entry point's handler still
    ends the command with 130 and writes nothing (the signal is sent at a fixed import, not a time)."""
    ds = micro[0]
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-c", INTERRUPT_DURING_IMPORT, "estimate", str(ds), "-o", str(out)],
                          capture_output=True, text=True, timeout=300,
                          cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    assert proc.returncode == 130, proc.stderr
    assert "interrupted; no partial output" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists() and not [n for n in os.listdir(tmp_path) if "-partial-" in n]


def test_a_min_pixels_no_face_reaches_names_the_setting(copy, tmp_path, capsys):
    """Faces hit by pixel centres, none with min_pixels of them: the setting is named, not the poses."""
    ds, _, _ = copy
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r", "--set", "min_pixels=1000000"], "min_pixels=1000000",
                 "lower min_pixels", inputs=[ds], absent=[tmp_path / "r"])


def test_a_binary_obj_is_a_one_line_error(tmp_path):
    """Random bytes named .obj: an InputError naming the file, whatever trimesh's optional
    encoding modules (missing, trimesh asks for charset_normalizer)."""
    from estimator import InputError
    from harness.io.mesh import load_mesh_file

    path = tmp_path / "mesh.obj"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(InputError, match=r"cannot read mesh file .*mesh\.obj"):
        load_mesh_file(path)


def test_a_flag_another_import_source_takes_and_a_foreign_run_format_are_refused(copy, tmp_path, capsys):
    """``--file`` beside ``--from uv-textures`` (or ``--mesh`` beside ``--from per-face``) would be
    ignored: refused naming the flag; a run.json whose ``format`` is another is not a run."""
    ds, run, _ = copy
    out = tmp_path / "imp"
    expect_error(capsys, ["import", ds, "--from", "uv-textures", "--mesh", ds / "mesh.ply", "--diffuse", "d.exr",
                          "--file", run / "estimate.npz", "-o", out], "--file", "uv-textures",
                 inputs=[ds], absent=[out])
    expect_error(capsys, ["import", ds, "--from", "per-face", "--file", run / "estimate.npz", "--mesh",
                          ds / "mesh.ply", "-o", out], "--mesh", "per-face", inputs=[ds], absent=[out])
    record = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps({**record, "format": "nope"}))
    expect_error(capsys, ["render", run, "-o", out], "run.json", "'nope'", inputs=[run, ds], absent=[out])


def test_a_mesh_whose_texture_coordinates_are_not_finite_is_named(tmp_path):
    """An OBJ with a NaN ``vt``: one error naming the mesh, not NumPy's warnings and then an
    error blaming the texture sampled through those coordinates."""
    from estimator import InputError
    from harness.io.mesh import load_mesh_with_uv

    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt nan 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    with pytest.raises(InputError, match=r"quad\.obj: its texture coordinates hold NaN"):
        load_mesh_with_uv(path)


# ---------------------------------------------------------------- issue 25/27 session, hostile-input run

def test_text_arrays_a_bare_npy_and_out_of_range_labels_in_a_run_are_refused(copy, capsys):
    """Arrays of text, a .npy saved under the .npz name, labels beyond the faces, a run that
    estimated nothing and a negative albedo each stop with one line naming the file and key."""
    ds, run, _ = copy
    out = run.parent / "rep2"
    good = dict(np.load(run / "estimate.npz"))
    negative = good["diffuse"].copy()
    negative[np.argmax(good["observed"])] = -5.0
    for key, value, needle in (("diffuse", good["diffuse"].astype(str), "diffuse must hold real numbers"),
                               ("pseudo_sh", good["pseudo_sh"].astype(complex), "pseudo_sh must hold real numbers"),
                               ("labels", np.full(80, 10 ** 12), "labels must lie in [-1, 80)"),
                               ("observed", np.zeros(80, bool), "estimated nothing"),
                               ("diffuse", negative, "have a negative albedo")):
        np.savez(run / "estimate.npz", **{**good, key: value})
        expect_error(capsys, ["report", run, "-o", out, "--no-mitsuba"], "estimate.npz", needle,
                     inputs=[run, ds], absent=[out])
    np.save(run / "bare.npy", good["diffuse"])
    os.replace(run / "bare.npy", run / "estimate.npz")
    for command in (["report", run, "-o", out, "--no-mitsuba"], ["render", run, "-o", out]):
        expect_error(capsys, command, "estimate.npz", "a single .npy array", inputs=[run, ds], absent=[out])


def test_text_ground_truth_and_a_bare_npy_per_face_file_are_refused(copy, tmp_path, capsys):
    ds, run, _ = copy
    mats = dict(np.load(ds / "ground_truth" / "materials.npz"))
    np.savez(ds / "ground_truth" / "materials.npz", **{**mats, "diffuse": mats["diffuse"].astype(str)})
    expect_error(capsys, ["report", run, "-o", tmp_path / "r", "--no-mitsuba"], "materials.npz",
                 "diffuse must hold real numbers", inputs=[run, ds], absent=[tmp_path / "r"])
    np.save(tmp_path / "faces.npy", mats["diffuse"])
    os.replace(tmp_path / "faces.npy", tmp_path / "faces.npz")
    expect_error(capsys, ["import", ds, "--from", "per-face", "--file", tmp_path / "faces.npz", "-o", tmp_path / "x"],
                 "faces.npz", "a single .npy array", inputs=[ds], absent=[tmp_path / "x"])


@pytest.mark.parametrize("edit, needle", [
    (lambda run: run.update(cross_validation=[1]), "'cross_validation' must be an object"),
    (lambda run: run.update(cross_validation={"psnr": "x"}), "'cross_validation.psnr' must be a number"),
    (lambda run: run.setdefault("trust", {}).update(outlier_share="high"), "'trust.outlier_share' must be a number"),
])
def test_report_numbers_of_run_json_are_checked(copy, tmp_path, capsys, edit, needle):
    ds, run, _ = copy
    record = json.loads((run / "run.json").read_text())
    edit(record)
    (run / "run.json").write_text(json.dumps(record))
    expect_error(capsys, ["report", run, "-o", tmp_path / "r", "--no-mitsuba"], "run.json", needle,
                 inputs=[run, ds], absent=[tmp_path / "r"])


def test_an_intrinsic_integer_beyond_a_float_is_one_line(copy, tmp_path, capsys):
    ds, _, _ = copy
    record = json.loads((ds / "transforms.json").read_text())
    record["w"] = 10 ** 400
    (ds / "transforms.json").write_text(json.dumps(record))
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "intrinsic 'w' must be a finite number",
                 inputs=[ds], absent=[tmp_path / "r"])


def test_a_frame_listed_again_without_its_extension_is_refused(copy, tmp_path, capsys):
    ds, _, _ = copy
    record = json.loads((ds / "transforms.json").read_text())
    twin = dict(record["frames"][0], file_path=record["frames"][0]["file_path"].removesuffix(".exr"))
    record["frames"].append(twin)
    (ds / "transforms.json").write_text(json.dumps(record))
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "again (frames[0])", inputs=[ds],
                 absent=[tmp_path / "r"])


def test_a_light_that_scales_albedos_beyond_a_reflectance_is_refused_on_import(copy, tmp_path, capsys):
    ds, run, _ = copy
    arrays = dict(np.load(run / "estimate.npz"))
    np.savez(tmp_path / "faces.npz", diffuse=arrays["diffuse"], pseudo_sh=arrays["pseudo_sh"] * 1e300)
    expect_error(capsys, ["import", ds, "--from", "per-face", "--file", tmp_path / "faces.npz", "-o", tmp_path / "x"],
                 "the light's scale is too large", inputs=[ds], absent=[tmp_path / "x"])


def test_an_exr_pixel_beyond_its_float_range_is_refused():
    from estimator import InputError
    from harness.io.exr import write_exr
    image = np.ones((2, 2, 3))
    image[0, 0, 1] = 1e39
    with pytest.raises(InputError, match="exceeds the float32 EXR's range"):
        write_exr("never-written.exr", image)
    image[0, 0, 1] = 7e4
    with pytest.raises(InputError, match="float16"):
        write_exr("never-written.exr", image, half=True)
    assert not os.path.exists("never-written.exr")


def test_an_empty_output_path_and_a_zero_field_of_view_are_one_line(copy, tmp_path, capsys):
    ds, _, _ = copy
    expect_error(capsys, ["estimate", ds, "-o", ""], "the output path is empty", inputs=[ds])
    record = json.loads((ds / "transforms.json").read_text())
    record.pop("fl_x", None)
    record.pop("fl_y", None)
    for frame in record["frames"] + record["test_frames"]:
        frame.pop("fl_x", None)
        frame.pop("fl_y", None)
    record["camera_angle_x"] = 0
    (ds / "transforms.json").write_text(json.dumps(record))
    with np.errstate(all="raise"):   # no numpy warning line before the error
        expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "camera_angle_x must lie in (0, pi)",
                     inputs=[ds], absent=[tmp_path / "r"])


# ---------------------------------------------------------------- third hostile-input run

def test_an_empty_method_name_is_refused_not_taken_for_the_default(copy, tmp_path, capsys):
    ds, _, _ = copy
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r", "--method", ""], "unknown method ''",
                 inputs=[ds], absent=[tmp_path / "r"])


def test_json_nested_too_deeply_is_named_not_a_traceback(copy, tmp_path, capsys):
    """Python's JSON parser recurses once per level: 100,000 nested brackets would raise
    RecursionError; the readers say the file is not valid JSON."""
    ds, run, _ = copy
    deep = "[" * 100_000 + "]" * 100_000
    baseline = tmp_path / "deep.json"
    baseline.write_text(deep)
    expect_error(capsys, ["report", run, "-o", tmp_path / "rep", "--no-mitsuba", "--baseline", baseline],
                 str(baseline), "cannot be read", "nested too deeply", inputs=[run, ds], absent=[tmp_path / "rep"])
    (ds / "transforms.json").write_text(deep)
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "transforms.json", "nested too deeply",
                 inputs=[ds], absent=[tmp_path / "r"])


def test_flags_a_command_would_ignore_and_one_run_compared_with_itself_are_refused(copy, tmp_path, capsys):
    ds, run, rep = copy
    expect_error(capsys, ["export", ds, "-o", tmp_path / "nerf", "--spp", "16"], "--spp applies to --format mitsuba",
                 inputs=[ds], absent=[tmp_path / "nerf"])
    expect_error(capsys, ["compare", run, str(run) + "/", "-o", tmp_path / "cmp"], "is given twice",
                 inputs=[run], absent=[tmp_path / "cmp"])


def test_test_frames_that_are_no_list_are_refused_before_the_estimate(copy, tmp_path, capsys):
    ds, _, _ = copy
    t = json.load(open(ds / "transforms.json"))
    t["test_frames"] = {"file_path": "images/test_000.exr"}
    json.dump(t, open(ds / "transforms.json", "w"))
    expect_error(capsys, ["estimate", ds, "-o", tmp_path / "r"], "test_frames must be a list", inputs=[ds],
                 absent=[tmp_path / "r"])


def test_the_demo_refuses_an_empty_path_pseudolight_output_and_a_foreign_dataset(tmp_path, capsys):
    """Checked before anything renders: an empty -o (the working directory), a folder that is
    itself pseudolight output (a dataset), and a dataset in the demo's place that the demo's
    spec did not render (here the micro scene), which would otherwise be reported as the demo."""
    expect_error(capsys, ["demo", "-o", ""], "output path is empty")
    ds = tmp_path / "ds"
    assert main(["generate", MICRO, "-o", str(ds)]) == 0
    capsys.readouterr()
    expect_error(capsys, ["demo", "-o", ds], "itself pseudolight output (dataset)", inputs=[ds],
                 absent=[ds / "earth-specular"])
    out = tmp_path / "out"
    assert main(["generate", MICRO, "-o", str(out / "earth-specular" / "dataset")]) == 0
    capsys.readouterr()
    expect_error(capsys, ["demo", "-o", out], "not earth-specular's", "scene 'micro' where the spec gives "
                 "'earth-specular'", "--overwrite", inputs=[out / "earth-specular" / "dataset"],
                 absent=[out / "earth-specular" / "run"])


def test_a_fault_asking_for_more_views_than_there_are_is_said(tmp_path, capsys):
    assert main(["generate", MICRO, "-o", str(tmp_path / "d"), "--set", "faults.glare_views=100"]) == 0
    assert "faults.glare_views = 100 asks for more views than the 6 training views; applied to 6" in \
        capsys.readouterr().err
