"""Hypotheses from the coat's reflection (:mod:`estimator.light.coat_map`): the light of the
lat-long map fitted to the colours' changes across views, which no albedo can bias, and the
map fit's diffuse radiance (the coat's reflection removed) under the edges' light."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...core import sh
from ...core.gauge import unit_dc
from ...core.reductions import group_quantile
from ...light import coat_map, edge_fit, sun
from .shading import at_indirect_scale, divide
from .values import FitContext, Hypothesis, LightSource, Shading


def coat_map_fit(ctx: FitContext) -> coat_map.ReflectedLight:
    """The light the coat reflects, fitted once per solve on the observations before any coat
    correction."""
    fits = ctx.fits
    if fits.coat_map is None:
        obs = fits.observations
        fits.coat_map = coat_map.fit_reflected_light(obs.face, obs.rgb, obs.view_dir, ctx.prep.data.mesh.face_normals,
                                                     ctx.prep.sampling, ctx.prep.visibility, ctx.config.coat_ior,
                                                     loss=ctx.loss)
    return fits.coat_map


def through_coat(ctx: FitContext) -> Shading:
    """The diffuse shading through the coat (the cosine weighted by the coat's entry
    transmission 1 - F, as Mitsuba's ``plastic``); its rows are computed once and kept on the
    shadow function (:func:`estimator.model.reflection.diffuse_matrix`)."""
    prep = ctx.prep
    return Shading(ctx.model.diffuse_matrix(prep.data.mesh, prep.sampling, prep.visibility,
                                            coat_ior=ctx.config.coat_ior), coat_ior=ctx.config.coat_ior)


def coat_map_candidate(ctx: FitContext, regions: bool) -> coat_map.ReflectedLight | None:
    """The coat's map when this fit may take its light: ``reflected_light`` on (and
    ``reflected_regions`` for an object of uniform regions) and the map determined (at least
    :data:`coat_map.ROWS_PER_VERTEX` rows per map vertex beyond the faces' unknowns)."""
    c = ctx.config
    if not c.reflected_light or (regions and not c.reflected_regions):
        return None
    fitted = coat_map_fit(ctx)
    return fitted if fitted.determined else None


def coat_map_hypothesis(ctx: FitContext, edges: Hypothesis, fitted: coat_map.ReflectedLight) -> Hypothesis | None:
    """The light of the coat's map, on the map fit's diffuse radiance (faces it did not see keep
    theirs), or None where the edge search kept a sun and the map's own sun is not kept within
    ``reflected_sun_max_angle`` of it (a 32 x 64 map's cells span about 6 degrees: a source
    narrower than a cell is blurred and casts no hard shadow in it).

    On a texture the SH part of the light is then fitted to the edges of that diffuse radiance,
    beside the map's sun; on uniform regions each region takes its faces' median albedo."""
    c = ctx.config
    radiance = np.where(np.isfinite(fitted.diffuse) & (fitted.diffuse > 0), fitted.diffuse, edges.radiance)
    light, shading = map_light(ctx, fitted, radiance)
    if edges.shading.sun is not None and (shading.sun is None or np.degrees(np.arccos(np.clip(
            shading.sun.direction @ edges.found.direction, -1.0, 1.0))) > c.reflected_sun_max_angle):
        return None
    source = LightSource.COAT_MAP
    if not edges.regions:
        edge_light, _ = edge_fit.log_shading_fit(radiance, shading.columns, ctx.edges, ctx.usable, **ctx.fit)
        if shading.sun is None or np.all(edge_light[-1] > 0):   # no dark sun
            light, source = edge_light, LightSource.COAT_MAP_DIFFUSE
    if source is LightSource.COAT_MAP:
        light = at_indirect_scale(ctx, shading, radiance, light)
    albedo, lit = divide(shading, radiance, light, ctx.usable, ctx.extra)
    labels = edges.labels
    if edges.regions:
        labels = np.where(lit, labels, -1)
        tied = labels >= 0
        albedo[tied] = group_quantile(labels[tied], albedo[tied], edges.regions, 0.5)[labels[tied]]
        source = LightSource.COAT_MAP_AND_REGIONS
    return Hypothesis(radiance, light, shading, albedo, lit, labels, edges.regions, edges.share, source,
                      shading.sun or edges.found, edges.deviation, edges.drift)


def map_light(ctx: FitContext, fitted: coat_map.ReflectedLight, radiance: np.ndarray) -> tuple[np.ndarray, Shading]:
    """The map's light and its shading through the coat (the cosine weighted by the coat's entry
    transmission 1 - F, as Mitsuba's ``plastic``).

    The map's brightest compact source is tried as a sun with exact shadows beside the map's
    sky (that source cut out), its irradiance over the sky's fitted to the albedo edges per
    channel (one unknown each); it is kept when positive in every channel and the edge cost
    ratio is at most ``reflected_sun_max_ratio``. Otherwise the whole map is the light (cutting
    its peak out without a sun would lose that light). Returns the light (M', 3) (unit sky DC,
    the sun's irradiance last when kept) and its shading."""
    c, prep, model = ctx.config, ctx.prep, ctx.model
    coated = through_coat(ctx)
    sky_map, direction = fitted.sky_and_sun()
    sky = model.unknown_from_radiance(sh.project_latlong(c.sh_order, sky_map))
    sky = unit_dc(sky)[0]
    sun_column = sun.sun_shading(prep.data.mesh, prep.caster, direction, c.coat_ior)
    sky_shading = coated.columns @ sky                                    # (F, 3)
    with_sun = np.zeros(3)
    for k in range(3):   # one unknown per channel: the sun's irradiance over the sky's
        pair = np.stack([sky_shading[:, k], sun_column], axis=1)
        with_sun[k] = edge_fit.log_shading_fit(radiance[:, [k]], pair, ctx.edges, ctx.usable,
                                               **ctx.plain_fit)[0][1, 0]
    both = sky_shading + with_sun * sun_column[:, None]
    ratio = edge_fit.edge_cost_ratio(edge_fit.edge_residuals(radiance, sky_shading, ctx.edges, ctx.usable),
                                     edge_fit.edge_residuals(radiance, np.maximum(both, 1e-300), ctx.edges, ctx.usable))
    if np.all(with_sun > 0) and ratio <= c.reflected_sun_max_ratio:
        found = sun.Sun(direction, ratio, 3, c.coat_ior)   # 3 evaluations: one fit per channel
        return np.vstack([sky, with_sun[None]]), coated.with_sun(found, sun_column)
    whole = model.unknown_from_radiance(fitted.sh(c.sh_order))
    return unit_dc(whole)[0], coated


def coated_diffuse(ctx: FitContext, edges: Hypothesis) -> tuple[np.ndarray, Shading] | None:
    """The map fit's diffuse radiance (F, 3) (the coat's reflection removed, its exit
    transmission divided out; faces the map did not see keep the edges' radiance) and the
    shading through the coat (the edge search's sun through it too), where the map is
    determined: the map's light errs where a source is narrower than a cell, but its
    reflection removed per view may still be closer to the diffuse radiance than a low
    quantile of the colours. None otherwise (or with ``reflected_light`` off)."""
    c, prep = ctx.config, ctx.prep
    if not c.reflected_light:
        return None
    fitted = coat_map_fit(ctx)
    if not fitted.determined:
        return None
    mesh = prep.data.mesh
    shading = through_coat(ctx)
    if edges.shading.sun is not None:
        found = replace(edges.found, coat_ior=c.coat_ior)
        shading = shading.with_sun(found, sun.sun_shadings(mesh, prep.caster, found.directions, c.coat_ior))
    radiance = np.where(np.isfinite(fitted.diffuse) & (fitted.diffuse > 0), fitted.diffuse, edges.radiance)
    return radiance, shading


def coated_diffuse_hypothesis(ctx: FitContext, edges: Hypothesis) -> Hypothesis | None:
    """The edges' light fitted on :func:`coated_diffuse`'s radiance and shading; None where
    :func:`coated_diffuse` is."""
    coated = coated_diffuse(ctx, edges)
    if coated is None:
        return None
    radiance, shading = coated
    light, _ = edge_fit.log_shading_fit(radiance, shading.columns, ctx.edges, ctx.usable, **ctx.fit)
    albedo, lit = divide(shading, radiance, light, ctx.usable, ctx.extra)
    return Hypothesis(radiance, light, shading, albedo, lit, edges.labels, edges.regions, edges.share,
                      LightSource.COAT_MAP_DIFFUSE, shading.sun or edges.found, edges.deviation, edges.drift)
