"""A deterministic direct-lighting integrator for scenes lit by delta lights.

Registered as ``pseudolight_direct``. Mitsuba's ``direct`` integrator picks one
random emitter per sample, so a scene with 40 directional lights renders with
noise. This one loops over *every* emitter at each hit, with one shadow ray
each (``scene.ray_test``); delta emitters (directional, point, spot) need no
random numbers, so the only sampling left is the pixel footprint
(supersampling for antialiasing). Surfaces are not emitters; a ray that
misses returns black with alpha 0.

It has no properties.
"""
from __future__ import annotations

import drjit as dr

from estimator import backend
from harness.plugins import DIRECT

# Mitsuba's classes depend on the variant: this module is imported by
# harness.plugins.register_all once the variant is chosen.
mi = backend.set_variant()



class DirectDeltaIntegrator(mi.SamplingIntegrator):
    def __init__(self, props):
        mi.SamplingIntegrator.__init__(self, props)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        si = scene.ray_intersect(ray, active)
        valid = active & si.is_valid()
        bsdf = si.bsdf(ray)
        ctx = mi.BSDFContext()
        result = mi.Spectrum(0.0)
        for emitter in scene.emitters():
            if not mi.has_flag(emitter.flags(), mi.EmitterFlags.Delta):
                raise ValueError(f"{DIRECT} handles delta lights only, got {emitter}; "
                                 "use the 'path' integrator for environment maps")
            ds, weight = emitter.sample_direction(si, mi.Point2f(0.5, 0.5), valid)
            visible = valid & (ds.pdf > 0) & ~scene.ray_test(si.spawn_ray_to(ds.p), valid)
            value = bsdf.eval(ctx, si, si.to_local(ds.d), visible)
            result += dr.select(visible, value * weight, 0.0)
        return result, valid, []

    def aov_names(self):
        return []

    def to_string(self):
        return "DirectDeltaIntegrator[]"
