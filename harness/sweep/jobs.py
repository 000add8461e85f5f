"""The jobs of a sweep: plain-dict in, plain-dict out, importable top-level functions, so
a spawned worker or a Dask worker runs them from specs and paths (never Mitsuba objects).

A job's identity is a hash of what determines its result: the resolved scene spec (a
dataset), that dataset's identity plus the method, its parameters and whether the report
holds the Mitsuba cross-check (a run), and the code version. A finished job leaves
``job.json`` holding its identity and result in its folder; a job whose folder holds the same
identity is not run again, except a run whose report was written without figures when the
sweep asks for them (figures change no metric, so they are not part of the identity).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import resource
import time

JOB_FILE = "job.json"
PACKAGES = ("estimator", "reports", "harness")


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """sha256 (16 hex digits) over the source files of the packages that shape results."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    digest = hashlib.sha256()
    for package in PACKAGES:
        for folder, dirs, files in sorted(os.walk(os.path.join(root, package))):
            dirs.sort()
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(folder, name)
                    digest.update(os.path.relpath(path, root).encode())
                    with open(path, "rb") as f:
                        digest.update(f.read())
    return digest.hexdigest()[:16]


def identity(payload: dict) -> str:
    """16 hex digits of sha256 over a JSON-able payload plus the code version."""
    text = json.dumps({"payload": payload, "code": code_version()}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def finished(folder: str, job_id: str, figures: bool = True) -> dict | None:
    """The recorded result when ``folder`` holds a finished job of this identity (a run, with
    its report's figures when ``figures``), else None."""
    path = os.path.join(folder, JOB_FILE)
    try:
        with open(path) as f:
            record = json.load(f)
    except (OSError, ValueError, RecursionError):   # unreadable: the job runs again
        return None
    if not isinstance(record, dict) or record.get("id") != job_id:
        return None
    if record.get("kind") == "run" and not (isinstance(record.get("metrics"), dict)
                                            and os.path.isfile(os.path.join(folder, "report", "metrics.json"))):
        return None   # a damaged record or a deleted report: run it again
    if record.get("kind") == "run" and figures and not record.get("figures", True):
        return None   # its report has no figures, and they are asked for now
    if record.get("kind") == "dataset" and (not os.path.isfile(os.path.join(folder, "transforms.json"))
                                            or record.get("files") != file_digests(folder)):
        return None   # a file changed, truncated or deleted since it was made: make it again
    return record


def file_digests(folder: str) -> dict[str, str]:
    """{relative path: BLAKE2b-128 hex} of every file under ``folder`` but the job record:
    a cached dataset is reused only while these match what was written."""
    out = {}
    for root, _, names in os.walk(folder):
        for name in names:
            path = os.path.join(root, name)
            rel = os.path.relpath(path, folder)
            if rel == JOB_FILE or name.startswith(f".{JOB_FILE}"):
                continue
            digest = hashlib.blake2b(digest_size=16)
            with open(path, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    digest.update(block)
            out[rel] = digest.hexdigest()
    return dict(sorted(out.items()))


def _record(folder: str, record: dict) -> dict:
    tmp = os.path.join(folder, f".{JOB_FILE}.tmp-{os.getpid()}")
    with open(tmp, "w") as f:
        json.dump(record, f, indent=1, default=str)
    os.replace(tmp, os.path.join(folder, JOB_FILE))
    return record


def _threads(job: dict) -> None:
    from estimator import backend

    backend.set_variant(job.get("variant"))
    if job.get("threads"):
        backend.set_thread_count(job["threads"])


def _reusable(job: dict) -> dict | None:
    """The finished job's record (marked reused) unless ``force``; else None, after setting
    this worker's thread count for the work to come."""
    done = None if job.get("force") else finished(job["folder"], job["id"], job.get("figures", True))
    if done:
        return {**done, "reused": True}
    _threads(job)
    return None


def dataset_job(job: dict) -> dict:
    """Generate one dataset. ``job``: id, folder, spec_path, profile, overrides, force,
    variant, threads. Returns its record (``reused`` when it was there)."""
    done = _reusable(job)
    if done:
        return done
    from harness.scene.generate import generate
    from harness.scene.spec import load_spec

    t = time.perf_counter()
    summary = generate(load_spec(job["spec_path"], job["profile"], job["overrides"]), job["folder"], overwrite=True,
                       variant=job.get("variant"))
    return _record(job["folder"], {"id": job["id"], "kind": "dataset", "seconds": time.perf_counter() - t,
                                   "faces": summary["faces"], "views": summary["views"],
                                   "files": file_digests(job["folder"]), "reused": False})


def run_job(job: dict) -> dict:
    """Estimate and report one dataset with one method. ``job``: id, folder, dataset,
    method, params, mitsuba, figures, force, variant, threads. Returns its record with the report's
    headline metrics (the comparison columns)."""
    done = _reusable(job)
    if done:
        return done
    from harness.cli.suite import run_method
    from reports.html import lookup
    from reports.sweep import SWEEP_METRICS

    t = time.perf_counter()
    os.makedirs(job["folder"], exist_ok=True)
    est, metrics, _ = run_method(job["dataset"], job["method"], os.path.join(job["folder"], "run"),
                                 os.path.join(job["folder"], "report"), job.get("mitsuba", False),
                                 overrides=job["params"] or None, log=lambda m: None,
                                 figures=job.get("figures", True))
    row = {key: lookup(metrics, key) for _, key in SWEEP_METRICS if key != "seconds"}
    return _record(job["folder"], {
        "id": job["id"], "kind": "run", "seconds": time.perf_counter() - t,
        "estimate_seconds": float(est.info["timings"]["total"]), "figures": job.get("figures", True),
        "worker_peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "metrics": {k: (None if v is None else float(v)) for k, v in row.items()},
        "warnings": est.info.get("warnings", []), "reused": False})


def dataset_payload(job) -> dict:
    """What determines a dataset: its resolved spec (a DatasetJob)."""
    from harness.scene.generate import spec_json
    from harness.scene.spec import load_spec

    spec = load_spec(job.spec_path, job.profile, job.overrides)
    return {"spec": spec_json(spec)}

