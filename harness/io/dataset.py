"""The on-disk dataset format (see docs/dataset-format.md): reading and writing.

One folder: ``transforms.json`` (nerfstudio conventions), ``mesh.ply``,
``images/*.exr`` and, for synthetic sets, ``ground_truth/``.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass

import numpy as np
from PIL import Image

from estimator import Camera, InputError, MultiViewData, TriangleMesh, View
from harness.io.arrays import read_npz, real_array
from harness.io.exr import read_exr, write_exr
from harness.io.images import read_linear_rgb
from harness.io.jsonio import load_json
from harness.io.lens import CAMERA_MODELS, COEFFICIENTS, Lens, undistort_image
from harness.io.mesh import load_mesh_file, polygon_count, save_mesh_ply
from reports.ground_truth import GroundTruth

FORMAT_NAME = "pseudolight-dataset"
FORMAT_VERSION = 2  # 2: ground_truth/illumination_sh.npz names its array radiance_sh (1: sh)
_INTRINSIC_KEYS = ("w", "h", "fl_x", "fl_y", "cx", "cy")


class DatasetError(InputError):
    """A dataset folder that does not follow the format; the message names the file or key."""


@dataclass(frozen=True)
class Dataset:
    """A dataset read from disk: the estimator's input plus optional ground truth."""

    path: str
    data: MultiViewData
    ground_truth: GroundTruth | None
    meta: dict
    files: tuple = ()  # every file read (mesh, images), which may lie outside ``path``

    @property
    def inputs(self) -> list[str]:
        """The folder and every file read from it or elsewhere: what an output must not touch."""
        return [self.path, *self.files]


def _frame_json(camera: Camera, file_path: str) -> dict:
    return {"file_path": file_path, "transform_matrix": camera.c2w.tolist()}


def write_dataset(folder: str, mesh: TriangleMesh, views: list[tuple[Camera, np.ndarray]],
                  test_views: list[tuple[Camera, np.ndarray]], meta: dict | None = None,
                  half: bool = False, ldr: list[np.ndarray | None] | None = None) -> None:
    """Write transforms.json, mesh.ply and images/ into an (empty) folder.

    Parameters
    ----------
    views, test_views : lists of (camera, (H, W, 4) RGBA linear image); all cameras share intrinsics.
    meta : extra top-level keys for transforms.json (e.g. the scene name).
    ldr : per training view, an (H, W, 4) uint8 sRGB RGBA image or None: the frame then
        points at it as PNG (what a camera's 8-bit output holds), the EXR kept as
        ``hdr_file_path``.
    """
    cams = [c for c, _ in views + test_views]
    first = cams[0]
    for c in cams:
        if (c.width, c.height, c.fx, c.fy, c.cx, c.cy) != (
            first.width,
            first.height,
            first.fx,
            first.fy,
            first.cx,
            first.cy,
        ):
            raise ValueError("write_dataset: all cameras must share intrinsics")
    os.makedirs(os.path.join(folder, "images"), exist_ok=True)
    frames, test_frames = [], []
    for prefix, items, out in (("train", views, frames), ("test", test_views, test_frames)):
        for k, (cam, image) in enumerate(items):
            rel = f"images/{prefix}_{k:03d}.exr"
            write_exr(os.path.join(folder, rel), image, half=half)
            low = ldr[k] if ldr is not None and prefix == "train" else None
            if low is None:
                out.append(_frame_json(cam, rel))
                continue
            png = f"images/{prefix}_{k:03d}.png"
            Image.fromarray(low, "RGBA").save(os.path.join(folder, png))
            out.append({**_frame_json(cam, png), "hdr_file_path": rel})
    save_mesh_ply(mesh, os.path.join(folder, "mesh.ply"))
    transforms = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "camera_model": "PINHOLE",
        "mesh_file_path": "mesh.ply",
        "world_up": [0.0, 1.0, 0.0],
        "color_space": "linear_rec709",
        **(meta or {}),
        # the cameras' own intrinsics win over any copied from another dataset's meta
        "w": first.width, "h": first.height,
        "fl_x": first.fx, "fl_y": first.fy, "cx": first.cx, "cy": first.cy,
        "camera_angle_x": float(np.radians(first.fov_x_deg)),
        "frames": frames,
        "test_frames": test_frames,
    }
    with open(os.path.join(folder, "transforms.json"), "w") as f:
        json.dump(transforms, f, indent=1)
    missing = [path for frame in frames + test_frames for path in (frame["file_path"], frame.get("hdr_file_path"))
               if path and not os.path.isfile(os.path.join(folder, path))]
    if missing:   # complete by construction: never published with a frame short
        raise OSError(f"{len(missing)} of the {len(frames) + len(test_frames)} frames' images vanished while the "
                      f"dataset was written ({', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''})")


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


