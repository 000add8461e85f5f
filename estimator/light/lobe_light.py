"""The light a shared glossy lobe reflects: SH radiance fitted to how colours change with the view.

A face with a Phong lobe of known exponent n (the paper's model, and the project's
``pseudolight_phong``) shows, per colour channel,

    rgb_fv = D_f + t_s (E_fv . L)

with D_f its diffuse radiance (unknown, one per face: the texture), t_s the specular
albedo shared by every face, and E_fv the lobe integrated exactly over the sphere, cut by
the horizon and the face's shadows (:func:`estimator.model.reflection.lobe_matrix`), times the
radiance SH L. The per-face D_f are eliminated (each face's rows minus their mean), and
P = t_s L solves a robust least-squares problem with a ridge on its coefficients.

The view changes cannot fix P's DC: a constant light reflects into every view alike
(wherever the lobe is whole), and each face's D_f absorbs it. That one number per channel
splits each face's radiance between diffuse and specular: :func:`dc_from_edges` picks it
where the albedos D_f / shading vary least across the mesh's edges (the Retinex prior of
:mod:`estimator.light.edge_fit`, on one unknown per channel). Under a broad lobe (n = 10) and a
white t_s of 0.2 the constant specular is most of a dark face's colour, so a 3 % error in
the DC moves such a face's albedo by tens of percent.

Unlike a dielectric coat (:mod:`estimator.light.coat_map`) the lobe has no Fresnel
factor: its reflection weighs every view angle alike.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..core.errors import InputError
from ..core.settings import Section
from ..solvers import robust
from . import edge_fit


@dataclass
class LobeLightConfig(Section):
    """The light a shared Phong lobe reflects (:func:`fit_lobe_light`).

    Attributes
    ----------
    reflected_lobe : also offer the lobe's light (SH radiance fitted to the colours' changes
        across views, every face's diffuse free, no Fresnel, exponent ``phong_exponent``) to
        ``retinex-segmented``'s decision. Off by default: on the random family's development
        seeds it never predicted the truth better than the edges' light, and once it
        predicted the observations better with albedos far off.
    """

    reflected_lobe: bool = False


@dataclass(frozen=True)
class LobeLight:
    """Result of :func:`fit_lobe_light`.

    Attributes
    ----------
    light : (M, 3) radiance SH times the specular albedo, its DC zero (the DC is
        :func:`dc_from_edges`'s).
    diffuse : (F, 3) each face's mean colour minus the lobe's reflection of ``light`` (NaN
        where a face has no row).
    dc_weight : (F,) each face's mean lobe row of the DC coefficient: the diffuse radiance
        under DC ``e`` is ``diffuse - e * dc_weight``.
    explained : (3,) share of the view-dependent variance (each face's mean removed) the
        lobe explains, per channel, robust-weighted.
    rows : number of rows used.
    """

    light: np.ndarray
    diffuse: np.ndarray
    dc_weight: np.ndarray
    explained: np.ndarray
    rows: int

    def with_dc(self, dc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The light (M, 3) and each face's diffuse radiance (F, 3) for the DC ``dc`` (3,)."""
        light = self.light.copy()
        light[0] = dc
        return light, self.diffuse - self.dc_weight[:, None] * dc[None, :]


def fit_lobe_light(face: np.ndarray, rgb: np.ndarray, lobe_rows: np.ndarray, num_faces: int,
                   ridge: float = 1e-3, rounds: int = 4, loss: str = "cauchy") -> LobeLight:
    """Fit the light a shared lobe reflects, with every face's diffuse radiance free.

    Parameters
    ----------
    face : (N,) face of each observation.
    rgb : (N, 3) observed colour (linear).
    lobe_rows : (N, M) each observation's lobe rows E_fv (:func:`estimator.model.reflection.lobe_matrix`).
    num_faces : F.
    ridge : weight of the coefficients' squared norm, relative to the data term's mean
        diagonal: the lobe damps the high orders (a broad one almost erases them), so their
        coefficients need a tie-breaker. The default was chosen during development, not yet
        measured over the random scene family.
    rounds : reweighting rounds of the robust ``loss``.

    Returns
    -------
    :class:`LobeLight`.
    """
    face = np.asarray(face, dtype=np.int64)
    n, m = lobe_rows.shape if lobe_rows.ndim == 2 else (-1, -1)
    if rgb.shape != (len(face), 3) or n != len(face):
        raise InputError(f"rgb and lobe_rows must have one row per observation ({len(face)}), "
                         f"got {rgb.shape} and {lobe_rows.shape}")
    if n == 0:
        raise InputError("no observation to fit the lobe's light to")
    if face.min() < 0 or face.max() >= num_faces:
        raise InputError(f"observation faces must lie in [0, {num_faces})")
    count = np.bincount(face, minlength=num_faces).astype(float)
    inverse = np.where(count > 0, 1.0 / np.maximum(count, 1.0), np.nan)
    faces_of_rows = sparse.csr_matrix((np.ones(n), (face, np.arange(n))), shape=(num_faces, n))   # (F, N)
    mean_rows = (faces_of_rows @ lobe_rows) * np.nan_to_num(inverse)[:, None]
    varying = lobe_rows[:, 1:] - mean_rows[face, 1:]                 # the DC column is fixed to zero
    changes = rgb - ((faces_of_rows @ rgb) * np.nan_to_num(inverse)[:, None])[face]   # each face's mean removed
    light = np.zeros((m, 3))
    explained = np.zeros(3)
    for c in range(3):
        y = changes[:, c]
        weights = np.ones(n)
        for _ in range(max(rounds, 1)):
            normal = varying.T @ (weights[:, None] * varying)
            level = max(np.trace(normal) / (m - 1), 1e-300) if m > 1 else 1.0
            light[1:, c] = np.linalg.solve(normal + level * ridge * np.eye(m - 1), varying.T @ (weights * y))
            residual = y - varying @ light[1:, c]
            weights = robust.irls_weights(np.abs(residual), loss, robust.robust_scale(np.abs(residual), floor=1e-12))
        total = np.sum(weights * y ** 2)
        explained[c] = 1.0 - np.sum(weights * residual ** 2) / total if total > 0 else 0.0
    diffuse = (faces_of_rows @ (rgb - lobe_rows @ light)) * inverse[:, None]
    return LobeLight(light, diffuse, mean_rows[:, 0], explained, n)


def dc_from_edges(lobe: LobeLight, c_matrix: np.ndarray, edges: np.ndarray, usable: np.ndarray,
                  steps: int = 32, refine: int = 24) -> np.ndarray:
    """(3,) the light's DC per channel whose albedos vary least across the mesh's edges.

    For DC e a face's albedo is a_f = (D_f - e w_f) / S_f with S_f = C_f . P(e), P(e) the lobe's
    light with DC e. An edge (i, j) contributes the albedo difference in units of its noise,

        r_ij = (a_i - a_j) / sqrt(1 / S_i^2 + 1 / S_j^2) = (D_i S_j - D_j S_i) / sqrt(S_i^2 + S_j^2)

    (D's noise does not depend on e; a log ratio's does, and grows as e darkens the dark
    faces, which biases a log-ratio cost towards a low DC). e runs from 0 to the value that turns the 1 % darkest faces'
    diffuse radiance non-positive; the Cauchy cost of the residuals is sampled at ``steps``
    points and refined by a golden-section search between the best sample's neighbours,
    twice: with the cost's scale (:func:`estimator.solvers.robust.robust_scale`) taken at the middle
    of the range, then at the first minimum (a scale set far from the minimum keeps the true
    albedo edges in the quadratic part of the cost, which biases the DC).

    Parameters
    ----------
    lobe : :class:`LobeLight`.
    c_matrix : (F, M) diffuse rows: face f's shading under radiance SH L is c_matrix[f] @ L.
    edges : (E, 2) neighbouring faces.
    usable : (F,) faces that enter the cost.
    """
    seen = usable & np.all(np.isfinite(lobe.diffuse), axis=1) & (lobe.dc_weight > 0)
    if not seen.any():
        raise InputError("no face has a lobe row to split its colour into diffuse and specular")
    base = c_matrix @ lobe.light                                          # (F, 3) shading without DC
    out = np.zeros(3)
    for c in range(3):
        top = float(np.percentile(lobe.diffuse[seen, c] / lobe.dc_weight[seen], 1))
        if not top > 0:
            raise InputError(f"the lobe's light leaves no positive diffuse radiance in channel {c}")

        def residuals(e, c=c):
            d = lobe.diffuse[:, c] - e * lobe.dc_weight
            s = base[:, c] + e * c_matrix[:, 0]
            i, j = edge_fit.usable_edges(edges, seen & (s > 0))
            return (d[i] * s[j] - d[j] * s[i]) / np.sqrt(s[i] ** 2 + s[j] ** 2)

        def cost(e, scale):
            r = residuals(e)
            return edge_fit.edge_cost(r[:, None], scale) / max(len(r), 1)

        e = 0.5 * top
        for _ in range(2):   # the cost's scale from the residuals at the middle, then at the first minimum
            scale = np.array([robust.robust_scale(np.abs(residuals(e)), floor=1e-12)])
            e = _golden_minimum(lambda x, s=scale: cost(x, s), 0.0, top, steps, refine)
        out[c] = e
    return out


def _golden_minimum(cost, low: float, high: float, steps: int, refine: int) -> float:
    """The minimum of ``cost`` on [low, high]: the best of ``steps`` + 1 samples, refined by
    ``refine`` golden-section steps between its neighbours."""
    grid = np.linspace(low, high, steps + 1)
    k = int(np.argmin([cost(x) for x in grid]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, steps)]
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - golden * (hi - lo), lo + golden * (hi - lo)
    fa, fb = cost(a), cost(b)
    for _ in range(refine):
        if fa <= fb:
            hi, b, fb = b, a, fa
            a = hi - golden * (hi - lo)
            fa = cost(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + golden * (hi - lo)
            fb = cost(b)
    return 0.5 * (lo + hi)
