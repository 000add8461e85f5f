"""The public API refuses what it cannot use with an InputError naming the argument, instead of
a raw numpy error from deep inside, a silently wrong number, or a process aborted by Dr.Jit."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator import (
    Camera,
    EstimatorConfig,
    InputError,
    MultiViewData,
    RayCaster,
    estimate,
    fresnel_dielectric,
    look_at,
    psnr_db,
    sh,
)

from .micro import micro_config, micro_scene


@pytest.fixture(scope="module")
def scene():
    return micro_scene(micro_config())


def test_rays_of_unequal_counts_or_none_are_refused_not_launched(scene):
    """Dr.Jit aborts the process on a launch it cannot size: these never reach it."""
    caster = RayCaster(scene[0].mesh)
    with pytest.raises(InputError, match=r"one shape \(N, 3\), got \(2, 3\) and \(1, 3\)"):
        caster.first_hit_faces(np.zeros((2, 3)), np.ones((1, 3)))
    with pytest.raises(InputError, match=r"got \(1, 3\) and \(0, 3\)"):
        caster.escapes(np.zeros((1, 3)), np.zeros((0, 3)))
    with pytest.raises(InputError, match="samples must be an integer >= 1, got 0"):
        caster.subpixel_faces(scene[0].views[0].camera, 0, np.arange(4))


def test_an_estimate_of_inconsistent_arrays_is_refused(scene):
    truth = scene[1]
    f = len(truth.diffuse)
    with pytest.raises(InputError, match="observed must be bool"):
        dataclasses.replace(truth, observed=np.ones(f, int))
    with pytest.raises(InputError, match=r"diffuse and specular must be \(F, 3\) alike"):
        dataclasses.replace(truth, specular=truth.specular[:-1])
    with pytest.raises(InputError, match="5 is not a number of SH coefficients"):
        dataclasses.replace(truth, pseudo_sh=np.ones((5, 3)))


def test_views_with_one_name_are_refused(scene):
    data = scene[0]
    same = [dataclasses.replace(v, name="same") for v in data.views]
    with pytest.raises(InputError, match="distinct names; repeated: 'same'"):
        MultiViewData(data.mesh, same)
    with pytest.raises(InputError, match="mesh must be a TriangleMesh"):
        MultiViewData(None, data.views)


def test_degenerate_cameras_are_refused():
    with pytest.raises(InputError, match="the eye and the target are one point"):
        look_at(np.zeros(3), np.zeros(3))
    with pytest.raises(InputError, match="width must be an integer number of pixels, got 32.5"):
        Camera(np.eye(4), 10.0, 10.0, 16.0, 16.0, 32.5, 32)
    with pytest.raises(InputError, match="fov_x"):
        Camera.from_fov(np.eye(4), "60", 32, 32)


def test_physical_and_sh_arguments_out_of_their_domain_are_refused():
    with pytest.raises(InputError, match="index of refraction"):
        fresnel_dielectric(np.array([0.5]), -1.5)
    with pytest.raises(InputError, match=r"\|m\| <= l, got \(1, 5\)"):
        sh.index(1, 5)
    with pytest.raises(InputError, match="whole number >= 0, got 2.5"):
        sh.num_coeffs(2.5)
    with pytest.raises(InputError, match="unit vectors: row 0 has length 2"):
        sh.basis(2, np.array([[0.0, 2.0, 0.0]]))
    with pytest.raises(InputError, match="finite mean squared error"):
        psnr_db(-1.0, 1.0)
    with pytest.raises(InputError, match="finite peak > 0"):
        psnr_db(0.1, 0.0)


def test_estimate_checks_its_arguments_and_a_config_changed_after_its_making(scene):
    data = scene[0]
    config = micro_config()
    config.sh_order = -3
    with pytest.raises(InputError, match="sh_order"):
        estimate(data, "median-color", config)
    with pytest.raises(InputError, match=r"known_sh must be \(\(L \+ 1\)\^2, 3\)"):
        estimate(data, "known-illumination", micro_config(), known_sh=np.ones((9, 2)))
    with pytest.raises(InputError, match="log must be a callable"):
        estimate(data, "median-color", micro_config(), log=5)
    with pytest.raises(InputError, match="config must be an EstimatorConfig"):
        estimate(data, "median-color", {"sh_order": 2})
    order = EstimatorConfig(sh_order=np.int64(2)).sh_order     # numpy's integers are taken, held as int
    assert order == 2 and type(order) is int


def test_a_view_and_a_mesh_out_of_their_domain_are_refused(scene):
    from estimator import TriangleMesh, View

    view = scene[0].views[0]
    with pytest.raises(InputError, match=r"alpha must be a coverage in \[0, 1\]"):
        View(view.name, view.camera, view.rgb, np.full(view.rgb.shape[:2], 5.0))
    with pytest.raises(InputError, match="camera must be a Camera"):
        View(view.name, None, view.rgb)
    mesh = scene[0].mesh
    with pytest.raises(InputError, match="face areas overflow"):
        TriangleMesh(mesh.vertices * 1e100, mesh.faces)
    with pytest.raises(InputError, match=r"radiance SH must be \(M, C\)"):
        sh.pseudo_illumination(np.ones(4), 10.0)
    with pytest.raises(InputError, match="lat-long map must be"):
        sh.project_latlong(2, np.ones((1, 8, 3)))
