"""Pixels as equations in the faces they cover: observations of faces smaller than a pixel.

A rendered or photographed pixel is the mean radiance over its footprint (a box filter). Where
faces are about a pixel in size, a pixel covers several faces, and the colour of the pixel
whose centre ray hits a face mixes that face with its neighbours. Here each pixel is one
equation in the faces it covers, weighted by the share of its area each covers (from
``samples`` x ``samples`` sub-pixel rays, :func:`pixel_shares`):

    I_p = sum_f w_pf R_f + (what changes with the view),

and the faces' view-independent radiance R (F, 3) is the least-absolute-deviations solution over
every pixel of every view (:func:`footprint_radiance`): views whose pixel grids fall differently
on the surface tell the faces of a pixel apart. A face's row in a view is then its own radiance
plus the share-weighted mean residual of the pixels it covers (:func:`unmixed_rows`): a pure
pixel gives its own colour back, and a mixed one gives the face its neighbours' colour no more,
only the view-dependent light the pixel shows beyond the faces' radiance (a coat's reflection,
which the method's own quantile over the views then sets aside).

The fit adds a total-variation term, :data:`SMOOTHNESS` times the absolute radiance difference
across each mesh edge: a surface's colours are piecewise smooth, and an absolute (not squared)
difference keeps albedo edges sharp while it settles what the views cannot tell apart (two
slivers always in the same pixels). Both absolute values are iteratively reweighted least
squares, each round a conjugate-gradient solve of the sparse normal equations, preconditioned
by their diagonal (a direct factorisation of 58k faces took 33 s, the whole fit 2-3 s).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg

from ..core.edge_graph import EdgeGraph

# a ridge towards the footprint mean (the pixel centres' colour), relative to the median face's
# information (its diagonal of the normal equations): it only keeps the equations definite
# for a face that no pixel and no edge reaches
RIDGE = 1e-4
# reweighting rounds; measured on a dense bunny (58,784 faces), the radiance after 6 rounds
# differs from that after 10 by a median 0.3 % (90th percentile 1.6 %, 99th 8 %)
ROUNDS = 6
# a residual or an edge difference below this share of the median pixel's colour counts as
# this (the reweighting's floor): Monte Carlo and sensor noise are about a percent of a level
NOISE_SHARE = 0.01
# the total-variation weight: one edge's absolute radiance difference against one pixel's
# absolute residual (a face touches 3 edges and covers some 10 pixels over 30 views). Measured
# on six random-family draws subdivided to about a pixel per face (development seeds): 0.1,
# 0.3 and 1 gain 26, 32 and 36 dB in summed diffuse PSNR over pixel centres; 1 beats 0.3 on
# three draws and loses on the other three (by up to 2.8 dB either way), so 0.3 is kept
SMOOTHNESS = 0.3


@dataclass(frozen=True)
class Footprints:
    """Every usable pixel of every view as a row of the faces it covers.

    Attributes
    ----------
    shares : (P, F) float64 CSR, the share of each pixel's area each face covers (rows sum to 1).
    rgb : (P, 3) float64 pixel colours.
    view : (P,) int64 view of each pixel.
    """

    shares: sp.csr_matrix
    rgb: np.ndarray
    view: np.ndarray


def pixel_shares(ids: np.ndarray, num_faces: int) -> sp.csr_matrix:
    """(P, F) CSR share of each pixel each face covers, from the faces ``ids`` (P, S) int that
    S sub-pixel rays per pixel hit (every id >= 0)."""
    pixels, samples = ids.shape
    keys = np.repeat(np.arange(pixels, dtype=np.int64), samples) * num_faces + ids.ravel()
    keys, counts = np.unique(keys, return_counts=True)
    return sp.csr_matrix((counts / samples, (keys // num_faces, keys % num_faces)), shape=(pixels, num_faces))


def footprint_radiance(fp: Footprints, edges: np.ndarray | None = None,
                       rounds: int = ROUNDS) -> tuple[np.ndarray, np.ndarray]:
    """The faces' view-independent radiance (F, 3) that best explains every pixel in absolute
    deviation, and (F,) each face's area over all pixels (sum of its shares; 0: in no pixel).

    With ``edges`` (E, 2) neighbouring faces, :data:`SMOOTHNESS` x the absolute radiance
    difference across each edge is added to the cost (total variation); a tiny ridge
    (:data:`RIDGE`) towards each face's footprint mean, sum_p w_pf I_p / sum_p w_pf, keeps the
    equations definite."""
    w = fp.shares
    f = w.shape[1]
    area = np.asarray(w.sum(axis=0)).ravel()
    prior = np.zeros((f, 3))
    seen = area > 0
    prior[seen] = (w.T @ fp.rgb)[seen] / area[seen, None]
    floor = NOISE_SHARE * max(float(np.median(np.linalg.norm(fp.rgb, axis=1))), 1e-30)
    graph = EdgeGraph(edges[:, 0], edges[:, 1], f) if edges is not None and len(edges) else None
    radiance = prior.copy()
    weight = np.full(w.shape[0], 1.0 / floor)          # the first round: every residual and difference at the floor
    edge_weight = None if graph is None else np.full(len(graph), SMOOTHNESS / floor)
    for round_ in range(rounds + 1):
        if round_:
            residual = np.linalg.norm(fp.rgb - w @ radiance, axis=1)
            weight = 1.0 / np.maximum(residual, floor)
            if graph is not None:
                edge_weight = SMOOTHNESS / np.maximum(np.linalg.norm(graph.difference(radiance), axis=1), floor)
        normal = (w.T @ sp.diags(weight) @ w).tocsr()
        diagonal = normal.diagonal()
        ridge = RIDGE * float(np.median(diagonal[seen])) if seen.any() else 1.0
        normal = normal + sp.diags(np.full(f, ridge))
        if graph is not None:
            smooth = graph.laplacian(edge_weight)
            normal = normal + smooth
            diagonal = diagonal + smooth.diagonal()
        rhs = w.T @ (weight[:, None] * fp.rgb) + ridge * prior
        precondition = sp.diags(1.0 / (diagonal + ridge))
        for k in range(3):
            radiance[:, k], _ = cg(normal, rhs[:, k], x0=radiance[:, k], rtol=1e-4, maxiter=500, M=precondition)
    return radiance, area


def unmixed_rows(fp: Footprints, radiance: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One row per (face, view) pair where some sub-pixel ray of a pixel hits the face: the
    face's radiance (F, 3) plus the share-weighted mean residual, I_p - sum_g w_pg R_g, of the
    pixels it covers in that view.

    Returns (K,) faces, (K,) views, (K, 3) colours and (K,) the pixel area the face covers in
    the view (the sum of its shares), sorted by view then face."""
    w = fp.shares.tocoo()
    residual = fp.rgb - fp.shares @ radiance                                      # (P, 3)
    keys, inverse = np.unique(fp.view[w.row] * w.shape[1] + w.col, return_inverse=True)
    share = np.bincount(inverse, w.data, minlength=len(keys))
    moved = np.stack([np.bincount(inverse, w.data * residual[w.row, k], minlength=len(keys)) for k in range(3)],
                     axis=1)
    face, view = keys % w.shape[1], keys // w.shape[1]
    return face, view, radiance[face] + moved / share[:, None], share


def radiance_error(fp: Footprints, radiance: np.ndarray) -> np.ndarray:
    """(F, 3) standard error of each face's footprint radiance (:func:`footprint_radiance`):
    the pixels' robust noise level per channel, 1.4826 x the median absolute residual
    I_p - sum_g w_pg R_g, over the root of the face's information sum_p w_pf^2 over every view's
    pixels (inf for a face in no pixel). It holds the neighbours' radiance known, so it is the
    least the face's radiance is uncertain by: a face an eighth of one pixel wide, seen in one
    view, is uncertain by 8 times the pixels' noise. Every row of an unresolved face holds this
    one radiance, so their scatter over the views cannot show its error."""
    w = fp.shares
    residual = fp.rgb - w @ radiance
    noise = 1.4826 * np.median(np.abs(residual), axis=0)
    information = np.asarray(w.power(2).sum(axis=0)).ravel()
    with np.errstate(divide="ignore", invalid="ignore"):   # a face in no pixel: inf (0 / 0 in a black channel)
        return np.where(information[:, None] > 0, noise[None, :] / np.sqrt(information)[:, None], np.inf)
