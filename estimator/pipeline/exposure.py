"""Per-view exposure and white balance: a gain per view and channel, found before the solve.

A camera on auto-exposure or auto white balance records view v's radiance times an unknown
gain g_vc per channel. The albedos and the light absorb one common gain (the estimate's gauge),
but not one that differs from view to view: each view then disagrees with the others by its
gain, which the solve spreads over the albedos and the light.

A diffuse face's colour does not depend on the view, so in the log domain a face seen from
several views shows log rgb_fvc = level_fc + log g_vc + r: a two-way layout, faces by views,
whose view effects are the gains. With ``view_gains`` they are its weighted least-squares
fit, the face levels eliminated (a V x V system, V the views), reweighted by the Cauchy loss
so that glints, shadows and a coat's highlights (a minority of a view's faces) pass, then
centred (a geometric mean of 1 over the views, the gauge). (Tukey's median polish, the usual
robust two-way fit, stalls on this incomplete layout, each face seen by a few views: 8 %
off on noise-free data.) No estimate is needed, so it serves every method, costs no extra
solve and cannot let the light absorb the gains. The views' images and observations are
divided by their gains before the method runs.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ..core.data import MultiViewData, View
from ..core.settings import Section
from ..solvers import robust
from .observations import Observations
from .prepared import Prepared

ROBUST_ROUNDS = 8   # IRLS rounds of the two-way fit (each an exact weighted least squares)


@dataclass
class ExposureConfig(Section):
    """Views recorded at different exposure or white balance (:mod:`estimator.pipeline.exposure`).

    Attributes
    ----------
    view_gains : estimate a gain per view and channel (auto-exposure, auto white balance)
        from the faces' colours across views, and divide it out before the solve. Off by
        default: on views of one fixed exposure the gains are 1, and estimating them can only
        add the error of the estimate.
    """

    view_gains: bool = False


def view_gains(obs: Observations) -> np.ndarray:
    """(V, 3) each view's gain per channel: the view effects of the two-way fit of the log
    colours of faces seen from at least two views (a face seen once says nothing of the
    gains), with a geometric mean of 1 over the views; 1 for a view with no such observation.
    One robust weight per row (its residual's norm over the channels, as elsewhere), so the
    three channels share each round's system."""
    usable = np.all(obs.rgb > 0, axis=1)
    usable &= np.bincount(obs.face[usable], minlength=obs.num_faces)[obs.face] >= 2
    if not usable.any():   # no face seen twice: nothing relates the views
        return np.ones((obs.num_views, 3))
    face, view, values = obs.face[usable], obs.view[usable], np.log(obs.rgb[usable])
    # the (face, view) pairs as a CSR pattern built once; each round only refills its weights
    pair, inverse = np.unique(face * obs.num_views + view, return_inverse=True)
    pattern = sparse.csr_matrix((np.ones(len(pair)), pair % obs.num_views,
                                 np.concatenate([[0], np.cumsum(np.bincount(pair // obs.num_views,
                                                                            minlength=obs.num_faces))])),
                                shape=(obs.num_faces, obs.num_views))
    weights = np.ones(len(face))
    gains = np.zeros((obs.num_views, 3))
    for _ in range(ROBUST_ROUNDS):
        gains, level = _two_way_fit(pattern, inverse, face, view, values, weights)
        residual = np.linalg.norm(values - gains[view] - level[face], axis=1)
        weights = robust.irls_weights(residual, "cauchy", robust.robust_scale(residual, floor=1e-9))
    return np.exp(gains)


def _two_way_fit(pattern, inverse, face, view, y, w) -> tuple[np.ndarray, np.ndarray]:
    """View effects g (V, 3) and face levels (F, 3) of the weighted least-squares fit
    y ~ level[face] + g[view] (rows y (N, 3), weights w (N,)). The levels are eliminated (each
    face's weighted mean), leaving the V x V system D - B^T T^-1 B, B[f, v] the weight of face
    f's rows in view v (``pattern`` refilled through ``inverse``, each row's pair), T its row
    sums. g is centred over the views that have rows (the gauge); 0 for the others."""
    num_faces, num_views = pattern.shape
    b = pattern.copy()
    b.data = np.bincount(inverse, w, minlength=b.nnz)
    total = np.maximum(np.bincount(face, w, minlength=num_faces), 1e-300)
    by = np.stack([np.bincount(face, w * y[:, c], minlength=num_faces) for c in range(3)], 1)
    vy = np.stack([np.bincount(view, w * y[:, c], minlength=num_views) for c in range(3)], 1)
    scaled = sparse.diags(1.0 / total) @ b
    system = (sparse.diags(np.asarray(b.sum(axis=0)).ravel()) - b.T @ scaled).toarray()
    rhs = vy - scaled.T @ by
    seen = np.bincount(view, minlength=num_views) > 0
    # the system is singular along the common gain (all ones): the gauge row fixes its mean
    g = np.linalg.lstsq(np.vstack([system[np.ix_(seen, seen)], np.ones(seen.sum())]),
                        np.vstack([rhs[seen], np.zeros((1, 3))]), rcond=None)[0]
    gains = np.zeros((num_views, 3))
    gains[seen] = g - g.mean(axis=0)
    return gains, (by - b @ gains) / total[:, None]


def divide_gains(prep: Prepared, gains: np.ndarray) -> Prepared:
    """``prep`` with each view's images and observations divided by its gains (``gains``
    (V, 3)), so that a method reading either (``mitsuba-ad`` renders against the images) sees
    one exposure."""
    def divided(o: Observations) -> Observations:
        return replace(o, rgb=o.rgb / gains[o.view])

    views = [View(v.name, v.camera, v.rgb / gains[k].astype(np.float32), v.alpha)
             for k, v in enumerate(prep.data.views)]
    return replace(prep, data=MultiViewData(prep.data.mesh, views), obs=divided(prep.obs),
                   all_obs=divided(prep.all_obs))
