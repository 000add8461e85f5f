"""Distorted captures: the same scene rendered through a pinhole and through distorting
lenses (Mitsuba traces the rays of each distorted pixel, ``harness.scene.render.render_through_lens``),
estimated from the images as recorded, with the lens written in transforms.json (the reader
undistorts them, ``harness.io.lens``) and with the lens keys removed (what a reader that
ignored them would get).

    python benchmarks/lens.py [--out DIR] [--scene real-light] [--profile tiny]

Prints one row per case: diffuse albedo PSNR and share within ±10 % (least-squares gauge),
the share of faces estimated and the time; writes DIR/lens.json.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from scoring import score  # noqa: E402

from estimator import estimate  # noqa: E402
from harness.io.dataset import read_dataset, read_ground_truth  # noqa: E402
from harness.io.lens import COEFFICIENTS  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402
from harness.scene.generate import generate  # noqa: E402
from harness.scene.spec import load_spec, resolve_scene  # noqa: E402

# a wide-angle lens as COLMAP reports them (barrel, slight decentring) and a mild fisheye
LENSES = {
    "pinhole": {},
    "opencv": {"cameras.lens_model": "OPENCV", "cameras.k1": -0.3, "cameras.k2": 0.08,
               "cameras.p1": 0.002, "cameras.p2": -0.001},
    "fisheye": {"cameras.lens_model": "OPENCV_FISHEYE", "cameras.k1": 0.05, "cameras.k2": -0.01},
}


def strip_lens(source: str, target: str) -> None:
    """A copy of a dataset whose transforms.json says PINHOLE and has no distortion keys."""
    shutil.copytree(source, target)
    path = os.path.join(target, "transforms.json")
    with open(path) as f:
        top = json.load(f)
    for key in COEFFICIENTS:
        top.pop(key, None)
    top["camera_model"] = "PINHOLE"
    with open(path, "w") as f:
        json.dump(top, f, indent=1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/bench-lens")
    p.add_argument("--scene", default="real-light")
    p.add_argument("--profile")
    args = p.parse_args()
    folders = {}
    for name, overrides in LENSES.items():
        folders[name] = os.path.join(args.out, name)
        if not os.path.isdir(folders[name]):
            generate(load_spec(resolve_scene(args.scene), args.profile, overrides), folders[name])
        if overrides:
            folders[f"{name} ignored"] = os.path.join(args.out, f"{name}-ignored")
            if not os.path.isdir(folders[f"{name} ignored"]):
                strip_lens(folders[name], folders[f"{name} ignored"])
    rows = []
    for name, folder in folders.items():
        ds = read_dataset(folder, load_test=False, load_truth=False)
        truth = read_ground_truth(folder, ds.data.mesh.num_faces)
        method, config = estimator_settings(ds.meta, None, None)
        t = time.perf_counter()
        est = estimate(ds.data, method, config)
        row = {"case": name, "method": method, "seconds": time.perf_counter() - t, **score(ds, truth, est)}
        rows.append(row)
        print(f"{name:18s} PSNR {row['psnr']:6.2f} dB  ±10% {row['within_10']:.3f}  "
              f"estimated {row['estimated_share']:.3f}  {row['seconds']:5.1f} s", flush=True)
    with open(os.path.join(args.out, "lens.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
