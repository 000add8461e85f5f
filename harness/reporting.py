"""`pseudolight report` and `pseudolight compare`: reading runs, rendering what the
comparison needs (ground truth under rotated light, the estimate through Mitsuba),
and writing the report folder atomically."""
from __future__ import annotations

import json
import os
import time

import numpy as np

from estimator.forward import Predictor
from estimator.sh import axis_angle_matrix
from reports import figures
from reports.evaluate import ImageSet, evaluate
from reports.html import compare_page, lookup, report_page, terminal_summary
from reports.regression import check

from .atomic import atomic_directory
from .dataset import read_dataset
from .mitsuba_export import export_scene, render_estimate
from .relight import render_truth
from .runs import RunError, read_run, versions

# relative L2 on pixels covered by one face, at the default 64 spp: measured 0.003 (earth-specular)
# and 0.022 (sparse-colored, Monte Carlo noise of the two signed envmap renders; 0.012 at 256 spp)
CROSS_CHECK_TOLERANCE = 0.03


def build_report(run_dir: str, out_dir: str, dataset_dir: str | None = None, rotation=("y", 90.0),
                 cross_check_spp: int | None = None, mitsuba: bool = True, baseline: dict | None = None,
                 overwrite: bool = False, log=print) -> tuple[dict, list[dict] | None]:
    """Evaluate a run against its dataset's ground truth and write the report folder.

    Images are compared on the object pixels whose face the estimate covers;
    the share of object pixels left unestimated is reported beside.
    ``cross_check_spp`` defaults to 64 (512 for ``specular_model='lobe'``, whose
    radiance environment makes the Phong-lobe render noisier).

    Returns (metrics, regression rows or None).
    """
    t0 = time.perf_counter()
    est, run = read_run(run_dir)
    ds = read_dataset(dataset_dir or run["dataset"])
    if ds.ground_truth is None:
        raise ValueError(f"{ds.path} has no ground_truth/: a report compares with ground truth")
    if ds.data.mesh.num_faces != est.diffuse.shape[0]:
        raise ValueError(f"the run has {est.diffuse.shape[0]} faces, the dataset's mesh {ds.data.mesh.num_faces}")
    mesh = ds.data.mesh
    predictor = Predictor(mesh, est)
    views = ds.data.test_views or ds.data.views[:2]
    view_note = "" if ds.data.test_views else "the dataset has no test_frames: training views 0-1 used"
    cams = [v.camera for v in views]
    names = [os.path.splitext(os.path.basename(v.name))[0] for v in views]
    preds = [predictor.predict(c) for c in cams]
    estimated = [(ids >= 0) & est.observed[np.maximum(ids, 0)] for ids in predictor.caster.face_id_buffers(cams)]
    obj = [(v.alpha if v.alpha is not None else np.ones(v.rgb.shape[:2])) > 0.999 for v in views]
    unestimated = float(np.mean([1 - (o & e).sum() / max(o.sum(), 1) for o, e in zip(obj, estimated)]))
    novel = ImageSet(names, [p for p, _ in preds], [v.rgb for v in views],
                     [m & e for m, e in zip(obj, estimated)], note=view_note)

    rot = axis_angle_matrix(rotation[0], float(rotation[1]))
    log(f"rendering the ground truth with the light turned {rotation[1]} deg about {rotation[0]}")
    truth_relit = render_truth(ds, cams, rot)
    relit_preds = [predictor.predict(c, rot) for c in cams]
    relit = ImageSet(names, [p for p, _ in relit_preds], [t[..., :3] for t in truth_relit],
                     [(t[..., 3] > 0.999) & e for t, e in zip(truth_relit, estimated)],
                     note=f"light turned {rotation[1]} deg about {rotation[0]}")

    cross = None
    cross_check_spp = cross_check_spp or (512 if est.config.specular_model == "lobe" else 64)
    if mitsuba:
        try:
            log(f"rendering the estimate through Mitsuba ({cross_check_spp} spp)")
            rendered = render_estimate(mesh, est, cams, cross_check_spp)
            pure = predictor.caster.face_id_buffers(cams, pure=True)
            cross = ImageSet(names, [r[..., :3] for r in rendered], [p for p, _ in preds],
                             [(pu >= 0) & (r[..., 3] > 0.999) for pu, r in zip(pure, rendered)], align=False,
                             note="Mitsuba path tracer (2 bounces) vs the estimator's forward model, "
                                  "on pixels covered by one face alone")
        except ValueError as exc:
            cross = ImageSet([], [], [], [], note=f"skipped: {exc}")

    ev = evaluate(mesh, ds.ground_truth, est, novel, relit, cross, CROSS_CHECK_TOLERANCE)
    m = {"schema": ev.metrics.pop("schema"), "schema_version": ev.metrics.pop("schema_version"),
         "scene": ds.meta.get("scene", os.path.basename(ds.path)), "method": est.method,
         "parameters": est.config.to_dict(), "dataset": ds.path, "run": os.path.abspath(run_dir),
         "versions": versions(), "estimate_timings": run.get("timings"), **ev.metrics}
    for key in ("novel_views", "relighting"):
        if m.get(key):
            m[key]["unestimated_pixel_share"] = unestimated
    regressions = check(m, baseline) if baseline is not None else None

    figs = [("Pseudo illumination", "estimated vs Phong-filtered ground truth (shared exposure)",
             figures.illumination(est.sh, ev.filtered_truth_sh)),
            ("Albedo", "estimated / true albedo per face (the paper's Fig. 5e)", figures.ratio_histograms(ev.ratios))]
    present = {c: getattr(est, c) for c in ("specular", "diffuse") if lookup(m, f"albedo.{c}.present")}
    if present:
        figs.append(("Albedo", "texture maps: lat-long projection from the mesh centre",
                     figures.texture_maps(predictor.caster, present, {c: getattr(ds.ground_truth, c) for c in present})))
    figs.append(("Clusters", "faces coloured by cluster (grey: seen, not estimated)",
                 figures.clusters(predictor.caster, cams[:3], est.labels, ds.ground_truth.regions)))
    for key, images, caption in (("Novel views", novel, "prediction (scaled per channel)"),
                                 ("Relighting", relit, "prediction, light rotated (scaled)"),
                                 ("Mitsuba cross-check", cross, "Mitsuba render of the estimate")):
        if images is not None and images.names:
            figs.append((key, images.note or key, figures.image_comparison(
                images.names[:3], images.predictions[:3], images.references[:3], images.masks[:3], caption)))
    m["report_seconds"] = time.perf_counter() - t0

    with atomic_directory(out_dir, overwrite=overwrite) as tmp:
        with open(os.path.join(tmp, "metrics.json"), "w") as f:
            json.dump(m, f, indent=1)
        np.savez(os.path.join(tmp, "ratios.npz"), **{k: v for k, v in ev.ratios.items()})
        for index, (section, _, png) in enumerate(figs):
            with open(os.path.join(tmp, f"fig{index:02d}_{section.lower().replace(' ', '_')}.png"), "wb") as f:
                f.write(png)
        with open(os.path.join(tmp, "report.html"), "w") as f:
            f.write(report_page(m, figs, regressions))
        try:
            export_scene(os.path.join(tmp, "mitsuba"), mesh, est, cams[0])
        except ValueError:
            pass  # the estimate's model has no single-environment Mitsuba equivalent (see metrics)
    return m, regressions


