"""How ``retinex-segmented`` decides where the light comes from: the one file to change for that.

Every hypothesis the data allow is formed (:func:`light_hypotheses`): the edges' (the albedo
edges, a sun when one lowers their cost, uniform regions tied when they hold, and those regions
parted where their albedos still differ under the tied light), and, because no
albedo can bias them, those of the fits of how the colours change across views: the coat's
lat-long map (a Fresnel dielectric coat), the edges' light on the map's diffuse radiance (the
coat's reflection removed), and a shared Phong lobe. Each becomes an estimate, and one
criterion computed without ground truth chooses among them (:func:`prediction_cost`): how well
the estimate predicts the observations it was solved from, as a robust negative
log-likelihood, with the Bayesian information criterion's price for each unknown.
"""
from __future__ import annotations

import numpy as np

from ...diagnostics.trust import observation_residuals
from ...light.sun import Sun
from ...model.estimate import Estimate
from ...pipeline.prepared import Prepared
from ...solvers.robust import TUNING, relative_residuals, robust_scale
from .coat import coat_map_candidate, coat_map_hypothesis, coated_diffuse_hypothesis
from .edges import edge_hypothesis, kept_regions, parted_regions
from .lobe import lobe_candidate, lobe_hypothesis
from .values import FitContext, Hypothesis, LightSource


def light_hypotheses(ctx: FitContext, radiance: np.ndarray, found: Sun | None,
                     labels: np.ndarray | None = None) -> list[Hypothesis]:
    """Every light hypothesis of one fit, the edges' first.

    ``radiance`` (F, 3): each face's diffuse radiance (a low quantile over the views);
    ``found``: the sun of an earlier fit (None: the edge stage searches for one); ``labels``
    (F,): the uniform regions of an earlier fit, tied as they are for one more hypothesis
    (:func:`.edges.kept_regions`; None: none)."""
    edges = edge_hypothesis(ctx, radiance, found)
    out = [edges]
    if labels is not None:
        out.append(kept_regions(ctx, edges, labels))            # None: no lit face in a region
    if edges.source is LightSource.EDGES_AND_REGIONS:
        out.append(parted_regions(ctx, edges))                  # None: no region parts under the tied light
    coat_map = coat_map_candidate(ctx, regions=edges.regions > 0)
    if coat_map is not None:
        out.append(coat_map_hypothesis(ctx, edges, coat_map))   # None: its sun disagrees with the edges'
    lobe = lobe_candidate(ctx)
    if lobe is not None:
        out.append(lobe_hypothesis(ctx, edges, lobe))            # None: the lobe left no diffuse radiance
    if edges.source is LightSource.EDGES and not edges.regions:
        out.append(coated_diffuse_hypothesis(ctx, edges))
    return [h for h in out if h is not None]


def prediction_cost(prep: Prepared, estimates: list[Estimate], added: list[np.ndarray | None] | None = None,
                    extra_unknowns: list[int] | None = None) -> np.ndarray:
    """(H,) the criterion of each estimate: the lower, the better it explains the observations.

    ``added``: per estimate, None or (N, 3) colours its model adds to the estimate's own
    prediction of each observation (a coat's reflection subtracted before the solve), with
    ``extra_unknowns`` the unknowns that term took.

    On the observations of faces every estimate holds (so that each is judged on the same
    data), the relative residuals r (:func:`observation_residuals`) are priced by the Cauchy
    negative log-likelihood sum log(1 + (r / (c s))^2), c the Cauchy constant of 95 % Gaussian
    efficiency and s one robust scale for all: the least over the estimates of 1.4826 x the
    median of their residuals as if each were held out from its own albedo's fit
    (:func:`held_out`; a free albedo per face shrinks its faces' residuals, and to 0 where a
    face has one observation, which would take the noise for nil). Each unknown (the estimate's
    ``degrees_of_freedom.unknowns``: albedos of its groups and the light) costs (1/2) ln n, n
    the colour values compared: the Bayesian information criterion, so a hypothesis with more
    free albedos (the lobe's texture beside tied regions) wins only when the data ask for it.
    Whether the edges' light ties regions at all is decided before, by the region gates
    (:func:`.edges.tied_regions`). No threshold is fitted here."""
    held = np.logical_and.reduce([e.observed for e in estimates])[prep.obs.face]
    added = added or [None] * len(estimates)
    rgb = prep.obs.rgb
    residuals = []
    for e, more in zip(estimates, added):
        predicted = rgb - observation_residuals(prep, e)[0] + (0.0 if more is None else more)
        residuals.append(relative_residuals(rgb[held], predicted[held]))
    n = 3 * int(held.sum())
    if n == 0:
        return np.zeros(len(estimates))
    scale = min(robust_scale(held_out(r, e, prep.obs.face[held]), floor=1e-12) for e, r in zip(estimates, residuals))
    nll = np.array([np.sum(np.log1p((r / (TUNING["cauchy"] * scale)) ** 2)) for r in residuals])
    unknowns = np.array([e.info["degrees_of_freedom"]["unknowns"] for e in estimates], float)
    unknowns += np.asarray(extra_unknowns or 0, float)
    return nll + 0.5 * unknowns * np.log(n)


def held_out(residuals: np.ndarray, est: Estimate, face: np.ndarray) -> np.ndarray:
    """(N,) the ``residuals`` of observations of ``face`` (N,) as they would be were each left
    out of its albedo's fit: times n / (n - 1), n the observations of the face's group
    (``est.labels``: a region, or the face alone), the leverage of one of n equally weighted
    observations of one unknown; inf where n is 1 (the albedo interpolates it)."""
    _, inverse, counts = np.unique(est.labels[face], return_inverse=True, return_counts=True)
    n = counts[inverse].astype(float)
    return np.where(n > 1, residuals * n / np.maximum(n - 1, 1), np.inf)


def choose(prep: Prepared, hypotheses: list[Hypothesis], estimates: list[Estimate]) -> int:
    """The index of the estimate of least :func:`prediction_cost`; every hypothesis' source and
    cost are recorded in that estimate's ``info['hypotheses']``."""
    costs = prediction_cost(prep, estimates) if len(estimates) > 1 else np.zeros(1)
    best = int(np.argmin(costs))
    estimates[best].info["hypotheses"] = [{"light_from": h.source.value, "cost": float(cost), "chosen": i == best}
                                          for i, (h, cost) in enumerate(zip(hypotheses, costs))]
    return best
