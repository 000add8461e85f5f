"""A report's content: the image sets, the metrics and the figures of one estimate
against one synthetic dataset's ground truth, and the columns of a comparison.

Everything here works on in-memory arrays; reading runs and datasets, the
Mitsuba renders (the truth under turned light, the estimate re-rendered) and
writing the report folder are the harness's (``harness.cli.reporting``).
"""
from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from estimator import Estimate, Predictor, View, axis_angle_matrix

from . import figures
from .evaluate import ImageSet, evaluate
from .ground_truth import GroundTruth
from .html import lookup

# relative L2 on pixels covered by one face, at the default 64 spp: measured 0.003 (earth-specular)
# and 0.022 (sparse-colored, Monte Carlo noise of the two signed envmap renders; 0.012 at 256 spp)
CROSS_CHECK_TOLERANCE = 0.03


@dataclass
class Renders:
    """Images rendered by Mitsuba for a report (RGBA (H, W, 4) per test view).

    relit : the ground-truth scene with its light turned by ``rotation``.
    estimate : the estimate's Mitsuba scene (None when skipped; ``estimate_note`` says why).
    estimate_twin : the same render with another seed (None: one render only); the cross-check
        compares their mean, and their difference measures its Monte Carlo noise.
    """

    rotation: tuple[str, float]
    relit: list[np.ndarray]
    estimate: list[np.ndarray] | None = None
    estimate_note: str = ""
    estimate_twin: list[np.ndarray] | None = None


@dataclass
class ReportContent:
    """What a report folder holds: metrics.json, ratios.npz and the figures.

    figures : (section, caption, draw) each; ``draw()`` returns the figure's PNG bytes. Figures
        are drawn only when the report is written with them (matplotlib takes most of a small
        report's time, which a sweep of many runs may skip).
    """

    metrics: dict
    ratios: dict
    figures: list[tuple[str, str, Callable[[], bytes]]] = field(default_factory=list)


def view_names(views: list[View]) -> list[str]:
    """Short names of views: their image file names without folder and extension."""
    return [os.path.splitext(os.path.basename(v.name))[0] for v in views]


def novel_views(predictor: Predictor, views: list[View], note: str = "",
                protocols: tuple[str, ...] = ()) -> tuple[ImageSet, float, list]:
    """The estimate's images of ``views`` against their recorded images, on the object pixels
    (alpha at least the estimator's ``min_coverage``) whose face the estimate covers, scored
    also by the named ``protocols`` (:mod:`reports.protocols`).

    Returns (the image set, the mean share of object pixels left unestimated, per view the
    (H, W) bool pixels of estimated faces)."""
    est = predictor.estimate
    cams = [v.camera for v in views]
    preds = [predictor.predict(c)[0] for c in cams]
    estimated = [(ids >= 0) & est.observed[np.maximum(ids, 0)] for ids in predictor.caster.face_id_buffers(cams)]
    obj = [(v.alpha if v.alpha is not None else np.ones(v.rgb.shape[:2])) >= est.config.min_coverage for v in views]
    unestimated = float(np.mean([1 - (o & e).sum() / max(o.sum(), 1) for o, e in zip(obj, estimated)]))
    images = ImageSet(view_names(views), preds, [v.rgb for v in views], [m & e for m, e in zip(obj, estimated)],
                      note=note, protocols=protocols)
    return images, unestimated, estimated


def cross_check_images(names: list[str], renders: list[np.ndarray], predictions: list[np.ndarray],
                       masks: list[np.ndarray], noise: list[float] | None) -> ImageSet:
    """The Mitsuba cross-check's image set: each view's render (H, W, 3) against the forward
    model's prediction on its ``masks`` (H, W) (pixels covered by one face alone), with the
    renders' relative ``noise`` per view (None: one render). A view with no such pixel (faces
    about a pixel or smaller) has nothing to compare: it is left out and the note counts it;
    with none left the set has no view and the report keeps the note alone."""
    kept = [k for k, m in enumerate(masks) if m.any()]
    note = "Mitsuba path tracer (2 bounces) vs the estimator's forward model, on pixels covered by one face alone"
    if len(kept) < len(masks):
        note += f"; {len(masks) - len(kept)} view(s) without such a pixel left out"
    return ImageSet([names[k] for k in kept], [renders[k] for k in kept], [predictions[k] for k in kept],
                    [masks[k] for k in kept], align=False, noise=None if noise is None else [noise[k] for k in kept],
                    note=note)


