"""Regression checks of metrics against a stored baseline, with per-metric tolerances."""
from __future__ import annotations

import difflib
import math

from estimator import InputError

from .html import lookup

# dotted metric path -> (which direction is better, absolute tolerance)
TRACKED: dict[str, tuple[str, float]] = {
    "illumination.relative_l2": ("lower", 0.01),
    "albedo.specular.dc.luminance.within_10": ("higher", 0.02),
    "albedo.specular.dc.luminance.within_5": ("higher", 0.02),
    "albedo.specular.lstsq.luminance.within_10": ("higher", 0.02),
    "albedo.diffuse.dc.luminance.within_10": ("higher", 0.02),
    "albedo.diffuse.lstsq.luminance.within_10": ("higher", 0.02),
    "albedo.diffuse.ciede2000.median": ("lower", 0.5),
    "albedo.diffuse.psnr_lstsq": ("higher", 0.5),
    "albedo.diffuse.robust.luminance.within_10": ("higher", 0.02),
    "albedo.specular.robust.luminance.within_10": ("higher", 0.02),
    "albedo.diffuse.psnr_robust": ("higher", 0.5),
    "albedo.specular.ciede2000.median": ("lower", 0.5),
    "clusters.ari": ("higher", 0.02),
    "novel_views.psnr_srgb": ("higher", 0.5),
    "novel_views.ssim_srgb": ("higher", 0.01),
    "relighting.psnr_srgb": ("higher", 0.5),
    # the two models' disagreement with the render's own Monte Carlo noise taken out: the
    # noisy figure moves with any change of the sampler (a sample count) and not the models
    "mitsuba_cross_check.relative_l2_noise_free": ("lower", 0.005),
}


def make_baseline(metrics: dict) -> dict:
    """A baseline from a metrics dict: the tracked values it has, with their tolerances, and
    the size of the dataset it was made on (a report on a dataset of another size is not
    compared with it)."""
    values = {path: lookup(metrics, path) for path in TRACKED}
    values = {k: float(v) for k, v in values.items()
              if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)}
    return {"scene": metrics.get("scene"), "method": metrics.get("method"),
            "parameters": metrics.get("parameters"), "dataset_size": metrics.get("dataset_size"), "metrics": values,
            "tolerances": {k: {"better": TRACKED[k][0], "tolerance": TRACKED[k][1]} for k in values}}


DATASET_SIZE_KEYS = ("faces", "views", "width", "height")   # a baseline's dataset_size (made by the report)


def validate_baseline(baseline, source: str = "baseline") -> dict:
    """Check a baseline's structure; raises InputError naming ``source`` and the metric."""
    if not isinstance(baseline, dict) or not isinstance(baseline.get("metrics"), dict):
        raise InputError(f"{source}: a baseline is a JSON object with a 'metrics' table")
    tolerances = baseline.get("tolerances", {})
    if not isinstance(tolerances, dict):
        raise InputError(f"{source}: 'tolerances' must be a table")
    size = baseline.get("dataset_size")
    if size is not None and not (isinstance(size, dict) and all(
            isinstance(size.get(k), int) and not isinstance(size.get(k), bool) for k in DATASET_SIZE_KEYS)):
        raise InputError(f"{source}: dataset_size must be a table of integers {', '.join(DATASET_SIZE_KEYS)}, "
                         f"got {size!r}")
    for path, value in baseline["metrics"].items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError(f"{source}: metrics.{path} must be a finite number, got {value!r}")
        entry = tolerances.get(path)
        if entry is None:
            continue
        if not isinstance(entry, dict) or entry.get("better") not in ("higher", "lower") \
                or isinstance(entry.get("tolerance"), bool) or not isinstance(entry.get("tolerance"), (int, float)) \
                or not math.isfinite(entry["tolerance"]) or entry["tolerance"] < 0:
            raise InputError(
                f"{source}: tolerances.{path} must be {{better: 'higher'|'lower', tolerance: number >= 0}}, "
                f"got {entry!r}"
            )
    return baseline


def metric_paths(metrics: dict, prefix: str = "") -> list[str]:
    """The dotted paths of every metric in a metrics dict (nested tables), e.g.
    'albedo.diffuse.psnr_lstsq': each number, and each None (a metric the run could not compute)."""
    out = []
    for key, value in metrics.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            out.extend(metric_paths(value, path + "."))
        elif value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)):
            out.append(path)
    return out


def unknown_metric(metrics: dict, path: str) -> str | None:
    """None where the report names ``path`` (its value may still be missing: a metric the
    run could not compute), else why it is not a metric of the report: with the closest name it
    has or tracks, so a typo in a hand-written baseline reads as one. A tracked metric is never
    unknown: a report may lack it (``--no-mitsuba`` computes no cross-check)."""
    known = set(metric_paths(metrics)) | set(TRACKED)
    if path in known:
        return None
    close = difflib.get_close_matches(path, sorted(known), n=1, cutoff=0.8)
    return "not a metric of this report" + (f"; did you mean {close[0]!r}?" if close else "")


def check(metrics: dict, baseline: dict) -> list[dict]:
    """Compare every metric of the baseline; a row per metric with status 'ok', 'worse' or 'missing'.

    A metric is worse when it moved in the bad direction by more than its
    tolerance (the baseline's own, else :data:`TRACKED`'s); missing when the
    current metrics lack it or it is not a finite number (a NaN never passes). A missing
    metric whose name the report does not hold at all carries ``note``
    (:func:`unknown_metric`: a typo in the baseline, with the closest name); it still fails
    the check, since the report cannot show the baseline's figure holds.
    """
    validate_baseline(baseline)
    rows = []
    for path, base in baseline["metrics"].items():
        tol_entry = baseline.get("tolerances", {}).get(path)
        better, tol = (tol_entry["better"], tol_entry["tolerance"]) if tol_entry else TRACKED.get(path, ("higher", 0.0))
        current = lookup(metrics, path)
        if isinstance(current, bool) or not isinstance(current, (int, float)) or not math.isfinite(current):
            current, status = None, "missing"
        else:
            change = (current - base) if better == "higher" else (base - current)
            status = "worse" if change < -tol else "ok"
        row = {"metric": path, "baseline": float(base), "current": None if current is None else float(current),
               "direction": better, "tolerance": float(tol), "status": status}
        note = unknown_metric(metrics, path) if status == "missing" else None
        if note:
            row["note"] = note
        rows.append(row)
    return rows
