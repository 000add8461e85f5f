"""The reflection of a smooth dielectric coat, as far as the diffuse solve must remove it.

A plastic's clear coat reflects the environment about the mirror direction with the
Fresnel factor of the view angle. Its sharp glints rarely reach a low quantile of a
face's colours, but the reflection of the broad, low-order part of the light does: it is
an additive term that inflates dark albedos and dark channels most, relative to their
own level. That term varies with the view while the diffuse
radiance does not, so its weight is fitted to each face's colour changes across views:

    rgb_fv - mean_v(rgb_fv)  ~  k_c [x_fv - mean_v(x_fv)],   x_fv = F(n . v) L_low(r_fv)

with F the dielectric Fresnel reflectance of ``ior``, r the mirror direction and L_low
the light truncated to ``order`` (the orders the diffuse shading determines). k >= 0 per
channel; a bare diffuse surface gives k ~ 0 and is left unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import sh
from ..core.settings import Section
from ..model.reflection import fresnel_dielectric, mirror_directions
from ..solvers import robust


@dataclass
class CoatConfig(Section):
    """The reflection of a smooth dielectric coat, removed from the colours (:func:`fit_coat`).

    Attributes
    ----------
    coat_correction : fit and remove the coat's reflection, then find the light again.
    coat_ior : the coat's index of refraction (Fresnel reflectance and transmission).
    coat_order : highest SH degree of the light that the coat's reflection carries (at most
        ``sh_order``).
    coat_min_share : the coat is removed only when its median share of the colours exceeds this.
    coat_max_negative : the fitted weight is scaled down until subtracting it turns at most
        this share more of the observations non-positive (a coat cannot reflect more than a
        pixel shows).
    """

    coat_correction: bool = True
    coat_ior: float = 1.5
    coat_order: int = 4
    coat_min_share: float = 0.005
    coat_max_negative: float = 0.005

    def check(self):
        return [
            (self.coat_ior > 1, "coat_ior must be > 1"),
            (0 <= self.coat_min_share < 1, "coat_min_share must lie in [0, 1)"),
            (0 <= self.coat_max_negative < 1, "coat_max_negative must lie in [0, 1)"),
            (self.coat_order >= 0, "coat_order must be >= 0"),
        ]


def coat_rows(normals: np.ndarray, view_dir: np.ndarray, light: np.ndarray, order: int, ior: float) -> np.ndarray:
    """(N, 3) the coat's reflection per unit weight, F(n . v) L_low(r), of observations
    with face normals (N, 3) and unit directions to the camera (N, 3), under ``light``
    (M, 3) SH (truncated to ``order``)."""
    m = min(sh.num_coeffs(order), light.shape[0])
    mirror = mirror_directions(normals, view_dir)
    low = sh.basis(sh.order_of(m), mirror) @ light[:m]
    return fresnel_dielectric(np.sum(normals * view_dir, axis=1), ior)[:, None] * low


def fit_coat(face: np.ndarray, rgb: np.ndarray, rows: np.ndarray, num_faces: int, loss: str = "cauchy",
             rounds: int = 5) -> np.ndarray:
    """(3,) weight k_c >= 0 of ``rows`` (N, 3) in the colours ``rgb`` (N, 3) of faces
    ``face`` (N,): least squares on each face's deviations from its mean over views,
    reweighted by ``loss`` (glints and shadows the coat term does not explain)."""
    counts = np.maximum(np.bincount(face, minlength=num_faces), 1).astype(float)

    def deviation(values):
        mean = np.stack([np.bincount(face, values[:, k], minlength=num_faces) for k in range(3)], 1) / counts[:, None]
        return values - mean[face]

    x, y = deviation(rows), deviation(rgb)
    weights = np.ones(len(face))
    k = np.zeros(3)
    for _ in range(rounds):
        wx = weights[:, None] * x
        k = np.sum(wx * y, axis=0) / np.maximum(np.sum(wx * x, axis=0), 1e-300)
        residual = np.linalg.norm(y - k * x, axis=1)
        weights = robust.irls_weights(residual, loss, robust.robust_scale(residual, floor=1e-12))
    return np.maximum(k, 0.0)


def admissible_scale(rgb: np.ndarray, coat: np.ndarray, max_negative: float, steps: int = 20) -> float:
    """Largest t in [0, 1] such that subtracting t x ``coat`` (N, 3) from ``rgb`` (N, 3)
    leaves at most ``max_negative`` of the rows with a channel <= 0: a coat cannot reflect
    more than the pixel shows (bisection)."""
    def negative(t):
        return float(np.mean(np.any(rgb - t * coat <= 0, axis=1)))

    base = negative(0.0)
    if negative(1.0) <= base + max_negative:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if negative(mid) <= base + max_negative else (lo, mid)
    return lo
