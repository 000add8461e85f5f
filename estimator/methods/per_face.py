"""``bilinear-per-face``: every face its own group (the paper's Fig. 7 d, e)."""
from __future__ import annotations

from ..diagnostics import trust
from ..solvers import albedo_prior
from .base import Method, register_method


@register_method
class BilinearPerFace(Method):
    """Every face its own cluster (the paper's Fig. 7 d, e): exact for specular-only
    data, ambiguous between diffuse and the constant part of specular otherwise."""

    name = "bilinear-per-face"
    default_loss = "cauchy"  # one glare view ruins a least-squares per-face fit (0.058 within ±10 % against 0.980)
    streams = True

    def solve(self, prep):
        est = self._solve_per_face(prep)
        width = self.config.albedo_prior
        if width > 0:
            diffuse_precision, specular_precision = trust.albedo_precision(prep, est)
            edges = prep.data.mesh.face_adjacency
            spreads = {}
            for name, precision in (("diffuse", diffuse_precision), ("specular", specular_precision)):
                if self.config.components in (name, "both"):
                    smoothed, spread = albedo_prior.smooth_albedo(getattr(est, name), precision, edges,
                                                                  est.observed, width)
                    setattr(est, name, smoothed)
                    spreads[name] = spread.tolist()
            est.info["albedo_prior"] = {"width": width, "spread": spreads}
        return est