def _number(where: str, key: str, value) -> float:
    try:   # an integer beyond a float's range (JSON integers are unbounded) overflows
        number = None if isinstance(value, bool) or not isinstance(value, (int, float)) else float(value)
    except OverflowError:
        number = None
    if number is None or not np.isfinite(number):
        raise DatasetError(f"{where}: intrinsic '{key}' must be a finite number, got {repr(value)[:40]}")
    return number


def _lens(where: str, frame: dict, top: dict) -> Lens | None:
    """The frame's lens distortion (frame keys win over top-level ones), or None for a
    pinhole camera. Only nerfstudio's camera models are read; any other is refused."""
    model = frame.get("camera_model", top.get("camera_model", "PINHOLE"))
    if model not in CAMERA_MODELS:
        raise DatasetError(f"{where}: camera_model {model!r} is not supported (one of {', '.join(CAMERA_MODELS)}; "
                           "undistort the images first, e.g. with COLMAP's image_undistorter)")
    values = {key: frame.get(key, top.get(key, 0.0)) for key in COEFFICIENTS}
    if model in ("PINHOLE", "SIMPLE_PINHOLE"):
        if any(values.values()):
            key = next(k for k, v in values.items() if v)
            raise DatasetError(f"{where}: camera_model {model!r} has no lens distortion, but {key} = "
                               f"{values[key]!r}; write camera_model OPENCV (or OPENCV_FISHEYE) for a distorted lens")
        return None
    try:   # Lens names a coefficient that is not a finite number
        lens = Lens(model, **values)
    except InputError as exc:
        raise DatasetError(f"{where}: {exc}") from None
    return None if lens.is_identity else lens


def _intrinsics(where: str, frame: dict, top: dict) -> Camera:
    values = {}
    for key in _INTRINSIC_KEYS:
        value = frame.get(key, top.get(key))
        if key == "fl_y" and value is None:   # square pixels: fl_x as given or derived from camera_angle_x
            value = values.get("fl_x")
        if key == "fl_x" and value is None:
            angle = frame.get("camera_angle_x", top.get("camera_angle_x"))
            w = frame.get("w", top.get("w"))
            if angle is not None and w is not None:
                angle = _number(where, "camera_angle_x", angle)
                if not 0 < angle < np.pi:
                    raise DatasetError(f"{where}: camera_angle_x must lie in (0, pi) radians, got {angle:g}")
                value = 0.5 * _number(where, "w", w) / np.tan(0.5 * angle)
        if key in ("cx", "cy") and value is None:
            size = frame.get("w" if key == "cx" else "h", top.get("w" if key == "cx" else "h"))
            value = None if size is None else 0.5 * _number(where, "w" if key == "cx" else "h", size)
        if value is None:
            raise DatasetError(f"{where}: intrinsic '{key}' missing (top level or per frame)")
        values[key] = _number(where, key, value)
    for key in ("w", "h"):
        if values[key] != int(values[key]) or values[key] < 1:
            raise DatasetError(f"{where}: intrinsic '{key}' must be a positive integer, got {values[key]:g}")
    raw = frame.get("transform_matrix")
    try:
        # numbers only: NumPy would read the text "1" as 1.0 where the intrinsics refuse it
        if not all(type(v) in (int, float) for row in raw for v in row):
            raise TypeError
        matrix = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise DatasetError(f"{where}: transform_matrix must be a 4x4 array of numbers, got {str(raw)[:60]!r}") from None
    if matrix.shape != (4, 4):
        raise DatasetError(f"{where}: transform_matrix must be a 4x4 array of numbers, got shape {matrix.shape}")
    try:
        return Camera(matrix, values["fl_x"], values["fl_y"], values["cx"], values["cy"],
                      int(values["w"]), int(values["h"]))
    except InputError as exc:
        raise DatasetError(f"{where}: {exc}") from None


