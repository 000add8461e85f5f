"""The two steps of every benchmark job: :func:`ensure_dataset` and :func:`run_method`
(``pseudolight demo`` is one such job on the default scene; sweeps run them through
``harness.sweep``)."""
from __future__ import annotations

import os

from estimator import REGISTRY, Estimate, InputError, estimate
from harness.cli.reporting import build_report
from harness.io.dataset import fingerprint, read_dataset, read_ground_truth
from harness.io.runs import estimator_settings, write_run
from harness.scene.generate import generate
from harness.scene.spec import load_spec, resolve_scene


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
               baseline: dict | None = None, overrides: dict | None = None, log=print,
               figures: bool = True) -> tuple[Estimate, dict, list[dict] | None]:
    """Estimate a dataset with ``method`` (None: the dataset's recommendation), write the
    run, and report it (against ``baseline`` when given; with its figures unless
    ``figures=False``). Returns (estimate, metrics, regressions)."""
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
                                        overwrite=True, log=log, figures=figures)
    return est, metrics, regressions