def assemble(predictor: Predictor, truth: GroundTruth, views: list[View], renders: Renders,
             header: dict, view_note: str = "", protocols: tuple[str, ...] = ()) -> ReportContent:
    """Compare an estimate (through its ``predictor``) with the ground truth.

    Images are compared on the object pixels whose face the estimate covers
    (coverage of at least the estimator's ``min_coverage``); the share of object
    pixels left unestimated is reported beside. ``header`` (scene, method, paths,
    versions) opens the metrics.
    """
    est: Estimate = predictor.estimate
    mesh = predictor.mesh
    min_coverage = est.config.min_coverage
    cams = [v.camera for v in views]
    names = view_names(views)
    novel, unestimated, estimated = novel_views(predictor, views, view_note, protocols)
    preds = novel.predictions

    axis, degrees = renders.rotation
    rot = axis_angle_matrix(axis, float(degrees))
    relit = ImageSet(names, [predictor.predict(c, rot)[0] for c in cams], [t[..., :3] for t in renders.relit],
                     [(t[..., 3] >= min_coverage) & e for t, e in zip(renders.relit, estimated)],
                     note=f"light turned {degrees} deg about {axis}", protocols=protocols)
    cross = None
    if renders.estimate is not None:
        pure = predictor.caster.face_id_buffers(cams, pure=True)
        masks = [(pu >= 0) & (r[..., 3] >= min_coverage) for pu, r in zip(pure, renders.estimate)]
        halves = [r[..., :3] for r in renders.estimate]
        renders_rgb, noise = halves, None
        if renders.estimate_twin is not None:
            twins = [t[..., :3] for t in renders.estimate_twin]
            renders_rgb = [0.5 * (a + b) for a, b in zip(halves, twins)]
            # the mean of two renders deviates from its expectation by |A - B| / 2 (same variance each)
            noise = [float(0.5 * np.linalg.norm((a - b)[m]) / max(np.linalg.norm(p[m]), 1e-300))
                     for a, b, p, m in zip(halves, twins, preds, masks)]
        cross = cross_check_images(names, renders_rgb, preds, masks, noise)
    elif renders.estimate_note:
        cross = ImageSet([], [], [], [], note=renders.estimate_note)

    ev = evaluate(mesh, truth, est, novel, relit, cross, CROSS_CHECK_TOLERANCE,
                  shadow=(predictor.sampling, predictor.visibility))
    m = {"schema": ev.metrics.pop("schema"), "schema_version": ev.metrics.pop("schema_version"), **header,
         "method": est.method, "parameters": est.config.to_dict(), **ev.metrics}
    for key in ("novel_views", "relighting"):
        if m.get(key):
            m[key]["unestimated_pixel_share"] = unestimated

    figs = [("Pseudo illumination", "estimated vs Phong-filtered ground truth (shared exposure)",
             partial(figures.illumination, est.pseudo_sh, ev.filtered_truth_sh)),
            ("Albedo", "estimated / true albedo per face (the paper's Fig. 5e)",
             partial(figures.ratio_histograms, ev.ratios))]
    present = {c: getattr(est, c) for c in ("specular", "diffuse") if lookup(m, f"albedo.{c}.present")}
    if present:
        figs.append(("Albedo", "texture maps: lat-long projection from the mesh centre",
                     partial(figures.texture_maps, predictor.caster, present,
                             {c: getattr(truth, c) for c in present})))
    figs.append(("Clusters", "faces coloured by cluster (grey: seen, not estimated)",
                 partial(figures.clusters, predictor.caster, cams[:3], est.labels, truth.regions)))
    for key, images, caption in (("Novel views", novel, "prediction (scaled per channel)"),
                                 ("Relighting", relit, "prediction, light rotated (scaled)"),
                                 ("Mitsuba cross-check", cross, "Mitsuba render of the estimate")):
        if images is not None and images.names:
            figs.append((key, images.note or key, partial(
                figures.image_comparison, images.names[:3], images.predictions[:3], images.references[:3],
                images.masks[:3], caption)))
    return ReportContent(m, ev.ratios, figs)


IDENTITY_COLUMNS = [("scene", "scene"), ("method", "method"), ("sweep values", "sweep_values"), ("seed", "seed"),
                    ("components", "components")]
COMPARE_COLUMNS = IDENTITY_COLUMNS + [
    ("SH rel. L2", "illumination.relative_l2"),
    ("spec ±10 % (DC)", "albedo.specular.dc.luminance.within_10"),
    ("spec median", "albedo.specular.dc.luminance.median_ratio"),
    ("spec ±10 % (lstsq)", "albedo.specular.lstsq.luminance.within_10"),
    ("diff ±10 % (DC)", "albedo.diffuse.dc.luminance.within_10"),
    ("diff ±10 % (lstsq)", "albedo.diffuse.lstsq.luminance.within_10"),
    ("diff ±10 % (robust)", "albedo.diffuse.robust.luminance.within_10"),
    ("diff median |err| (median gauge)", "diffuse_median_abs_error"),
    ("ARI", "clusters.ari"), ("clusters", "clusters.clusters"),
    ("novel PSNR sRGB", "novel_views.psnr_srgb"), ("relit PSNR sRGB", "relighting.psnr_srgb"),
]


