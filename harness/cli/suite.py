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
    """Generate a shipped scene (or spec file) into ``data_dir`` unless it is there already; a
    dataset there that the spec did not render (another scene, size, seed or sampling, or
    faults) is refused rather than reported as the scene's."""
    spec = load_spec(resolve_scene(scene), profile)
    if os.path.isdir(data_dir) and not overwrite:
        differs = _rendered_otherwise(data_dir, spec)
        if differs:
            raise InputError(f"{data_dir} holds a dataset that is not {spec.name}'s ({differs}); pass --overwrite to "
                             "render it again, or choose another -o")
        log(f"reusing dataset {data_dir} (pass --overwrite to render it again)")
        return
    summary = generate(spec, data_dir, overwrite=overwrite, variant=variant, log=log)
    log(f"generated {summary['scene']}: {summary['views']} views in {summary['seconds']['total']:.1f} s")


def _rendered_otherwise(data_dir: str, spec) -> str:
    """What in ``data_dir``'s transforms.json differs from what ``spec`` renders ('' when
    nothing does): the scene's name, seed, samples per pixel, image size, view counts, faults."""
    import json

    try:
        with open(os.path.join(data_dir, "transforms.json")) as f:
            meta = json.load(f)
    except (OSError, ValueError) as exc:
        return f"its transforms.json cannot be read: {exc}"
    cams = spec.cameras
    expected = {"scene": spec.name, "seed": spec.seed, "spp": spec.render.spp, "w": cams.width, "h": cams.height,
                "views": cams.count, "test views": cams.test_count, "faults": "faults" if spec.faults.active else None}
    found = {"scene": meta.get("scene"), "seed": meta.get("seed"), "spp": meta.get("spp"), "w": meta.get("w"),
             "h": meta.get("h"), "views": len(meta.get("frames", [])), "test views": len(meta.get("test_frames", [])),
             "faults": "faults" if meta.get("faults") else None}
    return ", ".join(f"{key} {found[key]!r} where the spec gives {value!r}"
                     for key, value in expected.items() if found[key] != value)


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
