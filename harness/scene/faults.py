"""Faults of real captures applied to a rendered dataset: image noise, exposure clipping,
8-bit output, pose and focal-length errors, mesh noise, glare and occluder patches.

Every function is pure numpy on in-memory arrays and draws from the generator it is
given, so a fault set is reproducible from its seed. ``apply_faults`` applies a
:class:`~harness.scene.spec.FaultSpec` to the training views and the mesh, and returns
the record written to ``transforms.json``.
"""
from __future__ import annotations

import dataclasses
import json
import os

import numpy as np

from estimator import Camera, TriangleMesh
from harness.scene.spec import FaultSpec
from reports.metrics import srgb_encode


def exposure_level(image: np.ndarray) -> float:
    """The 99th percentile of the object pixels' largest channel of an RGBA image (H, W, 4)
    (1 when nothing is covered): the level noise and clipping are relative to."""
    covered = image[..., 3] > 0
    if not covered.any():
        return 1.0
    return max(float(np.percentile(image[..., :3][covered].max(axis=1), 99)), 1e-12)


def add_noise(image: np.ndarray, read: float, shot: float, rng: np.random.Generator) -> np.ndarray:
    """RGBA (H, W, 4) with shot and read noise on RGB (alpha unchanged).

    Variance per channel: (read x level)^2 + shot x level x max(value, 0).
    """
    level = exposure_level(image)
    rgb = image[..., :3].astype(np.float64)
    sigma = np.sqrt((read * level) ** 2 + shot * level * np.maximum(rgb, 0.0))
    out = image.astype(np.float32).copy()
    out[..., :3] = rgb + sigma * rng.standard_normal(rgb.shape)
    return out


def to_ldr(image: np.ndarray, white: float) -> np.ndarray:
    """(H, W, 4) uint8 RGBA: RGB / white sRGB-encoded, alpha linear, both rounded to 8 bits."""
    out = np.empty(image.shape[:2] + (4,), dtype=np.uint8)
    out[..., :3] = np.round(255.0 * srgb_encode(image[..., :3] / white)).astype(np.uint8)
    out[..., 3] = np.round(255.0 * np.clip(image[..., 3], 0.0, 1.0)).astype(np.uint8)
    return out


def rotation_about(axis: np.ndarray, degrees: float) -> np.ndarray:
    """(3, 3) rotation by ``degrees`` about the unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)


def perturb_pose(camera: Camera, rotation_deg: float, translation: float, centre: np.ndarray,
                 rng: np.random.Generator) -> tuple[Camera, float, float]:
    """A camera whose pose is off by a random rotation (std ``rotation_deg``, random axis,
    about the camera centre) and a random translation (std ``translation`` x the distance
    to ``centre`` per axis). Returns (camera, the angle in degrees, the shift in world units)."""
    angle = rotation_deg * rng.standard_normal()
    axis = rng.standard_normal(3)
    shift = translation * np.linalg.norm(camera.center - centre) * rng.standard_normal(3)
    c2w = camera.c2w.copy()
    c2w[:3, :3] = rotation_about(axis, angle) @ c2w[:3, :3]
    c2w[:3, 3] += shift
    return dataclasses.replace(camera, c2w=c2w), abs(float(angle)), float(np.linalg.norm(shift))


def scale_focal(camera: Camera, error: float) -> Camera:
    """The camera with focal lengths multiplied by (1 + error) (principal point kept)."""
    return dataclasses.replace(camera, fx=camera.fx * (1.0 + error), fy=camera.fy * (1.0 + error))


def vertex_normals(mesh: TriangleMesh) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals."""
    v, f = mesh.vertices, mesh.faces
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    normals = np.zeros_like(v)
    for corner in range(3):
        np.add.at(normals, f[:, corner], cross)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)


def displace_vertices(mesh: TriangleMesh, sigma: float, rng: np.random.Generator) -> TriangleMesh:
    """The mesh with each vertex moved along its normal by N(0, sigma x mean edge length);
    faces (and so face identity) unchanged."""
    v, f = mesh.vertices, mesh.faces
    edges = np.concatenate([v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 1]], v[f[:, 0]] - v[f[:, 2]]])
    step = sigma * float(np.linalg.norm(edges, axis=1).mean())
    moved = v + vertex_normals(mesh) * (step * rng.standard_normal(len(v)))[:, None]
    return TriangleMesh(moved, f)


