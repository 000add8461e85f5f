"""The estimate of a chosen light: the unit-DC gauge, the specular albedo with the light fixed,
and what the run reports of how the light was found."""
from __future__ import annotations

import numpy as np

from ...core import sh
from ...core.gauge import unit_dc
from ...model.estimate import Estimate
from .values import FitContext, Hypothesis


def to_estimate(ctx: FitContext, h: Hypothesis, method) -> Estimate:
    """The :class:`Estimate` of hypothesis ``h``: a sun joins the reported light as a delta
    light in SH; the light takes a unit DC per channel (the albedos the inverse scale); the
    specular albedo is solved with the light fixed (``method``'s robust group solve), per region,
    faces outside every region sharing the regions' median (without regions, every face the
    median of the per-face fits: one face's specular is too weakly seen to stand alone)."""
    c, prep, model = ctx.config, ctx.prep, ctx.model
    f = prep.data.mesh.num_faces
    m = ctx.sky_width
    found, light = h.found, h.light
    used = h.shading.sun is not None
    sun_info = None if found is None else {"direction": found.direction.tolist(), "cost_ratio": found.cost_ratio,
                                            "gain": found.gain, "penalty": found.penalty,
                                            "evaluations": found.evaluations, "used": used,
                                            "through_coat": found.coat_ior is not None}
    irradiance = light[m:]                  # one row per source of the sun (none without one)
    if used:
        light = light[:m] + model.unknown_from_radiance(
            sh.project_directional(sh.order_of(m), found.directions, irradiance))
    light, dc = unit_dc(light)
    albedo = h.albedo * dc
    if used:                # in the reported light's gauge
        sun_info["irradiance"] = (irradiance[0] / dc).tolist()
        sun_info["others"] = [{"direction": d.tolist(), "irradiance": (e / dc).tolist()}
                              for d, e in zip(found.others, irradiance[1:])]
    labels, regions = h.labels, h.regions
    group = labels.copy()
    free = np.nonzero(group < 0)[0]
    group[free] = regions + np.arange(len(free))
    groups = f if regions == 0 else regions + len(free)
    # on the rows' projections onto the light: O(N) memory, and each robust round weighs
    # (N, 3) projections instead of (N, M) rows
    result = method._solve_groups(prep.projected(light), group, groups, np.eye(3))
    specular = np.zeros((f, 3))
    reference = result.specular[:regions] if regions else result.specular[group[h.lit]]
    specular[:] = np.median(reference, axis=0) if len(reference) else 0.0
    specular[labels >= 0] = result.specular[labels[labels >= 0]]
    observed = h.lit & np.all(np.isfinite(albedo), axis=1)
    free_seen = int((~(labels >= 0) & observed).sum())
    # a diffuse albedo per region and per free face; a specular per region (the free faces
    # take the regions' median), or one the free faces share (without regions)
    specular_groups = (regions or int(free_seen > 0)) if c.components == "both" else 0
    fits = ctx.fits
    info = {"clusters": int(len(np.unique(group[observed]))), "uniform_regions": regions,
            "uniform_share": h.share, "residuals": result.residuals, "lm_residuals": result.lm_residuals,
            "sun": sun_info, "light_from": h.source.value, "region_deviation": h.deviation, "region_drift": h.drift,
            # the groups (labels) below this fit a specular of their own; the free faces share one
            "own_specular_groups": regions,
            "reflection_explained": (fits.coat_map.explained.tolist() if fits.coat_map is not None
                                     and fits.coat_map.determined else None),
            "lobe_explained": None if fits.lobe is None else fits.lobe[0].explained.tolist(),
            "degrees_of_freedom": {"observations": int(3 * len(prep.obs.face)),
                                   "unknowns": int(3 * (regions + free_seen + specular_groups + light.shape[0] - 1))}}
    zero = ~observed[:, None]
    return Estimate(np.where(zero, 0.0, albedo), np.where(zero, 0.0, specular), model.pseudo_from_light(light),
                    np.where(observed, group, -1).astype(np.int64), observed, method.name, c, info,
                    light if model.light == "radiance" else None)
