"""A Phong BSDF plugin for Mitsuba 3 with spatially varying diffuse and specular albedo.

Registered as ``pseudolight_phong``. Its value including the cosine is exactly
the form the estimator assumes:

    f(wi, wo) cos(theta_o) = t_d / pi * cos(theta_o)
                           + t_s * (n + 1) / (2 pi) * max(0, r . wo)^n,

with r = reflect(wi) the mirrored view direction and n the Phong exponent
(normalised lobe: a white specular lobe reflects all light arriving around r
whenever the lobe is not cut by the horizon). Light arriving from below the
surface, or viewed from below, contributes nothing.

Importance sampling mixes cosine-weighted hemisphere sampling and the
cos^n lobe around r, in proportion to the luminance of t_d and t_s;
``pdf`` is the matching mixture density, so sampling and eval agree.

Properties
----------
diffuse_reflectance : texture or RGB, default 0.5.
specular_reflectance : texture or RGB, default 0.
exponent : float > 0, default 10.
"""
from __future__ import annotations

import drjit as dr

from estimator import backend
from harness.plugins import PHONG
from harness.plugins.properties import texture_property

# Mitsuba's classes depend on the variant: this module is imported by
# harness.plugins.register_all once the variant is chosen.
mi = backend.set_variant()



class PhongBSDF(mi.BSDF):
    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.diffuse = texture_property(props, "diffuse_reflectance", 0.5)
        self.specular = texture_property(props, "specular_reflectance", 0.0)
        exponent = float(props.get("exponent", 10.0))
        if not exponent > 0.0:
            raise ValueError(f"{PHONG}: exponent must be > 0, got {exponent}")
        self.exponent = mi.Float(exponent)
        diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        self.m_components = [diffuse, glossy]
        self.m_flags = diffuse | glossy

    def _albedos(self, si, active):
        td = self.diffuse.eval(si, active)
        ts = self.specular.eval(si, active)
        lum_d, lum_s = mi.luminance(td), mi.luminance(ts)
        total = lum_d + lum_s
        p_spec = dr.select(total > 0, lum_s / dr.maximum(total, 1e-12), 0.5)
        return td, ts, p_spec

    def _lobe(self, wi, wo):
        r = mi.reflect(wi)
        return dr.maximum(dr.dot(r, wo), 0.0)

    def _eval_pdf(self, si, wo, active):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0)
        td, ts, p_spec = self._albedos(si, active)
        n = self.exponent
        lobe = dr.power(self._lobe(si.wi, wo), n) * (n + 1) * dr.inv_two_pi
        value = td * (cos_o * dr.inv_pi) + ts * lobe
        pdf = (1 - p_spec) * cos_o * dr.inv_pi + p_spec * lobe
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

    def eval(self, ctx, si, wo, active=True):
        return self._eval_pdf(si, wo, active)[0]

    def pdf(self, ctx, si, wo, active=True):
        return self._eval_pdf(si, wo, active)[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        return self._eval_pdf(si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        active = active & (cos_i > 0)
        _, _, p_spec = self._albedos(si, active)
        pick_spec = sample1 < p_spec
        n = self.exponent
        cos_a = dr.power(sample2.x, 1.0 / (n + 1))
        sin_a = dr.safe_sqrt(1 - cos_a * cos_a)
        sin_p, cos_p = dr.sincos(dr.two_pi * sample2.y)
        lobe_dir = mi.Frame3f(mi.reflect(si.wi)).to_world(mi.Vector3f(sin_a * cos_p, sin_a * sin_p, cos_a))
        wo = dr.select(pick_spec, lobe_dir, mi.warp.square_to_cosine_hemisphere(sample2))
        value, pdf = self._eval_pdf(si, wo, active)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = wo
        bs.pdf = pdf
        bs.eta = 1.0
        bs.sampled_component = dr.select(pick_spec, mi.UInt32(1), mi.UInt32(0))
        bs.sampled_type = dr.select(pick_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                    mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
        valid = active & (pdf > 0)
        return bs, dr.select(valid, value / dr.maximum(pdf, 1e-20), 0.0)

    def traverse(self, callback):
        callback.put("diffuse_reflectance", self.diffuse, mi.ParamFlags.Differentiable)
        callback.put("specular_reflectance", self.specular, mi.ParamFlags.Differentiable)

    def to_string(self):
        return f"PhongBSDF[exponent={self.exponent}]"
