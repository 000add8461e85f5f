"""Uniform-albedo regions on the mesh: per-face diffuse radiance, albedo features, graph
segmentation, and the parting of regions that hold two albedos (used by the
``bilinear-segmented`` and ``retinex-segmented`` methods).

Neighbouring faces receive nearly the same light, so where their shading-corrected
albedos agree they belong to one region (a Retinex edge cue), whatever the hue.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.sparse.csgraph import connected_components

from ..core.reductions import group_quantile
from ..core.settings import Section
from .clustering import mean_shift


@dataclass
class SegmentationConfig(Section):
    """Uniform regions on the face-adjacency graph (:func:`segment`).

    Attributes
    ----------
    segment_threshold : neighbours whose log-albedos differ by less than this join one region.
    uniform_spread : a region is uniform (its faces share one albedo) when its log-albedo
        spread is below this.
    """

    segment_threshold: float = 0.12
    uniform_spread: float = 0.08

    def check(self):
        return [(self.segment_threshold > 0 and self.uniform_spread > 0,
                 "segment_threshold and uniform_spread must be > 0")]


def albedo_features(albedo: np.ndarray) -> np.ndarray:
    """(F, 4) features in which a distance is a relative albedo difference whatever the
    colour: log brightness (mean over channels) and half the chromaticity (albedo /
    brightness). Per-channel logs are not used: a channel near zero (the blue of a
    yellow) would turn noise into large differences."""
    level = np.maximum(albedo.mean(axis=1), 1e-30)
    return np.column_stack([np.log(level), 0.5 * albedo / level[:, None]])


def segment(albedo: np.ndarray, edges: np.ndarray, valid: np.ndarray,
            threshold: float = SegmentationConfig.segment_threshold,
            uniform_spread: float = SegmentationConfig.uniform_spread, min_size: int = 10,
            merge_bandwidth: float = 0.12, merge: str = "mean-shift",
            bridges: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Uniform-albedo regions on the face-adjacency graph.

    Neighbours whose :func:`albedo_features` differ by less than ``threshold`` (largest
    component) are joined (connected components). A component of at least ``min_size``
    faces whose feature spread (median absolute deviation, largest component) is below
    ``uniform_spread`` is uniform. With ``bridges``, a component is cut at its bridges, the
    faces whose close neighbours differ from each other by ``threshold`` or more
    (:func:`bridge_faces`), where that leaves two parts of at least ``min_size`` faces whose
    medians differ by ``threshold`` or more (:func:`_parted`): where a face's colour may blend
    its neighbours' albedos (a cluster of several faces, a face smaller than the pixels that
    see it) a blend along a boundary lies within ``threshold`` of both sides, and one chain of
    such blends ties two regions into one component (too wide to be uniform, or, a small
    region tied to a large one, uniform by the median spread and wrong). A component whose
    parts agree stays whole: where noise between neighbours nears the threshold, faces inside
    one region have close neighbours that far apart too. The cut is made once.

    Uniform components with similar albedo are one region even when apart: with
    ``merge='mean-shift'`` those a mean shift (``merge_bandwidth``) takes to one mode, which
    also joins components up to about twice that apart (generous, for a light fit that tests
    the ties: :func:`split_regions`); with ``merge='complete'`` those whose medians all lie
    within ``threshold`` of each other in every feature (complete linkage: no chain of small
    steps), as they would have been joined had they touched.

    Returns
    -------
    labels : (F,) int64 region of each valid face in a uniform region, else -1.
    medians : (R, C) median albedo of each region.
    """
    f = len(albedo)
    feat = albedo_features(np.where(valid[:, None], albedo, 1.0))
    e0, e1 = edges[:, 0], edges[:, 1]
    close = valid[e0] & valid[e1] & (np.max(np.abs(feat[e0] - feat[e1]), axis=1) < threshold)
    inverse, medians, uniform, _ = _components(feat, edges[close], valid, min_size, uniform_spread)
    bridge = bridge_faces(feat, edges[close], threshold) if bridges else np.zeros(f, dtype=bool)
    if bridge.any():   # without a bridge the parts are the components themselves: nothing to cut
        in_parted = np.zeros(f, dtype=bool)
        in_parted[valid] = _parted(feat, edges[close & ~bridge[e0] & ~bridge[e1]], valid, inverse, len(uniform),
                                   threshold, min_size, uniform_spread)[inverse]
        cut = bridge & in_parted
        if cut.any():
            close &= ~cut[e0] & ~cut[e1]
            inverse, medians, uniform, _ = _components(feat, edges[close], valid, min_size, uniform_spread)
    labels = np.full(f, -1, dtype=np.int64)
    if not uniform.any():
        return labels, np.zeros((0, albedo.shape[1]))
    if merge == "complete":
        merged = (fcluster(linkage(medians[uniform], method="complete", metric="chebyshev"), threshold,
                           criterion="distance") - 1) if uniform.sum() > 1 else np.zeros(1, dtype=np.int64)
    else:
        merged, _ = mean_shift(medians[uniform], merge_bandwidth, metric="euclidean")
    region_of_component = np.full(len(uniform), -1)
    region_of_component[np.nonzero(uniform)[0]] = merged
    labels[valid] = region_of_component[inverse]
    labels, present = compact_regions(labels)
    inside = labels >= 0
    return labels, group_quantile(labels[inside], albedo[inside], len(present), 0.5, interpolate=True)