def decimate(mesh: TriangleMesh, keep: float, steps: int = 24) -> TriangleMesh:
    """The mesh simplified by vertex clustering to about ``keep`` x its faces: vertices in
    one cell of a cubic grid merge into their mean, collapsed and repeated faces go. The
    cell size is found by bisection on the face count (within 5 % of the target, or the
    closest of ``steps`` tries that keeps a mesh: at least 4 faces, so a target below what
    clustering can reach gives the coarsest mesh it can, never an empty one)."""
    v, f = mesh.vertices, mesh.faces
    target = max(4, int(round(keep * len(f))))
    extent = float(np.ptp(v, axis=0).max())

    def cluster(cell: float) -> TriangleMesh | None:
        keys = np.floor((v - v.min(axis=0)) / cell).astype(np.int64)
        _, ids = np.unique(keys, axis=0, return_inverse=True)
        ids = ids.ravel()
        count = np.bincount(ids).astype(float)
        centres = np.stack([np.bincount(ids, v[:, k]) for k in range(3)], 1) / count[:, None]
        faces = ids[f]
        ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
        faces = faces[ok]
        _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
        faces = faces[np.sort(first)]
        if len(faces) < 4:   # collapsed past a mesh
            return None
        used, compact = np.unique(faces, return_inverse=True)
        return TriangleMesh(centres[used], compact.reshape(-1, 3))

    lo, hi = 1e-6 * extent, extent
    best = mesh
    for _ in range(steps):
        cell = np.sqrt(lo * hi)
        out = cluster(cell)
        count = 0 if out is None else out.num_faces
        if out is not None and abs(count - target) < abs(best.num_faces - target):
            best = out
        if abs(count - target) <= 0.05 * target:
            break
        lo, hi = (cell, hi) if count > target else (lo, cell)
    return best


def nearest_faces(source: TriangleMesh, target: TriangleMesh) -> np.ndarray:
    """(F_target,) index of the ``source`` face whose centroid is nearest to each ``target``
    face's centroid (how ground truth follows a decimated mesh)."""
    from scipy.spatial import cKDTree

    return cKDTree(source.centroids).query(target.centroids)[1].astype(np.int64)


