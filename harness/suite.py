"""Benchmark suites: scenes x methods -> datasets, runs, reports and one comparison."""
from __future__ import annotations

import os
import time
import tomllib

from estimator.methods import REGISTRY, estimate

from .dataset import read_dataset
from .generate import generate
from .reporting import build_report, compare_runs
from .runs import estimator_settings, known_light, write_run
from .scene_spec import SCENES_DIR, SpecError, load_spec, resolve_scene


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
    return suite


def run_suite(suite: dict, out_dir: str, profile: str | None = None, mitsuba: bool = True,
              overwrite: bool = False, log=print) -> list[dict]:
    """Generate each scene (reused when present), run every method, report, compare.

    Layout: OUT/SCENE/dataset, OUT/SCENE/METHOD/{run,report}, OUT/compare.
    """
    profile = profile or suite.get("profile")
    reports = []
    for scene in suite["scenes"]:
        data_dir = os.path.join(out_dir, scene, "dataset")
        if not os.path.isdir(data_dir) or overwrite:
            t = time.perf_counter()
            generate(load_spec(resolve_scene(scene), profile), data_dir, overwrite=overwrite)
            log(f"{scene}: dataset in {time.perf_counter() - t:.1f} s")
        ds = read_dataset(data_dir, load_test=False)
        known = known_light(ds.ground_truth)
        for method in suite["methods"]:
            _, config = estimator_settings(ds.meta, method)
            t = time.perf_counter()
            est = estimate(ds.data, method, config, **known)
            run_dir = os.path.join(out_dir, scene, method, "run")
            write_run(run_dir, est, data_dir, overwrite=True, extra={"scene": ds.meta.get("scene")})
            report_dir = os.path.join(out_dir, scene, method, "report")
            build_report(run_dir, report_dir, data_dir, mitsuba=mitsuba, overwrite=True, log=lambda m: None)
            log(f"{scene} / {method}: estimated in {est.info['timings']['total']:.1f} s, "
                f"reported in {time.perf_counter() - t:.1f} s")
            reports.append(report_dir)
    return compare_runs(reports, os.path.join(out_dir, "compare"), overwrite=True)
