"""An estimate as a Mitsuba scene: the physically based cross-check of the model.

The estimator predicts R = t_d sum h C + t_s sum h D. With the paper's model
(``specular_model='mirror'``, ``diffuse_light='pseudo'``) the same image comes
out of Mitsuba's path tracer (two bounces) when the mesh carries the per-face
albedos on the diffuse + perfect-mirror BSDF and the pseudo illumination h is
the environment map. With ``specular_model='lobe'`` the scene uses the Phong
BSDF and the radiance L = h / (Phong filter) as environment map.
"""
from __future__ import annotations

import os

import numpy as np

from estimator import sh
from estimator.camera import Camera, gl_to_mitsuba
from estimator.data import TriangleMesh
from estimator.methods import Estimate

from . import diffuse_mirror_bsdf
from .exr import write_exr
from .illumination import Illumination
from .render import build_scene, render_views

ENVMAP_SIZE = (256, 512)


def _model(est: Estimate) -> tuple[float | None, np.ndarray]:
    """(Phong exponent or None for diffuse + mirror, environment SH) of an estimate."""
    cfg = est.config
    if cfg.specular_model == "lobe":
        return cfg.phong_exponent, est.radiance_sh
    if cfg.diffuse_light != "pseudo":
        raise ValueError("the Mitsuba cross-check needs one light for both terms: diffuse_light='pseudo' "
                         "(with specular_model='mirror') or specular_model='lobe'")
    return None, est.sh


def environment(est: Estimate) -> np.ndarray:
    """The estimate's environment map (H, W, 3) as signed radiance (SH ringing can go negative)."""
    _, coeffs = _model(est)
    return sh.to_latlong(coeffs, *ENVMAP_SIZE)


def render_estimate(mesh: TriangleMesh, est: Estimate, cameras: list[Camera], spp: int = 64,
                    seed: int = 7) -> list[np.ndarray]:
    """Render the estimate with Mitsuba's path tracer -> list of (H, W, 4) RGBA.

    Rendering is linear in the environment, and Mitsuba's ``envmap`` needs
    non-negative radiance, so the positive and negative parts of the SH
    environment are rendered separately and subtracted: the result is the
    render of the signed environment, as the forward model sees it.
    """
    exponent, _ = _model(est)
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


def export_scene(folder: str, mesh: TriangleMesh, est: Estimate, camera: Camera | None = None) -> str:
    """Write ``scene.xml``, ``mesh.ply`` (per-face albedos as face attributes) and
    ``envmap.exr`` into ``folder``; returns the XML path. The environment is
    clamped at 0 (Mitsuba's envmap needs non-negative radiance); where the SH
    ring below zero the exported scene is brighter than the forward model.

    Load with :func:`load_exported_scene`, which registers the pseudolight BSDFs.
    """
    exponent, _ = _model(est)
    envmap = np.maximum(environment(est), 0.0)
    os.makedirs(folder, exist_ok=True)
    write_exr(os.path.join(folder, "envmap.exr"), envmap)
    _write_ply(os.path.join(folder, "mesh.ply"), mesh, est.diffuse, est.specular)
    bsdf_type = "pseudolight_diffuse_mirror" if exponent is None else "pseudolight_phong"
    exponent_xml = "" if exponent is None else f'\n            <float name="exponent" value="{exponent}"/>'
    sensor = ""
    if camera is not None:
        matrix = " ".join(f"{v:.9g}" for v in gl_to_mitsuba(camera.c2w).ravel())
        sensor = f"""
    <sensor type="perspective">
        <float name="fov" value="{camera.fov_x_deg:.9g}"/>
        <string name="fov_axis" value="x"/>
        <transform name="to_world"><matrix value="{matrix}"/></transform>
        <film type="hdrfilm"><integer name="width" value="{camera.width}"/><integer name="height" value="{camera.height}"/>
            <string name="pixel_format" value="rgba"/><rfilter type="box"/></film>
        <sampler type="multijitter"><integer name="sample_count" value="64"/></sampler>
    </sensor>"""
    xml = f"""<scene version="3.0.0">
    <!-- pseudolight estimate ({est.method}); per-face albedos are PLY face attributes -->
    <integrator type="path"><integer name="max_depth" value="2"/><boolean name="hide_emitters" value="true"/></integrator>
    <shape type="ply">
        <string name="filename" value="mesh.ply"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="{bsdf_type}">{exponent_xml}
            <texture type="mesh_attribute" name="diffuse_reflectance"><string name="name" value="face_diffuse_color"/></texture>
            <texture type="mesh_attribute" name="specular_reflectance"><string name="name" value="face_specular_color"/></texture>
        </bsdf>
    </shape>
    <emitter type="envmap"><string name="filename" value="envmap.exr"/></emitter>{sensor}
</scene>
"""
    path = os.path.join(folder, "scene.xml")
    with open(path, "w") as f:
        f.write(xml)
    return path


def load_exported_scene(path: str):
    """``mi.load_file`` of an exported scene, with the pseudolight plugins registered."""
    from . import phong_bsdf

    phong_bsdf.register()
    diffuse_mirror_bsdf.register()
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
