"""Robust weights for observations the reflection model cannot explain.

Real images hold what the bilinear model has no term for: glints of a sharp light in a
smooth coat (a handful of observations can carry most of the squared colour norm), glare,
occluders, misregistered pixels. Least squares lets them pull the light; iteratively
reweighted least squares (IRLS) with a redescending M-estimator gives them a weight near
zero. Residuals are relative to the exposure level (90th percentile of the observations'
colour norms); the scale is their normalised median.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..core.reductions import group_quantile
from ..core.settings import Section

# tuning constants (in units of the robust scale) with 95 % efficiency under Gaussian noise
TUNING = {"huber": 1.345, "cauchy": 2.385, "tukey": 4.685}


LOSSES = ("auto", "none", "huber", "cauchy", "tukey")


@dataclass
class RobustConfig(Section):
    """The iteratively reweighted solve.

    Attributes
    ----------
    robust_loss : M-estimator on colour residuals relative to the exposure level (the 90th
        percentile of the observations' colour norms, :func:`exposure_level`) ('none':
        least squares, the paper; 'huber', 'cauchy' or 'tukey'; 'auto': the method's own
        ``default_loss``).
    robust_rounds : reweighting rounds (each one more bilinear solve).
    glint_ratio : before the first robust solve, a row brighter than this x its face's
        median colour is clipped to that level (a glint must not set the first light).
    """

    robust_loss: str = "auto"
    robust_rounds: int = 2
    glint_ratio: float = 4.0

    def check(self):
        return [
            (self.robust_loss in LOSSES, f"robust_loss must be one of {LOSSES}"),
            (self.robust_rounds >= 0, "robust_rounds must be >= 0"),
            (self.glint_ratio > 1, "glint_ratio must be > 1"),
        ]


def face_levels(face: np.ndarray, rgb: np.ndarray, num_faces: int) -> np.ndarray:
    """(F,) norm of each face's median colour over its rows (face (N,), rgb (N, 3))."""
    med = group_quantile(face, rgb, num_faces, 0.5, interpolate=True)
    return np.linalg.norm(np.nan_to_num(med), axis=1)


def initial_weights(face: np.ndarray, rgb: np.ndarray, num_faces: int, ratio: float,
                    levels: np.ndarray | None = None) -> np.ndarray:
    """(N,) weights before any fit: a row brighter than ``ratio`` x its face's median colour
    norm is softly clipped to that level (weight (ratio level / norm)^2), so a glint cannot
    dominate the first solve; later IRLS rounds judge it by the model's residual. ``levels``
    (F,): :func:`face_levels` of these rows, where already computed (None: computed here)."""
    level = (face_levels(face, rgb, num_faces) if levels is None else levels)[face]
    norm = np.linalg.norm(rgb, axis=1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        w = np.where(norm > ratio * level, (ratio * level / np.maximum(norm, 1e-300)) ** 2, 1.0)
    return np.nan_to_num(w, nan=1.0)


def relative_residuals(rgb: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """(N,) colour residual norm of each row (rgb, predicted (N, 3)) divided by the 90th
    percentile of the rows' colour norms (the exposure level): one yardstick for every face,
    so a face that is dark in most views (unlit, or specular-only off its highlight) is not
    judged by its own tiny level."""
    return np.linalg.norm(rgb - predicted, axis=1) / exposure_level(rgb)


def exposure_level(rgb: np.ndarray) -> float:
    """The 90th percentile of the colour norms of the rows rgb (N, 3) (1 without rows; at
    least 1e-300): the yardstick of :func:`relative_residuals`."""
    level = float(np.percentile(np.linalg.norm(rgb, axis=1), 90)) if len(rgb) else 1.0
    return max(level, 1e-300)


def robust_scale(residuals: np.ndarray, weights: np.ndarray | None = None, floor: float = 1e-3) -> float:
    """1.4826 x the median of the residuals (of rows with weight > 0), at least ``floor``."""
    r = residuals if weights is None else residuals[weights > 0]
    return max(1.4826 * float(np.median(r)) if len(r) else floor, floor)


def irls_weights(residuals: np.ndarray, loss: str, scale: float) -> np.ndarray:
    """(N,) IRLS weights w(r / (c scale)) of relative residuals (N,) for ``loss``.

    huber: min(1, 1/|u|); cauchy: 1 / (1 + u^2); tukey: (1 - u^2)^2 for |u| < 1, else 0.
    """
    if loss not in LOSSES:
        raise InputError(f"robust loss must be one of {LOSSES}, got {loss!r}")
    if loss == "none":
        return np.ones_like(residuals)
    u = residuals / (TUNING[loss] * scale)
    if loss == "huber":
        return np.minimum(1.0, 1.0 / np.maximum(np.abs(u), 1e-300))
    if loss == "cauchy":
        return 1.0 / (1.0 + u * u)
    return np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
