"""The differentiable-rendering peer: registered, time-bounded, its loss falls, and its
result has the shape and gauge of every estimate."""
import os

import numpy as np
import pytest

from estimator import REGISTRY, estimate
from estimator.config import EstimatorConfig
from estimator.core.errors import InputError
from estimator.methods.mitsuba_ad import downsample, resolution_factor, scaled_camera
from harness.io.dataset import read_dataset
from harness.scene.generate import generate
from harness.scene.spec import load_spec
from tests.estimator.micro import micro_scene

MICRO = os.path.join(os.path.dirname(os.path.dirname(__file__)), "fixtures", "micro.toml")


def test_resolution_factor_and_downsampling():
    assert resolution_factor(256, 256, 64) == 4 and resolution_factor(24, 24, 64) == 1
    assert resolution_factor(96, 64, 30) == 2
    from estimator.core.camera import Camera, look_at
    from estimator.core.data import View
    cam = Camera(look_at(np.array([0.0, 0.0, 3.0]), np.zeros(3)), 40.0, 40.0, 16.0, 16.0, 32, 32)
    view = View("v", cam, np.arange(32 * 32 * 3, dtype=np.float32).reshape(32, 32, 3), None)
    small = downsample(view, 4)
    assert small.shape == (8, 8, 3) and small[0, 0, 0] == pytest.approx(view.rgb[:4, :4, 0].mean())
    half = scaled_camera(cam, 2)
    assert (half.width, half.fx, half.cx) == (16, 20.0, 8.0) and half.fov_x_deg == pytest.approx(cam.fov_x_deg)


@pytest.mark.parametrize("layout, steps", [("atlas", 80), ("face", 40)])
def test_mitsuba_ad_runs_its_steps_and_fits(tmp_path, layout, steps):
    """A step-capped run under a budget no machine reaches: the same steps everywhere (the
    atlas's learning rate decays over its run, so it is given more of them to halve its loss)."""
    assert "mitsuba-ad" in REGISTRY
    generate(load_spec(MICRO), str(tmp_path / "micro"))
    data = read_dataset(str(tmp_path / "micro"), load_test=False).data
    est = estimate(data, "mitsuba-ad", EstimatorConfig(sh_order=2, directions=100, ad_time_budget=3600.0,
                                                       ad_max_steps=steps, ad_albedo=layout, ad_texture_size=64))
    loss = est.info["ad_history"]["loss"]
    assert est.info["steps"] == steps and np.mean(loss[-3:]) < 0.5 * np.mean(loss[:3])
    assert est.diffuse.shape == (80, 3) and np.all(est.diffuse >= 0)
    assert est.specular.shape == (80, 3) and np.all(est.specular >= 0)
    if layout == "face":
        assert np.any(est.specular > 0) and est.info["degrees_of_freedom"]["unknowns"] > 2 * 3 * 80   # the coat
    else:   # principled: no Phong specular albedo; a base colour per texel and one roughness
        assert np.all(est.specular == 0) and 0.02 <= est.info["roughness"] <= 1.0
        assert est.info["degrees_of_freedom"]["unknowns"] > 3 * 64 * 64
    np.testing.assert_allclose(est.pseudo_sh[0], 1.0)
    history = est.face_stats["albedo_history"]
    assert history.shape[0] == 80 and history.shape[2] == 3 and history.shape[1] >= 2
    # the report scores every snapshot: the error-against-time curve of the comparison
    from reports.evaluate import evaluate
    truth = read_dataset(str(tmp_path / "micro"), load_test=False).ground_truth
    diffuse = evaluate(data.mesh, truth, est).metrics["albedo"]["diffuse"]
    curve = diffuse["psnr_history"]
    assert len(curve["seconds"]) == len(curve["psnr_lstsq"]) == history.shape[1]
    assert np.all(np.diff(curve["seconds"]) > 0) and all(np.isfinite(curve["psnr_lstsq"]))
    # and from the written run, as report and compare read it
    from harness.io.runs import read_run, write_run
    write_run(str(tmp_path / "run"), est, str(tmp_path / "micro"))
    again, _ = read_run(str(tmp_path / "run"))
    assert evaluate(data.mesh, truth, again).metrics["albedo"]["diffuse"]["psnr_history"] == curve
    with pytest.raises(InputError, match="ad_time_budget"):
        EstimatorConfig(ad_time_budget=0.0)
    with pytest.raises(InputError, match="ad_albedo"):
        EstimatorConfig(ad_albedo="vertex")


def test_mitsuba_ad_takes_at_least_one_step_whatever_its_budget(tmp_path):
    """--time-budget 1e-9 ran no step and returned the initial guess with exit 0."""
    generate(load_spec(MICRO), str(tmp_path / "micro"))
    data = read_dataset(str(tmp_path / "micro"), load_test=False).data
    est = estimate(data, "mitsuba-ad", EstimatorConfig(sh_order=2, directions=100, ad_time_budget=1e-9))
    assert est.info["steps"] == 1
    assert any(f"ran 1 step(s) in its budget (1e-09 s), fewer than the {len(data.views)} views" in w
               for w in est.info["warnings"])


def test_a_stop_request_ends_the_fit_at_its_next_step():
    """A SIGTERM raised inside Dr.Jit's loop callback could be swallowed and the fit ran on:
    the handler's stop request is checked at every step."""
    from estimator import StopRequested, clear_stop, request_stop

    data, _ = micro_scene()
    request_stop()
    try:
        with pytest.raises(StopRequested):
            estimate(data, "mitsuba-ad", EstimatorConfig(sh_order=2, directions=100, ad_time_budget=3600.0))
    finally:
        clear_stop()