def view_rgba(view: View) -> np.ndarray:
    """(H, W, 4) float32 RGBA of a view as ``write_dataset`` takes it (alpha 1 when the frame has none)."""
    alpha = np.ones(view.rgb.shape[:2], np.float32) if view.alpha is None else view.alpha
    return np.concatenate([view.rgb, alpha[..., None]], axis=2).astype(np.float32)


LDR_FRAME_EXTENSIONS = (".png", ".jpg", ".jpeg")


def read_frame_image(path: str) -> np.ndarray:
    """A frame's image as float32 (H, W, 3 or 4): EXR as stored (linear); a PNG (8 or 16 bits
    per channel) or JPEG as sRGB-encoded, linearised to [0, 1], alpha linear
    (:func:`harness.io.images.read_linear_rgb`)."""
    if os.path.splitext(path)[1].lower() not in LDR_FRAME_EXTENSIONS:
        return read_exr(path)
    try:
        return read_linear_rgb(path, alpha=True)
    except InputError as exc:
        raise DatasetError(str(exc)) from None


def _undistorted(where: str, image: np.ndarray, cam: Camera, lens: Lens) -> np.ndarray:
    """The pinhole image (H, W, 4) of a distorted frame: pixels whose source lies outside
    the frame get alpha 0, so they add no observation."""
    if image.shape[2] == 3:
        image = np.concatenate([image, np.ones(image.shape[:2] + (1,), image.dtype)], axis=2)
    try:
        return undistort_image(image, cam.fx, cam.fy, cam.cx, cam.cy, lens)[0]
    except InputError as exc:
        raise DatasetError(f"{where}: {exc}") from None


def _image_path(file_path: str) -> str:
    """A frame's image path as read: without an extension it names an EXR (nerfstudio's
    ``file_path`` may leave the extension out)."""
    return file_path if os.path.splitext(file_path)[1] else file_path + ".exr"


def _read_views(folder: str, frames, top: dict, key: str, files: list) -> list[View]:
    """The views of a frame list; every image path read is appended to ``files``."""
    if not isinstance(frames, list):
        raise DatasetError(f"transforms.json {key} must be a list of frames, got {type(frames).__name__}")
    views = []
    for k, frame in enumerate(frames):
        where = f"transforms.json {key}[{k}]"
        if not isinstance(frame, dict):
            raise DatasetError(f"{where} must be an object, got {type(frame).__name__}")
        if not isinstance(frame.get("file_path"), str) or not frame["file_path"]:
            raise DatasetError(f"{where}: file_path missing or not a string")
        cam = _intrinsics(where, frame, top)
        lens = _lens(where, frame, top)
        path = os.path.join(folder, _image_path(frame["file_path"]))
        if not os.path.isfile(path):
            raise DatasetError(f"{where}: image not found: {path}")
        image = read_frame_image(path)
        if image.shape[:2] != (cam.height, cam.width):
            raise DatasetError(f"{path}: image is {image.shape[1]}x{image.shape[0]} but the intrinsics say "
                               f"{cam.width}x{cam.height} ({where})")
        if lens is not None:
            image = _undistorted(where, image, cam, lens)
        alpha = image[..., 3] if image.shape[2] == 4 else None
        try:
            views.append(View(frame["file_path"], cam, image[..., :3], alpha))
            files.append(path)
        except InputError as exc:
            raise DatasetError(f"{path}: {exc}") from None
    return views


