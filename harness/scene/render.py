"""Scenes -> Mitsuba, and rendering of calibrated views."""
from __future__ import annotations

import numpy as np
from tqdm import tqdm

from estimator import (
    Camera,
    TriangleMesh,
    axis_angle_matrix,
    backend,
    fibonacci_sphere,
    gl_to_mitsuba,
    look_at,
    mitsuba_mesh,
    mitsuba_sensor,
    multijitter_count,
)
from harness import plugins
from harness.io.lens import Lens, undistort
from harness.scene.illumination import Illumination
from harness.scene.spec import CameraSpec


def camera_positions(spec: CameraSpec, test: bool = False) -> np.ndarray:
    """(N, 3) camera centres around the origin for the training or the test views.

    'fibonacci' spreads them uniformly over the sphere of radius ``distance``;
    test views use a rotated lattice so they fall between training views.
    'ring' places them at ``elevation`` degrees, evenly in azimuth (test views
    offset by half a step). 'table-top' spreads them over the band of elevations from
    ``min_elevation`` to ``max_elevation`` degrees (an object on a table: the underside is
    never seen), uniformly in area on a golden-angle spiral (test views between them).
    """
    n = spec.test_count if test else spec.count
    if n == 0:
        return np.zeros((0, 3))
    if spec.distribution == "fibonacci":
        if n < 4:
            pts = fibonacci_sphere(4)[:n]
        else:
            pts = fibonacci_sphere(n)
        if test:
            pts = pts @ (axis_angle_matrix("y", 23.0) @ axis_angle_matrix("x", 11.0)).T
    elif spec.distribution == "table-top":
        lo, hi = np.sin(np.radians([spec.min_elevation, spec.max_elevation]))
        k = np.arange(n) + (0.5 if test else 0.0)
        height = lo + (hi - lo) * (k + 0.5) / n
        az = k * np.pi * (3.0 - np.sqrt(5.0)) + (0.3 if test else 0.0)
        ring = np.sqrt(1.0 - height ** 2)
        pts = np.stack([ring * np.sin(az), height, ring * np.cos(az)], axis=1)
    else:
        az = 2 * np.pi * (np.arange(n) + (0.5 if test else 0.0)) / n
        el = np.radians(spec.elevation)
        pts = np.stack([np.cos(el) * np.sin(az), np.full(n, np.sin(el)), np.cos(el) * np.cos(az)], axis=1)
    return spec.distance * pts


def make_cameras(spec: CameraSpec, test: bool = False) -> list[Camera]:
    """Cameras looking at the origin (world +Y up) with the spec's resolution and fov."""
    return [Camera.from_fov(look_at(p, np.zeros(3)), spec.fov, spec.width, spec.height)
            for p in camera_positions(spec, test)]


# a one-texel-per-face atlas (face_atlas) read back exactly: nearest texel, no gamma, no wrap
ATLAS_TEXTURE = {"type": "bitmap", "filter_type": "nearest", "wrap_mode": "clamp", "raw": True}


def bsdf_dict(material: float | dict | None) -> dict:
    """The Mitsuba BSDF of a material, its albedos read from the mesh's face attributes.

    ``material``: a Phong exponent (float), None (the diffuse + mirror BSDF), or a
    ground-truth BRDF dict (``{'model': 'phong'|'diffuse'|'plastic'|'roughplastic', ...}``,
    see :func:`harness.scene.generate.material_dict`). Mitsuba's own ``diffuse``,
    ``plastic`` and ``roughplastic`` take the per-face diffuse albedo; their specular
    part is the dielectric coating's.
    """
    diffuse = {"type": "mesh_attribute", "name": "face_diffuse"}
    atlas = {**ATLAS_TEXTURE, "filename": ""}
    textures = {"diffuse_reflectance": diffuse,
                "specular_reflectance": {"type": "mesh_attribute", "name": "face_specular"}}
    if material is None:
        return {"type": plugins.DIFFUSE_MIRROR, **textures}
    if not isinstance(material, dict):
        return {"type": plugins.PHONG, "exponent": float(material), **textures}
    model = material["model"]
    if model == "phong":
        return {"type": plugins.PHONG, "exponent": float(material["exponent"]), **textures}
    # Mitsuba's plastic needs the texture's mean (mesh_attribute has none): per-face albedo
    # comes from a one-texel-per-face atlas instead (see face_atlas)
    if model == "diffuse":
        return {"type": "diffuse", "reflectance": atlas}
    if model == "plastic":
        return {"type": "plastic", "diffuse_reflectance": atlas, "int_ior": float(material["int_ior"])}
    if model == "roughplastic":
        return {"type": "roughplastic", "diffuse_reflectance": atlas, "int_ior": float(material["int_ior"]),
                "alpha": float(material["alpha"]), "distribution": material["distribution"]}
    raise ValueError(f"unknown material model {model!r}")