def add_patch(image: np.ndarray, size: int, value: float, replace: bool, rng: np.random.Generator
              ) -> tuple[np.ndarray, list[int]]:
    """RGBA with a ``size`` x ``size`` square centred on a random covered pixel (the image
    centre when none is) where ``value`` is added (glare) or written (``replace``, an
    occluder). Returns (image, [x0, y0, x1, y1] of the patch)."""
    h, w = image.shape[:2]
    ys, xs = np.nonzero(image[..., 3] > 0)
    k = int(rng.integers(len(ys))) if len(ys) else None
    cy, cx = (int(ys[k]), int(xs[k])) if k is not None else (h // 2, w // 2)
    y0, x0 = max(cy - size // 2, 0), max(cx - size // 2, 0)
    y1, x1 = min(y0 + size, h), min(x0 + size, w)
    out = image.copy()
    if replace:
        out[y0:y1, x0:x1, :3] = value
    else:
        out[y0:y1, x0:x1, :3] += value
    return out, [x0, y0, x1, y1]


def apply_faults(faults: FaultSpec, seed: int, mesh: TriangleMesh, train: list[tuple[Camera, np.ndarray]],
                 test: list[Camera]) -> tuple[TriangleMesh, list[tuple[Camera, np.ndarray]], list[Camera],
                                              list[np.ndarray | None], dict]:
    """Apply a fault set to the training views (camera, RGBA image) and the mesh; the test
    cameras get only the focal-length error (intrinsics are shared by every view).

    Returns
    -------
    mesh : the mesh to write (vertex noise: same faces; decimation: fewer faces, and
        ``record['face_source']`` (F',) gives the rendered face each written face stands for).
    train : the faulted (camera, image) pairs (poses and focal as written; images as seen).
    test : the test cameras as written.
    ldr : per view, the (H, W, 4) uint8 sRGB image to write as PNG, or None.
    record : the fault parameters as applied, the seed and what was drawn (per-view pose
        error, exposure and white-balance gains, patch boxes), for ``transforms.json``;
        ``clamped`` lists a patch count that asked for more views than there are (requested
        and applied).
    """
    rng = np.random.default_rng([seed, faults.seed, 0x5EED])
    record: dict = {"spec": dataclasses.asdict(faults), "seed": [seed, faults.seed]}
    centre = mesh.vertices.mean(axis=0)
    if faults.vertex_noise > 0:
        mesh = displace_vertices(mesh, faults.vertex_noise, rng)
    if faults.decimate > 0:
        rendered, mesh = mesh, decimate(mesh, faults.decimate)
        record["decimated"] = {"faces_rendered": rendered.num_faces, "faces_written": mesh.num_faces}
        record["face_source"] = nearest_faces(rendered, mesh)
    out, pose_errors, gains = [], [], []
    for camera, image in train:
        if faults.exposure_jitter > 0 or faults.white_balance_jitter > 0:
            gain = np.exp(faults.exposure_jitter * rng.standard_normal() + faults.white_balance_jitter
                          * rng.standard_normal(3))
            image = np.concatenate([image[..., :3] * gain.astype(np.float32), image[..., 3:]], axis=2)
            gains.append(gain.tolist())
        if faults.noise_read > 0 or faults.noise_shot > 0:
            image = add_noise(image, faults.noise_read, faults.noise_shot, rng)
        if faults.pose_rotation > 0 or faults.pose_translation > 0:
            camera, angle, shift = perturb_pose(camera, faults.pose_rotation, faults.pose_translation, centre, rng)
            pose_errors.append({"degrees": angle, "translation": shift})
        if faults.focal_error:
            camera = scale_focal(camera, faults.focal_error)
        out.append((camera, image))
    patches = []
    for kind, count, size, value in (("glare", faults.glare_views, faults.glare_size, faults.glare_value),
                                     ("occluder", faults.occluder_views, faults.occluder_size,
                                      faults.occluder_value)):
        if count > len(out):   # more views asked for than there are: record what was applied
            record["spec"][f"{kind}_views"] = len(out)
            record.setdefault("clamped", {})[f"{kind}_views"] = {"requested": count, "applied": len(out)}
        for index in rng.choice(len(out), size=min(count, len(out)), replace=False):
            camera, image = out[index]
            image, box = add_patch(image, size, value, kind == "occluder", rng)
            out[index] = (camera, image)
            patches.append({"kind": kind, "view": int(index), "box": box, "value": value})
    ldr: list[np.ndarray | None] = [None] * len(out)
    if faults.clip > 0 or faults.ldr:
        # one exposure for every view (a fixed camera setting): the level of the median view
        white = (faults.clip or 1.0) * float(np.median([exposure_level(image) for _, image in out]))
        record["white_level"] = white
        for index, (camera, image) in enumerate(out):
            image = image.copy()
            image[..., :3] = np.minimum(image[..., :3], white)
            if faults.ldr:
                ldr[index] = to_ldr(image, white)
            out[index] = (camera, image)
    record["pose_errors"] = pose_errors
    record["view_gains"] = gains
    record["patches"] = patches
    if faults.focal_error:
        test = [scale_focal(camera, faults.focal_error) for camera in test]
    return mesh, out, test, ldr, record


def corrupt_dataset(source: str, out_dir: str, faults: FaultSpec, seed: int = 0, overwrite: bool = False) -> dict:
    """Write a copy of the dataset at ``source`` with ``faults`` applied to its training
    views (and mesh), atomically; ``ground_truth/`` is copied (per-face arrays carried to
    the faces of a decimated mesh), and the fault record is added to ``transforms.json``.
    Returns that record.

    The images are the dataset's own (alpha 1 where a frame has none), so a sweep of
    fault levels renders once.
    """
    import shutil

    from harness.io.atomic import atomic_directory
    from harness.io.dataset import read_dataset, view_rgba, write_dataset

    ds = read_dataset(source, load_test=True, load_truth=False)
    train = [(v.camera, view_rgba(v)) for v in ds.data.views]
    test = [(v.camera, view_rgba(v)) for v in ds.data.test_views]
    meta = {k: v for k, v in ds.meta.items() if k not in ("frames", "test_frames", "faults")}
    with atomic_directory(out_dir, overwrite=overwrite, inputs=[source, *ds.inputs], kind="dataset") as tmp:
        mesh, views, test_cams, ldr, record = apply_faults(faults, seed, ds.data.mesh, train,
                                                           [c for c, _ in test])
        record["source"] = os.path.abspath(source)
        face_source = record.pop("face_source", None)
        write_dataset(tmp, mesh, views, list(zip(test_cams, [img for _, img in test])), {**meta, "faults": record},
                      ldr=ldr)
        truth = os.path.join(source, "ground_truth")
        if os.path.isdir(truth):
            shutil.copytree(truth, os.path.join(tmp, "ground_truth"))
            materials = os.path.join(tmp, "ground_truth", "materials.npz")
            if face_source is not None and os.path.isfile(materials):
                # a decimated mesh: each written face carries the truth of the face it stands for
                with np.load(materials) as old:
                    arrays = {k: old[k][face_source] if old[k].shape[:1] == (ds.data.mesh.num_faces,) else old[k]
                              for k in old.files}
                np.savez(materials, **arrays)
                remap_brdf_labels(os.path.join(tmp, "ground_truth", "illumination.json"), face_source)
    return record


def remap_brdf_labels(path: str, face_source: np.ndarray) -> None:
    """A mixed-material ground truth's per-face ``brdf.labels`` in a ground_truth/illumination.json,
    carried to the written faces of a decimated mesh (each takes its rendered face's label)."""
    with open(path) as f:
        record = json.load(f)
    brdf = record.get("brdf") or {}
    if brdf.get("model") == "mixed":
        brdf["labels"] = np.asarray(brdf["labels"])[face_source].tolist()
        with open(path, "w") as f:
            json.dump(record, f, indent=1)
