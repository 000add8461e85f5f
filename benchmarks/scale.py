"""Time, peak memory and accuracy of generation and estimation against mesh size (a shipped
icosphere or blob scene, 24 views), one fresh process per size so each peak RSS is that size's
own.

    python benchmarks/scale.py [--scene earth-specular] [--method NAME] [--out DIR]
                               [--subdivisions 5,7,8] [--resolution 1024] [--spp 1] [--pure-pixels]

``--scene`` (default earth-specular, whose texture is in the specular albedo) is estimated with
its recommended method, or ``--method``; ``sunsky-earth`` (a textured diffuse albedo) and
``sparse-colored`` (uniform regions) measure the default method. The score is the albedo the
method estimates (the specular for a specular-only run, else the diffuse).

Subdivision s of the icosphere gives 20 x 4^s faces: 5 -> 20,480, 7 -> 327,680,
8 -> 1,310,720. At 1024² a face of the 1.3M mesh covers about one pixel, so no pixel lies
inside a single face: the default uses every pixel centre (``pure_pixels`` off; ``--pure-pixels``
keeps the scene's setting). Above ``dense_rows`` (1.5 M faces + observations) the estimator
streams its reflection rows (:class:`estimator.pipeline.prepared.Prepared`).

Prints per size: faces, observations, generation and estimation seconds (per stage), the
peak RSS of each, the albedo PSNR and share of faces within ±10 % of the truth (least-squares
gauge, :func:`scoring.score`) and the estimated share; then how the stages grow:
shadow-function time per face x direction, observation time per view x pixel.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

GENERATE = r"""
import json, resource, sys, time
sys.path.insert(0, {root!r})
from harness.scene.generate import generate
from harness.scene.spec import load_spec, resolve_scene
t = time.perf_counter()
generate(load_spec(resolve_scene({scene!r}), None, {overrides!r}), {folder!r})
print(json.dumps({{"generate_s": time.perf_counter() - t,
                  "generate_peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}}))
"""

ESTIMATE = r"""
import json, resource, sys
from dataclasses import replace
sys.path.insert(0, {root!r}); sys.path.insert(0, {root!r} + "/benchmarks")
from scoring import score
from harness.io.dataset import read_dataset, read_ground_truth
from harness.io.runs import estimator_settings
from estimator import estimate
ds = read_dataset({folder!r}, load_test=False, load_truth=False)
method, config = estimator_settings(ds.meta, {method!r})
if not {pure!r}:
    config = replace(config, pure_pixels=False)
est = estimate(ds.data, method, config)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
truth = read_ground_truth({folder!r}, ds.data.mesh.num_faces)
component = "specular" if config.components == "specular" else "diffuse"
print(json.dumps({{"faces": ds.data.mesh.num_faces, "views": len(ds.data.views), "method": method,
                  "pixels": int(ds.data.views[0].camera.width * ds.data.views[0].camera.height),
                  "directions": config.directions, "timings": est.info["timings"],
                  "observations": est.info["observations"], "streamed": "light_faces" in est.info,
                  "component": component, **score(ds, truth, est, component), "peak_mib": peak}}))
"""


def _child(code: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"child failed ({out.returncode}):\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="earth-specular")
    p.add_argument("--method", default=None, help="the method (default: the scene's recommended one)")
    p.add_argument("--out", default="out/bench-scale")
    p.add_argument("--subdivisions", default="5,7,8")
    p.add_argument("--resolution", type=int, default=1024)
    p.add_argument("--spp", type=int, default=1)
    p.add_argument("--pure-pixels", action="store_true", help="keep the scene's pure_pixels (on)")
    args = p.parse_args()
    rows = []
    for sub in (int(s) for s in args.subdivisions.split(",")):
        folder = os.path.abspath(os.path.join(args.out, f"{args.scene}-s{sub}-{args.resolution}-spp{args.spp}"))
        row = {}
        if not os.path.isdir(folder):
            overrides = {"geometry.subdivisions": sub, "cameras.width": args.resolution,
                         "cameras.height": args.resolution, "render.spp": args.spp}
            row.update(_child(GENERATE.format(root=ROOT, scene=args.scene, folder=folder, overrides=overrides)))
        row.update(_child(ESTIMATE.format(root=ROOT, folder=folder, method=args.method, pure=args.pure_pixels)))
        rows.append(row)
        t = row["timings"]
        made = (f"generated in {row['generate_s']:.0f} s (peak {row['generate_peak_mib']:.0f} MiB); "
                if "generate_s" in row else "")
        print(f"{row['faces']:9d} faces: {made}estimate {t['total']:6.1f} s (observations {t['observations']:.1f}, "
              f"visibility {t['visibility']:.1f}, reflection {t['reflection']:.1f}, solve {t['solve']:.1f}, "
              f"trust {t.get('trust', 0.0):.1f}), "
              f"peak {row['peak_mib']:.0f} MiB; {row['observations']} observations"
              f"{' (streamed)' if row['streamed'] else ''}; {row['method']}: {row['component']} PSNR "
              f"{row['psnr']:.2f} dB, {100 * row['within_10']:.1f} % within ±10 %, "
              f"{100 * row['estimated_share']:.1f} % estimated", flush=True)
    for row in rows:
        t = row["timings"]
        print(
            f"{row['faces']:9d} faces: shadow function {1e9 * t['visibility'] / (row['faces'] * row['directions']):.1f}"
            f" ns per face x direction; observations {1e9 * t['observations'] / (row['views'] * row['pixels']):.0f}"
            f" ns per view x pixel; solve {1e6 * t['solve'] / row['observations']:.1f} us per observation"
        )
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, f"scale-{args.scene}-{args.method or 'recommended'}.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
