"""Run a suite: generate each distinct dataset once, run every method on it, report each
run, and write the comparison with one plot per sweep axis. Jobs are cached by identity
(``harness.sweep.jobs``): an interrupted sweep resumes, a finished one does no work.

Layout: OUT/datasets/SCENE-ID/, OUT/runs/SCENE-ID-LABEL/{run,report,job.json},
OUT/compare/{compare.html,compare.json,sweep.html,sweep.json}; each row of sweep.json names its
run folder relative to OUT/compare. The folder's marker names the suite, so a second suite is
refused rather than replacing the first's comparison.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import time

from tqdm import tqdm

from estimator import InputError, backend
from harness.cli.reporting import compare_runs
from harness.io.atomic import OutputError
from harness.sweep.executor import run_jobs, worker_threads
from harness.sweep.jobs import dataset_job, dataset_payload, identity, run_job
from reports import sweep as sweep_report


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-") or "x"


def plan(suite: dict, out_dir: str, mitsuba: bool = False, force: bool = False, variant: str | None = None,
         threads: int | None = None, figures: bool = True) -> tuple[list[dict], list[dict]]:
    """(dataset jobs, run jobs) of a suite as plain dicts with identities and folders. A run's
    identity holds whether its report holds the Mitsuba cross-check; ``figures`` is carried
    beside it (figures change no metric: a run reported with them serves a sweep without)."""
    datasets, runs = [], []
    for d in suite["datasets"]:
        did = identity(dataset_payload(d))
        folder = os.path.join(out_dir, "datasets", f"{_slug(d.scene)}-{did}")
        datasets.append({"id": did, "folder": folder, "scene": d.scene, "spec_path": d.spec_path,
                         "profile": d.profile, "overrides": d.overrides, "axes": d.axes, "seed": d.seed,
                         "force": force, "variant": variant, "threads": threads})
        for m in suite["methods"]:
            rid = identity({"dataset": did, "method": m.method, "params": m.params, "mitsuba": mitsuba})
            runs.append({"id": rid, "folder": os.path.join(out_dir, "runs", f"{_slug(d.scene)}-{did}-{_slug(m.label)}"),
                         "dataset": folder, "scene": d.scene, "axes": d.axes, "seed": d.seed, "label": m.label,
                         "method": m.method, "params": m.params, "mitsuba": mitsuba, "figures": figures, "force": force,
                         "variant": variant, "threads": threads})
    folders: dict[str, str] = {}
    for r in runs:
        if folders.setdefault(r["folder"], r["label"]) != r["label"]:
            raise InputError(f"method labels {folders[r['folder']]!r} and {r['label']!r} map to the same run folder "
                             f"{os.path.basename(r['folder'])}; give them labels that differ in letters or digits")
    unique = {j["id"]: j for j in datasets}   # two sweep points may resolve to one spec
    unique_runs = {r["id"]: r for r in runs}
    return list(unique.values()), list(unique_runs.values())


def _execute(fn, jobs, what, executor, workers, scheduler, log, gpus=0) -> dict[str, dict]:
    results, failed = {}, []
    with tqdm(total=len(jobs), desc=what, unit="job", disable=None) as bar:
        for job, result in run_jobs(fn, jobs, executor, workers, scheduler, gpus):
            bar.update(1)
            name = os.path.basename(job["folder"])
            if isinstance(result, BaseException):
                failed.append(name)
                log(f"{what} {name}: FAILED: {type(result).__name__}: {result}")
                continue
            results[job["id"]] = result
            state = "reused" if result.get("reused") else f"done in {result['seconds']:.1f} s"
            log(f"{what} {name}: {state}")
    if failed:
        raise InputError(f"{len(failed)} {what} job(s) failed: {', '.join(failed[:5])}; finished jobs are kept, "
                         "run the suite again to resume")
    return results


SWEEP_MARKER = ".pseudolight-sweep"   # a sweep folder: its cache of jobs may be resumed and its files replaced


def claim_sweep_folder(out_dir: str, suite_name: str) -> bool:
    """Make ``out_dir`` the sweep folder of suite ``suite_name``, or refuse it: it must be new,
    empty, or that suite's sweep folder already (it holds :data:`SWEEP_MARKER`, which names the
    suite): a folder of the user's is never written into, and another suite's comparison is not
    replaced. Returns whether the folder was made here (it did not exist): an interrupted first
    run removes it again (:func:`release_sweep_folder`)."""
    root = os.path.abspath(out_dir)
    marker = os.path.join(root, SWEEP_MARKER)
    made = not os.path.lexists(root)
    if not made:
        if not os.path.isdir(root) or os.path.islink(root):
            raise OutputError(f"sweep output {root} exists and is not a folder")
        if os.listdir(root) and not os.path.exists(marker):
            raise OutputError(f"refusing to write the sweep into {root}: it is not empty and was not made by "
                              f"pseudolight bench (no {SWEEP_MARKER}); choose another -o")
        if os.path.exists(marker):
            with open(marker) as f:
                named = [line[len("suite: "):].strip() for line in f if line.startswith("suite: ")]
            if named and named[0] != suite_name:
                raise OutputError(f"refusing to write suite {suite_name!r} into {root}: it holds the sweep of suite "
                                  f"{named[0]!r}, whose comparison it would replace; choose another -o")
    try:
        os.makedirs(root, exist_ok=True)
        with open(marker, "w") as f:
            f.write(f"pseudolight sweep folder: cached jobs, runs, reports and the comparison\nsuite: {suite_name}\n")
    except OSError as exc:
        raise OutputError(f"cannot write the sweep into {root}: {exc.strerror or exc}") from None
    return made


def release_sweep_folder(out_dir: str) -> None:
    """Remove a sweep folder that holds no file but its marker (a first run stopped before any
    job finished: the jobs' own folders are written atomically, so what an interrupted one
    leaves is empty folders), so that an interrupted sweep leaves no folder behind."""
    root = os.path.abspath(out_dir)
    try:
        files = [name for _, _, names in os.walk(root) for name in names]
        if files == [SWEEP_MARKER]:
            shutil.rmtree(root)
    except OSError:
        pass


def run_sweep(suite: dict, out_dir: str, executor: str = "local", workers: int = 1, scheduler: str | None = None,
              force: bool = False, mitsuba: bool = False, variant: str | None = None, log=print,
              baseline_rows: list[dict] | None = None, figures: bool = True) -> dict:
    """Run a loaded suite (:func:`harness.sweep.suite.load_suite`) into ``out_dir``; the runs'
    reports hold the Mitsuba cross-check when ``mitsuba`` and their figures when ``figures``.

    Returns a summary: job counts (run and reused), seconds, the rows of sweep.json, and
    with ``baseline_rows`` (a previous sweep's) the regression verdict
    (:func:`reports.sweep.regressions`).
    """
    t0 = time.perf_counter()
    # the CUDA variant: one worker per GPU (Dr.Jit's CPU thread count does not apply)
    gpus = backend.cuda_device_count() if backend.resolve_variant(variant) == "cuda_ad_rgb" else 0
    threads = worker_threads(workers) if executor == "local" and workers > 1 and not gpus else None
    datasets, runs = plan(suite, out_dir, mitsuba, force, variant, threads, figures)
    done_d = _execute(dataset_job, datasets, "dataset", executor, workers, scheduler, log, gpus)
    done_r = _execute(run_job, runs, "run", executor, workers, scheduler, log, gpus)
    compare_dir = os.path.join(out_dir, "compare")
    # each row's run folder relative to sweep.json's own folder: the same wherever the sweep ran from
    rows = [{"scene": r["scene"], "label": r["label"], "method": r["method"], "axes": r["axes"], "seed": r["seed"],
             "run": os.path.relpath(r["folder"], compare_dir), "seconds": done_r[r["id"]]["estimate_seconds"],
             **done_r[r["id"]]["metrics"]} for r in runs]
    compare_runs([os.path.join(r["folder"], "report") for r in runs], compare_dir, overwrite=True,
                 tags=[{"label": r["label"], "axes": r["axes"], "seed": r["seed"]} for r in runs])
    verdict = sweep_report.regressions(rows, baseline_rows) if baseline_rows is not None else None
    sweep_report.write(compare_dir, suite["name"], rows, verdict)
    reused = sum(1 for r in list(done_d.values()) + list(done_r.values()) if r.get("reused"))
    summary = {"datasets": len(datasets), "runs": len(runs), "reused": reused,
               "executed": len(datasets) + len(runs) - reused, "seconds": time.perf_counter() - t0, "rows": rows,
               "regressions": verdict}
    with open(os.path.join(out_dir, "sweep-summary.json"), "w") as f:
        json.dump({k: v for k, v in summary.items() if k not in ("rows", "regressions")}, f, indent=1)
    return summary
