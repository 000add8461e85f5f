"""The reflection of a dielectric coat, as far as the diffuse solve must remove it.

A plastic's clear coat reflects the environment about the mirror direction with the
Fresnel factor of the view angle. Its sharp glints rarely reach a low quantile of a
face's colours, but its reflection of the environment's broad part does: it is an additive
term that inflates dark albedos and dark channels most, relative to their own level. That
term varies with the view while the diffuse radiance does not, so its weight is fitted to
each face's colour changes across views:

    rgb_fv - mean_v(rgb_fv)  ~  k_c [x_fv - mean_v(x_fv)],   x_fv = F(n . v) L_low(r_fv)

with F the dielectric Fresnel reflectance of ``ior``, r the mirror direction and L_low the
light truncated to an SH degree: degree 0 is the environment's mean level, which only the
Fresnel factor and the object's own blocking of r (s_f(r): 1 where r escapes the object, 0
where the object blocks it, :func:`mirror_escapes`) modulate; higher degrees follow the
light's broad shape.
k >= 0 per channel; a bare diffuse surface gives k ~ 0 and is left unchanged.

A glossy lobe without Fresnel (the paper's Phong: paints, glazes) reflects the same light
blurred by its lobe, alike at every view angle: x_fv = P_n(r_fv) s_f(r_fv), P_n the light
filtered by the normalised Phong lobe of exponent n (:func:`lobe_rows`). Its exponent is the
one of :data:`LOBE_EXPONENTS` whose rows leave the least of the colours' changes unexplained
(:func:`unexplained_cost`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import sh
from ..core.settings import Section
from ..model.reflection import fresnel_dielectric, mirror_directions, mirror_shadow
from ..rays.visibility import SphereSampling, Visibility
from ..solvers import robust

# the Phong exponents a coat's lobe is chosen among: factors of sqrt(2) from the broad lobe of
# a satin paint (5) to 80, beyond which an order-10 light cannot tell lobes apart (the filter
# of exponent 80 still passes half of degree 10: :func:`estimator.core.sh.phong_filter`)
LOBE_EXPONENTS = (5.0, 7.0, 10.0, 14.0, 20.0, 28.0, 40.0, 56.0, 80.0)
# observations per chunk of the lobe rows: the (chunk, M) SH basis at the mirror directions
# stays about 60 MB at order 10
LOBE_CHUNK = 65_536


@dataclass
class CoatConfig(Section):
    """The reflection of a dielectric coat, removed from the colours (:func:`fit_coat`).

    Attributes
    ----------
    coat_correction : fit and remove the coat's reflection, then find the light again.
    coat_per_region : fit a grey coat's strength per uniform region (objects that mix matte,
        coated and glossy parts), else one weight for the whole object (the default: on
        objects of one rough coat, or under a sun, the smooth coat's rows misfit each region
        differently and the per-region strengths bend the albedo ratios; docs/estimator.md).
    coat_ior : the coat's index of refraction (Fresnel reflectance and transmission).
    coat_order : highest SH degree of the light that the coat's reflection carries (at most
        ``sh_order``). Two reflections are tried, the environment's mean level (degree 0) and the
        light to this degree, and the decision's criterion keeps one of them or neither.
        Measured on the random family's 40 development seeds (1000-1039, full size): 3 lost
        14.0 dB of PSNR summed over the seeds (median 33.8 -> 32.8 dB); on the rough-coated seed
        1000 the rows of degrees 3 and 4 explain the true reflection (rendered alone) best, 61-78 %
        of its variance, against 46-70 % at 2 and 32-51 % at 6.
    coat_lobe : also try a Phong lobe's reflection (no Fresnel factor, the light filtered by the
        lobe of the exponent that best explains the colours' changes across views), beside the
        dielectric coat's two; the decision's criterion keeps one of them or none. Off by
        default: on 20 development seeds of the random family it gained 3.7 dB of PSNR summed
        (1.5 dB on two rough coats), on the 20 validation seeds 1040-1059 it lost 3.4 dB summed
        (-5.4 and -4.1 dB on a rough coat under a sun and a broad Phong lobe, whose lobe
        predicted the colours far better: a lobe that explains the changes across views can
        still subtract the wrong view-independent level).
    coat_level : where a coat's reflection is seen (some reflection this correction tries exceeds
        ``coat_min_share``), also find the level that reflection adds to every view of a face,
        from the albedo edges together with the light (:mod:`estimator.light.coat_level`), and
        subtract it before the light is fitted again and the coat corrected. Off by default: it
        does not hold on every coated object (under some probes it moves one channel's albedo
        ratios between regions; docs/estimator.md).
    coat_min_share : the coat is removed only when its median share of the colours exceeds this.
    coat_max_negative : the fitted weight is scaled down until subtracting it turns at most
        this share more of the observations non-positive (a coat cannot reflect more than a
        pixel shows).
    """

    coat_correction: bool = True
    coat_per_region: bool = False
    coat_ior: float = 1.5
    coat_order: int = 4
    coat_lobe: bool = False
    coat_level: bool = False
    coat_min_share: float = 0.005
    coat_max_negative: float = 0.005

    def check(self):
        return [
            (self.coat_ior > 1, "coat_ior must be > 1"),
            (0 <= self.coat_min_share < 1, "coat_min_share must lie in [0, 1)"),
            (0 <= self.coat_max_negative < 1, "coat_max_negative must lie in [0, 1)"),
            (self.coat_order >= 0, "coat_order must be >= 0"),
        ]


def coat_rows(normals: np.ndarray, view_dir: np.ndarray, light: np.ndarray, order: int, ior: float,
              escapes: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) the coat's reflection per unit weight, F(n . v) L_low(r) s(r), of observations
    with face normals (N, 3) and unit directions to the camera (N, 3), under ``light``
    (M, 3) SH (truncated to ``order``); ``escapes`` (N,) s(r): 1 where the mirror direction
    escapes the object, 0 where the object blocks it (None: everywhere, :func:`mirror_escapes`)."""
    m = min(sh.num_coeffs(order), light.shape[0])
    mirror = mirror_directions(normals, view_dir)
    low = sh.basis(sh.order_of(m), mirror) @ light[:m]
    factor = fresnel_dielectric(np.sum(normals * view_dir, axis=1), ior)
    if escapes is not None:
        factor = factor * escapes
    return factor[:, None] * low


