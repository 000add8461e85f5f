"""Benchmark suites: scenes x methods -> datasets, runs, reports and one comparison.

:func:`ensure_dataset` and :func:`run_method` are the two steps of every job;
``pseudolight demo`` is one such job on the default scene.
"""
from __future__ import annotations

import os
import time
import tomllib

from estimator.data import Estimate
from estimator.errors import InputError
from estimator.methods import REGISTRY, estimate

from harness.cli.reporting import build_report, compare_runs
from harness.io.dataset import fingerprint, read_dataset, read_ground_truth
from harness.io.runs import estimator_settings, write_run
from harness.scene.generate import generate
from harness.scene.spec import SCENES_DIR, SpecError, load_spec, resolve_scene


def load_suite(path_or_name: str) -> dict:
    """A suite TOML (path, or name under scenes/suites/) with 'scenes' and 'methods' lists."""
    path = path_or_name
    if not os.path.isfile(path):
        path = os.path.join(SCENES_DIR, "suites", f"{path_or_name}.toml")
    if not os.path.isfile(path):
        raise SpecError(f"suite not found: {path_or_name}")
    with open(path, "rb") as f:
        suite = tomllib.load(f)
    unknown = sorted(set(suite) - {"name", "scenes", "methods", "profile"})
    if unknown:
        raise SpecError(f"unknown suite key(s): {', '.join(unknown)}")
    for key in ("scenes", "methods"):
        if not isinstance(suite.get(key), list) or not suite[key]:
            raise SpecError(f"suite.{key} must be a non-empty list")
    for method in suite["methods"]:
        if method not in REGISTRY:
            raise SpecError(f"suite.methods: {method!r} is not a registered method ({', '.join(REGISTRY)})")
    for scene in suite["scenes"]:
        resolve_scene(scene)
    suite["path"] = os.path.abspath(path)
    return suite


def ensure_dataset(scene: str, data_dir: str, profile: str | None = None, overwrite: bool = False,
                   variant: str | None = None, log=print) -> None:
    """Generate a shipped scene (or spec file) into ``data_dir`` unless it is there already."""
    if os.path.isdir(data_dir) and not overwrite:
        log(f"reusing dataset {data_dir} (pass --overwrite to render it again)")
        return
    summary = generate(load_spec(resolve_scene(scene), profile), data_dir, overwrite=overwrite, variant=variant,
                       log=log)
    log(f"generated {summary['scene']}: {summary['views']} views in {summary['seconds']['total']:.1f} s")


def run_method(data_dir: str, method: str | None, run_dir: str, report_dir: str, mitsuba: bool = True,
               baseline: dict | None = None, overrides: dict | None = None,
               log=print) -> tuple[Estimate, dict, list[dict] | None]:
    """Estimate a dataset with ``method`` (None: the dataset's recommendation), write the
    run, and report it (against ``baseline`` when given). Returns (estimate, metrics, regressions)."""
    ds = read_dataset(data_dir, load_test=False, load_truth=False)
    method, config = estimator_settings(ds.meta, method, overrides)
    known = {}
    if REGISTRY[method].needs_illumination:
        truth = read_ground_truth(data_dir, ds.data.mesh.num_faces)
        if truth is None:
            raise InputError(f"method {method} needs the true light, and {data_dir} has no ground_truth/")
        known = truth.known_light()
    est = estimate(ds.data, method, config, **known)
    write_run(run_dir, est, data_dir, overwrite=True, extra={"scene": ds.meta.get("scene")},
              fingerprint=fingerprint(ds.data))
    log(f"estimated with {method} ({config.components}) in {est.info['timings']['total']:.1f} s")
    metrics, regressions = build_report(run_dir, report_dir, data_dir, mitsuba=mitsuba, baseline=baseline,
                                        overwrite=True, log=log)
    return est, metrics, regressions


def run_suite(suite: dict, out_dir: str, profile: str | None = None, mitsuba: bool = True,
              overwrite: bool = False, log=print) -> list[dict]:
    """Generate each scene (reused when present), run every method, report, compare.

    Layout: OUT/SCENE/dataset, OUT/SCENE/METHOD/{run,report}, OUT/compare.
    """
    profile = profile or suite.get("profile")
    reports = []
    for scene in suite["scenes"]:
        data_dir = os.path.join(out_dir, scene, "dataset")
        ensure_dataset(scene, data_dir, profile, overwrite, log=log)
        for method in suite["methods"]:
            t = time.perf_counter()
            root = os.path.join(out_dir, scene, method)
            run_method(data_dir, method, os.path.join(root, "run"), os.path.join(root, "report"), mitsuba,
                       log=lambda m: None)
            log(f"{scene} / {method}: estimated and reported in {time.perf_counter() - t:.1f} s")
            reports.append(os.path.join(root, "report"))
    return compare_runs(reports, os.path.join(out_dir, "compare"), overwrite=True)