def read_ground_truth(folder: str, num_faces: int) -> GroundTruth | None:
    """ground_truth/ of a dataset, or None when it has none. Every missing file or key,
    wrong shape and non-finite value raises :class:`DatasetError` naming the file and key."""
    gt = os.path.join(folder, "ground_truth")
    if not os.path.isdir(gt):
        return None
    mats = read_npz(os.path.join(gt, "materials.npz"), DatasetError)
    shz = read_npz(os.path.join(gt, "illumination_sh.npz"), DatasetError)
    info = load_json(os.path.join(gt, "illumination.json"), "ground-truth illumination", DatasetError)
    for key in ("diffuse", "specular"):
        if key not in mats:
            raise DatasetError(f"{gt}/materials.npz: key '{key}' missing")
        mats[key] = real_array(f"{gt}/materials.npz: {key}", mats[key], DatasetError)
        if mats[key].shape != (num_faces, 3):
            raise DatasetError(f"{gt}/materials.npz: {key} has shape {mats[key].shape}, mesh has {num_faces} faces")
        bad = ~np.all(np.isfinite(mats[key]), axis=1)
        if bad.any():
            raise DatasetError(f"{gt}/materials.npz: {key} has {int(bad.sum())} rows with NaN or Inf "
                               f"(first: face {int(np.argmax(bad))})")
    key = "radiance_sh" if "radiance_sh" in shz else "sh"  # format 1 named it sh
    if key not in shz:
        raise DatasetError(f"{gt}/illumination_sh.npz: key 'radiance_sh' missing")
    radiance = real_array(f"{gt}/illumination_sh.npz: {key}", shz[key], DatasetError)
    if radiance.ndim != 2 or radiance.shape[1] != 3 or int(np.sqrt(radiance.shape[0])) ** 2 != radiance.shape[0]:
        raise DatasetError(f"{gt}/illumination_sh.npz: {key} must be ((L+1)^2, 3), got {radiance.shape}")
    if not np.all(np.isfinite(radiance)):
        raise DatasetError(f"{gt}/illumination_sh.npz: {key} contains NaN or Inf")
    for name in ("brdf", "illumination"):
        if not isinstance(info.get(name), dict):
            raise DatasetError(f"{gt}/illumination.json: key '{name}' missing or not an object")
    exponent = info["brdf"].get("exponent")
    if (
        isinstance(exponent, bool)
        or not isinstance(exponent, (int, float))
        or not np.isfinite(exponent)
        or exponent <= 0
    ):
        raise DatasetError(f"{gt}/illumination.json: brdf.exponent must be a positive number, got {exponent!r}")
    regions = mats.get("regions")
    if regions is not None and (regions.shape != (num_faces,) or not np.issubdtype(regions.dtype, np.integer)
                                or (num_faces and (regions.min() < 0 or regions.max() >= num_faces))):
        raise DatasetError(f"{gt}/materials.npz: regions must be {num_faces} integers in [0, {num_faces}), "
                           f"got {regions.dtype} of shape {regions.shape}")
    return GroundTruth(diffuse=mats["diffuse"], specular=mats["specular"], radiance_sh=radiance,
                       brdf=info["brdf"], illumination=info["illumination"], regions=regions)


def _check_distinct_frames(tpath: str, frames, test_frames) -> None:
    """Refuse a frame listed twice (it would count its pixels twice and hide an underdetermined
    solve) and a test frame among the training frames (the held-out score would see its own data)."""
    seen: dict[str, str] = {}
    for key, items in (("frames", frames), ("test_frames", test_frames)):
        if not isinstance(items, list):
            continue
        for k, frame in enumerate(items):
            path = frame.get("file_path") if isinstance(frame, dict) else None
            if not isinstance(path, str):
                continue
            path = os.path.normpath(_image_path(path))
            if path in seen:
                raise DatasetError(f"{tpath}: {key}[{k}] lists {frame['file_path']!r} again ({seen[path]}): each image "
                                   "may appear once, and a test frame never among the training frames")
            seen[path] = f"{key}[{k}]"


