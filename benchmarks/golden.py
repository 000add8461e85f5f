"""Golden outputs of every deterministic method, for refactors that must not change results.

    python benchmarks/golden.py record DATASET... -o GOLDEN_DIR
    python benchmarks/golden.py check  DATASET... -o GOLDEN_DIR

``record`` runs each deterministic registered method (all but ``mitsuba-ad``, whose step
count follows the wall clock) on each dataset with the dataset's own estimator defaults and
stores the estimate's arrays and its ``info`` (timings removed) in GOLDEN_DIR.
``check`` runs them again and compares bit for bit: arrays with ``np.array_equal``
(NaN equal to NaN), ``info`` as JSON text. It exits 1 on the first difference it reports.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from estimator import REGISTRY, estimate
from harness.io.dataset import read_dataset
from harness.io.runs import estimator_settings

ARRAYS = ("diffuse", "specular", "pseudo_sh", "labels", "observed", "radiance_sh")
SKIPPED = {"mitsuba-ad"}


def _info_text(info: dict) -> str:
    clean = {k: v for k, v in info.items() if k not in ("timings", "clustering_s")}
    return json.dumps(clean, sort_keys=True, default=lambda o: np.asarray(o).tolist())


def _run(path: str, method: str) -> tuple[dict, str]:
    ds = read_dataset(path, load_test=False, load_truth=True)
    _, config = estimator_settings(ds.meta, method)
    known = ds.ground_truth.known_light() if REGISTRY[method].needs_illumination else {}
    est = estimate(ds.data, method, config, **known)
    arrays = {name: getattr(est, name) for name in ARRAYS if getattr(est, name, None) is not None}
    arrays.update({f"face_stats.{k}": np.asarray(v) for k, v in est.face_stats.items()})
    return arrays, _info_text(est.info)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("mode", choices=("record", "check"))
    p.add_argument("datasets", nargs="+")
    p.add_argument("-o", "--golden", required=True)
    args = p.parse_args(argv)
    os.makedirs(args.golden, exist_ok=True)
    failed = 0
    for path in args.datasets:
        for method in sorted(set(REGISTRY) - SKIPPED):
            key = f"{os.path.basename(os.path.normpath(path))}--{method}"
            try:
                arrays, info = _run(path, method)
            except Exception as exc:   # a refusal is a result too: it must stay the same
                arrays, info = {}, f"error: {type(exc).__name__}: {exc}"
            stored = os.path.join(args.golden, key)
            if args.mode == "record":
                np.savez(stored + ".npz", **arrays)
                with open(stored + ".json", "w") as f:
                    f.write(info)
                print(f"recorded {key}")
                continue
            with np.load(stored + ".npz") as old, open(stored + ".json") as f:
                same = set(old.files) == set(arrays) and all(
                    np.array_equal(old[n], arrays[n], equal_nan=arrays[n].dtype.kind == "f") for n in arrays)
                same_info = f.read() == info
            print(f"{'same' if same and same_info else 'DIFFERENT'} {key}"
                  + ("" if same else " (arrays)") + ("" if same_info else " (info)"))
            failed += not (same and same_info)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
