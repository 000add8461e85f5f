"""Ground-truth renders of a synthetic dataset under rotated illumination (relighting)."""
from __future__ import annotations

import json
import os

import numpy as np

from estimator import Camera
from harness.io.dataset import Dataset
from harness.io.exr import read_exr
from harness.scene.illumination import Illumination
from harness.scene.render import build_scene, render_views


def true_illumination(dataset: Dataset) -> Illumination:
    """The illumination a synthetic dataset was rendered with (from ground_truth/)."""
    if dataset.ground_truth is None:
        raise ValueError(f"{dataset.path} has no ground_truth/: cannot render the true scene")
    info = dataset.ground_truth.illumination
    envmap = None
    if info["kind"] == "envmap":
        envmap = read_exr(os.path.join(dataset.path, "ground_truth", info["envmap_file"]))[..., :3].astype(np.float64)
    return Illumination.from_json(info, envmap)


def render_truth(dataset: Dataset, cameras: list[Camera], rotation: np.ndarray | None = None,
                 spp: int | None = None) -> list[np.ndarray]:
    """Render the dataset's true scene (its mesh, true albedos, BRDF, light turned by
    ``rotation`` (3, 3)) from ``cameras`` -> list of (H, W, 4) RGBA."""
    gt = dataset.ground_truth
    light = true_illumination(dataset)
    if rotation is not None:
        light = light.rotated(rotation)
    with open(os.path.join(dataset.path, "ground_truth", "illumination.json")) as f:
        spec = json.load(f).get("scene_spec", {})
    render = spec.get("render", {})
    spp = spp or int(dataset.meta.get("spp", render.get("spp", 16)))
    integrator = "direct" if light.is_delta else "path"
    scene = build_scene(dataset.data.mesh, gt.diffuse, gt.specular, gt.brdf, light, cameras[0], spp,
                        integrator, int(render.get("max_depth", 6)))
    return render_views(scene, cameras, spp, int(dataset.meta.get("seed", 0)) + 1, desc="ground truth")
