"""Warnings on clean scenes: the false-alarm rate of the estimator's warnings.

Every shipped scene and seeds of the random family (docs/scene-spec.md) are generated
without any capture fault, estimated with each dataset's defaults, and each warning the
estimate raises is counted by kind (its text up to the first ':'). A warning on these
scenes is a false alarm, except 'face(s) left unestimated' (a statement, not an alarm:
counted apart, as is the share of faces no view sees near their normal: both describe what
the views cover). With ``--holdout K`` each run is also cross-validated on K held-out
views (as ``estimate --holdout-views K``), its warnings counted too, and the largest
departure of a held-out view's exposure gain from 1 recorded (what clean scenes show
bounds any exposure test drawn from it). With ``--faults``, the same on scenes with those
capture faults (the detection rate).

    python benchmarks/false_alarms.py [--out DIR] [--profile tiny] [--seeds 0-19] [--holdout 4]
                                      [--scenes all] [--faults KEY=VALUE ...] [--name NAME]

Writes DIR/NAME.json (one row per scene) and prints the rate per warning kind.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from random_family import seeds as parse_seeds  # noqa: E402
from scoring import setting  # noqa: E402

from estimator import InputError, estimate  # noqa: E402
from estimator.diagnostics.validation import cross_validate, cross_validation_warnings  # noqa: E402
from harness.io.dataset import read_dataset  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402
from harness.scene.generate import generate  # noqa: E402
from harness.scene.random_family import random_spec  # noqa: E402
from harness.scene.spec import load_spec, shipped_scenes  # noqa: E402

# statements about what the data cover, not alarms: the faces they leave without an estimate
STATEMENTS = ("face(s) left unestimated", "% of the faces have no observation")


def kind(warning: str) -> str:
    """A warning's kind: its words before the first ':' or number, e.g. 'outlier view'."""
    head = warning.split(":")[0]
    words = [w for w in head.split() if not any(ch.isdigit() for ch in w) and "/" not in w and "." not in w]
    return " ".join(words[:4])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/bench-false-alarms")
    p.add_argument("--profile", default="tiny", help="the scenes' profile ('' for full size)")
    p.add_argument("--seeds", default="0-19", help="random family seeds, e.g. 0-19 ('' for none)")
    p.add_argument("--scenes", default="all", help="shipped scenes, comma-separated, 'all' or ''")
    p.add_argument("--faults", type=setting, action="append", default=[], metavar="KEY=VALUE",
                   help="a capture fault for every scene, e.g. faults.exposure_jitter=0.3")
    p.add_argument("--holdout", type=int, default=4, help="held-out views for cross-validation (0: none)")
    p.add_argument("--name", default="false_alarms")
    args = p.parse_args()
    faults = {key if key.startswith("faults.") else f"faults.{key}": value for key, value in args.faults}
    tag = "-".join(f"{k.split('.')[-1]}{v}" for k, v in faults.items())
    specs = []
    names = sorted(shipped_scenes()) if args.scenes == "all" else [s for s in args.scenes.split(",") if s]
    for name in names:
        specs.append((name, lambda name=name: load_spec(shipped_scenes()[name], args.profile or None, faults)))
    for seed in parse_seeds(args.seeds) if args.seeds else []:
        specs.append((f"random-{seed:04d}", lambda seed=seed: random_spec(seed, args.profile or None, faults)))
    rows = []
    for name, build in specs:
        folder = os.path.join(args.out, f"{name}{'-' + tag if tag else ''}")
        if not os.path.isdir(folder):
            generate(build(), folder)
        ds = read_dataset(folder, load_test=False, load_truth=False)
        method, config = estimator_settings(ds.meta, None, None)
        t = time.perf_counter()
        try:
            est = estimate(ds.data, method, config)
        except InputError as exc:
            rows.append({"scene": name, "method": method, "error": str(exc)})
            print(f"{name:28s} {method:22s} error: {exc}", flush=True)
            continue
        warnings, deviation = list(est.info["warnings"]), None
        if args.holdout:
            cv = cross_validate(ds.data, args.holdout, lambda d, m=method, c=config: estimate(d, m, c))
            warnings += cross_validation_warnings(cv)
            gains = [g for v in cv["views"] for g in v["gain"] if g is not None]
            deviation = max(abs(g - 1.0) for g in gains) if gains else None
        views = (est.info.get("trust") or {}).get("views", [])
        rows.append({"scene": name, "method": method, "seconds": time.perf_counter() - t,
                     "warnings": warnings, "held_out_gain_deviation": deviation,
                     "views": [{k: v.get(k) for k in ("view", "observations", "gross_share")} for v in views]})
        print(f"{name:28s} {method:22s} held-out gain dev {deviation if deviation is not None else float('nan'):.3f}"
              f"  {[kind(w) for w in warnings]}", flush=True)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, f"{args.name}.json"), "w") as f:
        json.dump(rows, f, indent=1)
    done = [r for r in rows if "warnings" in r]
    counts = collections.Counter(k for r in done for k in {kind(w) for w in r["warnings"]})
    alarms = sum(1 for r in done if any(not any(s in w for s in STATEMENTS) for w in r["warnings"]))
    deviations = sorted(r["held_out_gain_deviation"] for r in done if r.get("held_out_gain_deviation") is not None)
    if deviations:
        print(f"held-out gain departure: median {deviations[len(deviations) // 2]:.3f}, max {deviations[-1]:.3f}")
    print(f"{len(done)} scenes estimated ({len(rows) - len(done)} refused); any alarm: {alarms} "
          f"({100 * alarms / max(len(done), 1):.0f} %)")
    for name, n in counts.most_common():
        statement = any(name.startswith(s) or s.startswith(name) for s in STATEMENTS)
        print(f"  {n:3d} ({100 * n / len(done):3.0f} %)  {name}{'  [statement]' if statement else ''}")


if __name__ == "__main__":
    main()
