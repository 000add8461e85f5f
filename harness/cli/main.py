"""The ``pseudolight`` command line.

Bad input (any :class:`estimator.core.errors.InputError`) ends with one line naming the
file, key or flag and exit code 2; an interrupt (Ctrl-C, SIGTERM) with 130 or
143 and no partial output; anything else is a bug and keeps its traceback (exit 1).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import resource
import signal
import sys
import time

import numpy as np

from estimator import VARIANTS, InputError, StopRequested, clear_stop, request_stop, stop_signals_handled
from harness.cli.heap import keep_freed_memory
from harness.io.atomic import MARKER, OutputError, check_output, output_kind, refuse_inputs, writable
from harness.io.jsonio import load_json
from harness.scene.spec import SCENES_DIR, load_spec, resolve_scene, shipped_scenes
from harness.sweep.executor import EXECUTORS
from reports.protocols import PROTOCOLS

DEFAULT_SCENE = "earth-specular"
PROTOCOL_NAMES = tuple(PROTOCOLS)


class Terminated(BaseException):
    """SIGTERM arrived: unwind like Ctrl-C, so atomic outputs are cleaned up."""


# the interruption a handler raised (Terminated or KeyboardInterrupt), recorded because Mitsuba's
# parser turns one raised inside a Python plugin's constructor into a RuntimeError with no cause
# to follow, and a library that catches BaseException (trimesh's optional imports) swallows it
_SIGNAL_SEEN: list[type | None] = [None]


def _on_signal(signum, frame):
    """SIGTERM or SIGINT: record it, request a stop (honoured at the next step of a loop whose
    Dr.Jit callback swallowed the exception) and unwind."""
    kind = Terminated if signum == signal.SIGTERM else KeyboardInterrupt
    _SIGNAL_SEEN[0] = kind
    request_stop()
    raise kind()


def _interruption(exc: BaseException) -> type | None:
    """Terminated or KeyboardInterrupt when ``exc`` is one or was caused by one (Dr.Jit
    wraps exceptions raised inside its kernels' Python callbacks in a RuntimeError)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, (Terminated, StopRequested)):
            return Terminated
        if isinstance(exc, KeyboardInterrupt):
            return KeyboardInterrupt
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _err(message: str) -> None:
    print(message, file=sys.stderr)


def _overrides(args) -> dict:
    out = {}
    if args.resolution is not None:
        out["cameras.width"] = out["cameras.height"] = args.resolution
    if args.views is not None:
        out["cameras.count"] = args.views
    if args.test_views is not None:
        out["cameras.test_count"] = args.test_views
    if args.spp is not None:
        out["render.spp"] = args.spp
    if args.seed is not None:
        out["seed"] = args.seed
    for item in args.set or []:
        out.update([_dotted_value(item)])
    return out


def _dotted_value(item: str) -> tuple[str, object]:
    """KEY=VALUE of ``--set`` -> (dotted key, value parsed as a TOML value, else the text)."""
    import tomllib

    key, sep, text = item.partition("=")
    if not sep or not key.strip():
        raise InputError(f"--set needs KEY=VALUE, got {item!r}")
    if "\n" in item or "\r" in item:   # TOML would read the next line as another key, and it would be dropped
        raise InputError(f"--set takes one KEY=VALUE on one line, got {item!r}")
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    return key.strip(), value


def _rotation(flag: str, values) -> tuple[str, float] | None:
    """(axis, degrees) of a ``--rotate-illumination AXIS DEG`` flag, validated."""
    if values is None:
        return None
    axis, text = values
    if axis not in ("x", "y", "z"):
        raise InputError(f"{flag}: axis must be x, y or z, got {axis!r}")
    try:
        degrees = float(text)
    except ValueError:
        raise InputError(f"{flag}: angle must be a number of degrees, got {text!r}") from None
    if not math.isfinite(degrees):
        raise InputError(f"{flag}: angle must be finite, got {text!r}")
    return axis, degrees


def cmd_scenes(args) -> int:
    for name, path in shipped_scenes().items():
        spec = load_spec(path)
        c = spec.cameras
        print(f"{name:16s} {c.count:3d} views {c.width}x{c.height} spp {spec.render.spp:<4d} "
              f"profiles: {', '.join(spec.profiles) or '-'}\n{'':16s} {spec.description}")
    return 0


def cmd_generate(args) -> int:
    from harness.scene.generate import generate

    if args.scene == "random":   # the seeded random family (harness.scene.random_family)
        from harness.scene.random_family import random_spec

        spec = random_spec(args.seed or 0, args.profile, _overrides(args))
    else:
        spec = load_spec(resolve_scene(args.scene), args.profile, _overrides(args))
    check_output(args.output, spec.inputs(), args.overwrite, kind="dataset")
    summary = generate(spec, args.output, overwrite=args.overwrite, variant=args.variant, log=_err)
    summary["peak_rss_mib"] = _peak_rss_mib()
    print(json.dumps(summary, indent=1) if args.json else
          f"dataset {summary['scene']}: {summary['views']} views + {summary['test_views']} test views, "
          f"{summary['faces']} faces, {summary['seconds']['total']:.1f} s, peak {summary['peak_rss_mib']:.0f} MiB\n"
          f"written to {summary['path']}")
    return 0


def _load_baseline(path: str | None) -> dict | None:
    from reports.regression import validate_baseline

    if path is None:
        return None
    return validate_baseline(load_json(path, "baseline"), path)


def _report_exit(metrics: dict, regressions, out: str) -> int:
    from reports.html import terminal_summary

    print(terminal_summary(metrics))
    print(f"report: {os.path.abspath(os.path.join(out, 'report.html'))}")
    cc = metrics.get("mitsuba_cross_check") or {}
    if cc.get("pass") is False:
        print(f"warning: the Mitsuba re-render differs from the forward model by more than {cc['tolerance']}")
    return 0 if regressions is None else _regression_exit(regressions, "baseline")


def _regression_exit(rows: list[dict], what: str) -> int:
    """Print a REGRESSION line per worse metric (rows of :func:`reports.regression.check` or
    :func:`reports.sweep.regressions`) and a summary; exit code 1 when any is worse."""
    worse = [r for r in rows if r["status"] != "ok"]
    for r in worse:
        now = (r.get("note") or "missing or not a finite number") if r["current"] is None else f"{r['current']:.4g}"
        where = f"{r['row']} " if "row" in r else ""
        _err(f"REGRESSION {where}{r['metric']}: baseline {r['baseline']:.4g}, now {now} "
             f"({r['direction']} is better, tolerance {r['tolerance']:g})")
    print(f"{what}: {len(rows) - len(worse)} of {len(rows)} tracked metrics within tolerance")
    return 1 if worse else 0


def _check_json_target(path: str, inputs: list) -> str:
    """Refuse a JSON output file that is an input, a folder, or in an unwritable place."""
    target = os.path.realpath(os.path.abspath(path))
    refuse_inputs(target, inputs)
    if os.path.isdir(target):
        raise OutputError(f"{path} is a folder, not a file")
    parent = os.path.dirname(target)
    if not os.path.isdir(parent):
        why = "is not a folder" if os.path.exists(parent) else "does not exist"
        raise OutputError(f"cannot write {path}: {parent} {why}")
    writable(parent, path)
    return target


def _existing_baseline(path: str) -> None:
    """Refuse to replace ``path`` unless it is a baseline already (updating a baseline is what
    ``--write-baseline`` is for; any other file needs ``--overwrite``)."""
    from reports.regression import validate_baseline

    try:
        with open(path) as f:
            validate_baseline(json.load(f), path)
    except (OSError, ValueError) as exc:
        raise OutputError(f"--write-baseline {path} exists and is not a baseline ({exc}); pass --overwrite to "
                          "replace it") from None


def _write_json_file(path: str, value: dict, inputs: list) -> None:
    """Write a JSON file whole (temporary file, then rename), never over an input."""
    from harness.io.jsonio import dump_json

    target = _check_json_target(path, inputs)
    tmp = f"{target}.partial-{os.getpid()}"
    try:
        dump_json(tmp, value)
        os.replace(tmp, target)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def cmd_report(args) -> int:
    from harness.cli.reporting import build_report
    from harness.io.runs import read_run

    rotation = _rotation("--rotate-illumination", args.rotate_illumination)
    _, run = read_run(args.run)
    dataset = args.dataset or run["dataset"]
    inputs = [args.run, dataset, args.baseline]
    check_output(args.output, inputs, args.overwrite)
    if args.write_baseline:
        _check_json_target(args.write_baseline, inputs)
        if os.path.exists(args.write_baseline) and not args.overwrite:
            _existing_baseline(args.write_baseline)
    baseline = _load_baseline(args.baseline)
    metrics, regressions = build_report(args.run, args.output, dataset, rotation, args.cross_check_spp,
                                        not args.no_mitsuba, baseline, args.overwrite, log=_err,
                                        check_fingerprint=not args.no_fingerprint_check,
                                        protocols=tuple(dict.fromkeys(args.protocol or PROTOCOL_NAMES)),
                                        figures=not args.no_figures)
    if args.write_baseline:
        from reports.regression import make_baseline

        _write_json_file(args.write_baseline, make_baseline(metrics), inputs)
        print(f"baseline written to {args.write_baseline}")
    return _report_exit(metrics, regressions, args.output)


def cmd_compare(args) -> int:
    from harness.cli.reporting import compare_runs, print_table

    seen: dict[str, str] = {}
    for run in args.runs:   # one folder twice compares nothing
        if (real := os.path.realpath(run)) in seen:
            raise InputError(f"{run} is given twice (as {seen[real]} too); compare distinct runs or reports")
        seen[real] = run
    check_output(args.output, args.runs, args.overwrite, kind="compare")
    rows = compare_runs(args.runs, args.output, overwrite=args.overwrite)
    print_table(rows)
    print(f"comparison: {os.path.abspath(os.path.join(args.output, 'compare.html'))}")
    return 0


def cmd_suite(args) -> int:
    from harness.sweep.executor import probe_scheduler
    from harness.sweep.runner import claim_sweep_folder, release_sweep_folder, run_sweep
    from harness.sweep.suite import load_suite
    from reports import sweep as sweep_report
    from reports.report import text_table
    from reports.sweep import SWEEP_METRICS, read_rows

    if args.scheduler and args.executor != "dask":
        raise InputError("--scheduler names a Dask scheduler; it needs --executor dask")
    suite = load_suite(args.suite, args.profile)
    if args.dry_run:
        return _dry_run(suite, args)
    baseline = read_rows(args.baseline) if args.baseline else None   # read before the sweep may replace it
    check_output(os.path.join(args.output, "compare"), [suite["path"]], True, kind="compare")
    if args.executor == "dask" and args.scheduler and args.scheduler.startswith("tcp://"):
        probe_scheduler(args.scheduler)   # before anything is written
    if args.executor == "local":   # a variant this machine cannot run fails here once, not in every job
        from estimator import backend
        if backend.resolve_variant(args.variant) == "cuda_ad_rgb" and backend.cuda_device_count() == 0:
            raise InputError("--variant cuda_ad_rgb: this machine has no usable CUDA GPU (the driver reports none); "
                             "use --variant llvm_ad_rgb, or --executor dask with GPU workers")
    made = claim_sweep_folder(args.output, suite["name"])
    try:
        summary = run_sweep(suite, args.output, args.executor, args.jobs, args.scheduler, args.force,
                            not args.no_mitsuba, args.variant, log=_err, baseline_rows=baseline,
                            figures=not args.no_figures)
    except BaseException:
        if made:   # stopped before any job finished: no folder is left behind
            release_sweep_folder(args.output)
        raise
    for line in text_table(sweep_report.table_rows(summary["rows"]), sweep_report.TABLE_COLUMNS + SWEEP_METRICS):
        print(line)
    print(f"{summary['datasets']} datasets, {summary['runs']} runs: {summary['executed']} jobs run, "
          f"{summary['reused']} reused, {summary['seconds']:.1f} s\n"
          f"comparison: {os.path.abspath(os.path.join(args.output, 'compare', 'compare.html'))}\n"
          f"sweep plots: {os.path.abspath(os.path.join(args.output, 'compare', 'sweep.html'))}")
    verdict = summary["regressions"]
    return 0 if verdict is None else _regression_exit(verdict, "baseline sweep")


def _dry_run(suite: dict, args) -> int:
    """Print a sweep's size without running it: datasets and runs, how many are cached, and a
    time estimate from the finished jobs' own records in the folder (when it holds any)."""
    from harness.sweep.jobs import finished
    from harness.sweep.runner import plan

    datasets, runs = plan(suite, args.output, not args.no_mitsuba, args.force, args.variant,
                          figures=not args.no_figures)
    cached = {kind: [finished(j["folder"], j["id"], j.get("figures", True)) for j in jobs]
              for kind, jobs in (("dataset", datasets), ("run", runs))}
    print(f"suite {suite['name']}: {len(datasets)} datasets x {len(suite['methods'])} methods = {len(runs)} runs "
          f"(scenes: {', '.join(sorted({d['scene'] for d in datasets}))})")
    lines = []
    for kind, records in cached.items():
        done = [r for r in records if r is not None and not args.force]
        todo = len(records) - len(done)
        seconds = [float(r["seconds"]) for r in done if isinstance(r.get("seconds"), (int, float))]
        estimate = (f", about {todo * float(np.median(seconds)) / 60:.0f} min at the median of the cached ones "
                    f"({np.median(seconds):.0f} s each, --jobs {args.jobs}: divide by the workers)"
                    if seconds and todo else "")
        lines.append(f"{kind}s: {len(done)} cached, {todo} to run{estimate}")
    print("\n".join(lines))
    if not any(r is not None for records in cached.values() for r in records):
        print("no finished job in the folder to time from: a tiny-profile job takes seconds, a full-size one "
              "tens of seconds to minutes (benchmarks/README.md)")
    return 0


def cmd_demo(args) -> int:
    """Generate the default scene, estimate with its recommended method, report against its baseline."""
    from harness.cli.suite import ensure_dataset, run_method

    if not str(args.output).strip():   # an empty -o would resolve to the working directory
        raise OutputError("the output path is empty; give -o a folder")
    if os.path.exists(os.path.join(args.output, MARKER)):
        raise OutputError(f"refusing to write the demo into {os.path.abspath(args.output)}: it is itself "
                          f"pseudolight output ({output_kind(args.output) or 'of unknown kind'}); choose another -o")
    root = os.path.join(args.output, DEFAULT_SCENE)
    data_dir = os.path.join(root, "dataset")
    check_output(os.path.join(root, "run"), [SCENES_DIR], True, kind="run")
    t0 = time.perf_counter()
    ensure_dataset(DEFAULT_SCENE, data_dir, overwrite=args.overwrite, variant=args.variant, log=_err)
    baseline = os.path.join(SCENES_DIR, "baselines", f"{DEFAULT_SCENE}.json")
    est, metrics, regressions = run_method(data_dir, None, os.path.join(root, "run"), os.path.join(root, "report"),
                                           baseline=_load_baseline(baseline) if os.path.isfile(baseline) else None,
                                           overrides={"variant": args.variant} if args.variant else None, log=_err)
    for line in est.info.get("warnings", []):
        _err(f"warning: {line}")
    print(f"total {time.perf_counter() - t0:.1f} s, peak {_peak_rss_mib():.0f} MiB")
    return _report_exit(metrics, regressions, os.path.join(root, "report"))


CONFIG_FLAGS = ("components", "sh_order", "directions", "iterations", "min_cos_view", "diffuse_light",
                "defilter_order", "phong_exponent", "specular_model", "variant", "robust_loss",
                "ad_time_budget", "pose_rounds")  # flags named as EstimatorConfig fields


FLAG_NAMES = {"ad_time_budget": "--time-budget", "pose_rounds": "--refine-poses"}   # else --key-with-dashes


def _config_flags(args) -> dict:
    return {k: getattr(args, k) for k in CONFIG_FLAGS if getattr(args, k, None) is not None}


def _flag_of(key: str) -> str:
    """The command-line flag that sets the EstimatorConfig field ``key``."""
    return FLAG_NAMES.get(key, "--" + key.replace("_", "-"))


def _positive_float(flag: str, text: str, auto: bool = False) -> float:
    """A finite number > 0 given to ``flag``; ``auto``: the flag also takes 'auto' (handled
    before this is called), which the message then names."""
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{flag} must be a number{' or auto' if auto else ''}, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{flag} must be a finite number > 0, got {text!r}")
    return value


def _estimator_sets(items: list[str]) -> dict:
    """``estimate --set KEY=VALUE``: any estimator setting (``KEY`` a field of
    :class:`estimator.EstimatorConfig`, optionally prefixed ``estimator.``), the value read as
    ``generate --set`` reads it (:func:`_dotted_value`). Unknown keys are named with the nearest."""
    import difflib

    from estimator import EstimatorConfig

    known = [f.name for f in dataclasses.fields(EstimatorConfig)]
    out = {}
    for item in items:
        key, value = _dotted_value(item)
        key = key.removeprefix("estimator.")
        if key not in known:
            near = difflib.get_close_matches(key, known, n=3)
            raise InputError(f"--set {key}: not an estimator setting" + (f" (did you mean {', '.join(near)}?)"
                                                                          if near else ""))
        out[key] = value
    return out


def _known_light(args, ds, method: str) -> dict:
    """The true light a method that needs it is given: the ground truth of ``--truth`` (a
    dataset of the same scene) or of the dataset itself."""
    from harness.io.dataset import read_ground_truth

    source = os.path.abspath(args.truth or args.dataset)
    if args.truth:
        other = load_json(os.path.join(source, "transforms.json"), "--truth dataset", InputError)
        if other.get("scene") and ds.meta.get("scene") and other["scene"] != ds.meta["scene"]:
            raise InputError(f"--truth {args.truth} is a dataset of scene {other['scene']!r}, and "
                             f"{args.dataset} of {ds.meta['scene']!r}: the known light must be this scene's")
    truth = read_ground_truth(source, ds.data.mesh.num_faces)
    if truth is None:
        raise InputError(f"method {method} needs the true light, and {source} has no ground_truth/ "
                         "(pass --truth DATASET)")
    return truth.known_light()


def cmd_estimate(args) -> int:
    from estimator import EXPONENT_CANDIDATES, estimate, get_method
    from harness.io.dataset import fingerprint, read_dataset
    from harness.io.runs import estimator_settings, write_run

    check_output(args.output, [args.dataset, args.truth], args.overwrite)
    ds = read_dataset(args.dataset, load_test=False, load_truth=False)
    # the mesh and images may lie outside the dataset folder
    check_output(args.output, [*ds.inputs, args.truth], args.overwrite, kind="run")
    flags = _config_flags(args)
    candidates = None
    if flags.get("phong_exponent") == "auto":
        flags.pop("phong_exponent")
        candidates = EXPONENT_CANDIDATES
    elif "phong_exponent" in flags:
        flags["phong_exponent"] = _positive_float("--phong-exponent", flags["phong_exponent"], auto=True)
    settings = _estimator_sets(args.set or [])
    try:
        method, config = estimator_settings(ds.meta, args.method, {**flags, **settings})
    except InputError as exc:   # name the flag or --set entry whose setting the message names
        named = [f"--set {key}" for key in settings if re.search(rf"\b{key}\b", str(exc))]
        named += [_flag_of(key) for key in flags if re.search(rf"\b{key}\b", str(exc))]
        raise InputError(f"{named[0]}: {exc}" if named else str(exc)) from None
    if "ad_time_budget" in flags and method != "mitsuba-ad":
        raise InputError(f"--time-budget applies to mitsuba-ad (the iterative peer), not to {method}")
    if "robust_loss" in flags and method == "mitsuba-ad":
        raise InputError("--robust-loss applies to the bilinear and retinex methods; mitsuba-ad fits the images "
                         "by gradient descent on an L2 loss")
    if args.truth and not get_method(method).needs_illumination:
        raise InputError(f"--truth applies to the methods given the true light (known-illumination), not to {method}")
    known = _known_light(args, ds, method) if get_method(method).needs_illumination else {}
    if args.holdout_views:
        from estimator import holdout_indices
        try:
            holdout_indices(len(ds.data.views), args.holdout_views)   # refuse a bad count before solving
        except InputError as exc:
            raise InputError(f"--holdout-views: {exc}") from None
    say = lambda m: _err(f"  {m}")  # noqa: E731
    est = estimate(ds.data, method, config, **known, log=say, exponent_candidates=candidates)
    if args.holdout_views:
        from estimator import cross_validate, cross_validation_warnings
        try:
            cv = cross_validate(ds.data, args.holdout_views,
                                lambda data: estimate(data, method, config, **known, exponent_candidates=candidates))
        except InputError as exc:   # the full solve stands; only the held-out solve failed
            cv = {"error": f"the solve without the held-out views failed: {exc}", "psnr": None, "held_out": []}
            est.info.setdefault("warnings", []).append(f"cross-validation failed: {exc}")
        est.info["cross_validation"] = cv
        est.info.setdefault("warnings", []).extend(cross_validation_warnings(cv))
        psnr = "-" if cv["psnr"] is None else f"{cv['psnr']:.2f}"
        _err(f"  cross-validation: {len(cv['held_out'])} views held out, prediction PSNR {psnr} dB")
    _print_trust(est)
    if "poses" in est.info:
        turns = [p["rotation_deg"] for p in est.info["poses"]]
        shifts = [p["translation"] for p in est.info["poses"]]
        _err(f"  pose refinement: {len(turns)} cameras corrected by a median {np.median(turns):.3f} deg "
             f"(max {max(turns):.3f}) and {np.median(shifts):.4f} (max {max(shifts):.4f}) world units, "
             f"{est.info['timings']['pose_refinement']:.1f} s; refined c2w in run.json 'poses'")
    for name, count in est.info.get("rejected_pixels", {}).items():
        _err(f"warning: {name}: {count} pixels negative beyond noise were left out")
    for line in est.info.get("warnings", []):
        _err(f"warning: {line}")
    est.info["peak_rss_mib"] = _peak_rss_mib()
    write_run(args.output, est, args.dataset, overwrite=args.overwrite, extra={"scene": ds.meta.get("scene")},
              fingerprint=fingerprint(ds.data), inputs=[*ds.inputs, args.truth])
    t = est.info["timings"]
    print(f"{method} on {ds.meta.get('scene', args.dataset)}: {est.info.get('clusters', '?')} clusters, "
          f"{100 * est.observed.mean():.1f}% faces estimated, {t['total']:.1f} s "
          f"(observations {t['observations']:.1f}, visibility {t['visibility']:.1f}, "
          f"reflection {t['reflection']:.1f}, solve {t['solve']:.1f}), peak {_peak_rss_mib():.0f} MiB\n"
          f"written to {os.path.abspath(args.output)}")
    if args.strict and est.info.get("warnings"):
        _err(f"pseudolight: --strict: {len(est.info['warnings'])} warning(s); the run is written, exit 3")
        return 3
    return 0


def _print_trust(est) -> None:
    """The short trust summary of an estimate (stderr)."""
    trust = est.info.get("trust")
    if not trust:
        return
    dof = est.info.get("degrees_of_freedom") or {}
    se = trust.get("albedo_relative_se") or {}
    cond = trust.get("light_condition")
    _err(f"  trust: {dof.get('observations', '?')} observations for {dof.get('unknowns', '?')} unknowns; "
         f"median relative residual {100 * (trust['residual']['median_relative'] or 0):.1f} %, "
         f"{100 * trust['outlier_share']:.1f} % outliers; light condition "
         f"{'inf' if cond is None else f'{cond:.3g}'}; albedo relative standard error median "
         f"{100 * se.get('median', float('nan')):.2f} %, p90 {100 * se.get('p90', float('nan')):.2f} %")


def cmd_render(args) -> int:
    from estimator import Predictor, axis_angle_matrix
    from harness.cli.reporting import open_run
    from harness.io.atomic import atomic_directory
    from harness.io.exr import write_exr

    rotation = _rotation("--rotate-illumination", args.rotate_illumination)
    est, _, ds, inputs = open_run(args.run, args.dataset, args.output, args.overwrite,
                                  check_fingerprint=not args.no_fingerprint_check, kind="render")
    views = {"test": ds.data.test_views, "train": ds.data.views,
             "all": ds.data.views + ds.data.test_views}[args.frames]
    if not views:
        raise InputError(f"the dataset {ds.path} has no {args.frames} frames")
    rotation = None if rotation is None else axis_angle_matrix(*rotation)
    predictor = Predictor(ds.data.mesh, est)
    limit = float(np.finfo(np.float32).max)   # what an EXR of float32 pixels holds
    with atomic_directory(args.output, overwrite=args.overwrite, inputs=inputs, kind="render") as tmp:
        for view in views:
            rgb, coverage = predictor.predict(view.camera, rotation)
            largest = float(np.max(np.abs(rgb), initial=0.0)) if np.all(np.isfinite(rgb)) else np.inf
            if largest > limit:   # the run's numbers, not the output file, are at fault
                raise InputError(f"{args.run}: the estimate predicts pixels of magnitude {largest:.3g} in view "
                                 f"{view.name}, beyond any image's range ({limit:.3g}): its light or albedos in "
                                 "estimate.npz are absurd")
            name = os.path.splitext(os.path.basename(view.name))[0] + ".exr"
            write_exr(os.path.join(tmp, name), np.concatenate([rgb, coverage[..., None]], axis=2))
    print(f"{len(views)} predicted images written to {os.path.abspath(args.output)}")
    return 0


def cmd_export_texture(args) -> int:
    from harness.cli.reporting import open_run
    from harness.io.atomic import atomic_directory
    from harness.io.mesh import load_mesh_with_uv
    from harness.io.texture import export_textures

    est, _, ds, inputs = open_run(args.run, args.dataset, args.output, args.overwrite, load_test=False,
                                  check_fingerprint=not args.no_fingerprint_check, kind="texture")
    _, uv = load_mesh_with_uv(os.path.join(ds.path, ds.meta.get("mesh_file_path", "mesh.ply")))
    with atomic_directory(args.output, overwrite=args.overwrite, inputs=inputs, kind="texture") as tmp:
        summary = export_textures(tmp, ds.data.mesh, est, uv, args.size)
    print(f"{summary['faces']} faces, {summary['size']}x{summary['size']} textures ({summary['uv_source']} UVs) "
          f"written to {os.path.abspath(args.output)}")
    return 0


def cmd_export(args) -> int:
    from harness.io.atomic import atomic_directory
    from harness.io.dataset import read_dataset
    from harness.io.nerf_synthetic import write_nerf_synthetic

    if args.format == "nerf-synthetic" and args.spp is not None:
        raise InputError("--spp applies to --format mitsuba (nerf-synthetic copies the dataset's rendered images)")
    check_output(args.output, [args.dataset], args.overwrite, kind="export")
    ds = read_dataset(args.dataset, load_test=True, load_truth=True)
    if args.format == "mitsuba":
        from harness.io.mitsuba_views import write_mitsuba_views

        with atomic_directory(args.output, overwrite=args.overwrite, inputs=[args.dataset, *ds.inputs],
                              kind="export") as tmp:
            summary = write_mitsuba_views(ds, tmp, args.spp)
        print(f"mitsuba: {summary['train']} train + {summary['test']} test scene XMLs ({summary['material']}, "
              f"{summary['light']} light, {summary['integrator']} integrator, {summary['spp']} spp) written to "
              f"{os.path.abspath(args.output)}")
        return 0
    with atomic_directory(
        args.output, overwrite=args.overwrite, inputs=[args.dataset, *ds.inputs], kind="export"
    ) as tmp:
        summary = write_nerf_synthetic(ds, tmp, args.size)
    print(f"nerf-synthetic: {summary['train']} train + {summary['test']} test frames (exposure "
          f"{summary['exposure']:.4g}){', ground truth textures' if 'ground_truth' in summary else ''} written to "
          f"{os.path.abspath(args.output)}")
    return 0


def cmd_import(args) -> int:
    from harness.io.dataset import fingerprint, read_dataset
    from harness.io.imports import (
        import_warnings,
        imported_estimate,
        read_mitsuba_xml,
        read_per_face,
        read_uv_textures,
        xml_referenced_files,
    )
    from harness.io.runs import write_run

    applies = {"--file": ("per-face", "mitsuba-xml"), "--mesh": ("uv-textures",), "--diffuse": ("uv-textures",),
               "--specular": ("uv-textures",), "--envmap": ("uv-textures",)}
    stray = [flag for flag, sources in applies.items()
             if getattr(args, flag[2:]) is not None and args.source not in sources]
    if stray:
        raise InputError(f"{', '.join(stray)} {'does' if len(stray) == 1 else 'do'} not apply to --from {args.source}")
    files = [p for p in (args.file, args.mesh, args.diffuse, args.specular, args.envmap) if p]
    if args.source == "mitsuba-xml" and args.file:   # the mesh, textures and envmap the XML names are inputs too
        files += xml_referenced_files(args.file)
    check_output(args.output, [args.dataset, *files], args.overwrite, kind="run")
    ds = read_dataset(args.dataset, load_test=False, load_truth=False)
    f = ds.data.mesh.num_faces
    if args.source in ("per-face", "mitsuba-xml") and not args.file:
        raise InputError(f"--from {args.source} needs --file " + ("RESULTS.npz|.csv" if args.source == "per-face"
                                                                   else "SCENE.xml"))
    if args.source == "per-face":
        arrays = read_per_face(args.file, f)
    elif args.source == "mitsuba-xml":
        arrays = read_mitsuba_xml(ds.data.mesh, args.file)
    else:
        if not (args.mesh and args.diffuse):
            raise InputError("--from uv-textures needs --mesh MESH_WITH_UVS and --diffuse TEXTURE "
                             "(--specular, --envmap optional)")
        arrays = read_uv_textures(ds.data.mesh, args.mesh, args.diffuse, args.specular, args.envmap)
    est = imported_estimate(arrays, f, f"{args.source}: {', '.join(os.path.abspath(p) for p in files)}",
                            _positive_float("--exponent", args.exponent))
    for warning in import_warnings(arrays, (ds.meta.get("estimator_defaults") or {}).get("components", "both")):
        _err(f"warning: {warning}")
    write_run(args.output, est, args.dataset, overwrite=args.overwrite, extra={"scene": ds.meta.get("scene")},
              fingerprint=fingerprint(ds.data), inputs=[*ds.inputs, *files])
    print(f"imported {args.source} for {f} faces as {est.method}; written to {os.path.abspath(args.output)} "
          "(score it with pseudolight report)")
    return 0


def _int_at_least(minimum: int, maximum: int | None = None):
    """An argparse type: an integer >= ``minimum`` (and <= ``maximum``; a one-line error otherwise)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum or (maximum is not None and value > maximum):
            bound = f"in [{minimum}, {maximum}]" if maximum is not None else f">= {minimum}"
            raise argparse.ArgumentTypeError(f"must be an integer {bound}, got {text!r}")
        return value
    return parse


MAX_JOBS = 256   # worker processes of a sweep: one per core of the largest machines


_positive_int, _count = _int_at_least(1), _int_at_least(0)


def _add_estimator_flags(p) -> None:
    from estimator import (
        COMPONENTS,
        DEFAULT_METHOD,
        DIFFUSE_LIGHTS,
        LOSSES,
        SPECULAR_MODELS,
    )

    p.add_argument("--method", help="registered method (default: the dataset's recommendation, "
                                    f"else {DEFAULT_METHOD})")
    p.add_argument("--components", choices=COMPONENTS)
    p.add_argument("--robust-loss", dest="robust_loss", choices=LOSSES,
                   help="M-estimator of the solve (default auto: the method's own)")
    p.add_argument("--time-budget", dest="ad_time_budget", type=float, metavar="SECONDS",
                   help="mitsuba-ad: wall-clock seconds of optimisation (default 60)")
    p.add_argument("--refine-poses", dest="pose_rounds", type=_positive_int, metavar="ROUNDS",
                   help="refine every training camera before the solve: silhouette, then ROUNDS rounds of "
                        "alignment with held-out estimates (2 is usually enough; several times the solve's time)")
    p.add_argument("--sh-order", type=int)
    p.add_argument("--directions", type=int, help="sample directions of the shadow function (paper: 1164)")
    p.add_argument("--iterations", type=int)
    p.add_argument("--min-cos-view", type=float, help="keep observations with r.n above this (default 0.5)")
    p.add_argument("--diffuse-light", choices=DIFFUSE_LIGHTS)
    p.add_argument("--defilter-order", type=int)
    p.add_argument("--phong-exponent", help="Phong exponent of the defiltered/lobe models, or 'auto' to "
                                            "estimate it (lowest residual over 5..40)")
    p.add_argument("--specular-model", choices=SPECULAR_MODELS,
                   help="mirror (the paper) or lobe (exact cut Phong lobe of --phong-exponent: 10 unless given)")
    p.add_argument("--variant", choices=VARIANTS + ("auto",))


MAX_CROSS_CHECK_SPP = 65536   # as render.spp: a 512^2 view at this count is 2^34 samples, hours


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block), exit code 2, like every other input error."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _add_suite_parser(sub, name: str) -> None:
    su = sub.add_parser(name, help=("benchmark sweeps: scenes x sweep points x seeds x methods -> cached datasets, "
                                    "runs, reports, comparison and sweep plots" + (" (alias of suite)"
                                                                                  if name == "bench" else "")))
    su.add_argument("suite", help="suite TOML, or a name under scenes/suites/ (e.g. smoke, paper, robustness)")
    su.add_argument("-o", "--output", required=True)
    su.add_argument("--profile", help="scene profile for every dataset (e.g. tiny, benchmark)")
    su.add_argument("--no-mitsuba", action="store_true", help="skip the Mitsuba cross-check in the reports")
    su.add_argument("--no-figures", action="store_true",
                    help="reports without figures (the comparison and sweep plots are still drawn)")
    su.add_argument("--force", "--overwrite", action="store_true", dest="force",
                    help="redo every job (finished jobs are otherwise reused)")
    su.add_argument("--jobs", type=_int_at_least(1, MAX_JOBS), default=1,
                    help=f"worker processes (spawned; Dr.Jit threads split between them), 1 to {MAX_JOBS}")
    su.add_argument("--executor", choices=EXECUTORS, default="local")
    su.add_argument("--scheduler", help="Dask scheduler address, tcp://HOST:PORT (--executor dask)")
    su.add_argument("--variant", choices=VARIANTS)
    su.add_argument("--baseline", help="a previous sweep's compare/sweep.json: a regression verdict per row and "
                                       "tracked metric (exit 1 when one is worse than its tolerance)")
    su.set_defaults(func=cmd_suite)
    su.add_argument("--dry-run", action="store_true",
                    help="print the datasets and runs the sweep holds (and which are cached), then stop")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pseudolight")
    except PackageNotFoundError:   # run from a checkout that was not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="pseudolight", description=__doc__)
    p.add_argument("--version", action="version", version=f"pseudolight {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("scenes", help="list the shipped scene specs")
    s.set_defaults(func=cmd_scenes)

    g = sub.add_parser("generate", help="render a scene spec into a dataset folder")
    g.add_argument("scene", help="scene spec TOML, the name of a shipped scene, or 'random' (the seeded random "
                                 "family: --seed N draws the scene)")
    g.add_argument("-o", "--output", required=True, help="dataset folder to create")
    g.add_argument("--profile", help="a [profiles.NAME] table of the spec, e.g. benchmark")
    g.add_argument("--resolution", type=_positive_int, help="image width and height in pixels")
    g.add_argument("--views", type=_positive_int, help="number of training views")
    g.add_argument("--test-views", type=_count, help="number of held-out test views")
    g.add_argument("--spp", type=_positive_int, help="samples per pixel")
    g.add_argument("--seed", type=_int_at_least(0, 2 ** 31 - 1))
    g.add_argument("--variant", choices=VARIANTS + ("auto",))
    g.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override any spec key, e.g. --set faults.noise_read=0.05 (repeatable; TOML values)")
    g.add_argument("--overwrite", action="store_true", help="replace an existing dataset folder")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    g.set_defaults(func=cmd_generate)

    e = sub.add_parser("estimate", help="estimate albedo and pseudo illumination from a dataset")
    e.add_argument("dataset")
    e.add_argument("-o", "--output", required=True, help="run folder to create")
    e.add_argument("--overwrite", action="store_true")
    e.add_argument("--strict", action="store_true",
                   help="exit with code 3 when the estimate warns (underdetermined, ill-conditioned, outlier "
                        "view, high residual, faces without views)")
    e.add_argument("--holdout-views", type=_positive_int, metavar="K",
                   help="also solve without K evenly spread views and record the prediction PSNR on them "
                        "(cross-validation, in run.json)")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="any estimator setting (docs/estimator.md), e.g. --set retinex_ridge=0.01; the value is read "
                        "as a TOML value, else as text; it wins over the flags above and the dataset's defaults")
    e.add_argument("--truth", metavar="DATASET", help="dataset whose ground_truth/ gives the known light of the "
                                                      "known-illumination oracle (default: the dataset itself)")
    _add_estimator_flags(e)
    e.set_defaults(func=cmd_estimate)

    r = sub.add_parser("render", help="predict images of a dataset's cameras from an estimate (RGBA EXRs: alpha "
                       "0 off the mesh and on unestimated faces)")
    r.add_argument("run")
    r.add_argument("--dataset", help="dataset folder (default: the one the run was made from)")
    r.add_argument("-o", "--output", required=True)
    r.add_argument("--frames", choices=("test", "train", "all"), default="test")
    r.add_argument("--rotate-illumination", nargs=2, metavar=("AXIS", "DEG"),
                   help="turn the pseudo illumination about x, y or z by DEG degrees")
    r.add_argument("--overwrite", action="store_true")
    r.add_argument("--no-fingerprint-check", action="store_true",
                    help="read a run against a dataset its fingerprint does not name (or a run without one)")
    r.set_defaults(func=cmd_render)

    rp = sub.add_parser("report", help="compare a run with its dataset's ground truth: metrics, figures, HTML")
    rp.add_argument("run")
    rp.add_argument("--dataset", help="dataset folder (default: the one the run was made from)")
    rp.add_argument("-o", "--output", required=True, help="report folder to create")
    rp.add_argument("--baseline", help="metrics baseline JSON: exit 1 naming each metric that got worse")
    rp.add_argument("--write-baseline", metavar="FILE",
                    help="store this report's tracked metrics as a baseline (replaces an existing baseline; any "
                         "other existing file only with --overwrite)")
    rp.add_argument("--rotate-illumination", nargs=2, metavar=("AXIS", "DEG"), default=["y", "90"],
                    help="relighting test: turn the light about x, y or z (default: y 90)")
    rp.add_argument("--cross-check-spp", type=_int_at_least(1, MAX_CROSS_CHECK_SPP),
                    help="spp of the Mitsuba re-render (default 64; 512 for --specular-model lobe; at most "
                         f"{MAX_CROSS_CHECK_SPP}, the scene specs' bound)")
    rp.add_argument("--no-mitsuba", action="store_true", help="skip the Mitsuba re-render cross-check")
    rp.add_argument("--no-figures", action="store_true",
                    help="write the metrics and the page without drawing the figures (most of a small report's time)")
    rp.add_argument("--protocol", action="append", choices=PROTOCOL_NAMES,
                    help="a published benchmark's metric set for the novel views and relighting (repeatable; "
                         f"default: all of {', '.join(PROTOCOL_NAMES)}); see docs/reports.md")
    rp.add_argument("--overwrite", action="store_true")
    rp.add_argument("--no-fingerprint-check", action="store_true",
                    help="read a run against a dataset its fingerprint does not name (or a run without one)")
    rp.set_defaults(func=cmd_report)

    cp = sub.add_parser("compare", help="one table and overlaid histograms over several reports")
    cp.add_argument("runs", nargs="+", help="report folders (or run folders holding report/)")
    cp.add_argument("-o", "--output", required=True)
    cp.add_argument("--overwrite", action="store_true")
    cp.set_defaults(func=cmd_compare)

    for name in ("suite", "bench"):   # one parser each, so each usage line names its own command
        _add_suite_parser(sub, name)

    tx = sub.add_parser("export-texture", help="an estimate as texture maps: UV atlas, PNG/EXR, OBJ+MTL, glTF")
    tx.add_argument("run")
    tx.add_argument("--dataset", help="dataset folder (default: the one the run was made from)")
    tx.add_argument("-o", "--output", required=True, help="folder to create")
    tx.add_argument("--size", type=_int_at_least(16), default=1024, help="texture width and height (default 1024)")
    tx.add_argument("--overwrite", action="store_true")
    tx.add_argument("--no-fingerprint-check", action="store_true",
                    help="read a run against a dataset its fingerprint does not name (or a run without one)")
    tx.set_defaults(func=cmd_export_texture)

    ex = sub.add_parser("export", help="a dataset in another tool's layout (nerf-synthetic, or stock Mitsuba "
                                       "scene XMLs per view)")
    ex.add_argument("dataset")
    ex.add_argument("--format", choices=("nerf-synthetic", "mitsuba"), default="nerf-synthetic")
    ex.add_argument("-o", "--output", required=True, help="folder to create")
    ex.add_argument("--size", type=_int_at_least(16), default=1024, help="ground-truth texture size (nerf-synthetic)")
    ex.add_argument(
        "--spp", type=_positive_int, help="samples per pixel of the Mitsuba scenes (default: the dataset's)"
    )
    ex.add_argument("--overwrite", action="store_true")
    ex.set_defaults(func=cmd_export)

    im = sub.add_parser(
        "import", help="another method's result (per-face arrays, UV textures or a Mitsuba scene XML) as a run"
    )
    im.add_argument("dataset")
    im.add_argument("--from", dest="source", choices=("per-face", "uv-textures", "mitsuba-xml"), required=True)
    im.add_argument("--file", help="per-face .npz (diffuse, specular, radiance_sh|pseudo_sh) or .csv; or a Mitsuba "
                                   "scene .xml")
    im.add_argument("--mesh", help="mesh file with texture coordinates (OBJ/PLY/glTF)")
    im.add_argument("--diffuse", help="diffuse texture (PNG/JPEG sRGB, EXR/HDR linear)")
    im.add_argument("--specular", help="specular texture")
    im.add_argument("--envmap", help="lat-long environment map (radiance, Mitsuba orientation)")
    im.add_argument("--exponent", default="10000",
                    help="Phong exponent filtering the envmap into the pseudo illumination (default 10000: a mirror)")
    im.add_argument("-o", "--output", required=True, help="run folder to create")
    im.add_argument("--overwrite", action="store_true")
    im.set_defaults(func=cmd_import)

    d = sub.add_parser("demo", help="the main job on the default scene (earth-specular)")
    d.add_argument("-o", "--output", default="out")
    d.add_argument("--variant", choices=VARIANTS + ("auto",))
    d.add_argument("--overwrite", action="store_true")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a bad flag (2, one line already printed)
        return int(exc.code or 0)
    _SIGNAL_SEEN[0] = None
    clear_stop()
    keep_freed_memory()
    with stop_signals_handled(_on_signal):
        try:
            return args.func(args)
        except BaseException as exc:
            kind = _SIGNAL_SEEN[0] or _interruption(exc)
            if kind is Terminated:
                print("pseudolight: terminated (SIGTERM); no partial output was left", file=sys.stderr)
                return 143
            if kind is KeyboardInterrupt:
                print("pseudolight: interrupted; no partial output was left", file=sys.stderr)
                return 130
            if isinstance(exc, InputError):
                print(f"pseudolight: error: {exc}", file=sys.stderr)
                return 2
            raise


if __name__ == "__main__":
    sys.exit(main())
