"""A diffuse + perfect-mirror BSDF plugin: the estimator's model as a Mitsuba material.

Registered as ``pseudolight_diffuse_mirror``. Lit by an environment map h, a
path tracer with two bounces renders

    R = t_d / pi * int h(w) s(w) cos dw + t_s * h(r) s(r),

i.e. t_d sum h C + t_s sum h D: the paper's reflection equation with the
pseudo illumination h as the environment. Sampling picks the mirror with
probability lum(t_s) / (lum(t_d) + lum(t_s)), as Mitsuba's ``plastic`` does
for its delta lobe.

Properties
----------
diffuse_reflectance : texture or RGB, default 0.5.
specular_reflectance : texture or RGB, default 0.
"""
from __future__ import annotations

import drjit as dr

from estimator import backend
from harness.plugins.properties import texture_property

# Mitsuba's classes depend on the variant: this module is imported by
# harness.plugins.register_all once the variant is chosen.
mi = backend.set_variant()



class DiffuseMirrorBSDF(mi.BSDF):
    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.diffuse = texture_property(props, "diffuse_reflectance", 0.5)
        self.specular = texture_property(props, "specular_reflectance", 0.0)
        diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        mirror = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide
        self.m_components = [diffuse, mirror]
        self.m_flags = diffuse | mirror

    def _p_mirror(self, si, active):
        lum_d = mi.luminance(self.diffuse.eval(si, active))
        lum_s = mi.luminance(self.specular.eval(si, active))
        return dr.select(lum_d + lum_s > 0, lum_s / dr.maximum(lum_d + lum_s, 1e-12), 0.0)

    def eval(self, ctx, si, wo, active=True):
        cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        ok = active & (cos_i > 0) & (cos_o > 0)
        return dr.select(ok, self.diffuse.eval(si, ok) * cos_o * dr.inv_pi, 0.0)

    def pdf(self, ctx, si, wo, active=True):
        cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        ok = active & (cos_i > 0) & (cos_o > 0)
        return dr.select(ok, (1 - self._p_mirror(si, ok)) * cos_o * dr.inv_pi, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0)
        p_mirror = self._p_mirror(si, active)
        mirror = sample1 < p_mirror
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = dr.select(mirror, mi.reflect(si.wi), mi.warp.square_to_cosine_hemisphere(sample2))
        cos_o = mi.Frame3f.cos_theta(bs.wo)
        bs.pdf = dr.select(mirror, p_mirror, (1 - p_mirror) * cos_o * dr.inv_pi)
        bs.eta = 1.0
        bs.sampled_component = dr.select(mirror, mi.UInt32(1), mi.UInt32(0))
        bs.sampled_type = dr.select(mirror, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                    mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
        weight = dr.select(mirror, self.specular.eval(si, active) / dr.maximum(p_mirror, 1e-12),
                           self.diffuse.eval(si, active) / dr.maximum(1 - p_mirror, 1e-12))
        valid = active & (bs.pdf > 0) & (cos_o > 0)
        return bs, dr.select(valid, weight, 0.0)

    def traverse(self, callback):
        callback.put("diffuse_reflectance", self.diffuse, mi.ParamFlags.Differentiable)
        callback.put("specular_reflectance", self.specular, mi.ParamFlags.Differentiable)

    def to_string(self):
        return "DiffuseMirrorBSDF[]"
