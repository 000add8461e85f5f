"""Faces outside the fit, joined to its regions afterwards. Two kinds:

* thin faces: the faces of a mesh the images resolve that no pure pixel covers (a teapot's
  rim and spout, slivers of a scan, faces mostly hidden behind another part), observed
  through their unmixed footprints (:attr:`estimator.pipeline.observations.Observations.thin`).
  Their radiance carries the unmixing's error (a face a third of a pixel wide mixes its
  neighbours' colours in every pixel it touches), so their rows take no part in what the
  faces determine together (the light, the sun, the regions, the coat);
* faces seen only beyond ``min_cos_view`` (a table-top camera's view of a bunny's flanks),
  whose rows no fit keeps.

The estimate is made without them, and they join its uniform regions under its light
(:meth:`.method.RetinexSegmented.solve_held`; on clusters, which would merge a thin face's
kept rows and so drop them, the faces seen only at grazing angles, thin or not, join in
:func:`.clusters.extend`)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...core.reductions import group_quantile
from ...pipeline.observations import Observations
from ...solvers.segmentation import albedo_features
from .shading import in_unit_dc, lit_faces
from .values import FitContext, Hypothesis


def thin_faces(obs: Observations) -> np.ndarray | None:
    """(F,) bool the thin faces with rows in ``obs`` (:attr:`Observations.thin`); None where
    there is none, or where no other face has a row (they are then all the fit has)."""
    if obs.thin is None:
        return None
    rows = obs.observed_faces()
    thin = obs.thin & rows
    return thin if thin.any() and (rows & ~thin).any() else None


def joined_to_regions(ctx: FitContext, h: Hypothesis, outside: np.ndarray, shade: np.ndarray) -> Hypothesis:
    """``h`` with the faces ``outside`` (F,) bool the fit left out (their radiance in
    ``h.radiance``) joined to its uniform regions: such a face lit under ``h``'s light (its
    shading ``shade`` (F, 3) above the level of the fit's faces, :func:`.shading.lit_faces`) joins
    the region that every one of its lit neighbours lies in (a texture's face counts as one
    more region) when that region is also the nearest to its own albedo, within the reach
    :func:`estimator.solvers.segmentation.assign_to_regions` gives a face near a region in
    albedo, and takes that region's albedo; joined faces count as lit neighbours in the next
    round, until a round joins none (a strip of slivers along a rim, or a flank seen only at
    grazing angles, is as deep as it is; each round but the last joins at least one face, so
    there is at most one round more than there are joining faces). Both conditions, not one: a
    sliver along the border of two regions has neighbours in both and a colour between them,
    and a strip of slivers across a border would carry a region over it round by round. A face
    that joins no region, or a hypothesis without regions (a texture), leaves it without an
    albedo: a thin face's own, unmixed from pixels its neighbours share, scored 1-3 dB below the
    fitted faces on the textured development seeds. The fit's own faces keep their albedos,
    labels and lit flags."""
    if not outside.any() or not h.regions:
        return h
    positive = np.all(np.isfinite(h.radiance) & (h.radiance > 0), axis=1)
    joining = lit_faces(shade, ctx.usable, outside & ~h.lit & positive)
    if not joining.any():
        return h
    member = h.lit & (h.labels >= 0)
    region_albedo = group_quantile(h.labels[member], h.albedo[member], h.regions, 0.5, interpolate=True)
    own = h.radiance[joining] / shade[joining]
    distance = np.max(np.abs(albedo_features(in_unit_dc(own, h.light))[:, None]
                             - albedo_features(in_unit_dc(region_albedo, h.light))[None]), axis=2)   # (J, R)
    nearest = np.full(len(outside), -1)
    distance = np.nan_to_num(distance, nan=np.inf)   # a region with no lit face has no centre
    nearest[joining] = np.where(distance.min(axis=1) < 2.5 * ctx.config.segment_threshold,
                                np.argmin(distance, axis=1), -1)
    labelled = np.where(h.lit, np.where(h.labels >= 0, h.labels, h.regions), -1)
    # the rounds read only the joining faces and their neighbours, renumbered: each costs the
    # edges of the joining faces, not the mesh
    near = ctx.edges[joining[ctx.edges[:, 0]] | joining[ctx.edges[:, 1]]]   # every edge a joining face has
    faces, local = np.unique(near, return_inverse=True)
    a, b = local.reshape(near.shape).T
    sub, want, goal = labelled[faces], joining[faces], nearest[faces]
    while True:
        region = unanimous_neighbour(sub, a, b, h.regions)
        new = want & (sub < 0) & (region >= 0) & (region < h.regions) & (goal == region)
        if not new.any():
            break
        sub[new] = region[new]
    labelled[faces] = sub
    tied = joining & (labelled >= 0) & (labelled < h.regions)
    labels, albedo = h.labels.copy(), h.albedo.copy()
    labels[tied] = labelled[tied]
    albedo[tied] = region_albedo[labelled[tied]]
    return replace(h, albedo=albedo, lit=h.lit | tied, labels=labels)


def unanimous_neighbour(labels: np.ndarray, a: np.ndarray, b: np.ndarray, regions: int) -> np.ndarray:
    """(F,) the label every labelled neighbour of a face has (``labels`` (F,) in [0, regions],
    -1: none; edges ``a``, ``b`` (E,)), or -1 where its labelled neighbours disagree or it has
    none."""
    low = np.full(len(labels), regions + 1, dtype=np.int64)
    high = np.full(len(labels), -1, dtype=np.int64)
    for i, j in ((a, b), (b, a)):
        known = labels[j] >= 0
        np.minimum.at(low, i[known], labels[j[known]])
        np.maximum.at(high, i[known], labels[j[known]])
    return np.where(low == high, high, -1)
