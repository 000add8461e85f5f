"""Time and peak memory of generation and estimation against mesh size (earth-specular,
24 views at 256², its recommended method), one fresh process per size so the peak RSS is
that size's own.

    python benchmarks/scale.py [--out DIR] [--subdivisions 5,6] [--resolution 256]

Subdivision s of the icosphere gives 20 x 4^s faces: 5 -> 20,480, 6 -> 81,920,
7 -> 327,680. Prints faces, generation and estimation seconds (per stage) and peak RSS, and
how time grows with faces x directions.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CHILD = r"""
import json, os, resource, sys, time
sys.path.insert(0, {root!r})
from harness.scene.generate import generate
from harness.scene.spec import load_spec, resolve_scene
from harness.io.dataset import read_dataset
from harness.io.runs import estimator_settings
from estimator.methods import estimate
folder = {folder!r}
t = time.perf_counter()
if not os.path.isdir(folder):
    generate(load_spec(resolve_scene("earth-specular"), None, {{"geometry.subdivisions": {sub}, "cameras.width": {res},
                                                               "cameras.height": {res}}}), folder)
gen = time.perf_counter() - t
gen_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
ds = read_dataset(folder, load_test=False, load_truth=False)
method, config = estimator_settings(ds.meta)
est = estimate(ds.data, method, config)
print(json.dumps({{"faces": ds.data.mesh.num_faces, "generate_s": gen, "generate_peak_mib": gen_rss,
                  "timings": est.info["timings"], "observations": est.info["observations"],
                  "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}}))
"""


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/bench-scale")
    p.add_argument("--subdivisions", default="5,6")
    p.add_argument("--resolution", type=int, default=256)
    args = p.parse_args()
    rows = []
    for sub in (int(s) for s in args.subdivisions.split(",")):
        folder = os.path.abspath(os.path.join(args.out, f"earth-s{sub}-{args.resolution}"))
        code = CHILD.format(root=ROOT, folder=folder, sub=sub, res=args.resolution)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        row = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append(row)
        t = row["timings"]
        print(f"{row['faces']:8d} faces: estimate {t['total']:6.1f} s (observations {t['observations']:.1f}, "
              f"visibility {t['visibility']:.1f}, reflection {t['reflection']:.1f}, solve {t['solve']:.1f}), "
              f"peak {row['peak_mib']:.0f} MiB; {row['observations']} observations", flush=True)
    for a, b in zip(rows, rows[1:]):
        print(f"x{b['faces'] / a['faces']:.1f} faces: estimate x{b['timings']['total'] / a['timings']['total']:.2f}, "
              f"visibility x{b['timings']['visibility'] / a['timings']['visibility']:.2f}, "
              f"peak x{b['peak_mib'] / a['peak_mib']:.2f}")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "scale.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
