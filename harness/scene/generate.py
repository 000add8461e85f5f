"""Scene spec -> synthetic dataset with exactly known ground truth."""
from __future__ import annotations

import dataclasses
import json
import os
import time

import numpy as np

from estimator import Camera, EstimatorConfig, RayCaster, TriangleMesh, backend, fresnel_dielectric
from harness.io.atomic import atomic_directory
from harness.io.dataset import write_dataset, write_ground_truth
from harness.io.images import read_linear_rgb
from harness.scene import geometry
from harness.scene.faults import apply_faults
from harness.scene.illumination import Illumination, build_illumination
from harness.scene.render import build_scene, make_cameras, render_through_lens, render_views
from harness.scene.spec import AlbedoSpec, SceneSpec, SpecError
from harness.scene.textures import (
    pattern_albedo,
    region_labels,
    spherical_texture_average,
    uv_texture_average,
)
from reports.ground_truth import GroundTruth

GROUND_TRUTH_SH_ORDER = 12


def build_mesh(spec: SceneSpec) -> tuple[TriangleMesh, np.ndarray | None]:
    """The spec's mesh and its per-vertex texture coordinates (None unless a mesh file has them)."""
    return geometry.build_geometry(spec.geometry, spec.seed)


def _albedo(mesh: TriangleMesh, uv: np.ndarray | None, albedo: AlbedoSpec, where: str, seed: int = 0) -> np.ndarray:
    return reflectance(where, _albedo_values(mesh, uv, albedo, where, seed))


def reflectance(where: str, values: np.ndarray) -> np.ndarray:
    """``values`` (F, 3), refused with the spec key ``where`` named where some albedo exceeds 1:
    an albedo is the share of the light a surface reflects, so the ground truth of a value
    above it (a texture's scale, a typo) would describe no surface."""
    top = float(np.max(values, initial=0.0))
    if top > 1.0:
        raise SpecError(f"{where} gives albedos up to {top:.4g}: an albedo is the share of the light reflected, "
                        "at most 1 (lower its value, colours or scale)")
    return values


def _albedo_values(mesh: TriangleMesh, uv: np.ndarray | None, albedo: AlbedoSpec, where: str, seed: int) -> np.ndarray:
    if albedo.value is not None:
        return np.tile(np.asarray(albedo.value, float) * albedo.scale, (mesh.num_faces, 1))
    if albedo.pattern is not None:
        return albedo.scale * pattern_albedo(mesh, albedo.pattern, albedo.colors, albedo.frequency, albedo.axis, seed)
    texture = read_linear_rgb(albedo.texture)
    if albedo.mapping == "uv":
        if uv is None:
            raise SpecError(f"{where}.mapping = 'uv' but the mesh file has no per-vertex texture coordinates")
        return albedo.scale * uv_texture_average(mesh, uv, texture)
    return albedo.scale * spherical_texture_average(mesh, texture)


