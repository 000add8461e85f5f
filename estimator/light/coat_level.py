"""The view-independent level of a glossy layer's reflection, found from the albedo edges.

A coat or a glossy lobe reflects the environment in every view of a face. Its changes across
views give the coat's weight (:mod:`estimator.light.coat`), but the part every view shares is a
level added to the face's diffuse radiance, and a per-face albedo absorbs it: dark albedos come
out too bright. The level differs from an albedo where the shading varies: a face's radiance
is r_f = a_f s_f + b_c, so across an edge between faces of one albedo the albedos
(r_i - b_c) / s_i and (r_j - b_c) / s_j agree only at the true b_c. The residual

    e_ij(b) = [(r_i - b) / s_i - (r_j - b) / s_j] / m_ij,   m_ij = (r_i / s_i + r_j / s_j) / 2

is that albedo difference relative to the faces' albedos without the level: its noise is the
radiance's relative noise whatever b, so no level shrinks it (in the log domain, a negative
level flattens every ratio towards 0, and a positive one amplifies the dark faces' noise).
It is linear in b. A dielectric coat and a white lobe reflect every wavelength alike, so the
level has the colour of the reflection itself (the environment's): b = beta * k, k (3,) that
colour (given by the caller: the light's own, with the interreflection term), one unknown
beta >= 0 for the three channels, fitted by iteratively reweighted least squares under a Cauchy
loss on each channel's robust scale of e_ij(0) (the residuals without the level). It is kept
when it lowers that Cauchy negative log-likelihood by more than (1/2) ln n, n the residuals
(the Bayesian information criterion, as the sun's), and capped so that at most
``max_negative`` of the usable faces have a channel of radiance at or below it (a reflection
cannot exceed what the pixels show, as :func:`estimator.light.coat.admissible_scale`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..solvers import robust

# IRLS rounds of the level's one unknown: each is a weighted mean over the edges, and the
# weights settle within a few rounds
ROUNDS = 20


@dataclass(frozen=True)
class CoatLevel:
    """The level a fit found.

    Attributes
    ----------
    level : (3,) the level per channel in radiance units (0 where it does not explain the
        edges by the criterion).
    gain : how much it lowered the edges' Cauchy negative log-likelihood.
    price : (1/2) ln n, the criterion's price of its one unknown.
    """

    level: np.ndarray
    gain: float
    price: float


def level_from_edges(radiance: np.ndarray, shade: np.ndarray, edges: np.ndarray, usable: np.ndarray,
                     colour: np.ndarray, max_negative: float) -> CoatLevel:
    """The level b = beta k of colour k that makes the albedos of neighbouring faces agree best.

    Parameters
    ----------
    radiance : (F, 3) each face's diffuse radiance (linear; the level still in it).
    shade : (F, 3) each face's shading under the light (radiance = albedo x shade + level).
    edges : (E, 2) pairs of neighbouring faces.
    usable : (F,) bool, faces whose radiance and shading are positive and enter the fit.
    colour : (3,) >= 0, not all 0: the level's colour in radiance units (its scale is free).
    max_negative : at most this share of the usable faces may have a channel of radiance at or
        below the level.

    Returns
    -------
    :class:`CoatLevel`.
    """
    f = len(radiance)
    if radiance.shape != (f, 3) or shade.shape != (f, 3) or usable.shape != (f,):
        raise InputError(f"radiance and shade must be (F, 3) and usable (F,), got {radiance.shape}, "
                         f"{shade.shape} and {usable.shape}")
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer) or (
            len(edges) and (edges.min() < 0 or edges.max() >= f)):
        raise InputError(f"edges must be (E, 2) face indices below {f}, got shape {edges.shape} of {edges.dtype}")
    colour = np.asarray(colour, dtype=float)
    if colour.shape != (3,) or not np.all(np.isfinite(colour) & (colour >= 0)) or not colour.any():
        raise InputError(f"the level's colour must be (3,), finite, >= 0 and not all 0, got {colour}")
    if not 0 <= max_negative < 1:
        raise InputError(f"max_negative must lie in [0, 1), got {max_negative}")
    usable = usable & np.all(np.isfinite(radiance) & (radiance > 0) & np.isfinite(shade) & (shade > 0), axis=1)
    i, j = edges[:, 0], edges[:, 1]
    pair = usable[i] & usable[j]
    i, j = i[pair], j[pair]
    none = CoatLevel(np.zeros(3), 0.0, 0.0)
    if len(i) < 2:
        return none
    inverse = 1.0 / np.where(usable[:, None], shade, 1.0)                       # (F, 3)
    albedo = radiance * inverse
    middle = 0.5 * (albedo[i] + albedo[j])                                      # (E', 3)
    base = (albedo[i] - albedo[j]) / middle                                     # e_ij(0)
    slope = colour * (inverse[i] - inverse[j]) / middle                         # -d e_ij / d beta
    scale = np.array([robust.robust_scale(np.abs(base[:, c]), floor=1e-12) for c in range(3)])
    base, slope = (base / scale).ravel(), (slope / scale).ravel()               # in units of each channel's scale
    # at most max_negative of the usable faces with some channel at or below the level
    shown = colour > 0
    cap = float(np.quantile(np.min(radiance[usable][:, shown] / colour[shown], axis=1), max_negative))
    beta = 0.0
    for _ in range(ROUNDS):
        weights = robust.irls_weights(np.abs(base - beta * slope), "cauchy", 1.0)
        beta = float(np.clip(np.sum(weights * base * slope) / max(np.sum(weights * slope * slope), 1e-300), 0.0, cap))
    tuning = robust.TUNING["cauchy"]
    gain = float(np.sum(np.log1p((base / tuning) ** 2)) - np.sum(np.log1p(((base - beta * slope) / tuning) ** 2)))
    price = 0.5 * float(np.log(len(base)))
    if gain <= price:
        return CoatLevel(np.zeros(3), gain, price)
    return CoatLevel(beta * colour, gain, price)
