"""Where the default method's time goes: cProfile of one estimate per dataset folder.

    python benchmarks/profile_default.py DATASET [DATASET ...] [--method NAME] [--top 25]

Each dataset (a folder ``pseudolight generate`` wrote, e.g. one of ``real_light.py``'s) is
estimated once with its own defaults under cProfile. Prints the estimate's stage timings
(``run.json``'s ``timings``) and the ``--top`` functions of the project and of NumPy/SciPy's
linear algebra by cumulative time, with their call counts. Run it alone: a loaded machine
inflates every stage (the estimate's BLAS runs on one thread, Dr.Jit's ray tracing on all).
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from estimator import estimate  # noqa: E402
from harness.cli.heap import keep_freed_memory  # noqa: E402
from harness.io.dataset import read_dataset  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402

SHOWN = ("estimator/", "linalg", "sparse/_base.py")   # the project's functions and the linear algebra


def main() -> None:
    keep_freed_memory()   # the heap the command line runs with
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("datasets", nargs="+")
    p.add_argument("--method", help="a registered method (default: the dataset's)")
    p.add_argument("--top", type=int, default=25, help="functions shown per dataset")
    args = p.parse_args()
    for folder in args.datasets:
        ds = read_dataset(folder, load_test=False, load_truth=False)
        method, config = estimator_settings(ds.meta, args.method, None)
        profile = cProfile.Profile()
        start = time.perf_counter()
        profile.enable()
        est = estimate(ds.data, method, config)
        profile.disable()
        wall = time.perf_counter() - start
        print(f"\n{os.path.basename(os.path.normpath(folder))} ({method}): {wall:.1f} s under cProfile; stages "
              + ", ".join(f"{k} {v:.2f} s" for k, v in est.info["timings"].items()))
        stats = pstats.Stats(profile)
        rows = [(cum, calls, f"{os.path.relpath(file, os.getcwd()) if 'estimator/' in file else file}:{line}({name})")
                for (file, line, name), (_, calls, _, cum, _) in stats.stats.items()
                if any(s in file for s in SHOWN)]
        print(f"{'cumulative s':>12} {'calls':>7}  function")
        for cum, calls, where in sorted(rows, reverse=True)[:args.top]:
            print(f"{cum:12.2f} {calls:7d}  {where}")


if __name__ == "__main__":
    main()