def build_materials(mesh: TriangleMesh, spec: SceneSpec, uv: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Per-face (diffuse (F, 3), specular (F, 3), regions (F,) or None). A region with an
    ``albedo`` texture takes that texture's values on its faces (seeded by the spec's seed
    plus the region's index)."""
    m = spec.material
    if m.regions:
        labels = region_labels(mesh, [(r.axis, r.ranges) for r in m.regions])
        for index, region in enumerate(m.regions):
            for name in ("diffuse", "specular"):
                reflectance(f"material.regions[{index}].{name}", np.array([getattr(region, name)], float))
        diffuse = np.array([r.diffuse for r in m.regions], float)[labels]
        specular = np.array([r.specular for r in m.regions], float)[labels]
        for index, region in enumerate(m.regions):
            if region.albedo is not None:
                inside = labels == index
                where = f"material.regions[{index}].albedo"
                textured = _albedo_values(mesh, uv, region.albedo, where, spec.seed + index)
                diffuse[inside] = reflectance(where, textured[inside])
        return diffuse, specular, labels
    return (_albedo(mesh, uv, m.diffuse, "material.diffuse", spec.seed),
            _albedo(mesh, uv, m.specular, "material.specular", spec.seed), None)


@dataclasses.dataclass
class GeneratedScene:
    """Everything needed to render a spec, before any image is made."""

    spec: SceneSpec
    mesh: TriangleMesh
    diffuse: np.ndarray
    specular: np.ndarray
    regions: np.ndarray | None
    illumination: Illumination

    def ground_truth(self) -> GroundTruth:
        return GroundTruth(self.diffuse, self.specular, self.illumination.sh(GROUND_TRUTH_SH_ORDER),
                           material_dict(self.spec.material, self.regions), self.illumination.to_json(), self.regions)

    def render(self, cameras, illumination: Illumination | None = None, desc: str = "render") -> list[np.ndarray]:
        """RGBA images (H, W, 4) of ``cameras``, optionally under another illumination."""
        if not cameras:
            return []
        r = self.spec.render
        light = illumination or self.illumination
        scene = build_scene(self.mesh, self.diffuse, self.specular, material_dict(self.spec.material, self.regions),
                            light,
                            cameras[0], r.spp, r.resolved_integrator(self.spec.illumination), r.max_depth)
        lens = self.spec.cameras.lens()
        if lens is not None:
            return render_through_lens(scene, cameras, lens, r.spp, self.spec.seed, desc)
        return render_views(scene, cameras, r.spp, self.spec.seed, desc)


def material_dict(m, regions: np.ndarray | None = None) -> dict:
    """The BRDF of a material spec as stored in ground_truth/illumination.json (``brdf``).

    An object of mixed materials (:attr:`MaterialSpec.mixed`) is ``{'model': 'mixed',
    'parts': [one region's BRDF each], 'labels': each face's region (F,)}``; its ``exponent``
    is the sharpest part's (the reports' pseudo illumination is then only approximate).

    ``exponent`` is the Phong exponent whose lobe filters the true radiance into the
    pseudo illumination the reports compare with: the spec's for Phong; for Mitsuba's
    ``roughplastic`` the Phong exponent of the same Beckmann width, 2 / alpha^2 - 2;
    10000 (a mirror: the filter is 1 to 0.6 % at order 10) for ``plastic`` and ``diffuse``.
    """
    if m.mixed:
        parts = [material_dict(m.region_material(r)) for r in m.regions]
        return {"model": "mixed", "parts": parts, "labels": np.asarray(regions).tolist(),
                "exponent": max(p["exponent"] for p in parts)}
    if m.model == "phong":
        return {"model": "phong", "exponent": float(m.exponent)}
    if m.model == "diffuse":
        return {"model": "diffuse", "exponent": 10000.0}
    out = {"model": m.model, "int_ior": float(m.int_ior), "exponent": 10000.0}
    if m.model == "roughplastic":
        # the Phong exponent of the same Beckmann width; at least 0.01 (alpha = 1 gives 0: a near-uniform lobe)
        exponent = max(float(2.0 / m.alpha ** 2 - 2.0), 0.01)
        out.update(alpha=float(m.alpha), distribution=m.distribution, exponent=exponent)
    return out


def prepare(spec: SceneSpec) -> GeneratedScene:
    """Geometry, materials and illumination of a spec (no rendering).

    For Mitsuba's own materials the specular albedo is not a parameter: the ground
    truth records the coating's Fresnel reflectance at normal incidence for
    ``plastic``/``roughplastic`` and 0 for ``diffuse``.
    """
    mesh, uv = build_mesh(spec)
    diffuse, specular, regions = build_materials(mesh, spec, uv)
    m = spec.material
    for faces, part in ([(regions == k, m.region_material(r)) for k, r in enumerate(m.regions)] if m.mixed
                        else [(slice(None), m)]):
        if part.model in ("plastic", "roughplastic"):
            specular[faces] = float(fresnel_dielectric(1.0, part.int_ior))   # ((n - 1) / (n + 1))^2
        elif part.model == "diffuse":
            specular[faces] = 0.0
    return GeneratedScene(spec, mesh, diffuse, specular, regions, build_illumination(spec.illumination, spec.seed))


LDR_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tga", ".ppm")


def cameras_inside(mesh: TriangleMesh, cameras: list[Camera]) -> list[int]:
    """Indices of the cameras whose centre lies inside the mesh: the first face a ray from the
    centre towards the mesh's centroid hits is seen from behind. Only a closed mesh has an
    inside: an open one (a shell, a mesh with holes) gives none, as a camera looking into its
    open side sees a back face from outside. Closed is judged on the surface, not the vertex
    list: vertices at one position are one (an STL file repeats them per face), a face listed
    twice counts once, and every edge must then border an even number of faces (two, or a
    non-manifold edge's four)."""
    _, corner = np.unique(np.round(mesh.vertices, 9), axis=0, return_inverse=True)
    faces = np.unique(np.sort(corner.reshape(-1)[mesh.faces], axis=1), axis=0)
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    if np.any(np.unique(edges, axis=0, return_counts=True)[1] % 2):
        return []
    centres = np.array([c.center for c in cameras])
    target = mesh.vertices.mean(axis=0)
    dirs = target[None] - centres
    dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-12)
    face = RayCaster(mesh).first_hit_faces(centres, dirs)
    hit = face >= 0
    back = np.zeros(len(cameras), bool)
    back[hit] = np.sum(mesh.face_normals[face[hit]] * dirs[hit], axis=1) > 0
    return [int(i) for i in np.nonzero(back)[0]]


