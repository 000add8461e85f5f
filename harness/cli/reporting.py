"""`pseudolight report` and `pseudolight compare`: reading runs and datasets, the Mitsuba
renders a report needs (ground truth under turned light, the estimate re-rendered),
and writing the report and comparison folders atomically. The content (metrics,
figures, columns) is :mod:`reports.report`'s."""
from __future__ import annotations

import os
import time

import numpy as np

from estimator import InputError, NoMitsubaEquivalent, Predictor, axis_angle_matrix, multijitter_count
from harness.io.atomic import atomic_directory, check_output
from harness.io.dataset import fingerprint, read_dataset
from harness.io.jsonio import dump_json, load_json
from harness.io.runs import RunError, read_run, versions
from harness.scene.export import export_scene, render_estimate
from harness.scene.relight import render_truth
from reports.html import compare_page, lookup, report_page
from reports.protocols import PROTOCOLS
from reports.regression import check
from reports.report import (
    COMPARE_COLUMNS,
    IDENTITY_COLUMNS,
    Renders,
    assemble,
    compare_figures,
    compare_row,
    novel_views,
    run_label,
    text_table,
)
from reports.selfcheck import self_check


def open_run(run_dir: str, dataset_dir: str | None, out_dir: str, overwrite: bool, load_test: bool = True,
             load_truth: bool = False, match: tuple[str, ...] = ("mesh",), check_fingerprint: bool = True,
             kind: str = "report"):
    """(estimate, run.json, dataset, inputs) of a run and the dataset it is read against
    (default: the one it was made from), after checking that ``out_dir`` touches none of
    their files and that the run was estimated from this dataset's ``match`` (of the run's
    fingerprint: 'mesh', 'cameras', 'images'; a mesh with the same face count but another face
    order would put each albedo on the wrong face). A run without a fingerprint is refused
    unless ``check_fingerprint`` is False (``--no-fingerprint-check``). ``kind``: what the
    command writes to ``out_dir`` (:func:`harness.io.atomic.check_output`)."""
    est, run = read_run(run_dir)
    dataset_dir = dataset_dir or run["dataset"]
    check_output(out_dir, [run_dir, dataset_dir], overwrite)
    ds = read_dataset(dataset_dir, load_test=load_test, load_truth=load_truth)
    inputs = [run_dir, *ds.inputs]
    check_output(out_dir, inputs, overwrite, kind=kind)   # the mesh and images may lie outside the dataset folder
    if ds.data.mesh.num_faces != est.diffuse.shape[0]:
        raise InputError(f"the run {run_dir} has {est.diffuse.shape[0]} faces, the mesh of {ds.path} "
                         f"{ds.data.mesh.num_faces}")
    if check_fingerprint:
        recorded = run.get("fingerprint")
        if not isinstance(recorded, dict) or any(not isinstance(recorded.get(k), str) for k in match):
            raise InputError(f"the run {run_dir} records no (or an incomplete) fingerprint of the dataset it was "
                             "estimated from, so "
                             f"nothing shows that {ds.path} is that dataset; pass --no-fingerprint-check to read "
                             "it against this dataset anyway")
        current = fingerprint(ds.data)
        differ = [k for k in match if recorded.get(k) != current[k]]
        if differ:
            raise InputError(f"the run {run_dir} was estimated from {run['dataset']}, whose {', '.join(differ)} "
                             f"{'differs' if len(differ) == 1 else 'differ'} from {ds.path}'s: use it with its own "
                             "dataset")
    return est, run, ds, inputs


def _size(size: dict) -> str:
    return f"{size.get('faces')} faces, {size.get('views')} views of {size.get('width')}x{size.get('height')}"


