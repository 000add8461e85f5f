"""The self-check: how far an estimate can be trusted, from its inputs alone. A report
without ground truth is only this; with ground truth it appears beside the comparison.

Sections: the trust summary recorded by the estimate (degrees of freedom, residual,
outliers, conditioning, standard errors, cross-validated PSNR, warnings), the training
views the estimate explains worst next to its prediction (residual maps), the per-view
residual and gross-error bars, and the per-face relative standard error as a map.
"""
from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np

from estimator import Predictor

from . import figures


def _number_or_none(value):
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _valid_views(views) -> list[dict]:
    """The per-view trust records (a run.json written by another version, or edited, may lack
    them or hold something else: then there is no per-view section)."""
    if not isinstance(views, list) or not all(isinstance(v, dict) for v in views):
        return []
    return [{"view": str(v.get("view")), "residual": _number_or_none(v.get("residual")),
             "gross_share": _number_or_none(v.get("gross_share"))} for v in views]


def _views_figure(predictor: Predictor, chosen: list) -> bytes:
    """Image | prediction | residual of the training views ``chosen`` ((index, View) pairs),
    on the pixels the estimate covers (and the alpha holds fully)."""
    names, predictions, references, masks = [], [], [], []
    for i, view in chosen:
        predicted, coverage = predictor.predict(view.camera)
        mask = coverage > 0
        if view.alpha is not None:
            mask &= view.alpha >= 0.999
        names.append(f"view {i} ({view.name})")
        predictions.append(predicted)
        references.append(view.rgb)
        masks.append(mask)
    return figures.image_comparison(names, predictions, references, masks, "prediction")


def self_check(predictor: Predictor, views: list, run: dict, est, max_views: int = 4
               ) -> tuple[dict, list[tuple[str, str, Callable[[], bytes]]]]:
    """(metrics, figures) of the self-check; figures as (section, caption, draw), ``draw()``
    returning the PNG bytes (:class:`reports.report.ReportContent`).

    Parameters
    ----------
    views : the training views (``estimator.core.data.View``) the run was solved from.
    run : the run's run.json (``trust``, ``warnings``, ``degrees_of_freedom``, optionally
        ``cross_validation``).
    est : the Estimate (``face_stats`` gives the per-face standard errors).
    """
    trust = run.get("trust") if isinstance(run.get("trust"), dict) else {}
    per_view = _valid_views(trust.get("views"))
    metrics = {"degrees_of_freedom": run.get("degrees_of_freedom"), "warnings": run.get("warnings", []),
               "residual": trust.get("residual"), "outlier_share": trust.get("outlier_share"),
               "light_condition": trust.get("light_condition"), "albedo_relative_se": trust.get("albedo_relative_se"),
               "cross_validation_psnr": (run.get("cross_validation") or {}).get("psnr")}
    figs = []
    if per_view:
        figs.append(("Self-check", "per training view: median relative residual and gross-error share",
                     partial(figures.view_bars, [v["view"] for v in per_view], [v["residual"] for v in per_view],
                             [v.get("gross_share") for v in per_view])))
        order = np.argsort([-(v.get("gross_share") or 0.0) for v in per_view])[:max_views]
        chosen = [int(i) for i in order if int(i) < len(views)]
    else:
        chosen = list(range(min(max_views, len(views))))
    if chosen:
        figs.append(("Self-check", "training views with the most gross errors: image | prediction | residual",
                     partial(_views_figure, predictor, [(i, views[i]) for i in chosen])))
    se = est.face_stats.get("albedo_se")
    if se is not None:
        level = np.linalg.norm(est.diffuse + est.specular, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            relative = np.linalg.norm(se, axis=1) / level
        figs.append(("Self-check", "per-face relative standard error of the albedo (grey: unseen or no inlier)",
                     partial(figures.face_values, predictor.caster, np.where(est.observed, relative, np.nan),
                             "relative standard error")))
    return metrics, figs
