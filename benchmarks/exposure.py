"""Auto-exposure: the default method with and without ``view_gains`` on views recorded at
different exposure and white balance (``faults.exposure_jitter``, ``faults.white_balance_jitter``).

    python benchmarks/exposure.py [--out DIR] [--scenes real-light,real-light-textured]
                                  [--materials plastic,diffuse] [--jitter 0,0.1,0.3]
                                  [--white-balance 0.05] [--profile tiny]

For each scene, material and exposure spread (the white-balance spread is applied with every
non-zero exposure spread), prints the diffuse PSNR and share within ±10 % without and with
``view_gains``, the estimated gains' median and largest relative error against the gains the
generator drew (both normalised to a geometric mean of 1 over the views), and the time;
writes the rows to DIR/exposure.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
from scoring import score  # noqa: E402

from estimator import estimate  # noqa: E402
from harness.io.dataset import read_dataset, read_ground_truth  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402
from harness.scene.generate import generate  # noqa: E402
from harness.scene.spec import load_spec, resolve_scene  # noqa: E402


def drawn_gains(meta: dict, views: int) -> np.ndarray:
    """(V, 3) the gains the generator drew for the training views (1 without the fault),
    normalised to a geometric mean of 1 per channel."""
    gains = np.asarray(meta.get("faults", {}).get("view_gains") or np.ones((views, 3)), float)[:views]
    return gains / np.exp(np.log(gains).mean(axis=0))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="out/bench-exposure")
    p.add_argument("--scenes", default="real-light,real-light-textured")
    p.add_argument("--materials", default="plastic,diffuse")
    p.add_argument("--jitter", default="0,0.1,0.3", help="exposure spreads (sigma of log gain)")
    p.add_argument("--white-balance", type=float, default=0.05, help="per-channel spread with each exposure spread")
    p.add_argument("--profile")
    args = p.parse_args()
    rows = []
    for scene in args.scenes.split(","):
        for material in args.materials.split(","):
            for jitter in (float(j) for j in args.jitter.split(",")):
                balance = args.white_balance if jitter > 0 else 0.0
                folder = os.path.join(args.out, f"{scene}-{material}-exposure{jitter:g}")
                if not os.path.isdir(folder):
                    generate(load_spec(resolve_scene(scene), args.profile, {
                        "material.model": material, "faults.exposure_jitter": jitter,
                        "faults.white_balance_jitter": balance}), folder)
                ds = read_dataset(folder, load_test=False, load_truth=False)
                truth = read_ground_truth(folder, ds.data.mesh.num_faces)
                drawn = drawn_gains(ds.meta, len(ds.data.views))
                for gains in (False, True):
                    method, config = estimator_settings(ds.meta, None, {"view_gains": gains})
                    t = time.perf_counter()
                    est = estimate(ds.data, method, config)
                    row = {"scene": scene, "material": material, "exposure_jitter": jitter,
                           "white_balance_jitter": balance, "view_gains": gains,
                           "seconds": time.perf_counter() - t, **score(ds, truth, est)}
                    error = "           -"
                    if gains:
                        found = np.array([est.info["view_gains"][v.name] for v in ds.data.views])
                        off = np.abs(found / drawn - 1)
                        row["gain_error_median"], row["gain_error_max"] = float(np.median(off)), float(off.max())
                        error = f"{row['gain_error_median']:.3f}/{row['gain_error_max']:.3f}"
                    rows.append(row)
                    print(f"{scene:20s} {material:9s} jitter {jitter:4g} gains {str(gains):5s} "
                          f"PSNR {row['psnr']:6.2f} dB  ±10% {row['within_10']:.3f}  gain error {error}  "
                          f"{row['seconds']:5.1f} s", flush=True)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "exposure.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
