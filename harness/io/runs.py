"""Estimate runs on disk: estimate.npz, illumination.exr, run.json."""
from __future__ import annotations

import dataclasses
import os
import platform
from importlib import metadata

import numpy as np

from estimator import DEFAULT_METHOD, Estimate, EstimatorConfig, InputError, get_method, sh
from harness.io.arrays import read_npz, real_array
from harness.io.atomic import atomic_directory
from harness.io.exr import write_exr
from harness.io.jsonio import dump_json, load_json

ILLUMINATION_MAP_SIZE = (128, 256)
RUN_FORMAT = "pseudolight-run"
RUN_FORMAT_VERSION = 2  # 2: estimate.npz names the pseudo illumination pseudo_sh (1: sh)


class RunError(InputError):
    """A run folder that is missing or malformed."""


# the figures of run.json that a report prints as numbers (dotted paths; each may be absent or null)
REPORTED_NUMBERS = ("trust.residual.median_relative", "trust.outlier_share", "trust.light_condition",
                    "trust.albedo_relative_se.median", "cross_validation.psnr")


def _check_report_numbers(path: str, run: dict) -> None:
    """``trust`` and ``cross_validation`` of run.json at ``path``, where present, are objects,
    and each of :data:`REPORTED_NUMBERS` along them is a number or null."""
    for key in ("trust", "cross_validation"):
        if run.get(key) is not None and not isinstance(run[key], dict):
            raise RunError(f"{path}: '{key}' must be an object, got {str(run[key])[:60]!r}")
    for dotted in REPORTED_NUMBERS:
        node = run
        for part in dotted.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if node is not None and (isinstance(node, bool) or not isinstance(node, (int, float))):
            raise RunError(f"{path}: '{dotted}' must be a number, got {str(node)[:60]!r}")


def estimator_settings(meta: dict, method: str | None = None, overrides: dict | None = None
                       ) -> tuple[str, EstimatorConfig]:
    """Method and config for a dataset: EstimatorConfig defaults <- the dataset's
    ``estimator_defaults`` (its scene's [estimator] table) <- ``method``/``overrides``."""
    defaults = meta.get("estimator_defaults") or {}
    if not isinstance(defaults, dict):
        raise InputError(f"transforms.json estimator_defaults must be an object, got {defaults!r}")
    chosen = dict(defaults)
    default_method = chosen.pop("method", None)
    default_method = DEFAULT_METHOD if default_method is None else default_method   # "" is refused below
    if not isinstance(default_method, str):
        raise InputError(f"transforms.json estimator_defaults.method must be a string, got {default_method!r}")
    known = {f.name for f in dataclasses.fields(EstimatorConfig)}
    unknown = sorted(set(chosen) - known)
    if unknown:
        raise InputError(f"transforms.json estimator_defaults: unknown key(s) {', '.join(unknown)}")
    try:   # the dataset's own values that the caller keeps, named as the dataset's
        EstimatorConfig(**{k: v for k, v in chosen.items() if k not in (overrides or {})})
        if method is None:
            get_method(default_method)
    except InputError as exc:
        raise InputError(f"transforms.json estimator_defaults: {exc}") from None
    if method is not None:
        get_method(method)   # an empty or unknown name is refused, not taken for the default
    chosen.update(overrides or {})
    return default_method if method is None else method, EstimatorConfig(**chosen)


