import json
import os

import numpy as np

from harness.cli.main import main
from harness.io.exr import read_exr
from harness.io.runs import read_run


def test_estimate_and_render_commands(tiny_earth, tmp_path, capsys):
    run = tmp_path / "run"
    # the dataset recommends bilinear-per-face with specular components (earth-specular's [estimator])
    assert main(["estimate", tiny_earth, "-o", str(run), "--directions", "300", "--sh-order", "6"]) == 0
    assert sorted(os.listdir(run)) == [".pseudolight-output", "estimate.npz", "illumination.exr", "run.json"]
    meta = json.load(open(run / "run.json"))
    assert meta["method"] == "bilinear-per-face" and meta["parameters"]["components"] == "specular"
    assert meta["parameters"]["sh_order"] == 6 and set(meta["timings"]) >= {"observations", "visibility", "solve"}
    assert meta["versions"]["mitsuba"] == "3.9.1" and meta["residuals"][-1] < meta["residuals"][0]
    est, _ = read_run(str(run))
    assert est.pseudo_sh.shape == (49, 3) and est.specular.shape == (1280, 3) and est.observed.dtype == bool
    env = read_exr(run / "illumination.exr")
    assert env.shape == (128, 256, 3) and env.min() >= 0
    # a second run into the same folder is refused; the first stays intact
    assert main(["estimate", tiny_earth, "-o", str(run), "--method", "median-color"]) == 2
    assert json.load(open(run / "run.json"))["method"] == "bilinear-per-face"
    out = tmp_path / "pred"
    assert main(["render", str(run), "-o", str(out), "--rotate-illumination", "y", "45"]) == 0
    images = sorted(os.listdir(out))
    assert images == [".pseudolight-output", "test_000.exr", "test_001.exr"]
    predicted = read_exr(out / images[1])
    assert predicted.shape == (96, 96, 4)
    # alpha 1 exactly on the pixels of estimated faces: 0 off the mesh and on unestimated faces
    # (faces no training view kept, which a test view shows)
    from estimator import RayCaster
    from harness.io.dataset import read_dataset

    ds = read_dataset(tiny_earth, load_test=True, load_truth=False)
    face = RayCaster(ds.data.mesh).face_id_buffer(ds.data.test_views[0].camera)   # test_000
    estimated = (face >= 0) & est.observed[np.maximum(face, 0)]
    assert ((face >= 0) & ~estimated).any()
    np.testing.assert_array_equal(predicted[..., 3], estimated)
    capsys.readouterr()


def test_estimate_errors(tiny_earth, tmp_path, capsys):
    assert main(["estimate", str(tmp_path / "none"), "-o", str(tmp_path / "r")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["estimate", tiny_earth, "-o", str(tmp_path / "r"), "--method", "nope"]) == 2
    assert "unknown method" in capsys.readouterr().err
    assert main(["render", str(tmp_path), "-o", str(tmp_path / "p")]) == 2
    assert "not a run folder" in capsys.readouterr().err
    assert not (tmp_path / "r").exists() and not (tmp_path / "p").exists()


def test_a_bad_estimator_default_of_the_dataset_is_named_as_transforms_json():
    """A dataset's ``estimator_defaults`` (its scene's [estimator] table, written into
    transforms.json) is refused naming transforms.json: a wrong value, an unknown method, a
    non-object; a value the caller overrides is not checked."""
    import pytest

    from estimator import InputError
    from harness.io.runs import estimator_settings

    for defaults, needle in (({"sh_order": "x"}, "sh_order must be int"),
                             ({"method": "nope"}, "unknown method 'nope'"),
                             ({"shorder": 3}, "unknown key(s) shorder"),
                             ([1], "must be an object")):
        with pytest.raises(InputError) as err:
            estimator_settings({"estimator_defaults": defaults})
        assert str(err.value).startswith("transforms.json estimator_defaults") and needle in str(err.value)
    method, config = estimator_settings({"estimator_defaults": {"method": "nope", "sh_order": "x"}},
                                        "median-color", {"sh_order": 3})
    assert method == "median-color" and config.sh_order == 3
