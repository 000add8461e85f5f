"""The peer a user would otherwise reach for: gradient-based inverse rendering with
Mitsuba 3's differentiable renderer, registered as the method ``mitsuba-ad``.

Unknowns: a per-face diffuse albedo and a per-face specular weight (``mesh_attribute``s of
the mesh: a ``blendbsdf`` of a Lambertian ``diffuse`` and a near-mirror ``roughconductor``,
GGX alpha :data:`AD_GLOSS_ALPHA`, weighted by w per face; Mitsuba's ``plastic`` cannot take
mesh-attribute textures), and a low-resolution lat-long environment map of radiance. Each
step renders one training view (round robin) with ``prb`` (direct light with shadows, the
glossy reflection of the envmap, background hidden) at a reduced resolution and a few
samples, takes the L2 loss against the view's image averaged to that resolution, and
updates all of them with Adam; values are clipped at a small positive floor (positivity),
w at 1. The envmap is coarse to fine: its resolution doubles halfway through the time
budget. The run stops at ``ad_time_budget`` seconds (or after ``ad_max_steps`` steps). ``ad_specular`` False keeps the
Lambertian model (no specular unknown).

The light becomes the estimate's pseudo illumination as for every method: the envmap's
radiance projected to SH, filtered by the Phong lobe of ``phong_exponent``, in the unit-DC
gauge. The estimate's diffuse albedo is (1 - w) x the fitted albedo, its specular albedo w
(grey), both in that gauge.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..core import sh
from ..core.camera import Camera, gl_to_mitsuba, mitsuba_sensor
from ..core.data import View
from ..core.errors import InputError
from ..core.gauge import unit_dc
from ..core.interrupt import raise_if_stop_requested
from ..core.settings import Section
from ..model.estimate import Estimate
from ..rays import backend
from ..rays.raycast import mitsuba_mesh
from .base import Method, register_method

AD_GLOSS_ALPHA = 0.05   # GGX roughness of the peer's specular lobe (a near-mirror coat)


@dataclass
class PeerConfig(Section):
    """The ``mitsuba-ad`` peer.

    Attributes
    ----------
    ad_time_budget : wall-clock seconds of Adam steps.
    ad_max_steps : at most this many steps (0: the time budget alone); the schedule (snapshots,
        the envmap's refinement, the stop) follows whichever of time and steps is further along,
        so a step-capped run under a generous budget is the same run on any machine.
    ad_resolution : the rendered width it aims at (the views are box-averaged by an integer factor).
    ad_spp : samples per pixel.
    ad_learning_rate : Adam's learning rate.
    ad_envmap_height : the final envmap height (it starts at half, doubling halfway).
    ad_specular : fit a per-face specular albedo too (``blendbsdf`` of diffuse and a
        near-mirror ``roughconductor``); False: Lambertian only.
    """

    ad_time_budget: float = 60.0
    ad_max_steps: int = 0
    ad_resolution: int = 64
    ad_spp: int = 4
    ad_learning_rate: float = 0.02
    ad_envmap_height: int = 16
    ad_specular: bool = True

    def check(self):
        return [
            (self.ad_time_budget > 0, "ad_time_budget must be > 0"),
            (self.ad_max_steps >= 0, "ad_max_steps must be >= 0 (0: the time budget alone)"),
            (self.ad_resolution >= 8 and self.ad_spp >= 1 and self.ad_envmap_height >= 4,
             "ad_resolution must be >= 8, ad_spp >= 1 and ad_envmap_height >= 4"),
            (self.ad_learning_rate > 0, "ad_learning_rate must be > 0"),
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


@register_method
class MitsubaAD(Method):
    """Per-face albedo and an envmap fitted by differentiable rendering (see module doc)."""

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
        views = data.views
        first = views[0].camera
        factor = resolution_factor(first.width, first.height, c.ad_resolution)
        refs = [mi.TensorXf(downsample(v, factor)) for v in views]
        level = float(np.mean([np.mean(v.rgb[v.alpha > 0.5]) if v.alpha is not None else np.mean(v.rgb)
                               for v in views]))
        props = mi.Properties()
        albedo_texture = {"type": "mesh_attribute", "name": "face_albedo"}
        bsdf = {"type": "diffuse", "reflectance": albedo_texture}
        if c.ad_specular:   # plastic's constructor needs a texture mean, which mesh attributes lack
            bsdf = {"type": "blendbsdf", "weight": {"type": "mesh_attribute", "name": "face_specular"},
                    "diffuse": bsdf, "gloss": {"type": "roughconductor", "material": "none", "alpha": AD_GLOSS_ALPHA}}
        props["bsdf"] = mi.load_dict(bsdf)
        shape = mitsuba_mesh(mesh, "object", props=props)
        shape.add_attribute("face_albedo", 3, mi.Float(np.full(3 * mesh.num_faces, 0.5, np.float32)))
        unknowns = ["object.face_albedo"]
        if c.ad_specular:
            shape.add_attribute("face_specular", 1, mi.Float(np.full(mesh.num_faces, 0.1, np.float32)))
            unknowns.append("object.face_specular")
        unknowns.append("emitter.data")
        height = max(2, c.ad_envmap_height // 2)
        env0 = np.full((height, 2 * height, 3), max(level / 0.5, 1e-3), np.float32)
        scene = mi.load_dict({
            "type": "scene", "embree_use_robust_intersections": True,
            "integrator": {"type": "prb", "max_depth": 2, "hide_emitters": True},
            "object": shape,
            "emitter": {"type": "envmap", "bitmap": mi.Bitmap(env0)},
            "sensor": mitsuba_sensor(mi, scaled_camera(first, factor), c.ad_spp),
        })
        params = mi.traverse(scene)
        opt = mi.ad.Adam(lr=c.ad_learning_rate)
        for key in unknowns:
            opt[key] = params[key]
        params.update(opt)
        t0 = time.perf_counter()
        history = {"seconds": [], "loss": [], "envmap": []}
        snapshots, snapshot_seconds = [], []
        next_snapshot, refined, step = 0.0, False, 0
        while True:
            raise_if_stop_requested()   # a SIGTERM raised inside Dr.Jit's loop callback can be swallowed
            elapsed = time.perf_counter() - t0
            progress = max(elapsed / c.ad_time_budget, step / c.ad_max_steps if c.ad_max_steps else 0.0)
            if progress >= next_snapshot:
                snapshots.append(np.array(opt["object.face_albedo"], dtype=np.float64).reshape(-1, 3))
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
            view = step % len(views)
            params["sensor.to_world"] = mi.ScalarTransform4f(gl_to_mitsuba(views[view].camera.c2w))
            params.update()
            image = mi.render(scene, params, spp=c.ad_spp, seed=step)
            loss = dr.mean(dr.square(image[:, :, :3] - refs[view]), axis=None)
            dr.backward(loss)
            opt.step()
            for key in unknowns:
                opt[key] = dr.clip(opt[key], 1e-4, 1.0 if key == "object.face_specular" else 1e4)
            params.update(opt)
            history["seconds"].append(time.perf_counter() - t0)
            history["loss"].append(float(np.array(loss).ravel()[0]))
            history["envmap"].append(list(np.array(opt["emitter.data"]).shape[:2]))
            step += 1
        albedo = np.array(opt["object.face_albedo"], dtype=np.float64).reshape(-1, 3)
        specular = np.zeros_like(albedo)
        if c.ad_specular:   # the blend's weight w: (1 - w) x albedo is the Lambertian part
            weight = np.clip(np.array(opt["object.face_specular"], dtype=np.float64), 0.0, 1.0)
            albedo, specular = albedo * (1.0 - weight)[:, None], np.repeat(weight[:, None], 3, axis=1)
        env = np.array(opt["emitter.data"], dtype=np.float64)[..., :3]
        radiance = sh.project_latlong(c.sh_order, env)
        pseudo = sh.phong_filtered(radiance, c.phong_exponent)
        pseudo, dc = unit_dc(pseudo)
        observed = prep.all_obs.observed_faces()
        f = mesh.num_faces
        short = [] if step >= len(views) else [
            f"mitsuba-ad ran {step} step(s) in its budget ({c.ad_time_budget:g} s), fewer than the {len(views)} views: "
            "some views never entered the fit; raise ad_time_budget (--time-budget) or ad_max_steps"]
        info = {"clusters": int(f), "steps": step, "method_warnings": short,
                "render_resolution": [first.width // factor, first.height // factor],
                "ad_history": {"seconds": history["seconds"], "loss": history["loss"],
                               "snapshot_seconds": snapshot_seconds},
                "degrees_of_freedom": {"observations": int(3 * len(prep.obs.face)),
                                       "unknowns": int(3 * f + (f if c.ad_specular else 0) + env.size)}}
        est = Estimate(np.where(observed[:, None], albedo * dc, 0.0), np.where(observed[:, None], specular * dc, 0.0),
                       pseudo,
                       np.where(observed, np.arange(f), -1), observed, self.name, c, info)
        est.face_stats["albedo_history"] = np.stack(snapshots, axis=1) * dc   # (F, K, 3), same gauge
        return est
