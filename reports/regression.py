"""Regression checks of metrics against a stored baseline, with per-metric tolerances."""
from __future__ import annotations

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
    "albedo.specular.ciede2000.median": ("lower", 0.5),
    "clusters.ari": ("higher", 0.02),
    "novel_views.psnr_srgb": ("higher", 0.5),
    "novel_views.ssim_srgb": ("higher", 0.01),
    "relighting.psnr_srgb": ("higher", 0.5),
    "mitsuba_cross_check.relative_l2": ("lower", 0.005),
}


def make_baseline(metrics: dict) -> dict:
    """A baseline from a metrics dict: the tracked values it has, with their tolerances."""
    values = {path: lookup(metrics, path) for path in TRACKED}
    values = {k: float(v) for k, v in values.items() if v is not None}
    return {"scene": metrics.get("scene"), "method": metrics.get("method"),
            "parameters": metrics.get("parameters"), "metrics": values,
            "tolerances": {k: {"better": TRACKED[k][0], "tolerance": TRACKED[k][1]} for k in values}}


def check(metrics: dict, baseline: dict) -> list[dict]:
    """Compare every metric of the baseline; a row per metric with status 'ok', 'worse' or 'missing'.

    A metric is worse when it moved in the bad direction by more than its
    tolerance (the baseline's own, else :data:`TRACKED`'s); missing when the
    current metrics lack it.
    """
    if "metrics" not in baseline:
        raise ValueError("baseline has no 'metrics' table")
    rows = []
    for path, base in baseline["metrics"].items():
        tol_entry = baseline.get("tolerances", {}).get(path)
        better, tol = (tol_entry["better"], tol_entry["tolerance"]) if tol_entry else TRACKED.get(path, ("higher", 0.0))
        current = lookup(metrics, path)
        if current is None:
            status = "missing"
        else:
            change = (current - base) if better == "higher" else (base - current)
            status = "worse" if change < -tol else "ok"
        rows.append({"metric": path, "baseline": float(base), "current": None if current is None else float(current),
                     "direction": better, "tolerance": float(tol), "status": status})
    return rows