def _components(features: np.ndarray, joined: np.ndarray, valid: np.ndarray, min_size: int,
                uniform_spread: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The connected components of the valid faces under the ``joined`` (E', 2) pairs: each
    valid face's component (V,) in [0, K), their median ``features`` (K, C), which are
    uniform (K,) (at least ``min_size`` faces, spread below ``uniform_spread``) and which have
    at least ``min_size`` faces (K,), uniform or not."""
    f = len(features)
    graph = sparse.csr_matrix((np.ones(len(joined)), (joined[:, 0], joined[:, 1])), shape=(f, f))
    _, comp = connected_components(graph, directed=False)
    ids, inverse, counts = np.unique(comp[valid], return_inverse=True, return_counts=True)
    values = features[valid]
    medians = group_quantile(inverse, values, len(ids), 0.5, interpolate=True)
    spreads = group_quantile(inverse, np.abs(values - medians[inverse]), len(ids), 0.5, interpolate=True).max(axis=1)
    large = counts >= min_size
    return inverse, medians, large & (spreads < uniform_spread), large


def _parted(features: np.ndarray, joined: np.ndarray, valid: np.ndarray, component: np.ndarray, count: int,
            threshold: float, min_size: int, uniform_spread: float) -> np.ndarray:
    """(K,) which of ``count`` components (``component`` (V,): each valid face's) fall apart
    into different albedos under the ``joined`` (E', 2) pairs that remain once the bridges
    are cut: among its parts of at least ``min_size`` faces, two whose median ``features``
    (F, C) differ by ``threshold`` or more in some feature (as :func:`segment` parts regions)."""
    part, medians, _, large = _components(features, joined, valid, min_size, uniform_spread)
    owner = np.zeros(len(large), dtype=np.int64)
    owner[part] = component                       # a part lies within one component
    high = np.full((count, features.shape[1]), -np.inf)
    low = np.full((count, features.shape[1]), np.inf)
    np.maximum.at(high, owner[large], medians[large])
    np.minimum.at(low, owner[large], medians[large])
    with np.errstate(invalid="ignore"):           # a component without a large part: -inf - inf
        return np.max(high - low, axis=1) >= threshold


def bridge_faces(features: np.ndarray, close: np.ndarray, threshold: float) -> np.ndarray:
    """(F,) True for a face whose close neighbours (``close`` (E', 2): the pairs of faces whose
    ``features`` (F, C) differ by less than ``threshold`` in every feature) differ from each
    other by ``threshold`` or more in some feature: joined, it would chain them. The widest
    difference between two of a face's close neighbours is, per feature, the range of their
    values (the face's own lies within ``threshold`` of each), so one scatter of maxima and
    minima over the close pairs finds them all."""
    src, dst = np.concatenate([close[:, 0], close[:, 1]]), np.concatenate([close[:, 1], close[:, 0]])
    high, low = features.copy(), features.copy()
    np.maximum.at(high, src, features[dst])
    np.minimum.at(low, src, features[dst])
    return np.max(high - low, axis=1) >= threshold


def split_regions(labels: np.ndarray, albedo: np.ndarray, valid: np.ndarray, edges: np.ndarray,
                  threshold: float, uniform_spread: float, bridges: bool = False) -> np.ndarray:
    """(F,) ``labels`` with each region split where, under ``albedo`` (a light fitted with the
    regions tied), its faces segment (:func:`segment`, complete linkage) into parts more than
    ``threshold`` apart: a generous merge joined two albedos. Faces of a region in no uniform
    part stay with its largest part; -1 stays -1. Regions are renumbered 0..R'-1. ``bridges``:
    as :func:`segment`'s."""
    inside = valid & (labels >= 0)
    if not inside.any():
        return labels.copy()
    part, _ = segment(albedo, edges, inside, threshold, uniform_spread, merge="complete", bridges=bridges)
    r, p = labels[inside], part[inside]
    width = int(p.max()) + 2
    pair = r * width + (p + 1)                  # (region, part); part 0 here: in no uniform part
    counts = np.bincount(pair, minlength=(int(r.max()) + 1) * width).reshape(-1, width)
    counts[:, 0] = 0
    largest = np.argmax(counts, axis=1)         # each region's largest part (0 if it has none)
    p1 = np.where(p >= 0, p + 1, largest[r])
    _, compact = np.unique(r * width + p1, return_inverse=True)
    out = labels.copy()
    out[inside] = compact
    return out


# two groups of a region's faces are two albedos, not one albedo's spread, when their medians
# along the line through them lie farther apart than the sum of the groups' 99 % ranges'
# half-widths: this many robust standard deviations (1.4826 MAD) of each, the normal
# distribution's two-sided 99 % quantile (its 99.5 % point). The two halves 2-means makes of a
# Gaussian spread (medians 1.35 standard deviations apart, each half's robust deviation 0.59 of
# it) reach 0.44 of that, of a uniform one 0.52; two albedos each with Gaussian noise part
# beyond 5.2 standard deviations. A heavily skewed spread (log-normal of sigma 2) can part.
MODE_QUANTILE = 2.576


def split_modes(labels: np.ndarray, albedo: np.ndarray, valid: np.ndarray, edges: np.ndarray,
                min_size: int = 10) -> np.ndarray:
    """(F,) ``labels`` with each region split in two, and each part again, while its valid
    faces' :func:`albedo_features` fall into two modes (:func:`two_modes`) each with at least
    ``min_size`` faces inside it: faces none of whose neighbours (``edges`` (E, 2)) in the
    region lies on the other side. -1 stays -1; a region's faces outside ``valid`` stay with
    the side that keeps its label; regions are renumbered 0..R'-1 in order of their first face.

    The segmentation joins neighbours within a fixed ``segment_threshold`` of each other, far
    above the noise of a uniform region's faces; two regions whose albedos differ by less than
    that (the same hue a little darker) become one, and their faces, under a light fitted with
    that region tied, still fall into two groups with a gap between them many times their own
    spread wide. A region's faces that spread smoothly (the shading model's misfit, a texture)
    form no such gap and stay whole. Faces along a boundary whose colours blend the albedos on
    either side (a pixel across it, a cluster of faces) can form a mode of their own, a strip
    with no face inside it: such a side is no region."""
    out = np.asarray(labels, dtype=np.int64).copy()
    if not np.any(out >= 0):
        return out
    side_of = np.full(len(out), -1, dtype=np.int64)   # 1 / 0: the side of the region being split
    e0, e1 = edges[:, 0], edges[:, 1]
    feat = albedo_features(np.where(valid[:, None], albedo, 1.0))
    todo, count = list(range(int(out.max()) + 1)), int(out.max()) + 1
    while todo:   # one region at a time: a region is split at most (faces / min_size) times
        region = todo.pop()
        faces = np.nonzero(valid & (out == region))[0]
        if len(faces) < 2 * min_size:
            continue
        side = two_modes(feat[faces], min_size)
        if side is None:
            continue
        side_of[faces] = side
        crossing = (side_of[e0] >= 0) & (side_of[e1] >= 0) & (side_of[e0] != side_of[e1])
        border = np.zeros(len(out), dtype=bool)
        border[e0[crossing]] = border[e1[crossing]] = True
        side_of[faces] = -1
        inner = ~border[faces]
        if min(np.sum(inner & side), np.sum(inner & ~side)) < min_size:
            continue
        out[faces[side]] = count
        todo += [region, count]
        count += 1
    inside = out >= 0
    _, first, inverse = np.unique(out[inside], return_index=True, return_inverse=True)
    out[inside] = np.argsort(np.argsort(first))[inverse]   # renumbered by first face
    return out


def two_modes(features: np.ndarray, min_size: int, iterations: int = 20) -> np.ndarray | None:
    """(n,) bool: one side of the 2-means split of ``features`` (n, C) where the two sides are
    two modes, else None. The split starts at the median along the principal axis (at the mean
    where ties leave one side empty) and moves by Lloyd's steps; the sides are two modes when
    each holds at least ``min_size`` points and, projected on the line through their medians,
    their medians lie more than :data:`MODE_QUANTILE` x (s_1 + s_2) apart, s_k each side's
    robust standard deviation there. 2-means may part a large spread rather than isolate a
    mode of few points (20 of 2,000 points 10 standard deviations off are not found)."""
    centred = features - features.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    projected = centred @ axis
    side = projected > np.median(projected)
    if side.all() or not side.any():   # more than half the points tie at the median
        side = projected > projected.mean()
    for _ in range(iterations):
        if side.all() or not side.any():
            return None
        a, b = features[side].mean(axis=0), features[~side].mean(axis=0)
        moved = np.sum((features - a) ** 2, axis=1) < np.sum((features - b) ** 2, axis=1)
        if np.array_equal(moved, side):
            break
        side = moved
    if min(side.sum(), (~side).sum()) < min_size:
        return None
    line = np.median(features[side], axis=0) - np.median(features[~side], axis=0)
    length = np.linalg.norm(line)
    if length == 0:
        return None
    along = features @ (line / length)
    spread = [1.4826 * np.median(np.abs(along[s] - np.median(along[s]))) for s in (side, ~side)]
    return side if length > MODE_QUANTILE * sum(spread) else None


def compact_regions(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) ``labels`` with the regions that hold a face numbered 0..R-1 in their order (-1,
    outside every region, kept), and (R,) the id each had in ``labels``: a region left without
    a face drops out (index per-region values by these ids to keep them with their regions)."""
    inside = labels >= 0
    ids, compact = np.unique(labels[inside], return_inverse=True)
    out = np.full(len(labels), -1, dtype=np.int64)
    out[inside] = compact
    return out, ids


def assign_to_regions(labels: np.ndarray, albedo: np.ndarray, seen: np.ndarray, edges: np.ndarray,
            reach: float) -> np.ndarray:
    """(F,) groups: the uniform regions keep their ids ``0 .. R-1`` (R = ``labels.max() + 1``);
    a face outside them joins the region whose albedo features are within ``reach`` of its
    own (shading noise in dim faces), or, when its albedo is unknown (no light) or 90 % of
    the faces are in regions already, the region most of its neighbours joined; any other
    seen face is a group of its own (texture), numbered from R on; an unseen face is put in
    group 0 (it has no rows). A region none of whose faces is seen keeps its id with no
    seen face, so ``group < R`` is always "in a region". A region's centre is the median
    of its seen faces with a finite albedo."""
    group = labels.copy()
    regions = int(group.max()) + 1
    if regions:
        finite = np.all(np.isfinite(albedo) & (albedo > 0), axis=1)
        feat = albedo_features(np.where(finite[:, None], albedo, 1.0))
        centred = (group >= 0) & seen & finite
        centres = group_quantile(group[centred], feat[centred], regions, 0.5, interpolate=True)
        # a region without such a face has NaN centres: no face is near it
        dist = np.nan_to_num(np.max(np.abs(feat[:, None, :] - centres[None]), axis=2), nan=np.inf)
        near = (group < 0) & seen & finite & (dist.min(axis=1) < reach)
        group[near] = np.argmin(dist[near], axis=1)
        # in a piecewise-uniform object (nearly every face in a region) the rest are faces
        # the shading model fails on (concavities, silhouettes): they follow their neighbours
        piecewise = np.mean(group[seen] >= 0) >= 0.9
        for _ in range(8):  # faces without a usable albedo follow their neighbours
            todo = (group < 0) & seen & (~finite | piecewise)
            if not todo.any():
                break
            votes = np.zeros((len(group), regions))
            for src, dst in ((edges[:, 0], edges[:, 1]), (edges[:, 1], edges[:, 0])):
                ok = todo[src] & (group[dst] >= 0)
                np.add.at(votes, (src[ok], group[dst[ok]]), 1.0)
            decided = todo & (votes.max(axis=1) > 0)
            group[decided] = np.argmax(votes[decided], axis=1)
    free = np.nonzero((group < 0) & seen)[0]
    group[free] = regions + np.arange(len(free))
    group[~seen] = 0
    return group.astype(np.int64)
