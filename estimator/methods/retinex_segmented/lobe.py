"""The hypothesis of a shared Phong lobe (:mod:`estimator.light.lobe_light`): SH radiance fitted
to the colours' changes across views, every face's diffuse free, its DC from the albedo edges."""
from __future__ import annotations

import numpy as np

from ...core.errors import InputError
from ...core.reductions import group_quantile
from ...light import edge_fit, lobe_light, sun
from ...model.reflection import diffuse_matrix, lobe_matrix, mirror_directions, phong_lobe
from ...pipeline.observations import Observations
from ...solvers.segmentation import segment
from .shading import at_indirect_scale, deviation, divide, in_unit_dc
from .values import FitContext, Hypothesis, LightSource, Shading


def lobe_candidate(ctx: FitContext) -> lobe_light.LobeLight | None:
    """The light a shared Phong lobe reflects, fitted once per solve on the observations before
    any coat correction, when ``reflected_lobe`` is on and the rows fit in memory."""
    c, prep, fits = ctx.config, ctx.prep, ctx.fits
    if not c.reflected_lobe or prep.streamed:
        return None
    if fits.lobe is None:
        obs = fits.observations
        rows = prep.d_rows if prep.model.name == "lobe" and obs is prep.obs else lobe_rows(ctx, obs)
        fits.lobe = (lobe_light.fit_lobe_light(obs.face, obs.rgb, rows, obs.num_faces, loss=ctx.loss), rows)
    return fits.lobe[0]


def lobe_rows(ctx: FitContext, obs: Observations) -> np.ndarray:
    """(N, M) the Phong lobe rows (exponent ``phong_exponent``) of the observations ``obs``."""
    prep = ctx.prep
    normals = prep.data.mesh.face_normals[obs.face]
    return lobe_matrix(obs.face, mirror_directions(normals, obs.view_dir), prep.sampling,
                       prep.visibility, ctx.config.sh_order, ctx.config.phong_exponent)


def lobe_hypothesis(ctx: FitContext, edges: Hypothesis, fitted: lobe_light.LobeLight) -> Hypothesis | None:
    """The light of the lobe's fit ``fitted`` (:func:`lobe_reflected_light`) and each face's
    diffuse radiance under it;
    regions found under the edges' light saw the lobe's reflection as albedo, so they are found
    again, and each takes its faces' median albedo when they deviate from it by at most
    ``region_max_deviation``. None: the lobe's light leaves no positive diffuse radiance in
    some channel (the lobe took the diffuse too: not a lobe)."""
    c = ctx.config
    try:
        radiance, light, shading = lobe_reflected_light(ctx, fitted, edges.found)
    except InputError:
        return None
    light = at_indirect_scale(ctx, shading, radiance, light)
    albedo, lit = divide(shading, radiance, light, ctx.usable, ctx.extra)
    labels, _ = segment(np.where(lit[:, None], in_unit_dc(albedo, light), 1.0), ctx.edges, lit,
                        c.segment_threshold, c.uniform_spread, bridges=ctx.prep.blends_albedos)
    share, regions = float(np.mean(labels[lit] >= 0)), int(labels.max()) + 1
    spread, source = None, LightSource.LOBE
    if regions and share >= c.retinex_min_uniform_share:
        tied = labels >= 0
        median = group_quantile(labels[tied], albedo[tied], regions, 0.5)
        spread = deviation(albedo[tied], median[labels[tied]])
        if spread <= c.region_max_deviation:
            albedo[tied] = median[labels[tied]]
            source = LightSource.LOBE_AND_REGIONS
    if source is LightSource.LOBE:
        regions, labels = 0, np.full(len(labels), -1, dtype=np.int64)
    return Hypothesis(radiance, light, shading, albedo, lit, labels, regions, share, source, shading.sun, spread)


def lobe_reflected_light(ctx: FitContext, fitted: lobe_light.LobeLight,
                         found: sun.Sun | None) -> tuple[np.ndarray, np.ndarray, Shading]:
    """The texture's light from the lobe's reflection: the SH radiance, its DC from the edges
    (:func:`lobe_light.dc_from_edges`). The edge search's sun, whether or not that search kept
    it, is tried as a delta light in both terms (its lobe column in the view fit, its exact
    shadows in the shading) and kept when its irradiance is positive in every channel and it
    lowers the edges' robust cost to at most ``reflected_sun_max_ratio`` of the cost without it.

    Returns each face's diffuse radiance (F, 3) (negative clipped to 0), the light (M', 3) (the
    model's light unknown, the sun's irradiance last when kept) and its shading (the sun's cost
    ratio in its ``cost_ratio``; no coat on its way)."""
    c, prep = ctx.config, ctx.prep
    mesh = prep.data.mesh
    rows = ctx.fits.lobe[1]   # the lobe rows of every observation
    plain = diffuse_matrix(mesh, prep.sampling, prep.visibility, c.sh_order)   # rows of the radiance

    def split(fit, shading_rows):
        light, diffuse = fit.with_dc(lobe_light.dc_from_edges(fit, shading_rows, ctx.edges, ctx.usable))
        return light, np.maximum(np.nan_to_num(diffuse), 0.0), shading_rows

    light, diffuse, plain = chosen = split(fitted, plain)
    kept = None
    if found is not None:
        obs = ctx.fits.observations
        shading = sun.sun_shading(mesh, prep.caster, found.direction)
        cosine = np.maximum(mesh.face_normals @ found.direction, 0.0)
        share = np.where(cosine > 0, shading * np.pi / np.maximum(cosine, 1e-300), 0.0)   # lit share
        mirror = mirror_directions(mesh.face_normals[obs.face], obs.view_dir)
        lobe = phong_lobe(mirror, found.direction[None, :], c.phong_exponent) * share[obs.face, None]   # (N, 1)
        with_sun = lobe_light.fit_lobe_light(obs.face, obs.rgb, np.hstack([rows, lobe]), obs.num_faces,
                                             loss=ctx.loss)
        trial = None
        if np.all(with_sun.light[-1] > 0):
            try:
                trial = split(with_sun, np.hstack([plain, shading[:, None]]))
            except InputError:   # the sun's lobe leaves no positive diffuse radiance: not this sun
                pass
        if trial is not None:
            ratio = edge_fit.edge_cost_ratio(
                edge_fit.edge_residuals(diffuse, plain @ light, ctx.edges, ctx.usable),
                edge_fit.edge_residuals(trial[1], np.maximum(trial[2] @ trial[0], 1e-300), ctx.edges, ctx.usable))
            if ratio <= c.reflected_sun_max_ratio:
                chosen, kept = trial, sun.Sun(found.direction, ratio, found.evaluations)
    light, diffuse, _ = chosen
    m = prep.c_matrix.shape[1]
    columns = Shading(ctx.model.diffuse_matrix(mesh, prep.sampling, prep.visibility))
    if kept is not None:
        columns = columns.with_sun(kept, shading)
    return diffuse, np.vstack([ctx.model.unknown_from_radiance(light[:m]), light[m:]]), columns
