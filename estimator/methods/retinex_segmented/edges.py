"""The first hypothesis: the light from albedo edges (with a sun when one is found), and the
uniform regions under it, tied to one albedo each when they hold like regions."""
from __future__ import annotations

import numpy as np

from ...light import edge_fit, sun
from ...solvers.segmentation import assign_to_regions, compact_regions, segment, split_modes, split_regions
from .shading import deviation, divide, in_unit_dc
from .values import FitContext, Hypothesis, LightSource, Shading

# the tied fits of :func:`tied_regions` at most: the first with the segmentation's regions, then
# with the faces each light's assignment joins, until that assignment repeats (a bound on the
# cost: each fit is a Gauss-Newton fit of the whole light)
TIE_FITS = 3


def edge_hypothesis(ctx: FitContext, radiance: np.ndarray, found: sun.Sun | None) -> Hypothesis:
    """The light fitted to the edges of ``radiance`` (F, 3) (:func:`edge_fit.log_shading_fit`).

    ``found``: the sun of an earlier fit (None: search for one when ``sun_min_gain`` < 1); it
    joins the shading when it explains the edges (:attr:`sun.Sun.explains`), lowered their
    cost by ``sun_min_gain`` and its irradiance is positive. Regions are then found under that
    light and, when they hold (:func:`tied_regions`), the light is fitted again with each
    region tied to one albedo."""
    c, prep = ctx.config, ctx.prep
    mesh = prep.data.mesh
    shading = Shading(prep.c_matrix)
    if found is None and c.sun_min_gain < 1:
        found = sun.find_suns(radiance, shading.columns, ctx.edges, ctx.usable, mesh, prep.caster,
                              prep.sampling.directions, loss=ctx.loss,
                              coat_ior=c.coat_ior if c.coat_correction else None, max_suns=c.max_suns)
    if found is not None and found.explains and found.cost_ratio <= 1 - c.sun_min_gain:
        shading = shading.with_sun(found, sun.sun_shadings(mesh, prep.caster, found.directions, found.coat_ior))
    light, _ = edge_fit.log_shading_fit(radiance, shading.columns, ctx.edges, ctx.usable, **ctx.fit)
    if shading.sun is not None and np.any(light[ctx.sky_width:] <= 0):   # no dark "sun"
        shading = Shading(prep.c_matrix)
        light, _ = edge_fit.log_shading_fit(radiance, shading.columns, ctx.edges, ctx.usable, **ctx.fit)
    albedo, lit = divide(shading, radiance, light, ctx.usable, ctx.extra)
    labels, _ = segment(np.where(lit[:, None], in_unit_dc(albedo, light), 1.0), ctx.edges, lit,
                        c.segment_threshold, c.uniform_spread, bridges=prep.blends_albedos)
    hypothesis = Hypothesis(radiance, light, shading, albedo, lit, labels, int(labels.max()) + 1,
                            float(np.mean(labels[lit] >= 0)), LightSource.EDGES, found)
    if hypothesis.regions and hypothesis.share >= c.retinex_min_uniform_share:
        hypothesis = tied_regions(ctx, hypothesis)
    if hypothesis.source is LightSource.EDGES:   # a texture: every face keeps its own albedo
        hypothesis.regions, hypothesis.labels = 0, np.full(mesh.num_faces, -1, dtype=np.int64)
    return hypothesis


def tied_regions(ctx: FitContext, edges_only: Hypothesis) -> Hypothesis:
    """The light refitted with each uniform region's faces tied to one albedo, taken when the
    regions hold. After each fit the faces outside the segmentation's regions join a region
    under that light (:func:`assign_to_regions`: near it in albedo, or by their neighbours'
    vote), from the segmentation's regions each time, and the light is fitted again with them
    tied until the assignment no longer changes: a face that a first, rougher light joined to
    the wrong region is neither kept there nor tied in the light returned (past
    :data:`TIE_FITS` fits, the assignment the last fit tied is kept with its light). A region
    with no lit face under that light drops out and the rest are numbered anew.
    The regions hold when their
    deviation (the median over their faces of the mean over channels of |log(face albedo /
    region albedo)|, each face's own albedo under the tied light) is at most
    ``region_max_deviation``, or its drift (that deviation over the same median between
    neighbouring faces of a region: independent Gaussian noise alone gives about 1 / sqrt(2),
    a texture chained into one region by small steps drifts further) is at most
    ``region_max_drift``.

    Returns the tied hypothesis, or ``edges_only`` with the deviation and drift measured."""
    c, h = ctx.config, edges_only
    segmented = labels = np.where(h.lit, h.labels, -1)
    light = h.light
    for _ in range(TIE_FITS):
        light, region_albedo = edge_fit.log_shading_fit(h.radiance, h.shading.columns, ctx.edges, ctx.usable, labels,
                                                        initial=light, **ctx.fit)
        albedo, lit = divide(h.shading, h.radiance, light, ctx.usable, ctx.extra)
        joined = assign_to_regions(segmented, in_unit_dc(albedo, light), lit, ctx.edges, 2.5 * c.segment_threshold)
        fitted, labels = labels, compact_regions(np.where(lit & (joined < h.regions), joined, -1))[0]
        if np.array_equal(labels, fitted):   # the light was fitted with the faces its assignment ties
            break
    # the faces the light and the regions' albedos were fitted with (the last assignment, where it
    # repeats), those now unlit left out and the regions without a lit face dropped
    labels, ids = compact_regions(np.where(lit, fitted, -1))
    region_albedo = region_albedo[ids]
    tied = labels >= 0
    a, b = ctx.edges[:, 0], ctx.edges[:, 1]
    inside = tied[a] & tied[b] & (labels[a] == labels[b])
    spread = deviation(albedo[tied], region_albedo[labels[tied]]) if tied.any() else np.inf
    noise = deviation(albedo[a[inside]], albedo[b[inside]]) if inside.any() else 0.0
    drift = spread / max(noise, 1e-12)
    h.deviation, h.drift = spread, drift
    if not (spread <= c.region_max_deviation or drift <= c.region_max_drift):
        return h
    albedo[tied] = region_albedo[labels[tied]]
    return Hypothesis(h.radiance, light, h.shading, albedo, lit, labels, len(ids), h.share,
                      LightSource.EDGES_AND_REGIONS, h.found, spread, drift)


