"""Property-based fuzzing of the command line's inputs (hypothesis).

Valid scene specs, ``transforms.json`` files, images and npz files are mutated at
random; every run must end either successfully (exit 0) or with exactly one
error line and exit 2, never with a traceback, and must leave its inputs unchanged.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile

import numpy as np
import OpenEXR
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness.cli.main import main

from .test_hostile_inputs import MICRO, snapshot

FUZZ = settings(max_examples=int(os.environ.get("PSEUDOLIGHT_FUZZ_EXAMPLES", 20)), deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

TOML_VALUES = ["nan", "-inf", "inf", "-1", "0", "1e308", "-1e-308", "3", "0.5", '"text"', "[]", "[1, 2]",
               "[0.0, 0.0, 0.0]", "true", "{ a = 1 }", '""', "[nan, 1, 1]", '"../../etc/passwd"']
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.text(max_size=8)
    | st.floats(allow_nan=True, allow_infinity=True),
    lambda children: st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=6), children, max_size=4),
    max_leaves=12)
PIXELS = st.sampled_from([np.nan, np.inf, -np.inf, -1e30, 1e30, -0.5, 0.0, 2.0, 65504.0])


@pytest.fixture(scope="module")
def micro_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    ds, run = root / "dataset", root / "run"
    assert main(["generate", MICRO, "-o", str(ds)]) == 0
    assert main(["estimate", str(ds), "-o", str(run)]) == 0
    return ds, run


def run_and_check(argv: list, inputs: list, capsys) -> int:
    before = snapshot(*inputs)
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code in (0, 2), err
    if code == 2:
        lines = [line for line in err.splitlines() if line.startswith("pseudolight")]
        assert len(lines) == 1, err
    assert "Traceback" not in err
    assert snapshot(*inputs) == before
    return code


def _workspace(micro_dataset):
    work = tempfile.mkdtemp(prefix="fuzz-")
    ds = os.path.join(work, "dataset")
    shutil.copytree(micro_dataset[0], ds)
    return work, ds


def _mutate_toml(path: str, line: int, value: str, drop: bool) -> str:
    """The TOML file at ``path`` with its ``line``-th assignment (modulo their count) dropped,
    or its value replaced by ``value``."""
    lines = open(path).read().splitlines()
    assignments = [i for i, text in enumerate(lines) if " = " in text and not text.startswith("#")]
    index = assignments[line % len(assignments)]
    if drop:
        del lines[index]
    else:
        lines[index] = f"{lines[index].split(' = ')[0]} = {value}"
    return "\n".join(lines) + "\n"


@FUZZ
@given(line=st.integers(0, 200), value=st.sampled_from(TOML_VALUES), drop=st.booleans())
def test_mutated_specs(line, value, drop, capsys):
    work = tempfile.mkdtemp(prefix="fuzz-")
    try:
        spec = os.path.join(work, "spec.toml")
        open(spec, "w").write(_mutate_toml(MICRO, line, value, drop))
        run_and_check(["generate", spec, "-o", os.path.join(work, "out")], [spec], capsys)
    finally:
        shutil.rmtree(work)


def _mutate_json(document, path_choice: int, value):
    """Replace (or delete, for value None with even path_choice) one node of a JSON document."""
    nodes = []

    def walk(node, parent, key):
        nodes.append((parent, key))
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, node, k)
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, node, i)

    walk(document, None, None)
    parent, key = nodes[path_choice % len(nodes)]
    if parent is None:
        return value
    if value is None and isinstance(parent, dict) and path_choice % 2 == 0:
        del parent[key]
    else:
        parent[key] = value
    return document


@FUZZ
@given(path_choice=st.integers(0, 10**6), value=JSON_VALUES)
def test_mutated_transforms_json(micro_dataset, path_choice, value, capsys):
    work, ds = _workspace(micro_dataset)
    try:
        path = os.path.join(ds, "transforms.json")
        doc = _mutate_json(json.load(open(path)), path_choice, value)
        open(path, "w").write(json.dumps(doc))
        run_and_check(["estimate", ds, "-o", os.path.join(work, "run")], [ds], capsys)
    finally:
        shutil.rmtree(work)


LENS_VALUES = st.one_of(st.floats(-3, 3), st.sampled_from([float("nan"), float("inf"), "x", None, True, [0.1]]))


@FUZZ
@given(model=st.sampled_from(["PINHOLE", "SIMPLE_PINHOLE", "OPENCV", "OPENCV_FISHEYE", "FOV", "", 3]),
       keys=st.dictionaries(st.sampled_from(["k1", "k2", "k3", "k4", "p1", "p2"]), LENS_VALUES, max_size=4),
       per_frame=st.booleans())
def test_camera_models_and_distortion(micro_dataset, model, keys, per_frame, capsys):
    """Any camera model and distortion coefficients, at the top or on one frame: success (a
    supported lens is undistorted on reading) or one line and exit 2."""
    work, ds = _workspace(micro_dataset)
    try:
        path = os.path.join(ds, "transforms.json")
        doc = json.load(open(path))
        target = doc["frames"][0] if per_frame else doc
        target.update({"camera_model": model, **keys})
        open(path, "w").write(json.dumps(doc))
        run_and_check(["estimate", ds, "-o", os.path.join(work, "run")], [ds], capsys)
    finally:
        shutil.rmtree(work)


@FUZZ
@given(view=st.integers(0, 5), value=PIXELS, y=st.integers(0, 20), x=st.integers(0, 20), size=st.integers(1, 12),
       channel=st.integers(0, 3))
def test_mutated_images(micro_dataset, view, value, y, x, size, channel, capsys):
    work, ds = _workspace(micro_dataset)
    try:
        path = os.path.join(ds, "images", f"train_{view:03d}.exr")
        with OpenEXR.File(path) as f:
            rgba = np.array(f.channels()["RGBA"].pixels, dtype=np.float32)
        rgba[y:y + size, x:x + size, channel] = value
        with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"RGBA": rgba}) as f:
            f.write(path)
        run_and_check(["estimate", ds, "-o", os.path.join(work, "run")], [ds], capsys)
    finally:
        shutil.rmtree(work)


NPZ_ARRAYS = st.sampled_from([
    np.zeros((0, 3)), np.full((80, 3), np.nan), np.ones((80, 2)), np.ones((79, 3)), np.array(["a", "b"]),
    np.ones((80, 3)) * -1, np.ones(80, dtype=np.int64), np.ones((80, 3), dtype=np.float16), np.array(3.0),
    np.full((9, 3), np.inf), np.ones((9, 3)), np.ones((121, 3)),
])


@FUZZ
@given(target=st.sampled_from(["ground_truth/materials.npz", "ground_truth/illumination_sh.npz", "estimate.npz"]),
       key_choice=st.integers(0, 100), array=NPZ_ARRAYS, mode=st.sampled_from(["replace", "drop", "garbage"]))
def test_mutated_npz_files(micro_dataset, target, key_choice, array, mode, capsys):
    work, ds = _workspace(micro_dataset)
    run = os.path.join(work, "run")
    shutil.copytree(micro_dataset[1], run)
    meta = json.load(open(os.path.join(run, "run.json")))
    meta["dataset"] = ds
    json.dump(meta, open(os.path.join(run, "run.json"), "w"))
    try:
        path = os.path.join(run if target == "estimate.npz" else ds, target)
        if mode == "garbage":
            open(path, "wb").write(bytes(range(97)) * 3)
        else:
            data = dict(np.load(path))
            key = sorted(data)[key_choice % len(data)]
            if mode == "drop":
                del data[key]
            else:
                data[key] = array
            np.savez(path, **data)
        run_and_check(["report", run, "-o", os.path.join(work, "report"), "--no-mitsuba"], [ds, run], capsys)
    finally:
        shutil.rmtree(work)


SUITE_VALUES = TOML_VALUES + ['"no-such-scene"', '["bilinear-clustered", 3]', '{ "cameras.count" = [] }',
                              '{ "cameras.count" = "x" }', '{ "nope.key" = 1 }', '[[1]]']


@FUZZ
@given(line=st.integers(0, 50), value=st.sampled_from(SUITE_VALUES), drop=st.booleans())
def test_mutated_suites(line, value, drop, capsys):
    """A suite file with one line changed or dropped, expanded by ``bench --dry-run`` (nothing runs)."""
    smoke = os.path.join(os.path.dirname(MICRO), "..", "..", "scenes", "suites", "smoke.toml")
    work = tempfile.mkdtemp(prefix="fuzz-")
    try:
        suite = os.path.join(work, "suite.toml")
        open(suite, "w").write(_mutate_toml(smoke, line, value, drop))
        run_and_check(["bench", suite, "-o", os.path.join(work, "out"), "--dry-run"], [suite], capsys)
        assert not os.path.exists(os.path.join(work, "out"))
    finally:
        shutil.rmtree(work)


XML_VALUES = ["abc", "nan", "-1", "1e308", "0.5", "", "1 2", "0,0,0"]


@FUZZ
@given(kind=st.sampled_from(["per-face-csv", "xml"]), value=st.sampled_from(XML_VALUES), row=st.integers(0, 90),
       column=st.integers(0, 5))
def test_mutated_imports(micro_dataset, kind, value, row, column, capsys):
    """A per-face CSV with one cell changed, or a Mitsuba XML with one value changed, imported
    (unchanged, both import: ``0.5`` is among the values)."""
    work, ds = _workspace(micro_dataset)
    try:
        est = np.load(os.path.join(micro_dataset[1], "estimate.npz"))
        if kind == "per-face-csv":
            table = np.concatenate([est["diffuse"], est["specular"]], axis=1).astype(object)
            lines = ["diffuse_r,diffuse_g,diffuse_b,specular_r,specular_g,specular_b"]
            lines += [",".join(f"{v:.6g}" for v in r) for r in table]
            body = lines[1 + row % (len(lines) - 1)].split(",")
            body[column] = value
            lines[1 + row % (len(lines) - 1)] = ",".join(body)
            source = os.path.join(work, "faces.csv")
            open(source, "w").write("\n".join(lines) + "\n")
            argv = ["import", ds, "--from", "per-face", "--file", source, "-o", os.path.join(work, "run")]
        else:
            from harness.io.exr import write_exr
            from harness.io.mesh import load_mesh_file, write_uv_ply

            mesh = load_mesh_file(os.path.join(ds, "mesh.ply"))   # the dataset's mesh, with UVs (Mitsuba's ply)
            uv = np.tile([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]], (mesh.num_faces, 1, 1))
            write_uv_ply(os.path.join(work, "object.ply"), mesh.vertices[mesh.faces], uv)
            write_exr(os.path.join(work, "env.exr"), np.ones((8, 16, 3), np.float32))
            values = ["0.5", "0.5", "1"]
            values[column % 3] = value
            source = os.path.join(work, "scene.xml")
            open(source, "w").write(
                "<scene version='3.0.0'><shape type='ply'><string name='filename' value='object.ply'/>"
                f"<bsdf type='blendbsdf'><float name='weight' value='{values[0]}'/>"
                f"<bsdf type='diffuse'><rgb name='reflectance' value='{values[1]}'/></bsdf>"
                "<bsdf type='conductor'/></bsdf></shape>"
                f"<emitter type='envmap'><string name='filename' value='env.exr'/>"
                f"<float name='scale' value='{values[2]}'/></emitter></scene>")
            argv = ["import", ds, "--from", "mitsuba-xml", "--file", source, "-o", os.path.join(work, "run")]
        run_and_check(argv, [ds, source], capsys)
    finally:
        shutil.rmtree(work)