def lobe_rows(normals: np.ndarray, view_dir: np.ndarray, light: np.ndarray, exponents,
              escapes: np.ndarray | None = None) -> np.ndarray:
    """(E, N, 3) a Phong lobe's reflection per unit weight, P_n(r) s(r), of observations with
    face normals (N, 3) and unit directions to the camera (N, 3), for each of the ``exponents``
    (E,): the light (M, 3) SH filtered by the normalised lobe of exponent n
    (:func:`estimator.core.sh.phong_filtered`) at the mirror direction r, times ``escapes``
    (N,) s(r) (None: 1). No Fresnel factor: the lobe reflects every view angle alike. The SH
    basis is evaluated once for all exponents, :data:`LOBE_CHUNK` observations at a time."""
    order = sh.order_of(light.shape[0])
    filtered = np.concatenate([sh.phong_filtered(light, n) for n in exponents], axis=1)   # (M, 3E)
    mirror = mirror_directions(normals, view_dir)
    out = np.empty((len(mirror), filtered.shape[1]))
    for start in range(0, len(mirror), LOBE_CHUNK):
        part = slice(start, start + LOBE_CHUNK)
        out[part] = sh.basis(order, mirror[part]) @ filtered
    if escapes is not None:
        out *= escapes[:, None]
    return out.reshape(len(mirror), len(exponents), 3).transpose(1, 0, 2)


def mirror_escapes(face: np.ndarray, normals: np.ndarray, view_dir: np.ndarray, sampling: SphereSampling,
                   visibility: Visibility) -> np.ndarray:
    """(N,) 1.0 where the mirror direction of observation k (face ``face`` (N,), its normal
    (N, 3), unit direction to the camera (N, 3)) escapes the object, 0.0 where the object
    blocks it (:func:`estimator.model.reflection.mirror_shadow`)."""
    return mirror_shadow(face, mirror_directions(normals, view_dir), sampling, visibility).astype(float)


