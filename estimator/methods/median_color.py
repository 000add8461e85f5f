"""``median-color``: the naive baseline without an illumination model."""
from __future__ import annotations

import numpy as np

from ..core import sh
from ..model.estimate import Estimate
from .base import Method, register_method


@register_method
class MedianColor(Method):
    """The naive baseline: albedo = median observed colour, no illumination model."""

    name = "median-color"
    streams = True
    reports_residual = False   # it fits nothing

    def solve(self, prep):
        med = prep.all_obs.median_color()
        observed = ~np.isnan(med[:, 0])
        med = np.nan_to_num(med)
        f = len(med)
        zero = np.zeros_like(med)
        diffuse, specular = (zero, med) if self.config.components == "specular" else (med, zero)
        h = np.zeros((sh.num_coeffs(self.config.sh_order), 3))
        h[0] = 1.0
        labels = np.where(observed, np.arange(f), -1)
        return Estimate(diffuse, specular, h, labels, observed, self.name, self.config,
                        {"clusters": int(observed.sum())}, h.copy() if self.model.light == "radiance" else None)
