"""Accuracy on the real-light family (Mitsuba's own materials, HDR envmaps, path tracing
with interreflections) for several methods, at full size by default.

    python benchmarks/real_light.py [--out DIR] [--probes lab,park,...] [--rotations 0,120]
                                    [--materials plastic,roughplastic,diffuse]
                                    [--methods NAME,...] [--scene real-light] [--profile tiny]
                                    [--set KEY=VALUE ...] [--name real_light]

``--probes`` takes shipped probe names and ``sunsky`` / ``sunsky-low`` (Mitsuba's sun and
sky, the sun 50 or 16 degrees high).

Datasets are generated once into DIR (reused when present). Prints one row per
(scene, material, probe, rotation, method): diffuse-albedo PSNR after a per-channel
least-squares scale, share of faces within ±10 % (least-squares gauge, luminance), ARI,
estimate time; writes the rows to DIR/NAME.json. ``--set`` overrides estimator settings
(JSON values, e.g. ``--set retinex_ridge=1e-11``) for every method.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
from scoring import score, setting  # noqa: E402

from estimator import estimate  # noqa: E402
from harness.io.dataset import read_dataset, read_ground_truth  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402
from harness.scene.generate import generate  # noqa: E402
from harness.scene.spec import load_spec, resolve_scene  # noqa: E402


def light_overrides(probe: str) -> dict:
    """Spec overrides of one light of the family: a shipped probe by name (an ``envmap``),
    or ``sunsky`` (Mitsuba's Hosek-Wilkie sun and sky, the spec's sun direction) and
    ``sunsky-low`` (a sun 15 degrees above the horizon)."""
    if probe == "sunsky":
        return {"illumination.type": "sunsky", "illumination.file": None}
    if probe == "sunsky-low":
        return {"illumination.type": "sunsky", "illumination.file": None, "illumination.to_sun": [0.8, 0.27, 0.53]}
    ext = "hdr" if probe in ("grace", "uffizi") else "exr"
    return {"illumination.file": f"assets/{probe}.{ext}"}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/bench-real-light")
    p.add_argument("--scene", default="real-light")
    p.add_argument("--profile")
    p.add_argument("--materials", default="plastic,roughplastic,diffuse")
    p.add_argument("--probes", default="lab,park,studio,city,sunrise,apartment")
    p.add_argument("--rotations", default="0,120")
    p.add_argument("--methods", default="bilinear-clustered")
    p.add_argument("--set", type=setting, action="append", default=[], metavar="KEY=VALUE",
                   help="estimator setting for every method (value read as JSON, else text)")
    p.add_argument("--name", default="real_light", help="basename of the written .json")
    args = p.parse_args()
    overrides = dict(args.set)
    rows = []
    for material in args.materials.split(","):
        for probe in args.probes.split(","):
            for rotation in (float(r) for r in args.rotations.split(",")):
                name = f"{args.scene}-{material}-{probe}-{rotation:g}"
                folder = os.path.join(args.out, name)
                if not os.path.isdir(folder):
                    spec = load_spec(resolve_scene(args.scene), args.profile, {
                        "material.model": material, "illumination.rotation": rotation, **light_overrides(probe)})
                    generate(spec, folder)
                ds = read_dataset(folder, load_test=False, load_truth=False)
                truth = read_ground_truth(folder, ds.data.mesh.num_faces)
                for method in args.methods.split(","):
                    m, config = estimator_settings(ds.meta, method, overrides or None)
                    t = time.perf_counter()
                    est = estimate(ds.data, m, config)
                    seconds = time.perf_counter() - t
                    row = {"scene": args.scene, "material": material, "probe": probe, "rotation": rotation,
                           "method": m, "seconds": seconds, "clusters": est.info.get("clusters"),
                           **score(ds, truth, est)}
                    rows.append(row)
                    ari = "-" if row["ari"] is None else f"{row['ari']:.3f}"
                    print(f"{material:12s} {probe:10s} {rotation:5g} {m:22s} PSNR {row['psnr']:6.2f} dB  "
                          f"±10% {row['within_10']:.3f}  ARI {ari}  clusters {row['clusters']}  "
                          f"{seconds:5.1f} s", flush=True)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, f"{args.name}.json"), "w") as f:
        json.dump(rows, f, indent=1)
    for method in sorted({r["method"] for r in rows}):
        sel = [r for r in rows if r["method"] == method]
        psnr = np.array([r["psnr"] for r in sel])
        print(f"{method}: PSNR median {np.median(psnr):.2f} dB (min {psnr.min():.2f}), "
              f"±10% median {np.median([r['within_10'] for r in sel]):.3f}, "
              f"time median {np.median([r['seconds'] for r in sel]):.1f} s, {len(sel)} cases")


if __name__ == "__main__":
    main()
