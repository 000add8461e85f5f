"""A dataset in the Blender / NeRF-synthetic layout that most inverse-rendering code reads.

Layout::

    transforms_{train,val,test}.json   camera_angle_x, frames[file_path, transform_matrix]
    train/r_000.png (RGBA, 8-bit sRGB) and train/r_000.exr (linear), test/...
    ground_truth/  mesh.obj + material.mtl and mesh.glb (UVs, xatlas), the true per-face
                   albedos baked as diffuse/specular PNG + EXR textures, radiance.exr

``file_path`` has no extension (``./train/r_000``; readers append ``.png``). The layout has
no third split of its own here: ``transforms_val.json`` lists the test frames (nerfstudio's
Blender parser and the original NeRF loader both open it). The layout holds one camera
(``camera_angle_x``), so a dataset whose frames differ in size or focal length is refused
(``--format mitsuba`` keeps each frame's own). Camera
matrices are OpenGL camera-to-world, as in ours. The PNGs are the linear images divided
by ``exposure`` (the 99th-percentile object value over all training views, written in both
JSON files), clipped and sRGB-encoded; the EXRs are the linear images themselves.
"""
from __future__ import annotations

import json
import os

import numpy as np
from PIL import Image

from estimator import Camera, Estimate, EstimatorConfig, InputError, View
from harness.io.dataset import Dataset, view_rgba
from harness.io.exr import write_exr
from harness.io.texture import export_textures, srgb8


def exposure_of(views: list[View]) -> float:
    """The 99th percentile of the object pixels' largest channel over ``views`` (1 if none)."""
    values = [v.rgb[(v.alpha > 0) if v.alpha is not None else np.ones(v.rgb.shape[:2], bool)].max(axis=1)
              for v in views]
    values = np.concatenate(values) if values else np.zeros(0)
    return float(np.percentile(values, 99)) if values.size and np.percentile(values, 99) > 0 else 1.0


def ground_truth_estimate(ds: Dataset) -> Estimate:
    """The dataset's ground truth as an Estimate (for baking it as textures)."""
    truth = ds.ground_truth
    f = ds.data.mesh.num_faces
    radiance = truth.radiance_sh[: (EstimatorConfig().sh_order + 1) ** 2]
    return Estimate(truth.diffuse, truth.specular, radiance, np.arange(f), np.ones(f, bool), "ground-truth",
                    EstimatorConfig(), {}, radiance)


def write_nerf_synthetic(ds: Dataset, out_dir: str, texture_size: int = 1024) -> dict:
    """Write ``ds`` (read with its test views and ground truth) into ``out_dir`` (which must
    exist). Returns a summary (frame counts, exposure, camera_angle_x)."""
    views = {"train": ds.data.views, "test": ds.data.test_views}
    exposure = exposure_of(ds.data.views)
    first: Camera = ds.data.views[0].camera
    for view in ds.data.views + ds.data.test_views:
        c = view.camera
        if (c.width, c.height, c.fx, c.fy, c.cx, c.cy) != (first.width, first.height, first.fx, first.fy, first.cx,
                                                            first.cy):
            raise InputError(f"{view.name}: its intrinsics ({c.width}x{c.height}, fl_x {c.fx:g}) differ from the first "
                             f"frame's ({first.width}x{first.height}, fl_x {first.fx:g}); the NeRF-synthetic layout "
                             "holds one camera: use --format mitsuba")
    angle = float(np.radians(first.fov_x_deg))
    for split, items in views.items():
        os.makedirs(os.path.join(out_dir, split), exist_ok=True)
        frames = []
        for k, view in enumerate(items):
            stem = f"{split}/r_{k:03d}"
            image = view_rgba(view)
            rgba = np.empty(image.shape[:2] + (4,), np.uint8)
            rgba[..., :3] = srgb8(image[..., :3] / exposure)
            rgba[..., 3] = np.round(255 * np.clip(image[..., 3], 0, 1)).astype(np.uint8)
            Image.fromarray(rgba, "RGBA").save(os.path.join(out_dir, f"{stem}.png"))
            write_exr(os.path.join(out_dir, f"{stem}.exr"), image)
            frames.append({"file_path": f"./{stem}", "transform_matrix": view.camera.c2w.tolist(),
                           "source": view.name})
        record = {"camera_angle_x": angle, "w": first.width, "h": first.height, "fl_x": first.fx,
                  "fl_y": first.fy, "cx": first.cx, "cy": first.cy, "exposure": exposure,
                  "color_space": "srgb png / linear exr", "frames": frames}
        for name in (("train",) if split == "train" else ("val", "test")):
            with open(os.path.join(out_dir, f"transforms_{name}.json"), "w") as f:
                json.dump(record, f, indent=1)
    summary = {"train": len(views["train"]), "test": len(views["test"]), "exposure": exposure,
               "camera_angle_x": angle}
    if ds.ground_truth is not None:
        folder = os.path.join(out_dir, "ground_truth")
        os.makedirs(folder)
        summary["ground_truth"] = export_textures(folder, ds.data.mesh, ground_truth_estimate(ds), None, texture_size)
    return summary