def sweep_values(axes: dict) -> str:
    """A sweep row's axis values as one short text: 'views=6, sh_order=4'."""
    return ", ".join(f"{k}={json.dumps(v) if isinstance(v, (list, dict)) else v}" for k, v in axes.items())


def compare_row(metrics: dict, ratios: dict, folder: str, tag: dict | None = None) -> dict:
    """One row of the comparison table from a report's metrics and its DC-gauge ratios
    (component -> (n, 4) array, luminance in column 3). ``tag``: the run's place in a sweep
    (its method label, axes and seed), which its report does not know."""
    tag = tag or {}
    row = {"folder": folder, "scene": metrics.get("scene"), "method": tag.get("label") or metrics.get("method"),
           "sweep_values": sweep_values(tag["axes"]) if tag.get("axes") else None, "seed": tag.get("seed"),
           "components": (metrics.get("parameters") or {}).get("components")}
    for _, key in COMPARE_COLUMNS[len(IDENTITY_COLUMNS):]:
        if key != "diffuse_median_abs_error":
            row[key] = lookup(metrics, key)
    row["diffuse_median_abs_error"] = None
    if "diffuse" in ratios:
        lum = ratios["diffuse"][:, 3]
        lum = lum[np.isfinite(lum)]
        if lum.size:
            row["diffuse_median_abs_error"] = float(np.median(np.abs(lum / np.median(lum) - 1)))
    return row


def run_label(row: dict) -> str:
    """A comparison row's name in a legend: its method, and its sweep values and seed when
    it has them (runs of one method that differ only there must not look alike)."""
    parts = [str(row.get("method"))] + [str(row[k]) for k in ("sweep_values",) if row.get(k)]
    return " · ".join(parts + ([f"seed {row['seed']}"] if row.get("seed") is not None else []))


def compare_figures(entries: list[tuple[dict, dict]], labels: list[str] | None = None) -> list[tuple[str, bytes]]:
    """Overlaid ratio histograms per (scene, component) over (metrics, ratios) pairs, each
    named by its entry of ``labels`` (default: its method), and per scene the diffuse albedo
    error against estimate time (a point per run, a curve for a method that records its
    albedo over time)."""
    hist: dict = {}
    timing: dict = {}
    labels = labels or [str(m.get("method")) for m, _ in entries]
    for (metrics, ratios), label in zip(entries, labels):
        for comp, r in ratios.items():
            hist.setdefault((metrics.get("scene"), comp), []).append((label, r[:, 3]))
        point = error_against_time(metrics)
        if point is not None:
            timing.setdefault(metrics.get("scene"), []).append(point)
    out = [(f"{scene}: {comp} albedo ratios", figures.compare_histograms(runs, comp))
           for (scene, comp), runs in sorted(hist.items(), key=lambda kv: str(kv[0]))]
    out += [(f"{scene}: diffuse albedo PSNR against estimate time", figures.error_against_time(runs))
            for scene, runs in sorted(timing.items(), key=lambda kv: str(kv[0]))]
    return out


def error_against_time(metrics: dict) -> dict | None:
    """(method, seconds, PSNR, curve) of a report: the estimate's total time and diffuse
    PSNR (least-squares scale), with the snapshots' (seconds, PSNR) when recorded; None
    without a diffuse albedo or a time."""
    psnr = lookup(metrics, "albedo.diffuse.psnr_lstsq")
    seconds = lookup(metrics, "estimate_timings.total")
    if psnr is None or seconds is None:
        return None
    history = lookup(metrics, "albedo.diffuse.psnr_history") or {}
    curve = [(t, p) for t, p in zip(history.get("seconds", []), history.get("psnr_lstsq", [])) if p is not None]
    return {"method": metrics.get("method"), "seconds": float(seconds), "psnr": float(psnr), "curve": curve}


def text_table(rows: list[dict], cols: list[tuple[str, str]] = COMPARE_COLUMNS) -> list[str]:
    """Rows as plain-text lines under the columns (label, key), one per row plus the header."""
    cells = [[label for label, _ in cols]] + [
        ["-" if r.get(k) is None else (f"{r[k]:.3f}" if isinstance(r[k], float) else str(r[k])) for _, k in cols]
        for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(cols))]
    return ["  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in cells]
