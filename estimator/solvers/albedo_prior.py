"""An edge-preserving prior on the albedo differences of neighbouring faces (Retinex-like).

A per-face solve determines each face's albedo from its own observations only; where those
are few or noisy, neighbours that share its albedo carry the missing information. With the
light fixed, face f's albedo estimate a_f has a precision p_f = sum_rows g^2 / sigma^2 (g its
shading or gloss in each observation, sigma the observations' robust noise level). The
smoothed albedos minimise, per channel,

    sum_f p_f (x_f - a_f)^2 + sum_(i,j) rho((x_i - x_j) / (k tau)),

over the face-adjacency graph, rho the Cauchy loss (IRLS), so a texture edge (a difference
of many tau) costs little and is kept while noise (differences of about tau or less) is
averaged away. The scale tau is set by the data (empirical Bayes): the robust spread of the
neighbour differences less the part the faces' own noise explains, at least
:data:`MIN_SPREAD` x the channel's median albedo. A face with a precise estimate barely
moves; without noise the prior changes nothing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.linalg import cg

from ..core.settings import Section

CHI2_MEDIAN = 0.4549    # the median of a chi-square with 1 degree of freedom: median(d^2) = 0.4549 var(d)
MIN_SPREAD = 0.02       # tau is at least this share of the channel's median albedo
MIN_RELATIVE_SE = 1e-6  # precisions are capped at a standard error of this share of the median albedo
ROUNDS = 5              # IRLS rounds
RIDGE = 1e-9            # added to every precision (in units of the channel's level^-2)


@dataclass
class AlbedoPriorConfig(Section):
    """The edge-preserving albedo prior of the per-face solve (:func:`smooth_albedo`).

    Attributes
    ----------
    albedo_prior : width of the Cauchy prior on neighbour differences, in units of the
        data's own texture spread (0: off, the paper's per-face solve).
    """

    albedo_prior: float = 2.0

    def check(self):
        return [(self.albedo_prior >= 0, "albedo_prior must be >= 0 (0: off)")]


def smooth_albedo(albedo: np.ndarray, precision: np.ndarray, edges: np.ndarray, estimated: np.ndarray,
                  width: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-face albedos pulled toward their neighbours where their own data is weak.

    Parameters
    ----------
    albedo : (F, 3) per-face estimates a_f.
    precision : (F, 3) their precisions p_f (1 / variance; 0 where unknown, inf where exact).
    edges : (E, 2) pairs of adjacent faces.
    estimated : (F,) bool, faces that hold an estimate (others are left as they are and
        are not neighbours).
    width : k, the Cauchy width in units of tau (2: differences beyond 2 tau are edges).

    Returns
    -------
    smoothed : (F, 3).
    spread : (3,) tau per channel (0 for a channel left alone: no edges, or a median of 0).
    """
    out = albedo.astype(np.float64).copy()
    spread = np.zeros(3)
    pairs = edges[estimated[edges[:, 0]] & estimated[edges[:, 1]]]
    if len(pairs) == 0:
        return out, spread
    i, j = pairs[:, 0], pairs[:, 1]
    f = len(albedo)
    rows, cols = np.concatenate([i, j, i, j]), np.concatenate([i, j, j, i])
    cap = 1.0 / MIN_RELATIVE_SE ** 2
    for c in range(3):
        level = float(np.median(np.abs(out[estimated, c])))
        if not np.isfinite(level) or level <= 0:
            continue   # zero on most faces: no texture level to judge differences by
        # in units of the channel's level, so that every size below is of order one
        a = out[:, c] / level
        with np.errstate(over="ignore"):   # a precision beyond the cap is the cap
            p = np.where(estimated, np.minimum(np.nan_to_num(precision[:, c] * level ** 2, posinf=cap), cap), 0.0)
        with np.errstate(divide="ignore"):
            variance = np.where(p > 0, 1.0 / p, np.inf)
        noise = float(np.median(variance[i] + variance[j]))
        diff2 = float(np.median((a[i] - a[j]) ** 2)) / CHI2_MEDIAN
        tau2 = max(diff2 - noise if np.isfinite(noise) else diff2, MIN_SPREAD ** 2)
        spread[c] = level * np.sqrt(tau2)
        x = a.copy()
        for _ in range(ROUNDS):
            d = x[i] - x[j]
            w = 1.0 / (tau2 * (1.0 + d * d / (width * width * tau2)))
            laplacian = sparse.csr_matrix((np.concatenate([w, w, -w, -w]), (rows, cols)), shape=(f, f))
            # a tiny ridge on every face, on both sides: it makes the system definite and keeps a
            # face without data or edges where it is, without pulling anything toward 0
            system = sparse.diags(p + RIDGE) + laplacian
            x, _ = cg(system, (p + RIDGE) * a, x0=x, rtol=1e-8, maxiter=500,
                      M=sparse.diags(1.0 / system.diagonal()))
        out[:, c] = np.where(estimated, level * x, out[:, c])
    return out, spread