def find_metrics(folder: str) -> str:
    """metrics.json of a report folder, or of RUN/report."""
    for candidate in (os.path.join(folder, "metrics.json"), os.path.join(folder, "report", "metrics.json")):
        if os.path.isfile(candidate):
            return candidate
    raise RunError(f"{folder} has no metrics.json (nor report/metrics.json): run `pseudolight report` first")


COMPARE_COLUMNS = [
    ("scene", "scene"), ("method", "method"), ("components", "components"),
    ("SH rel. L2", "illumination.relative_l2"),
    ("spec ±10 % (DC)", "albedo.specular.dc.luminance.within_10"),
    ("spec median", "albedo.specular.dc.luminance.median_ratio"),
    ("spec ±10 % (lstsq)", "albedo.specular.lstsq.luminance.within_10"),
    ("diff ±10 % (DC)", "albedo.diffuse.dc.luminance.within_10"),
    ("diff ±10 % (lstsq)", "albedo.diffuse.lstsq.luminance.within_10"),
    ("diff median |err| (lstsq)", "diffuse_median_abs_error"),
    ("ARI", "clusters.ari"), ("clusters", "clusters.clusters"),
    ("novel PSNR sRGB", "novel_views.psnr_srgb"), ("relit PSNR sRGB", "relighting.psnr_srgb"),
]


def compare_runs(folders: list[str], out_dir: str, overwrite: bool = False) -> list[dict]:
    """compare.json + compare.html over several reports (methods x scenes)."""
    rows, hist = [], {}
    for folder in folders:
        path = find_metrics(folder)
        with open(path) as f:
            m = json.load(f)
        row = {"folder": os.path.abspath(folder), "scene": m.get("scene"), "method": m.get("method"),
               "components": (m.get("parameters") or {}).get("components")}
        for _, key in COMPARE_COLUMNS[3:]:
            if key != "diffuse_median_abs_error":
                row[key] = lookup(m, key)
        ratios = np.load(os.path.join(os.path.dirname(path), "ratios.npz"))
        if "diffuse" in ratios:
            lum = ratios["diffuse"][:, 3]
            lum = lum[np.isfinite(lum)]
            row["diffuse_median_abs_error"] = float(np.median(np.abs(lum / np.median(lum) - 1))) if lum.size else None
        for comp in ratios.files:
            hist.setdefault((m.get("scene"), comp), []).append((m.get("method"), ratios[comp][:, 3]))
        rows.append(row)
    figs = [(f"{scene}: {comp} albedo ratios", figures.compare_histograms(entries, comp))
            for (scene, comp), entries in sorted(hist.items(), key=lambda kv: str(kv[0]))]
    with atomic_directory(out_dir, overwrite=overwrite) as tmp:
        with open(os.path.join(tmp, "compare.json"), "w") as f:
            json.dump({"columns": COMPARE_COLUMNS, "rows": rows}, f, indent=1)
        with open(os.path.join(tmp, "compare.html"), "w") as f:
            f.write(compare_page(rows, COMPARE_COLUMNS, figs))
    return rows


def print_table(rows: list[dict], log=print) -> None:
    """The comparison as a plain-text table."""
    cols = COMPARE_COLUMNS
    cells = [[label for label, _ in cols]] + [
        ["-" if r.get(k) is None else (f"{r[k]:.3f}" if isinstance(r[k], float) else str(r[k])) for _, k in cols]
        for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(cols))]
    for row in cells:
        log("  ".join(c.ljust(w) for c, w in zip(row, widths)))


__all__ = ["build_report", "compare_runs", "print_table", "terminal_summary"]