def generate(spec: SceneSpec, out_dir: str, overwrite: bool = False, variant: str | None = None,
             log=None) -> dict:
    """Render a spec into a dataset folder, atomically.

    Returns a summary dict (paths, counts, seconds). Nothing is left at
    ``out_dir`` if anything fails or the run is interrupted. ``log`` (a callable)
    receives warnings: cameras inside the mesh, a low-dynamic-range light probe.
    """
    say = log or (lambda message: None)
    backend.set_variant(variant)
    t0 = time.perf_counter()
    probe = spec.illumination.file
    if probe and os.path.splitext(probe)[1].lower() in LDR_EXTENSIONS:
        say(f"warning: illumination.file {probe} is a low-dynamic-range image; a light probe should be HDR "
            "(EXR or Radiance HDR): its bright light sources are clipped")
    with atomic_directory(out_dir, overwrite=overwrite, inputs=spec.inputs(), kind="dataset") as tmp:
        scene = prepare(spec)
        train_cams, test_cams = make_cameras(spec.cameras), make_cameras(spec.cameras, test=True)
        if scene.regions is not None:
            empty = np.nonzero(np.bincount(scene.regions, minlength=len(spec.material.regions)) == 0)[0]
            for k in empty:
                say(f"warning: material.regions[{k}] ({spec.material.regions[k].name}) covers no face of the mesh "
                    "(its bands hold no face centroid, or later regions take them all)")
        inside = cameras_inside(scene.mesh, train_cams + test_cams)
        if len(inside) == len(train_cams) + len(test_cams):
            raise SpecError(f"cameras.distance {spec.cameras.distance} puts every camera inside the mesh: the "
                            "images would show only its inside; place the cameras outside the object")
        if inside:
            say(f"warning: {len(inside)} of {len(train_cams) + len(test_cams)} cameras lie inside the mesh "
                f"(cameras.distance {spec.cameras.distance}): their images show the inside")
        t1 = time.perf_counter()
        train = scene.render(train_cams, desc=f"{spec.name} train")
        test = scene.render(test_cams, desc=f"{spec.name} test")
        t2 = time.perf_counter()
        # a view with no pixel the object covers wholly (the estimator's min_coverage) gives it nothing
        covered = spec.estimator.get("min_coverage", EstimatorConfig().min_coverage)
        empty = [i for i, image in enumerate(train) if not np.any(image[..., 3] >= covered)]
        if empty:
            say(f"warning: {len(empty)} of {len(train)} training views show no pixel wholly covered by the object "
                f"(first: view {empty[0]}): the mesh lies outside their frame or is smaller than a pixel, and the "
                f"estimate will refuse them; check its position and scale against cameras.distance "
                f"{spec.cameras.distance}")
        meta = {"scene": spec.name, "generator": "pseudolight", "variant": backend.active_variant(),
                "spp": spec.render.spp, "seed": spec.seed, "estimator_defaults": spec.estimator}
        if spec.cameras.lens() is not None:   # the images are as the lens recorded them: readers undistort them
            meta.update(spec.cameras.lens().as_json())
        mesh, views, ldr = scene.mesh, list(zip(train_cams, train)), None
        if spec.faults.active:
            mesh, views, test_cams, ldr, meta["faults"] = apply_faults(spec.faults, spec.seed, mesh, views, test_cams)
            say(f"faults applied to the {len(views)} training views: {spec.faults.summary()}")
            for key, counts in meta["faults"].get("clamped", {}).items():
                say(f"warning: faults.{key} = {counts['requested']} asks for more views than the {len(views)} training "
                    f"views; applied to {counts['applied']} (recorded in transforms.json)")
        source = meta.get("faults", {}).pop("face_source", None)
        write_dataset(tmp, mesh, views, list(zip(test_cams, test)), meta, half=spec.render.half, ldr=ldr)
        truth = scene.ground_truth()
        if source is not None:   # a decimated mesh: each written face carries its rendered face's truth
            brdf = truth.brdf if truth.brdf.get("model") != "mixed" else {
                **truth.brdf, "labels": np.asarray(truth.brdf["labels"])[source].tolist()}
            truth = dataclasses.replace(truth, diffuse=truth.diffuse[source], specular=truth.specular[source],
                                        regions=None if truth.regions is None else truth.regions[source], brdf=brdf)
        write_ground_truth(tmp, truth, envmap=scene.illumination.envmap,
                           extra={"scene_spec": spec_json(spec),
                                  "region_names": [r.name for r in spec.material.regions] or None})
        t3 = time.perf_counter()
    return {"path": os.path.abspath(out_dir), "scene": spec.name, "faces": scene.mesh.num_faces,
            "views": len(train), "test_views": len(test), "seconds": {
                "prepare": t1 - t0, "render": t2 - t1, "write": t3 - t2, "total": t3 - t0}}


def spec_json(spec: SceneSpec) -> dict:
    out = dataclasses.asdict(spec)
    out.pop("profiles", None)
    return json.loads(json.dumps(out, default=str))