def build_report(run_dir: str, out_dir: str, dataset_dir: str | None = None, rotation=("y", 90.0),
                 cross_check_spp: int | None = None, mitsuba: bool = True, baseline: dict | None = None,
                 overwrite: bool = False, log=print, check_fingerprint: bool = True,
                 protocols: tuple[str, ...] = tuple(PROTOCOLS), figures: bool = True
                 ) -> tuple[dict, list[dict] | None]:
    """Evaluate a run against its dataset's ground truth and write the report folder.

    ``figures=False`` writes the metrics, ratios and page without the figures (matplotlib
    takes most of a small report's time; a sweep of many runs may skip them).

    ``protocols``: the published benchmarks' metric sets to add to the novel-view and
    relighting figures (:mod:`reports.protocols`; all by default).

    ``cross_check_spp`` defaults to 64 (512 for a radiance model, whose Phong-lobe
    render of the radiance environment is noisier).

    Returns (metrics, regression rows or None).
    """
    t0 = time.perf_counter()
    est, run, ds, inputs = open_run(run_dir, dataset_dir, out_dir, overwrite, load_truth=True,
                                    match=("mesh", "cameras", "images"), check_fingerprint=check_fingerprint)
    mesh = ds.data.mesh
    predictor = Predictor(mesh, est)
    check_metrics, check_figures = self_check(predictor, ds.data.views, run, est)
    first = ds.data.views[0].camera
    header = {"scene": ds.meta.get("scene", os.path.basename(ds.path)), "dataset": ds.path,
              "dataset_size": {"faces": int(mesh.num_faces), "views": len(ds.data.views), "width": int(first.width),
                               "height": int(first.height)},
              "run": os.path.abspath(run_dir), "versions": versions(), "estimate_timings": run.get("timings")}
    if ds.ground_truth is None:
        novel = None
        if ds.data.test_views:   # a real capture's held-out frames are scored without any truth
            images, unestimated, _ = novel_views(predictor, ds.data.test_views,
                                                 "the dataset's test frames (no ground truth)", protocols)
            novel = {**images.metrics(), "unestimated_pixel_share": unestimated}
        log(f"{ds.path} has no ground_truth/: writing the self-check report"
            + (f" and scoring its {len(ds.data.test_views)} test frame(s)" if novel else " only (no test frames)"))
        drawn = _draw(check_figures) if figures else None
        m = {**header, "method": est.method, "ground_truth": None, "self_check": check_metrics,
             "novel_views": novel, "report_seconds": time.perf_counter() - t0}
        _write_report(out_dir, overwrite, inputs, m, None, drawn, None)
        return m, None
    views = ds.data.test_views or ds.data.views[:2]
    view_note = "" if ds.data.test_views else "the dataset has no test_frames: training views 0-1 used"
    cams = [v.camera for v in views]

    log(f"rendering the ground truth with the light turned {rotation[1]} deg about {rotation[0]}")
    renders = Renders(rotation, render_truth(ds, cams, axis_angle_matrix(rotation[0], float(rotation[1]))))
    if mitsuba:
        spp = cross_check_spp or (512 if est.model.light == "radiance" else 64)
        try:
            half = multijitter_count(max(1, spp // 2))   # two seeds: their difference measures the render's noise
            log(f"rendering the estimate through Mitsuba ({2 * half} spp, as two independent halves)")
            renders.estimate = render_estimate(mesh, est, cams, half, seed=7)
            renders.estimate_twin = render_estimate(mesh, est, cams, half, seed=8)
        except NoMitsubaEquivalent as exc:
            renders.estimate_note = f"skipped: {exc}"

    content = assemble(predictor, ds.ground_truth, views, renders, header, view_note, protocols)
    m = content.metrics
    m["self_check"] = check_metrics
    regressions = None
    if baseline is not None:
        made_at = baseline.get("dataset_size")
        if made_at is not None and made_at != m["dataset_size"]:
            log(f"baseline made on a dataset of {_size(made_at)}; this one is {_size(m['dataset_size'])}: not "
                "compared (a baseline holds at the size it was made; --write-baseline makes one at this size)")
            m["baseline"] = {"compared": False, "made_at": made_at}
        else:
            regressions = check(m, baseline)
    drawn = _draw(content.figures + check_figures) if figures else None
    m["report_seconds"] = time.perf_counter() - t0
    _write_report(out_dir, overwrite, inputs, m, content.ratios, drawn, regressions,
                  lambda folder: export_scene(folder, mesh, est, cams[0]))
    return m, regressions


def _draw(figs) -> list[tuple[str, str, bytes]]:
    """The figures (section, caption, draw) as (section, caption, PNG bytes)."""
    return [(section, caption, draw()) for section, caption, draw in figs]


def _write_report(out_dir, overwrite, inputs, metrics, ratios, drawn, regressions, export=None) -> None:
    """The report folder, atomically: metrics.json, ratios.npz (with ground truth), the
    figures as PNG (``drawn``: (section, caption, PNG bytes) each; None: not drawn),
    report.html, and the estimate as a Mitsuba scene when ``export`` is given."""
    with atomic_directory(out_dir, overwrite=overwrite, inputs=inputs, kind="report") as tmp:
        dump_json(os.path.join(tmp, "metrics.json"), metrics)
        if ratios is not None:
            np.savez(os.path.join(tmp, "ratios.npz"), **ratios)
        for index, (section, _, png) in enumerate(drawn or []):
            with open(os.path.join(tmp, f"fig{index:02d}_{section.lower().replace(' ', '_')}.png"), "wb") as f:
                f.write(png)
        with open(os.path.join(tmp, "report.html"), "w") as f:
            f.write(report_page(metrics, drawn, regressions))
        if export is not None:
            try:
                export(os.path.join(tmp, "mitsuba"))
            except NoMitsubaEquivalent:
                pass  # the estimate's model has no single-environment Mitsuba equivalent (see metrics)


def find_metrics(folder: str) -> str:
    """metrics.json of a report folder, or of RUN/report."""
    for candidate in (os.path.join(folder, "metrics.json"), os.path.join(folder, "report", "metrics.json")):
        if os.path.isfile(candidate):
            return candidate
    if not os.path.isdir(folder):
        raise RunError(f"report folder not found: {folder}")
    raise RunError(f"{folder} has no metrics.json (nor report/metrics.json): run `pseudolight report` first")


# the numbers a comparison reads from each report: its columns and its error against time
# (the median error column comes from ratios.npz, not from the metrics)
COMPARED_NUMBERS = tuple(key for _, key in COMPARE_COLUMNS[len(IDENTITY_COLUMNS):]
                         if key != "diffuse_median_abs_error") + ("albedo.diffuse.psnr_lstsq", "estimate_timings.total")


def check_metrics_format(metrics, path: str) -> dict:
    """``metrics`` as read from ``path``, refused (:class:`RunError`) when it is not a report's
    metrics table or was written by a newer pseudolight (another schema version): it must name
    its method, its scene must be a scalar (the dataset's name for it) or null, the objects a
    comparison reads objects, and every number it reads (:data:`COMPARED_NUMBERS`, the PSNR
    history) a number or null where present."""
    from reports.evaluate import SCHEMA, SCHEMA_VERSION

    if not isinstance(metrics, dict):
        raise RunError(f"{path}: not a report's metrics (a JSON object is expected)")
    if metrics.get("schema", SCHEMA) != SCHEMA:
        raise RunError(f"{path}: schema {metrics['schema']!r} is not {SCHEMA!r}")
    version = metrics.get("schema_version", SCHEMA_VERSION)
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= SCHEMA_VERSION:
        raise RunError(f"{path}: schema_version {version!r} is not one this pseudolight reads (1 to {SCHEMA_VERSION})")
    if not isinstance(metrics.get("method"), str):
        raise RunError(f"{path}: 'method' must name the method (a string), got {metrics.get('method')!r}")
    if isinstance(metrics.get("scene"), (list, dict)):   # a dataset's scene name is whatever JSON scalar it holds
        raise RunError(f"{path}: 'scene' must be a name (a string, a number or null), got {metrics['scene']!r}")
    for key in ("parameters", "estimate_timings"):
        if not isinstance(metrics.get(key), (dict, type(None))):
            raise RunError(f"{path}: '{key}' must be an object or null, got {str(metrics[key])[:60]!r}")
    for dotted in COMPARED_NUMBERS:
        node = metrics
        for depth, key in enumerate(dotted.split(".")):
            if node is None or key not in node:
                break   # a section the report has not (a run without relighting): shown as '-'
            node = node[key]
            inner = depth < dotted.count(".")
            if inner and not isinstance(node, (dict, type(None))):
                raise RunError(f"{path}: '{'.'.join(dotted.split('.')[:depth + 1])}' must be an object or null, "
                               f"got {node!r}")
            if not inner and not _number_or_null(node):
                raise RunError(f"{path}: '{dotted}' must be a number or null, got {node!r}")
    history = lookup(metrics, "albedo.diffuse.psnr_history")   # its parents are objects or null by now
    if history is not None and not (isinstance(history, dict) and all(
            isinstance(history.get(k, []), list) and all(map(_number_or_null, history.get(k, [])))
            for k in ("seconds", "psnr_lstsq"))):
        raise RunError(f"{path}: 'albedo.diffuse.psnr_history' must hold lists of numbers under 'seconds' and "
                       f"'psnr_lstsq', got {str(history)[:60]!r}")
    return metrics


def _number_or_null(value) -> bool:
    """A JSON number (not a boolean) or null."""
    return value is None or type(value) in (int, float)


def compare_runs(folders: list[str], out_dir: str, overwrite: bool = False,
                 tags: list[dict] | None = None) -> list[dict]:
    """compare.json + compare.html over several reports (methods x scenes); ``tags``: per
    folder its place in a sweep (label, axes, seed), shown in its row."""
    entries, rows = [], []
    for folder, tag in zip(folders, tags or [None] * len(folders)):
        path = find_metrics(folder)
        metrics = check_metrics_format(load_json(path, "report metrics", RunError), path)
        ratios_path = os.path.join(os.path.dirname(path), "ratios.npz")
        ratios = {}
        if os.path.exists(ratios_path):   # a report without ground-truth albedos writes none
            try:
                with np.load(ratios_path, allow_pickle=False) as archive:
                    ratios = {k: archive[k] for k in archive.files}
            except (OSError, ValueError, EOFError):
                raise RunError(f"{ratios_path}: unreadable (not a .npz archive)") from None
            for key, value in ratios.items():
                if value.ndim != 2 or value.shape[1] != 4 or not np.issubdtype(value.dtype, np.number):
                    raise RunError(f"{ratios_path}: '{key}' must be (n, 4) numbers (RGB and luminance ratios), "
                                   f"got {value.dtype} {value.shape}")
        entries.append((metrics, ratios))
        rows.append(compare_row(metrics, ratios, os.path.abspath(folder), tag))
    figs = compare_figures(entries, [run_label(r) for r in rows])
    with atomic_directory(out_dir, overwrite=overwrite, inputs=folders, kind="compare") as tmp:
        dump_json(os.path.join(tmp, "compare.json"), {"columns": COMPARE_COLUMNS, "rows": rows})
        with open(os.path.join(tmp, "compare.html"), "w") as f:
            f.write(compare_page(rows, COMPARE_COLUMNS, figs))
    return rows


def print_table(rows: list[dict], log=print) -> None:
    """The comparison as a plain-text table."""
    for line in text_table(rows):
        log(line)
