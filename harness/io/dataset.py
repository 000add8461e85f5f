"""The on-disk dataset format (see docs/dataset-format.md): reading and writing.

One folder: ``transforms.json`` (nerfstudio conventions), ``mesh.ply``,
``images/*.exr`` and, for synthetic sets, ``ground_truth/``.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

from estimator.camera import Camera
from estimator.data import MultiViewData, TriangleMesh, View
from reports.ground_truth import GroundTruth

from harness.io.exr import read_exr, write_exr
from harness.io.mesh import load_mesh_file, save_mesh_ply

FORMAT_NAME = "pseudolight-dataset"
FORMAT_VERSION = 2  # 2: ground_truth/illumination_sh.npz names its array radiance_sh (1: sh)
_INTRINSIC_KEYS = ("w", "h", "fl_x", "fl_y", "cx", "cy")


class DatasetError(ValueError):
    """A dataset folder that does not follow the format; the message names the file or key."""


@dataclass(frozen=True)
class Dataset:
    """A dataset read from disk: the estimator's input plus optional ground truth."""

    path: str
    data: MultiViewData
    ground_truth: GroundTruth | None
    meta: dict


def _frame_json(camera: Camera, file_path: str) -> dict:
    return {"file_path": file_path, "transform_matrix": camera.c2w.tolist()}


def write_dataset(folder: str, mesh: TriangleMesh, views: list[tuple[Camera, np.ndarray]],
                  test_views: list[tuple[Camera, np.ndarray]], meta: dict | None = None,
                  half: bool = False) -> None:
    """Write transforms.json, mesh.ply and images/ into an (empty) folder.

    Parameters
    ----------
    views, test_views : lists of (camera, (H, W, 4) RGBA linear image); all cameras share intrinsics.
    meta : extra top-level keys for transforms.json (e.g. the scene name).
    """
    cams = [c for c, _ in views + test_views]
    first = cams[0]
    for c in cams:
        if (c.width, c.height, c.fx, c.fy, c.cx, c.cy) != (first.width, first.height, first.fx, first.fy, first.cx, first.cy):
            raise ValueError("write_dataset: all cameras must share intrinsics")
    os.makedirs(os.path.join(folder, "images"), exist_ok=True)
    frames, test_frames = [], []
    for prefix, items, out in (("train", views, frames), ("test", test_views, test_frames)):
        for k, (cam, image) in enumerate(items):
            rel = f"images/{prefix}_{k:03d}.exr"
            write_exr(os.path.join(folder, rel), image, half=half)
            out.append(_frame_json(cam, rel))
    save_mesh_ply(mesh, os.path.join(folder, "mesh.ply"))
    transforms = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "camera_model": "PINHOLE",
        "w": first.width, "h": first.height,
        "fl_x": first.fx, "fl_y": first.fy, "cx": first.cx, "cy": first.cy,
        "camera_angle_x": float(np.radians(first.fov_x_deg)),
        "mesh_file_path": "mesh.ply",
        "world_up": [0.0, 1.0, 0.0],
        "color_space": "linear_rec709",
        **(meta or {}),
        "frames": frames,
        "test_frames": test_frames,
    }
    with open(os.path.join(folder, "transforms.json"), "w") as f:
        json.dump(transforms, f, indent=1)


def write_ground_truth(folder: str, truth: GroundTruth, envmap: np.ndarray | None = None,
                       extra: dict | None = None) -> None:
    """Write ground_truth/: materials.npz, illumination.json, illumination_sh.npz (+ envmap.exr)."""
    gt = os.path.join(folder, "ground_truth")
    os.makedirs(gt, exist_ok=True)
    arrays = {"diffuse": truth.diffuse.astype(np.float64), "specular": truth.specular.astype(np.float64)}
    if truth.regions is not None:
        arrays["regions"] = truth.regions.astype(np.int64)
    np.savez(os.path.join(gt, "materials.npz"), **arrays)
    np.savez(os.path.join(gt, "illumination_sh.npz"), radiance_sh=truth.radiance_sh, sh_order=truth.sh_order)
    if envmap is not None:
        write_exr(os.path.join(gt, "envmap.exr"), envmap)
    with open(os.path.join(gt, "illumination.json"), "w") as f:
        json.dump({"brdf": truth.brdf, "illumination": truth.illumination, **(extra or {})}, f, indent=1)