def fit_coat(face: np.ndarray, rgb: np.ndarray, rows: np.ndarray, num_faces: int, loss: str = "cauchy",
             rounds: int = 5, group: np.ndarray | None = None, num_groups: int = 1) -> np.ndarray:
    """(G, 3) weights k_gc >= 0 of ``rows`` (N, 3) in the colours ``rgb`` (N, 3) of faces
    ``face`` (N,), one strength per group of rows ``group`` (N,) in [0, G) (None: one group,
    G = 1) times a grey coat's per-channel factor (:func:`grey_weights`): least squares on each
    face's deviations from its mean over views, reweighted by ``loss`` (glints and shadows the
    coat term does not explain). Groups let each part of an object that mixes materials
    (matte, coated, glossy) take its own coat."""
    group = np.zeros(len(face), dtype=np.int64) if group is None else group

    def group_sum(values):
        return np.stack([np.bincount(group, values[:, k], minlength=num_groups) for k in range(3)], 1)

    x, y = view_changes(face, rows, num_faces), view_changes(face, rgb, num_faces)
    weights = np.ones(len(face))
    strength, colour = np.zeros(num_groups), np.zeros(3)
    for _ in range(rounds):
        wx = weights[:, None] * x
        strength, colour = grey_weights(group_sum(wx * y), group_sum(wx * x))
        residual = np.linalg.norm(y - (strength[group, None] * colour) * x, axis=1)
        weights = robust.irls_weights(residual, loss, robust.robust_scale(residual, floor=1e-12))
    return strength[:, None] * colour


def view_changes(face: np.ndarray, values: np.ndarray, num_faces: int) -> np.ndarray:
    """(N, 3) each observation's ``values`` (N, 3) less their mean over the observations of
    its face ``face`` (N,): what changes across views (a view-independent term cancels)."""
    counts = np.maximum(np.bincount(face, minlength=num_faces), 1).astype(float)
    mean = np.stack([np.bincount(face, values[:, k], minlength=num_faces) for k in range(3)], 1) / counts[:, None]
    return values - mean[face]


def unexplained_cost(face: np.ndarray, rgb: np.ndarray, reflections: list[np.ndarray], num_faces: int) -> np.ndarray:
    """(R,) how much of the colours' changes across views each reflection (N, 3) (rows times
    their fitted weights) leaves unexplained: the Cauchy cost sum log(1 + (e / s)^2) of the
    residual norms e, s the robust scale of the changes themselves (one scale, so the
    reflections compare)."""
    changes = view_changes(face, rgb, num_faces)
    scale = robust.robust_scale(np.linalg.norm(changes, axis=1), floor=1e-12)
    return np.array([np.sum(np.log1p((np.linalg.norm(changes - view_changes(face, r, num_faces), axis=1)
                                      / scale) ** 2)) for r in reflections])


def grey_weights(xy: np.ndarray, xx: np.ndarray, rounds: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Strengths s (G,) >= 0 and a colour w (3,) >= 0 whose weights k_gc = s_g w_c minimise
    sum_gc (xx_gc k_gc^2 - 2 xy_gc k_gc), the least-squares normal sums ``xy``, ``xx`` (G, 3) of
    each group and channel.

    A dielectric coat reflects every wavelength alike, so its weights across channels differ
    only by the error of the light's per-channel scale, which all groups share (w); each group
    takes its own strength s_g (a matte part none). Alternating least squares from the pooled
    weight; with one group s w is the per-channel least squares itself."""
    xx = np.maximum(xx, 1e-300)
    w = np.maximum(xy.sum(0) / xx.sum(0), 0.0)
    s = np.zeros(len(xy))
    for _ in range(rounds):
        s = np.maximum((xy @ w) / np.maximum(xx @ (w * w), 1e-300), 0.0)
        w = np.maximum((s @ xy) / np.maximum((s * s) @ xx, 1e-300), 0.0)
    return s, w


def admissible_scale(rgb: np.ndarray, coat: np.ndarray, max_negative: float, steps: int = 20,
                     group: np.ndarray | None = None, num_groups: int = 1) -> np.ndarray:
    """(G,) largest t_g in [0, 1] such that subtracting t_g x ``coat`` (N, 3) from ``rgb``
    (N, 3) leaves at most ``max_negative`` more of group g's rows (``group`` (N,), None: one
    group) with a channel <= 0: a coat cannot reflect more than the pixel shows (bisection,
    all groups at once)."""
    group = np.zeros(len(rgb), dtype=np.int64) if group is None else group
    size = np.maximum(np.bincount(group, minlength=num_groups), 1)

    def negative(t):
        return np.bincount(group, np.any(rgb - t[group, None] * coat <= 0, axis=1), minlength=num_groups) / size

    allowed = negative(np.zeros(num_groups)) + max_negative
    lo, hi = np.zeros(num_groups), np.ones(num_groups)
    whole = negative(hi) <= allowed
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        ok = negative(mid) <= allowed
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return np.where(whole, 1.0, lo)
