"""Albedos under a light: radiance over shading, and how far faces stray from their region."""
from __future__ import annotations

import numpy as np

from .values import Shading


def divide(shading: Shading, radiance: np.ndarray, light: np.ndarray, usable: np.ndarray,
           extra=0.0) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) radiance over the shading ``shading.columns @ light`` (plus an ``extra`` indirect
    shading), and (F,) where that is an albedo: usable and lit above 2 % of the 95th-percentile
    shading (a face in deep shadow divides noise by nearly nothing)."""
    shade = shading.columns @ light + extra
    lum = shade.mean(axis=1)
    level = max(float(np.percentile(lum[usable], 95)), 1e-30)
    lit = usable & np.all(shade > 0, axis=1) & (lum > 0.02 * level)
    with np.errstate(divide="ignore", invalid="ignore"):
        albedo = np.where(lit[:, None], radiance / np.where(shade > 0, shade, 1.0), 0.0)
    return albedo, lit


def deviation(albedo: np.ndarray, reference: np.ndarray) -> float:
    """The median over rows of the mean over channels of |log(albedo / reference)| (both (n, 3))."""
    return float(np.median(np.abs(np.log(np.maximum(albedo, 1e-12) / np.maximum(reference, 1e-12))).mean(axis=1)))
