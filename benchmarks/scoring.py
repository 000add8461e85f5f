"""What the benchmarks share: the scoring of one estimate against its ground truth, and the
``--set KEY=VALUE`` estimator setting."""
from __future__ import annotations

import argparse
import json

import numpy as np

from harness.cli.heap import keep_freed_memory
from reports import metrics
from reports.ground_truth import evaluation_mask, lit_faces, true_irradiance

# every benchmark that imports this module times the estimator with the heap the command line runs it with
keep_freed_memory()


def seen_faces(caster, views) -> np.ndarray:
    """(F,) bool: the faces some pixel centre of ``views`` hits, from the face-ID buffers of
    ``caster`` (reused when the estimate traced the same cameras with it; a pose refinement
    traces its refined cameras, and these are traced again)."""
    seen = np.zeros(caster.mesh.num_faces, dtype=bool)
    for ids in caster.face_id_buffers([v.camera for v in views]):
        seen[ids[ids >= 0]] = True
    return seen


def score(ds, truth, est, component: str = "diffuse", seen: np.ndarray | None = None) -> dict:
    """PSNR and share within ±10 % (least-squares gauge) of one albedo component, ARI, the
    evaluated faces and the share of faces the estimate holds; with ``seen`` (F,) bool
    (:func:`seen_faces`) also the share of those faces it holds (``estimated_of_seen``, NaN
    without a seen face): a face a camera shows but the estimate leaves out is a hole in its
    texture; and the share among the seen faces that receive light
    (``estimated_of_seen_lit``: :func:`reports.ground_truth.lit_faces`, the rule by which the
    PSNR leaves unlit faces out; a face the environment leaves dark is black in every view)."""
    irr = true_irradiance(ds.data.mesh, truth)
    mask = evaluation_mask(truth, irr, est.observed, component)
    estimated, true = getattr(est, component), getattr(truth, component)
    lstsq = metrics.albedo_ratios(estimated, true, mask, "lstsq")
    o = est.observed & (est.labels >= 0)
    ari = (
        metrics.adjusted_rand_index(truth.regions[o], est.labels[o]) if truth.regions is not None and o.any() else None
    )
    out = {"psnr": metrics.albedo_psnr(estimated, true, mask),
           "within_10": metrics.ratio_summary(lstsq[:, 3])["within_10"], "ari": ari,
           "evaluated": int(mask.sum()), "estimated_share": float(est.observed.mean())}
    if seen is not None:   # NaN where no face is seen: the share is undefined, not 0
        out["estimated_of_seen"] = float(est.observed[seen].mean()) if seen.any() else float("nan")
        shown = seen & lit_faces(irr)
        out["estimated_of_seen_lit"] = float(est.observed[shown].mean()) if shown.any() else float("nan")
    return out


def setting(text: str) -> tuple[str, object]:
    """``--set`` argument type: 'KEY=VALUE' -> (KEY, VALUE read as JSON, else the text)."""
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"--set takes KEY=VALUE, got {text!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value
