"""An estimate as a Mitsuba scene: the physically based cross-check of the model.

The estimate's reflection model (:mod:`estimator.models`) names the Mitsuba
BSDF that renders it: for the paper's model, the diffuse + perfect-mirror BSDF
lit by the pseudo illumination h; for the lobe model, the Phong BSDF lit by the
radiance L. The mesh carries the per-face albedos, the environment map is the
model's light unknown, and Mitsuba's path tracer with two bounces renders the
image the forward model predicts.
"""
from __future__ import annotations

import os

import numpy as np

from estimator import sh
from estimator.camera import Camera, gl_to_mitsuba
from estimator.data import Estimate, TriangleMesh
from estimator.models import MitsubaMaterial

from harness import plugins
from harness.io.exr import write_exr
from harness.scene.illumination import Illumination
from harness.scene.render import build_scene, render_views
from harness.scene.xml import scene_xml

ENVMAP_SIZE = (256, 512)
PLUGIN_OF_KIND = {"diffuse_mirror": plugins.DIFFUSE_MIRROR, "phong": plugins.PHONG}


def _exponent(material: MitsubaMaterial) -> float | None:
    """The Phong exponent :func:`harness.scene.render.build_scene` takes (None: diffuse + mirror)."""
    return material.properties["exponent"] if material.kind == "phong" else None


def environment(est: Estimate) -> np.ndarray:
    """The estimate's environment map (H, W, 3): its light unknown as signed radiance
    (SH ringing can go negative)."""
    return sh.to_latlong(est.light, *ENVMAP_SIZE)


def render_estimate(mesh: TriangleMesh, est: Estimate, cameras: list[Camera], spp: int = 64,
                    seed: int = 7) -> list[np.ndarray]:
    """Render the estimate with Mitsuba's path tracer -> list of (H, W, 4) RGBA.

    Rendering is linear in the environment, and Mitsuba's ``envmap`` needs
    non-negative radiance, so the positive and negative parts of the SH
    environment are rendered separately and subtracted: the result is the
    render of the signed environment, as the forward model sees it.
    Raises :class:`estimator.models.NoMitsubaEquivalent` for a model without one.
    """
    exponent = _exponent(est.model.mitsuba_material())
    signed = environment(est)
    total = None
    for sign, part in ((1.0, np.maximum(signed, 0.0)), (-1.0, np.maximum(-signed, 0.0))):
        if not part.any():
            continue
        light = Illumination("envmap", envmap=part)
        scene = build_scene(mesh, est.diffuse, est.specular, exponent, light, cameras[0], spp, "path", max_depth=2)
        images = render_views(scene, cameras, spp, seed, desc="mitsuba cross-check")
        if total is None:
            total = [np.concatenate([sign * im[..., :3], im[..., 3:]], axis=2) for im in images]
        else:
            for acc, im in zip(total, images):
                acc[..., :3] += sign * im[..., :3]
    return total


def scene_dict(est: Estimate, camera: Camera | None = None, spp: int = 64) -> dict:
    """The exported scene as a Mitsuba scene dictionary (files referenced by name)."""
    material = est.model.mitsuba_material()
    bsdf = {"type": PLUGIN_OF_KIND[material.kind], **material.properties,
            "diffuse_reflectance": {"type": "mesh_attribute", "name": "face_diffuse_color"},
            "specular_reflectance": {"type": "mesh_attribute", "name": "face_specular_color"}}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
        "object": {"type": "ply", "filename": "mesh.ply", "face_normals": True, "bsdf": bsdf},
        "light": {"type": "envmap", "filename": "envmap.exr"},
    }
    if camera is not None:
        scene["sensor"] = {
            "type": "perspective", "fov": float(camera.fov_x_deg), "fov_axis": "x",
            "to_world": gl_to_mitsuba(camera.c2w),
            "film": {"type": "hdrfilm", "width": int(camera.width), "height": int(camera.height),
                     "pixel_format": "rgba", "rfilter": {"type": "box"}},
            "sampler": {"type": "multijitter", "sample_count": int(spp)},
        }
    return scene


def export_scene(folder: str, mesh: TriangleMesh, est: Estimate, camera: Camera | None = None) -> str:
    """Write ``scene.xml``, ``mesh.ply`` (per-face albedos as face attributes) and
    ``envmap.exr`` into ``folder``; returns the XML path. The environment is
    clamped at 0 (Mitsuba's envmap needs non-negative radiance); where the SH
    ring below zero the exported scene is brighter than the forward model.

    Load with :func:`load_exported_scene`, which registers the pseudolight BSDFs.
    """
    scene = scene_dict(est, camera)
    os.makedirs(folder, exist_ok=True)
    write_exr(os.path.join(folder, "envmap.exr"), np.maximum(environment(est), 0.0))
    _write_ply(os.path.join(folder, "mesh.ply"), mesh, est.diffuse, est.specular)
    path = os.path.join(folder, "scene.xml")
    with open(path, "w") as f:
        f.write(scene_xml(scene, f"pseudolight estimate ({est.method}); per-face albedos are PLY face attributes"))
    return path


def load_exported_scene(path: str):
    """``mi.load_file`` of an exported scene, with the pseudolight plugins registered."""
    plugins.register_all()
    import mitsuba as mi

    return mi.load_file(path)


def _write_ply(path: str, mesh: TriangleMesh, diffuse: np.ndarray, specular: np.ndarray) -> None:
    """Binary PLY with face properties diffuse_r/g/b and specular_r/g/b (Mitsuba reads them
    as the face attributes ``face_diffuse_color`` and ``face_specular_color``)."""
    f = mesh.num_faces
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {mesh.vertices.shape[0]}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {f}\nproperty list uchar int vertex_indices\n"
              + "".join(f"property float {n}_{c}\n" for n in ("diffuse", "specular") for c in "rgb")
              + "end_header\n")
    face_dtype = np.dtype([("n", "u1"), ("v", "<i4", 3), ("attrs", "<f4", 6)])
    faces = np.empty(f, dtype=face_dtype)
    faces["n"] = 3
    faces["v"] = mesh.faces
    faces["attrs"] = np.concatenate([diffuse, specular], axis=1)
    with open(path, "wb") as out:
        out.write(header.encode("ascii"))
        out.write(mesh.vertices.astype("<f4").tobytes())
        out.write(faces.tobytes())
