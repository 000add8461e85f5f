"""Estimate runs on disk: estimate.npz, illumination.exr, run.json."""
from __future__ import annotations

import dataclasses
import json
import os
import platform
from importlib import metadata

import numpy as np

from estimator import sh
from estimator.config import EstimatorConfig
from estimator.data import Estimate

from harness.io.atomic import atomic_directory
from harness.io.exr import write_exr

ILLUMINATION_MAP_SIZE = (128, 256)
RUN_FORMAT = "pseudolight-run"
RUN_FORMAT_VERSION = 2  # 2: estimate.npz names the pseudo illumination pseudo_sh (1: sh)


class RunError(ValueError):
    """A run folder that is missing or malformed."""


def estimator_settings(meta: dict, method: str | None = None, overrides: dict | None = None
                       ) -> tuple[str, EstimatorConfig]:
    """Method and config for a dataset: EstimatorConfig defaults <- the dataset's
    ``estimator_defaults`` (its scene's [estimator] table) <- ``method``/``overrides``."""
    chosen = dict(meta.get("estimator_defaults") or {})
    default_method = chosen.pop("method", None) or "bilinear-clustered"
    chosen.update(overrides or {})
    return method or default_method, EstimatorConfig(**chosen)


def versions() -> dict:
    """Versions of pseudolight and the libraries that shape its numbers."""
    out = {"python": platform.python_version()}
    for name in ("pseudolight", "mitsuba", "drjit", "numpy", "scipy", "trimesh"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def write_run(folder: str, est: Estimate, dataset: str, overwrite: bool = False, extra: dict | None = None) -> None:
    """Write an estimate atomically (the folder appears whole or not at all).

    ``illumination.exr`` is the pseudo illumination on a 256x128 lat-long map in
    Mitsuba's envmap orientation, clamped at 0 (SH ringing can go negative;
    Mitsuba's envmap needs non-negative radiance); the exact SH are in estimate.npz.
    """
    with atomic_directory(folder, overwrite=overwrite) as tmp:
        extra_arrays = {} if est.radiance_sh is None else {"radiance_sh": est.radiance_sh}
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
            "versions": versions(),
            "faces": int(len(est.observed)),
            "observed_share": float(est.observed.mean()),
            "illumination_exr": {"size": list(ILLUMINATION_MAP_SIZE[::-1]), "clamped_at_zero": True,
                                 "negative_share": float(np.mean(image < 0))},
            **_jsonable(est.info),
            **(extra or {}),
        }
        with open(os.path.join(tmp, "run.json"), "w") as f:
            json.dump(run, f, indent=1)


def read_run(folder: str) -> tuple[Estimate, dict]:
    """(Estimate, run.json dict) of a run folder."""
    folder = os.path.abspath(folder)
    npz, js = os.path.join(folder, "estimate.npz"), os.path.join(folder, "run.json")
    for path in (npz, js):
        if not os.path.isfile(path):
            raise RunError(f"{folder} is not a run folder: {os.path.basename(path)} missing")
    with open(js) as f:
        run = json.load(f)
    data = np.load(npz)
    known = {f.name for f in dataclasses.fields(EstimatorConfig)}
    config = EstimatorConfig(**{k: v for k, v in run["parameters"].items() if k in known})
    pseudo = data["pseudo_sh"] if "pseudo_sh" in data else data["sh"]  # run format 1 named it sh
    est = Estimate(data["diffuse"], data["specular"], pseudo, data["labels"], data["observed"].astype(bool),
                   run["method"], config, {k: run[k] for k in ("timings",) if k in run},
                   data["radiance_sh"] if "radiance_sh" in data else None)
    return est, run


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value