def versions() -> dict:
    """Versions of pseudolight and the libraries that shape its numbers."""
    out = {"python": platform.python_version()}
    for name in ("pseudolight", "mitsuba", "drjit", "numpy", "scipy", "trimesh"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def write_run(folder: str, est: Estimate, dataset: str, overwrite: bool = False, extra: dict | None = None,
              fingerprint: dict | None = None, inputs: list | None = None) -> None:
    """Write an estimate atomically (the folder appears whole or not at all).

    ``illumination.exr`` is the pseudo illumination on a 256x128 lat-long map in
    Mitsuba's envmap orientation, clamped at 0 (SH ringing can go negative;
    Mitsuba's envmap needs non-negative radiance); the exact SH are in estimate.npz.
    ``fingerprint`` (:func:`harness.io.dataset.fingerprint`) identifies the mesh,
    cameras and images the estimate was computed from; ``report`` checks it. ``inputs``:
    further paths the output must not touch (the dataset's files, :attr:`Dataset.inputs`).
    """
    with atomic_directory(folder, overwrite=overwrite, inputs=[dataset, *(inputs or [])], kind="run") as tmp:
        extra_arrays = {} if est.radiance_sh is None else {"radiance_sh": est.radiance_sh}
        extra_arrays.update({f"face_{name}": value for name, value in est.face_stats.items()})
        np.savez(os.path.join(tmp, "estimate.npz"), diffuse=est.diffuse, specular=est.specular, pseudo_sh=est.pseudo_sh,
                 sh_order=est.sh_order, labels=est.labels, observed=est.observed, **extra_arrays)
        image = sh.to_latlong(est.pseudo_sh, *ILLUMINATION_MAP_SIZE)
        write_exr(os.path.join(tmp, "illumination.exr"), np.maximum(image, 0.0))
        run = {
            "format": RUN_FORMAT,
            "format_version": RUN_FORMAT_VERSION,
            "method": est.method,
            "parameters": est.config.to_dict(),
            "dataset": os.path.abspath(dataset),
            "fingerprint": fingerprint,
            "versions": versions(),
            "faces": int(len(est.observed)),
            "observed_share": float(est.observed.mean()),
            "illumination_exr": {"size": list(ILLUMINATION_MAP_SIZE[::-1]), "clamped_at_zero": True,
                                 "negative_share": float(np.mean(image < 0))},
            **est.info,
            **(extra or {}),
        }
        dump_json(os.path.join(tmp, "run.json"), run)


FACE_STATS = {  # per-face arrays of estimate.npz (face_<name>): trailing shape, integer, inf allowed
    "observations": ((), True, False), "albedo_se": ((3,), False, True), "albedo_history": ((None, 3), False, False),
    "unestimated_reason": ((), True, False)}


def _face_stats(npz: str, data: dict, f: int) -> dict:
    """The per-face trust arrays of an estimate.npz, each checked for shape, type and values."""
    out = {}
    for name, (tail, integer, inf_ok) in FACE_STATS.items():
        key = f"face_{name}"
        if key not in data:
            continue
        a = data[key]
        shape_ok = a.ndim == 1 + len(tail) and a.shape[0] == f and all(
            want is None or got == want for want, got in zip(tail, a.shape[1:]))
        kind_ok = np.issubdtype(a.dtype, np.integer) if integer else np.issubdtype(a.dtype, np.floating)
        if not (shape_ok and kind_ok):
            raise RunError(
                f"{npz}: {key} must be {'integer' if integer else 'float'} of shape "
                f"({f}{''.join(', ' + ('K' if t is None else str(t)) for t in tail)}), got {a.dtype} {a.shape}"
            )
        if not integer and (np.isnan(a).any() or (not inf_ok and not np.all(np.isfinite(a)))):
            raise RunError(f"{npz}: {key} contains NaN{'' if inf_ok else ' or Inf'}")
        out[name] = a
    return out


def read_run(folder: str) -> tuple[Estimate, dict]:  # noqa: C901  (one check per key of the format)
    """(Estimate, run.json dict) of a run folder; anything missing, malformed or
    non-finite raises :class:`RunError` naming the file and key."""
    folder = os.path.abspath(folder)
    npz, js = os.path.join(folder, "estimate.npz"), os.path.join(folder, "run.json")
    if not os.path.isdir(folder):
        raise RunError(f"run folder not found: {folder}")
    for path in (npz, js):
        if not os.path.isfile(path):
            raise RunError(f"{folder} is not a run folder: {os.path.basename(path)} missing")
    run = load_json(js, "run", RunError)
    if run.get("format", RUN_FORMAT) != RUN_FORMAT:
        raise RunError(f"{js}: format {run['format']!r} is not {RUN_FORMAT!r}: not a pseudolight run")
    version = run.get("format_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= RUN_FORMAT_VERSION:
        raise RunError(
            f"{js}: format_version {version!r} is not one this pseudolight reads (1 to {RUN_FORMAT_VERSION})"
        )
    for key, kind in (("method", str), ("parameters", dict), ("dataset", str)):
        if not isinstance(run.get(key), kind) or (kind is str and not run[key]):
            raise RunError(f"{js}: '{key}' missing or not a {kind.__name__}")
    warnings = run.get("warnings", [])
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        raise RunError(f"{js}: 'warnings' must be a list of strings, got {str(warnings)[:60]!r}")
    _check_report_numbers(js, run)
    data = read_npz(npz, RunError)
    pseudo_key = "sh" if "sh" in data and "pseudo_sh" not in data else "pseudo_sh"   # run format 1 named it sh
    for key in ("diffuse", "specular", pseudo_key, "labels", "observed"):
        if key not in data:
            raise RunError(f"{npz}: key '{key}' missing")
    for key in ("diffuse", "specular", pseudo_key, "radiance_sh"):
        if key in data:
            data[key] = real_array(f"{npz}: {key}", data[key], RunError)
            if not np.all(np.isfinite(data[key])):
                raise RunError(f"{npz}: {key} contains NaN or Inf")
            if np.any(np.abs(data[key]) > np.finfo(np.float32).max):   # images and textures hold float32
                raise RunError(f"{npz}: {key} exceeds the float32 range of the images and textures made from it "
                               f"(largest magnitude {np.abs(data[key]).max():.3g})")
    f = data["diffuse"].shape[0] if data["diffuse"].ndim == 2 else -1
    if f < 1 or data["diffuse"].shape != (f, 3) or data["specular"].shape != (f, 3) or data["labels"].shape != (f,) \
            or data["observed"].shape != (f,):
        raise RunError(f"{npz}: diffuse, specular (F, 3), labels and observed (F,) disagree in shape")
    if not np.issubdtype(data["labels"].dtype, np.integer) or data["observed"].dtype != bool:
        raise RunError(f"{npz}: labels must be integers and observed booleans, got {data['labels'].dtype} "
                       f"and {data['observed'].dtype}")
    if data["labels"].min() < -1 or data["labels"].max() >= f:
        raise RunError(f"{npz}: labels must lie in [-1, {f}) (a region or cluster of the {f} faces, -1 none), got "
                       f"{data['labels'].min()} to {data['labels'].max()}")
    if not data["observed"].any():
        raise RunError(f"{npz}: observed is false for every face: the run estimated nothing")
    negative = data["observed"] & np.any(data["diffuse"] + data["specular"] < 0, axis=1)
    if negative.any():   # the estimator marks such a face unestimated (estimator.diagnostics.screening)
        raise RunError(f"{npz}: {int(negative.sum())} observed faces have a negative albedo (diffuse + specular; "
                       f"first: face {int(np.argmax(negative))})")
    for key in (pseudo_key, "radiance_sh"):
        if key in data and (data[key].ndim != 2 or data[key].shape[1] != 3
                            or int(np.sqrt(data[key].shape[0])) ** 2 != data[key].shape[0]):
            raise RunError(f"{npz}: {key} must be ((L+1)^2, 3), got {data[key].shape}")
    if "radiance_sh" in data and data["radiance_sh"].shape != data[pseudo_key].shape:
        raise RunError(f"{npz}: radiance_sh and {pseudo_key} differ in shape")
    history = run.get("ad_history")
    if history is not None:
        seconds = history.get("snapshot_seconds", []) if isinstance(history, dict) else None
        if not isinstance(seconds, list) or not all(isinstance(t, (int, float)) and not isinstance(t, bool)
                                                    and np.isfinite(t) for t in seconds):
            raise RunError(f"{js}: ad_history.snapshot_seconds must be a list of finite numbers")
    known = {field.name for field in dataclasses.fields(EstimatorConfig)}
    try:
        config = EstimatorConfig(**{k: v for k, v in run["parameters"].items() if k in known})
    except (TypeError, InputError) as exc:
        raise RunError(f"{js}: parameters: {exc}") from None
    if data[pseudo_key].shape[0] != (config.sh_order + 1) ** 2:
        raise RunError(f"{npz}: {pseudo_key} has {data[pseudo_key].shape[0]} coefficients, run.json's sh_order "
                       f"{config.sh_order} needs {(config.sh_order + 1) ** 2}")
    est = Estimate(
        data["diffuse"],
        data["specular"],
        data[pseudo_key],
        data["labels"],
        data["observed"].astype(bool),
        run["method"],
        config,
        {k: run[k] for k in ("timings", "trust", "warnings", "ad_history") if k in run},
        data.get("radiance_sh"),
        _face_stats(npz, data, f),
    )
    if est.model.light == "radiance" and est.radiance_sh is None:
        raise RunError(f"{npz}: key 'radiance_sh' missing (the {est.model.name!r} model solves for the radiance)")
    return est, run
