"""Leave-views-out cross-validation: the prediction error on views the solve did not use,
the accuracy figure a user without ground truth can trust."""
from __future__ import annotations

import numpy as np

from ..core.data import MultiViewData
from ..core.errors import InputError
from ..core.psnr import psnr_db
from ..model.estimate import Estimate
from ..model.forward import Predictor
from ..pipeline.pose import plausible, refine_view


def holdout_indices(num_views: int, k: int) -> np.ndarray:
    """(k,) indices of ``k`` views spread evenly over ``num_views`` (at least 2 views stay in)."""
    if num_views < 3:
        raise InputError(f"holding views out needs at least 3 training views (2 stay in the solve), the dataset has "
                         f"{num_views}")
    if not 1 <= k <= num_views - 2:
        raise InputError(f"the number of held-out views must lie in [1, {num_views - 2}] for {num_views} views, "
                         f"got {k}")
    return np.unique(np.round(np.linspace(0, num_views - 1, k + 2)[1:-1]).astype(np.int64))


def prediction_scores(est: Estimate, data: MultiViewData, indices: np.ndarray, align: bool = False) -> list[dict]:
    """Per held-out view: PSNR (peak: the view's 99th-percentile object value) and relative
    RMSE of the estimate's predicted image over the pixels of estimated faces (alpha = 1).
    ``align``: each view's camera is first aligned with the prediction
    (:func:`estimator.pipeline.pose.refine_view`), as when the run refined its own poses."""
    predictor = Predictor(data.mesh, est)
    out = []
    for i in indices:
        view = data.views[int(i)]
        camera = view.camera
        if align:
            aligned = refine_view(view, predictor)[0]
            camera = aligned if plausible(view.camera, aligned, data.mesh.bounds_centre) else view.camera
        predicted, coverage = predictor.predict(camera)
        mask = (coverage > 0) & np.any(predicted > 0, axis=2)   # estimated faces, predicted lit
        if view.alpha is not None:
            mask &= view.alpha >= 0.999
        if not mask.any():
            out.append({"view": view.name, "pixels": 0, "psnr": None, "relative_rmse": None})
            continue
        actual, guess = view.rgb[mask].astype(np.float64), predicted[mask].astype(np.float64)
        out.append({"view": view.name, "pixels": int(mask.sum()), **image_scores(actual, guess),
                    "gain": exposure_gain(actual, guess)})
    return out


def image_scores(actual: np.ndarray, predicted: np.ndarray) -> dict:
    """PSNR and relative RMSE of a held-out view's pixels (N, 3) against their prediction (N, 3).

    The PSNR is taken over the range a display exposed for the view shows: both clipped to
    [0, peak], peak the 99th percentile of the pixels' largest channel. A small bright light's
    mirror image on a coat (the brightest percent of the pixels, up to a hundred times the
    diffuse level) lies beyond any SH light the estimate holds; unclipped, those few pixels made
    the whole error (a clean scene's held-out views at -1.5 to 14 dB). The relative RMSE stays
    unclipped, over the RMS of the pixels: above 1 the prediction lies further from the image
    than a black one, which missed highlights alone cannot do and a diverged solve does.

    Returns {'psnr': dB (None where the peak is 0), 'relative_rmse'}."""
    peak = float(np.percentile(actual.max(axis=1), 99))
    shown = float(np.mean((np.clip(actual, 0.0, peak) - np.clip(predicted, 0.0, peak)) ** 2))
    rmse = float(np.sqrt(np.mean((actual - predicted) ** 2)))
    return {"psnr": psnr_db(shown, peak) if peak > 0 else None,
            "relative_rmse": rmse / max(float(np.sqrt(np.mean(actual ** 2))), 1e-300)}


GAIN_MIN_SHARE = 0.05   # pixels predicted below this share of the view's 90th percentile: log ratio is noise


def exposure_gain(actual: np.ndarray, predicted: np.ndarray) -> list[float | None]:
    """A held-out view's exposure and white balance relative to the views the estimate was
    solved from: per channel, exp of the median log ratio of its pixels (N, 3) to their
    predictions (N, 3), over pixels whose prediction is not dark; None where none is.
    The estimate's light and albedos are the training views' gauge, so a camera on
    auto-exposure shows here as a gain away from 1, as does a view the estimate predicts
    poorly: a figure to read beside the view's PSNR, not a test."""
    out = []
    for c in range(3):
        level = np.percentile(predicted[:, c], 90)
        rows = (predicted[:, c] > GAIN_MIN_SHARE * level) & (actual[:, c] > 0) & (predicted[:, c] > 0)
        out.append(float(np.exp(np.median(np.log(actual[rows, c] / predicted[rows, c])))) if rows.any() else None)
    return out


def cross_validate(data: MultiViewData, k: int, solve) -> dict:
    """Solve without ``k`` evenly spread views and score the prediction of each.

    Parameters
    ----------
    solve : callable MultiViewData -> Estimate (the same method and settings as the run).

    Returns
    -------
    dict: ``held_out`` (view names), ``views`` (per-view scores, :func:`prediction_scores`),
    ``psnr`` (mean over views with pixels), ``relative_rmse`` (mean), ``aligned`` (the
    solve refined its poses, so each held-out view's pose was aligned with the prediction
    before scoring: a held-out view's pose error is then not counted against the light and
    albedos).
    """
    held = holdout_indices(len(data.views), k)
    keep = np.setdiff1d(np.arange(len(data.views)), held)
    train = MultiViewData(data.mesh, [data.views[int(i)] for i in keep])
    est = solve(train)
    aligned = "poses" in est.info
    scores = prediction_scores(est, data, held, align=aligned)
    psnr = [s["psnr"] for s in scores if s["psnr"] is not None]
    rmse = [s["relative_rmse"] for s in scores if s["relative_rmse"] is not None]
    return {"held_out": [data.views[int(i)].name for i in held], "views": scores,
            "psnr": float(np.mean(psnr)) if psnr else None,
            "relative_rmse": float(np.mean(rmse)) if rmse else None, "aligned": aligned}


MIN_CV_PSNR_DB = 10.0    # an error of a third of the exposure level on every held-out pixel
MAX_HELD_OUT_RMSE = 1.0  # a prediction further from its image than a black image is


def cross_validation_warnings(cv: dict) -> list[str]:
    """Warnings of a :func:`cross_validate` result: its mean prediction PSNR below
    :data:`MIN_CV_PSNR_DB`, or a held-out view whose relative RMSE exceeds
    :data:`MAX_HELD_OUT_RMSE` (the held-out solve diverged, or the model does not hold).

    No warning is drawn from the held-out views' exposure gains: on clean scenes they depart
    from 1 by 1 % to 10x wherever the estimate predicts a view poorly
    (``benchmarks/false_alarms.py``), so they cannot tell auto-exposure apart."""
    out = []
    if cv.get("psnr") is not None and cv["psnr"] < MIN_CV_PSNR_DB:
        out.append(f"cross-validation: the held-out views are predicted at {cv['psnr']:.1f} dB, below "
                   f"{MIN_CV_PSNR_DB:g} dB: the estimate does not predict views it was not solved from")
    bad = [v for v in cv.get("views", []) if v.get("relative_rmse") is not None
           and v["relative_rmse"] > MAX_HELD_OUT_RMSE]
    if bad:
        worst = max(bad, key=lambda v: v["relative_rmse"])
        out.append(f"cross-validation: {len(bad)} held-out view(s) predicted further from their images than a black "
                   f"image would be (worst {worst['view']}: relative RMSE {worst['relative_rmse']:.3g}): the "
                   "solve without them diverged")
    return out