def _intrinsics(where: str, frame: dict, top: dict) -> Camera:
    values = {}
    for key in _INTRINSIC_KEYS:
        value = frame.get(key, top.get(key))
        if key in ("fl_y",) and value is None:
            value = frame.get("fl_x", top.get("fl_x"))
        if key == "fl_x" and value is None:
            angle = frame.get("camera_angle_x", top.get("camera_angle_x"))
            w = frame.get("w", top.get("w"))
            if angle is not None and w is not None:
                value = 0.5 * w / np.tan(0.5 * angle)
        if key in ("cx", "cy") and value is None:
            size = frame.get("w" if key == "cx" else "h", top.get("w" if key == "cx" else "h"))
            value = None if size is None else 0.5 * size
        if value is None:
            raise DatasetError(f"{where}: intrinsic '{key}' missing (top level or per frame)")
        values[key] = value
    matrix = np.asarray(frame.get("transform_matrix"), dtype=np.float64)
    if matrix.shape != (4, 4):
        raise DatasetError(f"{where}: transform_matrix must be 4x4")
    try:
        return Camera(matrix, float(values["fl_x"]), float(values["fl_y"]), float(values["cx"]),
                      float(values["cy"]), int(values["w"]), int(values["h"]))
    except ValueError as exc:
        raise DatasetError(f"{where}: {exc}") from exc


def _read_views(folder: str, frames: list, top: dict, key: str) -> list[View]:
    views = []
    for k, frame in enumerate(frames):
        where = f"transforms.json {key}[{k}]"
        if "file_path" not in frame:
            raise DatasetError(f"{where}: file_path missing")
        cam = _intrinsics(where, frame, top)
        path = os.path.join(folder, frame["file_path"])
        if not os.path.splitext(path)[1]:
            path += ".exr"
        if not os.path.isfile(path):
            raise DatasetError(f"{where}: image not found: {path}")
        image = read_exr(path)
        alpha = image[..., 3] if image.shape[2] == 4 else None
        try:
            views.append(View(frame["file_path"], cam, image[..., :3], alpha))
        except ValueError as exc:
            raise DatasetError(f"{path}: {exc}") from exc
    return views


def read_ground_truth(folder: str, num_faces: int) -> GroundTruth | None:
    """ground_truth/ of a dataset, or None when it has none."""
    gt = os.path.join(folder, "ground_truth")
    if not os.path.isdir(gt):
        return None
    try:
        mats = np.load(os.path.join(gt, "materials.npz"))
        shz = np.load(os.path.join(gt, "illumination_sh.npz"))
        with open(os.path.join(gt, "illumination.json")) as f:
            info = json.load(f)
    except (OSError, ValueError, KeyError) as exc:
        raise DatasetError(f"{gt}: unreadable ground truth: {exc}") from exc
    for key in ("diffuse", "specular"):
        if mats[key].shape != (num_faces, 3):
            raise DatasetError(f"{gt}/materials.npz: {key} has shape {mats[key].shape}, mesh has {num_faces} faces")
    radiance = shz["radiance_sh"] if "radiance_sh" in shz else shz["sh"]  # format 1 named it sh
    return GroundTruth(diffuse=mats["diffuse"], specular=mats["specular"], radiance_sh=radiance,
                       brdf=info["brdf"], illumination=info["illumination"],
                       regions=mats["regions"] if "regions" in mats else None)


def read_dataset(folder: str | os.PathLike, load_test: bool = True) -> Dataset:
    """Read a dataset folder; every missing or malformed part raises :class:`DatasetError`."""
    folder = os.path.abspath(str(folder))
    tpath = os.path.join(folder, "transforms.json")
    if not os.path.isdir(folder):
        raise DatasetError(f"dataset folder not found: {folder}")
    if not os.path.isfile(tpath):
        raise DatasetError(f"{folder} has no transforms.json")
    try:
        with open(tpath) as f:
            top = json.load(f)
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{tpath} is not valid JSON: {exc}") from exc
    mesh_path = os.path.join(folder, top.get("mesh_file_path", "mesh.ply"))
    if not os.path.isfile(mesh_path):
        raise DatasetError(f"{folder} has no mesh ({os.path.basename(mesh_path)} not found)")
    try:
        mesh = load_mesh_file(mesh_path)
    except ValueError as exc:
        raise DatasetError(str(exc)) from exc
    frames = top.get("frames", [])
    if not frames:
        raise DatasetError(f"{tpath} has no frames")
    views = _read_views(folder, frames, top, "frames")
    test_views = _read_views(folder, top.get("test_frames", []), top, "test_frames") if load_test else []
    meta = {k: v for k, v in top.items() if k not in ("frames", "test_frames")}
    return Dataset(folder, MultiViewData(mesh, views, test_views), read_ground_truth(folder, mesh.num_faces), meta)
