"""An estimate as a Mitsuba scene: the physically based cross-check of the model.

The estimate's reflection model (:mod:`estimator.model.reflection_models`) names the Mitsuba
BSDF that renders it: for the paper's model, the diffuse + perfect-mirror BSDF
lit by the pseudo illumination h; for the lobe model, the Phong BSDF lit by the
radiance L. The mesh carries the per-face albedos, the environment map is the
model's light unknown, and Mitsuba's path tracer with two bounces renders the
image the forward model predicts.
"""
from __future__ import annotations

import os

import numpy as np

from estimator import (
    Camera,
    Estimate,
    MitsubaMaterial,
    TriangleMesh,
    mitsuba_sensor,
    sh,
)
from harness import plugins
from harness.io.exr import write_exr
from harness.io.mesh import write_uv_ply
from harness.scene.illumination import Illumination
from harness.scene.render import ATLAS_TEXTURE, build_scene, face_atlas, render_views
from harness.scene.xml import NUMPY_TRANSFORMS, scene_xml

ENVMAP_SIZE = (256, 512)
PLUGIN_OF_KIND = {"phong": plugins.PHONG}


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
    Raises :class:`estimator.model.reflection_models.NoMitsubaEquivalent` for a model without one.
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
    """The exported scene as a Mitsuba scene dictionary (files referenced by name).

    The paper's model (diffuse + mirror) uses Mitsuba's own plugins only: a ``blendbsdf``
    of weight 1/2 between ``diffuse`` (reflectance 2 t_d) and a mirror (``roughconductor``,
    ``material='none'``, GGX alpha 1e-3, specular reflectance 2 t_s), which sums to
    t_d / pi cos + t_s mirror, with per-face albedos from one-texel-per-face atlases
    (``diffuse.exr``, ``specular.exr``) on ``object.ply``. The mirror is a near-delta
    rough lobe because Mitsuba 3.9.1's ``blendbsdf`` of a smooth and a delta ``conductor``
    renders biased under the path tracer's MIS (measured: diffuse part 17 % too bright,
    mirror part 18 % too dark; with the rough lobe both agree with the forward model within
    0.2 %). The lobe model's Phong has no
    stock equivalent: it uses pseudolight's Phong plugin on ``mesh.ply`` face attributes
    (load with :func:`load_exported_scene`).
    """
    material = est.model.mitsuba_material()
    if material.kind == "diffuse_mirror":
        bsdf = {"type": "blendbsdf", "weight": 0.5,
                "diffuse": {"type": "diffuse", "reflectance": {**ATLAS_TEXTURE, "filename": "diffuse.exr"}},
                "mirror": {"type": "roughconductor", "material": "none", "alpha": 1e-3, "distribution": "ggx",
                           "specular_reflectance": {**ATLAS_TEXTURE, "filename": "specular.exr"}}}
        shape = {"type": "ply", "filename": "object.ply", "face_normals": True, "bsdf": bsdf}
    else:
        bsdf = {"type": PLUGIN_OF_KIND[material.kind], **material.properties,
                "diffuse_reflectance": {"type": "mesh_attribute", "name": "face_diffuse_color"},
                "specular_reflectance": {"type": "mesh_attribute", "name": "face_specular_color"}}
        shape = {"type": "ply", "filename": "mesh.ply", "face_normals": True, "bsdf": bsdf}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
        "object": shape,
        "light": {"type": "envmap", "filename": "envmap.exr"},
    }
    if camera is not None:
        scene["sensor"] = mitsuba_sensor(NUMPY_TRANSFORMS, camera, spp)
    return scene


def export_scene(folder: str, mesh: TriangleMesh, est: Estimate, camera: Camera | None = None) -> str:
    """Write ``scene.xml``, the mesh (``object.ply`` with atlas UVs and ``diffuse.exr`` /
    ``specular.exr`` for the stock diffuse + mirror export, else ``mesh.ply`` with per-face
    albedos as face attributes) and ``envmap.exr`` into ``folder``; returns the XML path.
    The environment is clamped at 0 (Mitsuba's envmap needs non-negative radiance); where
    the SH ring below zero the exported scene is brighter than the forward model, and the
    XML's comment says by how much of the map's total radiance.
    """
    scene = scene_dict(est, camera)
    os.makedirs(folder, exist_ok=True)
    signed = environment(est)
    clamped = float(np.abs(np.minimum(signed, 0.0)).sum() / max(float(np.abs(signed).sum()), 1e-300))
    write_exr(os.path.join(folder, "envmap.exr"), np.maximum(signed, 0.0))
    if scene["object"]["filename"] == "object.ply":
        for name, values in (("diffuse", est.diffuse), ("specular", est.specular)):
            image, uv = face_atlas(2.0 * np.asarray(values, np.float32))   # blendbsdf weight 1/2
            write_exr(os.path.join(folder, f"{name}.exr"), image)
        write_uv_ply(os.path.join(folder, "object.ply"), mesh.corners, uv)
        how = "stock Mitsuba plugins only; per-face albedos (x2, blend weight 1/2) in diffuse.exr / specular.exr"
    else:
        _write_ply(os.path.join(folder, "mesh.ply"), mesh, est.diffuse, est.specular)
        how = "needs pseudolight's Phong plugin; per-face albedos are PLY face attributes"
    path = os.path.join(folder, "scene.xml")
    with open(path, "w") as f:
        f.write(scene_xml(scene, f"pseudolight estimate ({est.method}); {how}; negative SH radiance clamped: "
                                 f"{100 * clamped:.2f} % of the map's absolute radiance"))
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