def read_dataset(folder: str | os.PathLike, load_test: bool = True, load_truth: bool = True) -> Dataset:
    """Read a dataset folder; every missing or malformed part raises :class:`DatasetError`.
    ``Dataset.inputs`` lists the folder and every file read (mesh and images may lie elsewhere).

    ``load_truth=False`` leaves ``ground_truth`` None without reading it: estimation
    reads only images, cameras and mesh.
    """
    if not str(folder):
        raise DatasetError("the dataset path is empty")
    folder = os.path.abspath(str(folder))
    tpath = os.path.join(folder, "transforms.json")
    if not os.path.isdir(folder):
        raise DatasetError(f"dataset folder not found: {folder}")
    if not os.path.isfile(tpath):
        raise DatasetError(f"{folder} has no transforms.json")
    top = load_json(tpath, "dataset cameras", DatasetError)
    version = top.get("format_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
        raise DatasetError(f"{tpath}: format_version {version!r} is not one this pseudolight reads "
                           f"(1 to {FORMAT_VERSION}); a newer pseudolight wrote it?")
    mesh_name = top.get("mesh_file_path", "mesh.ply")
    if not isinstance(mesh_name, str):
        raise DatasetError(f"{tpath}: mesh_file_path must be a string, got {mesh_name!r}")
    mesh_path = os.path.join(folder, mesh_name)
    if not os.path.isfile(mesh_path):
        raise DatasetError(f"{folder} has no mesh ({os.path.basename(mesh_path)} not found)")
    try:
        declared = polygon_count(mesh_path)
    except OSError as exc:
        raise DatasetError(f"{mesh_path}: cannot read the mesh ({exc.strerror or exc})") from None
    try:
        mesh = load_mesh_file(mesh_path)
    except InputError as exc:
        if declared and "has no faces" in str(exc):   # trimesh drops faces it cannot read as triangles
            raise DatasetError(f"{mesh_path}: holds {declared} faces but no triangle; a dataset's mesh must be "
                               "triangles (each face's index is its identity): triangulate it first") from None
        raise DatasetError(str(exc)) from None   # the mesh reader names the file
    if declared is not None and declared != mesh.num_faces:
        raise DatasetError(f"{mesh_path}: declares {declared} faces, which load as {mesh.num_faces} triangles: a "
                           "dataset's mesh must be triangles (each face's index is its identity, and splitting "
                           "polygons renumbers them); triangulate it first and keep that order")
    frames = top.get("frames", [])
    if not frames:
        raise DatasetError(f"{tpath} has no frames")
    if not isinstance(top.get("test_frames", []), list):   # refused before an estimate that does not read them
        raise DatasetError(f"{tpath}: test_frames must be a list of frames, got {type(top['test_frames']).__name__}")
    _check_distinct_frames(tpath, frames, top.get("test_frames", []))
    files = [mesh_path]
    views = _read_views(folder, frames, top, "frames", files)
    test_views = _read_views(folder, top.get("test_frames", []), top, "test_frames", files) if load_test else []
    meta = {k: v for k, v in top.items() if k not in ("frames", "test_frames")}
    truth = read_ground_truth(folder, mesh.num_faces) if load_truth else None
    return Dataset(folder, MultiViewData(mesh, views, test_views), truth, meta, tuple(files))


def fingerprint(data: MultiViewData) -> dict:
    """Hashes of what an estimate is computed from: the mesh, the training cameras and
    the training images (BLAKE2b-128 of the arrays' bytes), so a run can be matched to
    its dataset."""
    def digest(arrays) -> str:
        h = hashlib.blake2b(digest_size=16)
        for a in arrays:
            a = np.ascontiguousarray(a)
            h.update(str(a.shape).encode())
            h.update(a.tobytes())
        return h.hexdigest()

    cams = [np.array([*v.camera.c2w.ravel(), v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy,
                      v.camera.width, v.camera.height]) for v in data.views]
    return {"mesh": digest([data.mesh.vertices, data.mesh.faces]), "cameras": digest(cams),
            "images": digest([v.rgb for v in data.views])}