def face_atlas(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One texel per face: (image (n, n, C) float32, corner UVs (F, 3, 2)) with n = ceil(sqrt(F)).

    Face i's texel is at row i // n, column i % n; its three corners map to a small
    triangle inside that texel, so nearest-neighbour lookup gives exactly the face's value.
    """
    f = len(values)
    n = max(int(np.ceil(np.sqrt(f))), 1)
    image = np.zeros((n * n, values.shape[1]), np.float32)
    image[:f] = values
    index = np.arange(f)
    centre = np.stack([(index % n + 0.5) / n, (index // n + 0.5) / n], axis=1)
    offsets = np.array([[-0.2, -0.2], [0.2, -0.2], [0.0, 0.2]]) / n
    return image.reshape(n, n, -1), centre[:, None, :] + offsets[None]


def _atlas_mesh(mi, mesh: TriangleMesh, diffuse: np.ndarray, bsdf: dict):
    """A mesh with unshared vertices (face i = vertices 3i..3i+2) carrying per-face UVs,
    and the BSDF reading its diffuse albedo from the face atlas."""
    image, uv = face_atlas(np.asarray(diffuse, np.float32))
    key = "reflectance" if bsdf["type"] == "diffuse" else "diffuse_reflectance"
    bitmap = dict(bsdf[key])
    del bitmap["filename"]
    bsdf = {**bsdf, key: {**bitmap, "bitmap": mi.Bitmap(image)}}
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    f = mesh.num_faces
    m = mi.Mesh("object", 3 * f, f, has_vertex_normals=False, has_vertex_texcoords=True, props=props)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(mesh.corners.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(np.arange(3 * f, dtype=np.uint32))
    params["vertex_texcoords"] = mi.Float(uv.astype(np.float32).ravel())
    params.update()
    return m


def _object(mi, mesh: TriangleMesh, diffuse: np.ndarray, specular: np.ndarray, material):
    """The Mitsuba mesh of one material with its per-face albedos (an atlas for Mitsuba's own
    materials, face attributes for pseudolight's plugins)."""
    bsdf = bsdf_dict(material)
    if bsdf["type"] in ("diffuse", "plastic", "roughplastic"):
        return _atlas_mesh(mi, mesh, diffuse, bsdf)
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    m = mitsuba_mesh(mesh, "object", props=props)
    m.add_attribute("face_diffuse", 3, mi.Float(np.asarray(diffuse, np.float32).ravel()))
    m.add_attribute("face_specular", 3, mi.Float(np.asarray(specular, np.float32).ravel()))
    return m


def build_scene(mesh: TriangleMesh, diffuse: np.ndarray, specular: np.ndarray, material: float | dict | None,
                illumination: Illumination, camera: Camera, spp: int, integrator: str = "direct",
                max_depth: int = 6):
    """A Mitsuba scene: the mesh with per-face albedos, the lights, one sensor.

    Parameters
    ----------
    diffuse, specular : (F, 3) per-face linear albedo.
    material : see :func:`bsdf_dict` (a Phong exponent, None for the estimator's
        diffuse + mirror model, or a ground-truth BRDF dict; a 'mixed' one renders each of
        its ``parts`` on the faces its ``labels`` give it).
    integrator : 'direct' (deterministic loop over delta lights) or 'path'.
    """
    mi = backend.set_variant()
    plugins.register_all()
    if isinstance(material, dict) and material.get("model") == "mixed":   # one Mitsuba mesh per material
        labels = np.asarray(material["labels"])
        objects = {f"object_{k}": _object(mi, TriangleMesh(mesh.vertices, mesh.faces[labels == k]),
                                          diffuse[labels == k], specular[labels == k], part)
                   for k, part in enumerate(material["parts"]) if np.any(labels == k)}
    else:
        objects = {"object": _object(mi, mesh, diffuse, specular, material)}
    if integrator == "direct":
        if not illumination.is_delta:
            raise ValueError("the direct integrator needs delta lights; use 'path' for an envmap")
        integ = {"type": plugins.DIRECT}
    else:
        integ = {"type": "path", "max_depth": int(max_depth), "hide_emitters": True}
    scene = {
        "type": "scene",
        "embree_use_robust_intersections": True,
        "integrator": integ,
        **objects,
        "sensor": mitsuba_sensor(mi, camera, spp),
    }
    scene.update(illumination.mitsuba_emitters(mi))
    return mi.load_dict(scene)


def render_views(scene, cameras: list[Camera], spp: int, seed: int = 0, desc: str = "render") -> list[np.ndarray]:
    """Render each camera (same intrinsics as the scene's sensor) -> list of (H, W, 4) float32 RGBA,
    at :func:`estimator.multijitter_count` (``spp``) samples per pixel.

    The sensor pose is updated in place, so Dr.Jit compiles the kernel once.
    """
    mi = backend.set_variant()
    params = mi.traverse(scene)
    sensor = scene.sensors()[0]
    size = tuple(sensor.film().size())
    images = []
    for index, cam in enumerate(tqdm(cameras, desc=desc, unit="view", leave=False)):
        if (cam.width, cam.height) != size:
            raise ValueError(f"camera {index} is {cam.width}x{cam.height}, the film is {size[0]}x{size[1]}")
        params["sensor.to_world"] = mi.ScalarTransform4f(gl_to_mitsuba(cam.c2w))
        params.update()
        image = mi.render(scene, spp=multijitter_count(spp), seed=(seed * 100003 + index) % 2 ** 32)
        images.append(np.array(image, dtype=np.float32))
    return images


def render_through_lens(scene, cameras: list[Camera], lens: Lens, spp: int, seed: int = 0,
                        desc: str = "render") -> list[np.ndarray]:
    """Render each camera as seen through a distorted lens -> list of (H, W, 4) float32 RGBA.

    Mitsuba's ``perspective`` sensor has no lens distortion, so the rays are made here:
    ``spp`` uniformly jittered positions in each pixel of the distorted image are
    undistorted (:func:`harness.io.lens.undistort`) into pinhole directions and traced by the
    scene's integrator; each pixel is their mean (a box filter, as ``render_views``).
    Alpha is the share of a pixel's rays that hit the object.
    """
    mi = backend.set_variant()
    integrator = scene.integrator()
    images = []
    for index, cam in enumerate(tqdm(cameras, desc=desc, unit="view", leave=False)):
        count = cam.width * cam.height
        rng = np.random.default_rng((seed * 100003 + index) % 2 ** 32)
        pixel = np.repeat(np.arange(count), spp)
        u = pixel % cam.width + rng.random(pixel.size)
        v = pixel // cam.width + rng.random(pixel.size)
        x, y = undistort((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, lens)
        local = np.stack([x, -y, -np.ones_like(x)], axis=1)        # OpenGL camera: +Y up, looking down -Z
        world = local @ cam.c2w[:3, :3].T
        world /= np.linalg.norm(world, axis=1, keepdims=True)
        origin = np.broadcast_to(cam.c2w[:3, 3], world.shape)
        ray = mi.Ray3f(mi.Point3f(*(mi.Float(c) for c in origin.T.astype(np.float32))),
                       mi.Vector3f(*(mi.Float(c) for c in world.T.astype(np.float32))))
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed((seed * 100003 + index) % 2 ** 32, pixel.size)
        radiance, _, _ = integrator.sample(scene, sampler, ray)
        hit = np.array(scene.ray_test(ray), dtype=np.float64)
        rgba = np.concatenate([np.array(radiance, dtype=np.float64).reshape(3, -1).T, hit[:, None]], axis=1)
        mean = rgba.reshape(count, spp, 4).mean(axis=1)
        images.append(mean.reshape(cam.height, cam.width, 4).astype(np.float32))
    return images
