"""Time and peak memory of `pseudolight generate earth-specular` (the default scene), in a child process."""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def measure(scene: str, out: str, extra: list[str]) -> dict:
    cmd = [sys.executable, "-m", "harness.cli", "generate", scene, "-o", out, "--overwrite", "--json", *extra]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    summary = json.loads(proc.stdout)
    return {"scene": scene, "args": extra, "wall_s": round(wall, 2),
            "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, 1),
            "stages_s": {k: round(v, 2) for k, v in summary["seconds"].items()}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--scene", default="earth-specular")
    p.add_argument("--profile")
    args = p.parse_args()
    extra = ["--profile", args.profile] if args.profile else []
    out = os.path.join(ROOT, "out", "bench", args.scene + (f"-{args.profile}" if args.profile else ""))
    print(json.dumps(measure(args.scene, out, extra), indent=1))


if __name__ == "__main__":
    main()
