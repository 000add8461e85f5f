"""How ``retinex-segmented`` decides where the light comes from: the one file to change for that.

The first hypothesis is always the edges' (:func:`edge_hypothesis`: the albedo edges, a sun
when one lowers their cost, uniform regions tied when they hold). Two fits of how the colours
change across views may then replace it, because no albedo can bias them: the coat's lat-long
map (a Fresnel dielectric coat) and a shared Phong lobe. Each is a candidate only when it
explains at least ``reflected_min_explained`` of the view changes; where both are, the one
that explains more is the candidate (a coat's map that wins but whose sun disagrees with the
edges' falls back to the edges, not to the lobe). A texture whose coat's map explains the view changes well enough to
remove the coat's reflection (``reflected_diffuse_min_explained``), but not to give the light,
keeps the edges' light fitted on that cleaner diffuse radiance.
"""
from __future__ import annotations

import numpy as np

from ...light.sun import Sun
from .coat import coat_map_candidate, coat_map_hypothesis, coated_diffuse_hypothesis
from .edges import edge_hypothesis
from .lobe import lobe_candidate, lobe_hypothesis
from .values import FitContext, Hypothesis, LightSource


def decide_light(ctx: FitContext, radiance: np.ndarray, found: Sun | None) -> Hypothesis:
    """The light of one fit, and the albedos and regions under it.

    ``radiance`` (F, 3): each face's diffuse radiance (a low quantile over the views);
    ``found``: the sun of an earlier fit (None: the edge stage searches for one)."""
    edges = edge_hypothesis(ctx, radiance, found)
    coat_map = coat_map_candidate(ctx, regions=edges.regions > 0)
    lobe = lobe_candidate(ctx)
    if coat_map is not None and lobe is not None and np.mean(lobe.explained) > np.mean(coat_map.explained):
        coat_map = None     # a lobe without Fresnel explains the view changes better than a coat
    if coat_map is not None:
        taken = coat_map_hypothesis(ctx, edges, coat_map)   # None: its sun disagrees with the edges'
        if taken is not None:
            return taken
    elif lobe is not None:
        taken = lobe_hypothesis(ctx, edges, lobe)   # None: the lobe left no positive diffuse radiance
        if taken is not None:
            return taken
    if edges.source is LightSource.EDGES and not edges.regions:
        coated = coated_diffuse_hypothesis(ctx, edges)
        if coated is not None:
            return coated
    return edges