def parted_regions(ctx: FitContext, tied: Hypothesis) -> Hypothesis | None:
    """The tied hypothesis with each region parted where, under its light, the faces' own
    albedos fall into parts more than ``segment_threshold`` apart (:func:`split_regions`: the
    segmentation joins components apart generously, and a light fitted to two albedos tied
    as one still leaves them apart), and, on the colours as recorded (``ctx.recorded``), where
    they fall into two modes (:func:`split_modes`: two albedos closer than the threshold); the
    light fitted once more with the parts tied; None where nothing parts. Colours less a
    coat's reflection or level carry that fit's misfit, which differs from face to face and
    can spread one albedo's faces into modes of their own: there the coat's refits offer the
    first fit's regions as they are (:func:`kept_regions`). Whether the parts are two albedos or one
    albedo the model misfits (a coat's reflection in some faces' radiance) is for the
    prediction cost to decide (:mod:`.decision`): each part's albedo is three more unknowns."""
    c = ctx.config
    albedo, lit = divide(tied.shading, tied.radiance, tied.light, ctx.usable, ctx.extra)
    features = in_unit_dc(albedo, tied.light)
    labels = split_regions(tied.labels, features, lit, ctx.edges, c.segment_threshold, c.uniform_spread,
                           bridges=ctx.prep.blends_albedos)
    if ctx.recorded:
        labels = split_modes(labels, features, lit, ctx.edges)
    if int(labels.max()) + 1 <= tied.regions:
        return None
    light, albedo, lit, labels, regions = _tied_fit(ctx, tied, labels)
    return Hypothesis(tied.radiance, light, tied.shading, albedo, lit, labels, regions, tied.share,
                      LightSource.EDGES_AND_PARTED_REGIONS, tied.found, tied.deviation, tied.drift)


def kept_regions(ctx: FitContext, edges: Hypothesis, labels: np.ndarray) -> Hypothesis | None:
    """The light fitted to the edges of ``edges.radiance`` with the uniform regions ``labels``
    (F,) of an earlier fit tied, as they are (no region gate, no faces joined or parted); None
    when no lit face lies in a region.

    The coat's correction (:meth:`.method.RetinexSegmented._correct_coat`) passes the first
    fit's regions: a partition found in the colours as recorded is a hypothesis of the
    corrected colours too, where a reflection removed where it was not quite there can leave
    the faces of a region too noisy for the segmentation or the region gates to find it again
    (a rough coat: development seed 1000 lost its five regions to a texture). The prediction
    cost decides among it and the corrected colours' own hypotheses."""
    labels, ids = compact_regions(np.where(edges.lit, labels, -1))   # regions without a lit face dropped
    if not len(ids):
        return None
    light, albedo, lit, labels, regions = _tied_fit(ctx, edges, labels)
    return Hypothesis(edges.radiance, light, edges.shading, albedo, lit, labels, regions,
                      float(np.mean(labels[lit] >= 0)), LightSource.EDGES_AND_KEPT_REGIONS, edges.found)


def _tied_fit(ctx: FitContext, h: Hypothesis, labels: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """The light fitted from ``h``'s with the regions ``labels`` (F,) tied, and under it each
    face's albedo (a region's faces its region's), the lit faces, the labels of the lit ones
    (-1 elsewhere; a region without a lit face dropped, the rest numbered anew) and their count."""
    light, region_albedo = edge_fit.log_shading_fit(h.radiance, h.shading.columns, ctx.edges, ctx.usable, labels,
                                                    initial=h.light, **ctx.fit)
    albedo, lit = divide(h.shading, h.radiance, light, ctx.usable, ctx.extra)
    labels, ids = compact_regions(np.where(lit, labels, -1))
    inside = labels >= 0
    albedo[inside] = region_albedo[ids][labels[inside]]
    return light, albedo, lit, labels, len(ids)
