"""Albedos under a light: radiance over shading, and how far faces stray from their region."""
from __future__ import annotations

import numpy as np

from ...core.gauge import unit_dc
from ...light import edge_fit
from .values import FitContext, Shading


def divide(shading: Shading, radiance: np.ndarray, light: np.ndarray, usable: np.ndarray,
           extra=0.0) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) radiance over the shading ``shading.columns @ light`` (plus an ``extra`` indirect
    shading), and (F,) where that is an albedo (:func:`divide_shade`)."""
    return divide_shade(shading.columns @ light + extra, radiance, usable)


def divide_shade(shade: np.ndarray, radiance: np.ndarray, usable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) ``radiance`` over ``shade`` (F, 3), and (F,) where that is an albedo: the usable
    faces :func:`lit_faces` keeps."""
    lit = lit_faces(shade, usable, usable)
    with np.errstate(divide="ignore", invalid="ignore"):
        albedo = np.where(lit[:, None], radiance / np.where(shade > 0, shade, 1.0), 0.0)
    return albedo, lit


def lit_faces(shade: np.ndarray, usable: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool the ``faces`` lit above 2 % of the 95th-percentile shading of the ``usable``
    faces (``shade`` (F, 3) positive in every channel): a face in deep shadow divides noise by
    nearly nothing."""
    lum = shade.mean(axis=1)
    level = max(float(np.percentile(lum[usable], 95)), 1e-30)
    return faces & np.all(shade > 0, axis=1) & (lum > 0.02 * level)


def in_unit_dc(albedo: np.ndarray, light: np.ndarray) -> np.ndarray:
    """(F, 3) ``albedo`` in the gauge of ``light`` (M', 3) with a unit DC per channel: the
    albedos the segmentation compares. Its features are colours (chromaticity and brightness),
    so they must not take the light's per-channel scale, which only the faint light the object
    reflects onto itself determines (with ``interreflection``; measured on the Earth-textured
    blob, a red light ten times too dim joined its continents and oceans into three regions)."""
    return albedo * unit_dc(light)[1]


def deviation(albedo: np.ndarray, reference: np.ndarray) -> float:
    """The median over rows of the mean over channels of |log(albedo / reference)| (both (n, 3))."""
    return float(np.median(np.abs(np.log(np.maximum(albedo, 1e-12) / np.maximum(reference, 1e-12))).mean(axis=1)))


def at_indirect_scale(ctx: FitContext, shading: Shading, radiance: np.ndarray, light: np.ndarray) -> np.ndarray:
    """``light`` (M', 3) rescaled per channel to the units of the indirect shading ``ctx.extra``.

    A light found from the colours' changes across views (a coat's map, a lobe) has a unit DC
    or an unknown one; the light the object reflects onto itself is in radiance units, so the
    direct light's scale against it is one unknown per channel, fitted to the albedo edges
    (:func:`edge_fit.log_shading_fit` on the light's shading as one column). Unchanged without
    an interreflection term."""
    if np.isscalar(ctx.extra):
        return light
    shade = shading.columns @ light                                                      # (F, 3)
    scale = np.ones(3)
    for k in range(3):   # faces whose radiance and direct shading are positive in this channel
        usable = ctx.usable & np.isfinite(radiance[:, k]) & (radiance[:, k] > 0) & (shade[:, k] > 0)
        if usable.sum() >= 2:
            scale[k] = edge_fit.log_shading_fit(radiance[:, [k]], shade[:, [k]], ctx.edges, usable,
                                                **ctx.plain_fit, indirect=ctx.extra[:, [k]])[0][0, 0]
    return light * scale
