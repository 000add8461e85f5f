"""The peer a user would otherwise reach for: gradient-based inverse rendering with
Mitsuba 3's differentiable renderer, registered as the method ``mitsuba-ad``.

With ``ad_albedo = "atlas"`` (the default) it is set up as published baselines ship it: the
mesh unwrapped into a UV atlas (xatlas, :mod:`estimator.core.atlas`), Mitsuba's ``principled``
BSDF with a base-colour texture over that atlas and one roughness (``specular`` 0.5, a
dielectric of index 1.5; metallic 0), and a lat-long environment map of radiance (a roughness
texture drifts further from the albedo: its texels fall towards a mirror while the base colour
takes up the difference). The loss is the L2 image error plus ``ad_tv_weight`` times the
texture's total variation (scaled by the images' squared mean level, so that the weight does
not depend on the exposure); Adam's learning rate decays exponentially to
:data:`AD_FINAL_LR_RATIO` of ``ad_learning_rate`` over the run. A face's diffuse albedo is its
area mean of the base colour (:func:`estimator.core.atlas.face_means`).

With ``ad_albedo = "face"`` the unknowns are a per-face diffuse albedo and a per-face specular
weight (``mesh_attribute``s: a ``blendbsdf`` of a Lambertian ``diffuse`` and a near-mirror
``roughconductor``, GGX alpha :data:`AD_GLOSS_ALPHA`, weighted by w per face; Mitsuba's ``plastic``
cannot take mesh-attribute textures). ``ad_specular`` False keeps a Lambertian model (no
specular unknown) in both set-ups.

Each step renders one training view (round robin) with ``prb`` (direct light with shadows,
the glossy reflection of the envmap, background hidden) at a reduced resolution and a few
samples, takes the loss against the view's image averaged to that resolution, and updates
the unknowns with Adam; values are clipped to their ranges (positivity; a weight, a colour
or a roughness at most 1). The envmap is coarse to fine: its resolution doubles halfway
through the run. The run stops at ``ad_time_budget`` seconds (or after ``ad_max_steps``
steps).

The light becomes the estimate's pseudo illumination as for every method: the envmap's
radiance projected to SH, filtered by the Phong lobe of ``phong_exponent``, in the unit-DC
gauge. With per-face unknowns the estimate's diffuse albedo is (1 - w) x the fitted albedo
and its specular albedo w (grey); the atlas's ``principled`` model has no Phong specular
albedo, so its specular albedo is 0 and its roughness is kept in ``info["roughness"]``.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..core import sh
from ..core.atlas import face_means, uv_atlas
from ..core.camera import Camera, gl_to_mitsuba, mitsuba_sensor
from ..core.data import TriangleMesh, View
from ..core.errors import InputError
from ..core.gauge import unit_dc
from ..core.interrupt import raise_if_stop_requested
from ..core.settings import Section
from ..model.estimate import Estimate
from ..rays import backend
from ..rays.raycast import mitsuba_mesh
from .base import Method, register_method

AD_GLOSS_ALPHA = 0.05     # GGX roughness of the per-face peer's specular lobe (a near-mirror coat)
AD_FINAL_LR_RATIO = 0.1   # the atlas peer's learning rate at the end of its run, relative to its start
AD_ALBEDOS = ("atlas", "face")


@dataclass
class PeerConfig(Section):
    """The ``mitsuba-ad`` peer.

    Attributes
    ----------
    ad_albedo : the unknowns' layout: "atlas" (a texture over a UV atlas, ``principled``) or
        "face" (per-face mesh attributes, a blend of Lambertian and near-mirror).
    ad_time_budget : wall-clock seconds of Adam steps.
    ad_max_steps : at most this many steps (0: the time budget alone); the schedule (snapshots,
        the envmap's refinement, the learning rate, the stop) follows whichever of time and
        steps is further along, so a step-capped run under a generous budget is the same run
        on any machine.
    ad_resolution : the rendered width it aims at (the views are box-averaged by an integer factor).
    ad_spp : samples per pixel.
    ad_learning_rate : Adam's learning rate (at the start, for the atlas).
    ad_envmap_height : the final envmap height (it starts at half, doubling halfway).
    ad_specular : fit a specular part too (the atlas's ``principled`` roughness; the per-face
        weight of a near-mirror lobe); False: Lambertian only.
    ad_texture_size : the atlas texture's side in texels.
    ad_tv_weight : weight of the texture's total variation (the mean absolute difference of
        neighbouring texels) in the atlas's loss, relative to the images' squared mean level.
    """

    ad_albedo: str = "atlas"
    ad_time_budget: float = 60.0
    ad_max_steps: int = 0
    ad_resolution: int = 64
    ad_spp: int = 4
    ad_learning_rate: float = 0.02
    ad_envmap_height: int = 16
    ad_specular: bool = True
    ad_texture_size: int = 512
    ad_tv_weight: float = 1e-3

    def check(self):
        return [
            (self.ad_albedo in AD_ALBEDOS, f"ad_albedo must be one of {', '.join(AD_ALBEDOS)}"),
            (self.ad_time_budget > 0, "ad_time_budget must be > 0"),
            (self.ad_max_steps >= 0, "ad_max_steps must be >= 0 (0: the time budget alone)"),
            (self.ad_resolution >= 8 and self.ad_spp >= 1 and self.ad_envmap_height >= 4,
             "ad_resolution must be >= 8, ad_spp >= 1 and ad_envmap_height >= 4"),
            (self.ad_learning_rate > 0, "ad_learning_rate must be > 0"),
            (8 <= self.ad_texture_size <= 8192, "ad_texture_size must lie in [8, 8192]"),
            (self.ad_tv_weight >= 0, "ad_tv_weight must be >= 0"),
        ]


def downsample(view: View, factor: int) -> np.ndarray:
    """(H / factor, W / factor, 3) box average of a view's image (background as stored)."""
    h, w = view.rgb.shape[:2]
    return view.rgb.reshape(h // factor, factor, w // factor, factor, 3).mean(axis=(1, 3)).astype(np.float32)


def scaled_camera(camera: Camera, factor: int) -> Camera:
    """The camera with its image ``factor`` times smaller (same field of view)."""
    return Camera(camera.c2w, camera.fx / factor, camera.fy / factor, camera.cx / factor, camera.cy / factor,
                  camera.width // factor, camera.height // factor)


def resolution_factor(width: int, height: int, target: int) -> int:
    """The largest integer factor dividing both sides with width / factor >= target."""
    best = 1
    for factor in range(1, max(width, height) + 1):
        if width % factor == 0 and height % factor == 0 and width // factor >= target:
            best = factor
    return best


@dataclass
class Unknowns:
    """The peer's set-up: its object, the parameter keys Adam updates with each key's range,
    the texture keys its total variation regularises, and how the per-face diffuse albedo (F, 3),
    specular albedo (F, 3) and other fitted values (name -> float, for ``info``) are read from
    the parameters."""

    shape: object
    ranges: dict[str, tuple[float, float]]
    textures: list[str]
    read: Callable[[dict], tuple[np.ndarray, np.ndarray, dict]]


def face_unknowns(mi, mesh: TriangleMesh, c: PeerConfig) -> Unknowns:
    """Per-face albedo (and specular weight) as mesh attributes of the mesh."""
    props = mi.Properties()
    bsdf = {"type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": "face_albedo"}}
    if c.ad_specular:   # plastic's constructor needs a texture mean, which mesh attributes lack
        bsdf = {"type": "blendbsdf", "weight": {"type": "mesh_attribute", "name": "face_specular"},
                "diffuse": bsdf, "gloss": {"type": "roughconductor", "material": "none", "alpha": AD_GLOSS_ALPHA}}
    props["bsdf"] = mi.load_dict(bsdf)
    shape = mitsuba_mesh(mesh, "object", props=props)
    shape.add_attribute("face_albedo", 3, mi.Float(np.full(3 * mesh.num_faces, 0.5, np.float32)))
    ranges = {"object.face_albedo": (1e-4, 1e4)}
    if c.ad_specular:
        shape.add_attribute("face_specular", 1, mi.Float(np.full(mesh.num_faces, 0.1, np.float32)))
        ranges["object.face_specular"] = (1e-4, 1.0)

    def read(values: dict) -> tuple[np.ndarray, np.ndarray, dict]:
        albedo = np.asarray(values["object.face_albedo"], dtype=np.float64).reshape(-1, 3)
        if not c.ad_specular:
            return albedo, np.zeros_like(albedo), {}
        weight = np.clip(np.asarray(values["object.face_specular"], dtype=np.float64), 0.0, 1.0)
        return albedo * (1.0 - weight)[:, None], np.repeat(weight[:, None], 3, axis=1), {}

    return Unknowns(shape, ranges, [], read)


def atlas_unknowns(mi, mesh: TriangleMesh, c: PeerConfig) -> Unknowns:
    """A base-colour texture over an xatlas atlas of the mesh and one roughness, ``principled``."""
    vertices, faces, uv = uv_atlas(mesh)
    size = c.ad_texture_size

    def bitmap(channels: int, value: float) -> dict:
        return {"type": "bitmap", "data": mi.TensorXf(np.full((size, size, channels), value, np.float32)),
                "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp"}

    if c.ad_specular:
        bsdf = {"type": "principled", "base_color": bitmap(3, 0.5), "roughness": 0.5,
                "metallic": 0.0, "specular": 0.5}
        ranges = {"object.bsdf.base_color.data": (1e-4, 1.0), "object.bsdf.roughness.value": (0.02, 1.0)}
    else:
        bsdf = {"type": "diffuse", "reflectance": bitmap(3, 0.5)}
        ranges = {"object.bsdf.reflectance.data": (1e-4, 1.0)}
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    shape = mitsuba_mesh(TriangleMesh(vertices, faces), "object", props=props, uv=uv)
    colour = next(iter(ranges))

    def read(values: dict) -> tuple[np.ndarray, np.ndarray, dict]:
        albedo = face_means(np.asarray(values[colour], dtype=np.float64), faces, uv)
        extras = {}
        if c.ad_specular:
            extras["roughness"] = float(np.asarray(values["object.bsdf.roughness.value"]).ravel()[0])
        return albedo, np.zeros_like(albedo), extras

    return Unknowns(shape, ranges, [k for k in ranges if k.endswith(".data")], read)


def total_variation(dr, texture):
    """Mean absolute difference of neighbouring texels of an (H, W, C) tensor, both axes."""
    return (dr.mean(dr.abs(texture[1:, :, :] - texture[:-1, :, :]), axis=None)
            + dr.mean(dr.abs(texture[:, 1:, :] - texture[:, :-1, :]), axis=None))


@register_method
class MitsubaAD(Method):
    """Textures (or per-face values) and an envmap fitted by differentiable rendering (see module doc)."""

    name = "mitsuba-ad"
    reports_residual = False   # its loss is on downsampled renders, not the observations' relative residual

    def solve(self, prep):
        c = self.config
        mi = backend.set_variant(c.variant)
        if "_ad_" not in mi.variant():
            raise InputError(f"mitsuba-ad needs an autodiff variant (llvm_ad_rgb, cuda_ad_rgb), got {mi.variant()}")
        import drjit as dr

        data = prep.data
        mesh = data.mesh
        black = set(prep.all_obs.black_views.tolist())   # a failed capture is no image to fit
        views = [v for i, v in enumerate(data.views) if i not in black]
        first = views[0].camera
        factor = resolution_factor(first.width, first.height, c.ad_resolution)
        refs = [mi.TensorXf(downsample(v, factor)) for v in views]
        level = float(np.mean([np.mean(v.rgb[v.alpha > 0.5]) if v.alpha is not None else np.mean(v.rgb)
                               for v in views]))
        setup = (atlas_unknowns if c.ad_albedo == "atlas" else face_unknowns)(mi, mesh, c)
        ranges = dict(setup.ranges, **{"emitter.data": (1e-4, 1e4)})
        height = max(2, c.ad_envmap_height // 2)
        env0 = np.full((height, 2 * height, 3), max(level / 0.5, 1e-3), np.float32)
        scene = mi.load_dict({
            "type": "scene", "embree_use_robust_intersections": True,
            "integrator": {"type": "prb", "max_depth": 2, "hide_emitters": True},
            "object": setup.shape,
            "emitter": {"type": "envmap", "bitmap": mi.Bitmap(env0)},
            "sensor": mitsuba_sensor(mi, scaled_camera(first, factor), c.ad_spp),
        })
        params = mi.traverse(scene)
        opt = mi.ad.Adam(lr=c.ad_learning_rate)
        for key in ranges:
            opt[key] = params[key]
        params.update(opt)
        tv_weight = c.ad_tv_weight * level ** 2
        t0 = time.perf_counter()
        history = {"seconds": [], "loss": [], "envmap": []}
        snapshots, snapshot_seconds = [], []
        next_snapshot, refined, step = 0.0, False, 0
        while True:
            raise_if_stop_requested()   # a SIGTERM raised inside Dr.Jit's loop callback can be swallowed
            elapsed = time.perf_counter() - t0
            progress = max(elapsed / c.ad_time_budget, step / c.ad_max_steps if c.ad_max_steps else 0.0)
            if progress >= next_snapshot:
                snapshots.append(setup.read(opt)[0])
                snapshot_seconds.append(elapsed)
                next_snapshot += 1 / 8
                if history["loss"]:
                    self.log(f"mitsuba-ad: step {step}, loss {history['loss'][-1]:.4g}, {elapsed:.1f} s "
                             f"({min(progress, 1.0):.0%} of its budget)")
            if progress >= 1.0 and step > 0:   # at least one step, whatever the budget
                break
            if not refined and progress >= 0.5:
                refined = True   # coarse to fine: the envmap at twice the resolution, same radiance
                coarse = np.array(opt["emitter.data"])
                fine = np.repeat(np.repeat(coarse, 2, axis=0), 2, axis=1)
                opt["emitter.data"] = mi.TensorXf(fine.astype(np.float32))
                params.update(opt)
            if c.ad_albedo == "atlas":
                opt.set_learning_rate(c.ad_learning_rate * AD_FINAL_LR_RATIO ** min(progress, 1.0))
            view = step % len(views)
            params["sensor.to_world"] = mi.ScalarTransform4f(gl_to_mitsuba(views[view].camera.c2w))
            params.update()
            image = mi.render(scene, params, spp=c.ad_spp, seed=step)
            loss = dr.mean(dr.square(image[:, :, :3] - refs[view]), axis=None)
            objective = loss
            for key in setup.textures if tv_weight > 0 else []:
                objective = objective + tv_weight * total_variation(dr, opt[key])
            dr.backward(objective)
            opt.step()
            for key, (low, high) in ranges.items():
                opt[key] = dr.clip(opt[key], low, high)
            params.update(opt)
            history["seconds"].append(time.perf_counter() - t0)
            history["loss"].append(float(np.array(loss).ravel()[0]))
            history["envmap"].append(list(np.array(opt["emitter.data"]).shape[:2]))
            step += 1
        albedo, specular, extras = setup.read(opt)
        env = np.array(opt["emitter.data"], dtype=np.float64)[..., :3]
        radiance = sh.project_latlong(c.sh_order, env)
        pseudo = sh.phong_filtered(radiance, c.phong_exponent)
        pseudo, dc = unit_dc(pseudo)
        observed = prep.all_obs.observed_faces()
        f = mesh.num_faces
        short = [] if step >= len(views) else [
            f"mitsuba-ad ran {step} step(s) in its budget ({c.ad_time_budget:g} s), fewer than the {len(views)} views: "
            "some views never entered the fit; raise ad_time_budget (--time-budget) or ad_max_steps"]
        unknowns = sum(int(np.prod(np.array(opt[key]).shape)) for key in setup.ranges) + env.size
        info = {"clusters": int(f), "steps": step, "method_warnings": short, "ad_albedo": c.ad_albedo,
                **extras,
                "render_resolution": [first.width // factor, first.height // factor],
                "ad_history": {"seconds": history["seconds"], "loss": history["loss"],
                               "snapshot_seconds": snapshot_seconds},
                "degrees_of_freedom": {"observations": int(3 * len(prep.obs.face)), "unknowns": int(unknowns)}}
        est = Estimate(np.where(observed[:, None], albedo * dc, 0.0), np.where(observed[:, None], specular * dc, 0.0),
                       pseudo,
                       np.where(observed, np.arange(f), -1), observed, self.name, c, info)
        est.face_stats["albedo_history"] = np.stack(snapshots, axis=1) * dc   # (F, K, 3), same gauge
        return est
