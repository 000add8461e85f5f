"""A dataset as stock Mitsuba 3 scenes: one XML per view that renders it with no pseudolight import.

Layout::

    object.ply        the mesh, one vertex triple per face (face order kept), with UVs into
    albedo.exr        a one-texel-per-face atlas of the true diffuse albedo (linear)
    envmap.exr        the light, when it is an environment map
    train_000.xml ... test_000.xml   one scene per frame: the same shape, BSDF, emitters and
                      integrator as the generator used, and that frame's camera

Only Mitsuba's own plugins appear: ``diffuse``, ``plastic`` or ``roughplastic`` with a
``bitmap`` texture; ``envmap``, ``directional``, ``point`` or ``sunsky``; ``path`` (or
``direct`` for delta lights, which samples one light per sample where the generator loops
over them: the same expectation, more noise); the generator's ``perspective`` sensor with an
RGBA ``hdrfilm`` (:func:`estimator.core.camera.mitsuba_sensor`).
Datasets rendered with pseudolight's Phong BSDF have no stock equivalent and are refused.
"""
from __future__ import annotations

import os
import shutil

import numpy as np

from estimator import InputError, mitsuba_sensor
from harness.io.dataset import Dataset
from harness.io.exr import read_exr, write_exr
from harness.io.jsonio import load_json
from harness.io.mesh import write_uv_ply
from harness.scene.illumination import Illumination
from harness.scene.render import bsdf_dict, face_atlas
from harness.scene.xml import NUMPY_TRANSFORMS, scene_xml

STOCK_MATERIALS = ("diffuse", "plastic", "roughplastic")


def _emitters(illumination: dict) -> dict:
    """Emitter dicts of a ground-truth ``illumination`` record (illumination.json): the
    generator's own (:meth:`Illumination.mitsuba_emitters`), with the envmap by file name."""
    kind = illumination["kind"]
    if kind == "envmap":
        to_world = np.eye(4)
        to_world[:3, :3] = np.asarray(illumination.get("rotation", np.eye(3)), float)
        return {"envmap": {"type": "envmap", "filename": "envmap.exr", "to_world": to_world}}
    if kind not in ("directional", "point", "sunsky"):
        raise InputError(f"illumination kind {kind!r} has no stock Mitsuba emitter here")
    return Illumination.from_json(illumination).mitsuba_emitters(NUMPY_TRANSFORMS)


def write_mitsuba_views(ds: Dataset, out_dir: str, spp: int | None = None) -> dict:
    """Write the stock-Mitsuba scenes of ``ds`` (read with its ground truth and test views)
    into the existing folder ``out_dir``. ``spp``: samples per pixel (default: the dataset's).
    Returns a summary (frame counts, material, light kind, integrator)."""
    truth = ds.ground_truth
    if truth is None:
        raise InputError(f"--format mitsuba needs {os.path.join(ds.path, 'ground_truth')}/ (the true materials "
                         "and light); this dataset has none")
    model = truth.brdf.get("model")
    if model not in STOCK_MATERIALS:
        raise InputError(
            f"the dataset's material is {model!r}: stock Mitsuba 3 has no such BSDF (pseudolight's "
            f"Phong is a plugin); --format mitsuba exports datasets made with {', '.join(STOCK_MATERIALS)}"
        )
    record = load_json(os.path.join(ds.path, "ground_truth", "illumination.json"), "the ground-truth light")
    render = record.get("scene_spec", {}).get("render", {})
    emitters = _emitters(record["illumination"])
    if "envmap" in emitters:
        source = os.path.join(ds.path, "ground_truth", record["illumination"].get("envmap_file", "envmap.exr"))
        if not os.path.isfile(source):
            raise InputError(f"{source} is missing: the envmap light cannot be exported")
        # read, not only copied: a truncated map must not pass into the export (copied as it is
        # otherwise: the dataset was rendered with it)
        if not np.all(np.isfinite(read_exr(source)[..., :3])):
            raise InputError(f"{source}: the envmap holds NaN or Inf radiance")
        shutil.copyfile(source, os.path.join(out_dir, "envmap.exr"))
    image, uv = face_atlas(np.asarray(truth.diffuse, np.float32))
    write_exr(os.path.join(out_dir, "albedo.exr"), image)
    write_uv_ply(os.path.join(out_dir, "object.ply"), ds.data.mesh.corners, uv)
    bsdf = bsdf_dict(truth.brdf)
    key = "reflectance" if bsdf["type"] == "diffuse" else "diffuse_reflectance"
    bsdf[key] = {**bsdf[key], "filename": "albedo.exr"}
    if render.get("integrator", "path") == "path":
        integrator = {"type": "path", "max_depth": int(render.get("max_depth", 6)), "hide_emitters": True}
    else:
        integrator = {"type": "direct", "hide_emitters": True}
    shape = {"type": "ply", "filename": "object.ply", "face_normals": True, "bsdf": bsdf}
    samples = int(spp or ds.meta.get("spp", 64))
    counts = {}
    for split, views in (("train", ds.data.views), ("test", ds.data.test_views)):
        for k, view in enumerate(views):
            scene = {"type": "scene", "integrator": integrator, "object": shape, **emitters,
                     "sensor": mitsuba_sensor(NUMPY_TRANSFORMS, view.camera, samples)}
            comment = (
                f"pseudolight dataset {os.path.basename(os.path.abspath(ds.path))}, {split} frame {k} ({view.name})"
            )
            with open(os.path.join(out_dir, f"{split}_{k:03d}.xml"), "w") as f:
                f.write(scene_xml(scene, comment))
        counts[split] = len(views)
    return {**counts, "material": model, "light": record["illumination"]["kind"], "integrator": integrator["type"],
            "spp": samples}
