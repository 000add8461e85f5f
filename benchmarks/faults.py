"""Robustness to capture faults: earth-specular (full size by default) with each fault of
the issue's table applied to the training images and transforms.json after generation
(``harness.scene.faults.corrupt_dataset``: the estimator is not told), scored on the truth
and by leave-views-out cross-validation.

    python benchmarks/faults.py [--out DIR] [--profile tiny] [--losses none,cauchy] [--holdout 4]
                                [--refine-rounds 2]

Prints one row per (fault, robust loss): share of faces within ±10 % (least-squares gauge,
the scene's component), cross-validated prediction PSNR, the warnings raised and the time;
the clean, pose and focal-length cases run once more with pose refinement (the Cauchy loss), with
the cameras' median and max reprojection error of the mesh's vertices against the true
cameras before and after;
writes the rows to DIR/faults.json and an HTML sweep page DIR/faults.html (CV PSNR and the
true ±10 % share against the fault, one line per loss).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
from scoring import score  # noqa: E402

from estimator import estimate  # noqa: E402
from estimator.diagnostics.validation import cross_validate  # noqa: E402
from estimator.pipeline.pose import reprojection_error  # noqa: E402
from harness.io.dataset import read_dataset, read_ground_truth  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402
from harness.scene.faults import corrupt_dataset  # noqa: E402
from harness.scene.generate import generate  # noqa: E402
from harness.scene.spec import FaultSpec, load_spec, resolve_scene  # noqa: E402
from reports.figures import sweep_panels  # noqa: E402
from reports.html import embed_png  # noqa: E402

# (name, fault) in the order of the table; distances: object radius 1, cameras at 4,
# so 1 cm = 0.0025 of the distance
CASES = [
    ("clean", FaultSpec()),
    ("noise 5 %", FaultSpec(noise_read=0.05)),
    ("noise 10 %", FaultSpec(noise_read=0.10)),
    ("noise 20 %", FaultSpec(noise_read=0.20)),
    ("focal +3 %", FaultSpec(focal_error=0.03)),
    ("pose 0.5 deg + 1 cm", FaultSpec(pose_rotation=0.5, pose_translation=0.0025)),
    ("pose 2 deg + 4 cm", FaultSpec(pose_rotation=2.0, pose_translation=0.01)),
    ("glare 80 px +0.5, 1 view", FaultSpec(glare_views=1, glare_size=80, glare_value=0.5)),
    ("block 80 px -0.5, 1 view", FaultSpec(occluder_views=1, occluder_size=80, occluder_value=-0.5)),
    # photon (shot) noise: sigma = x at the exposure level and x sqrt(value / level) below it
    # (read noise above is x at every value: most of this scene's pixels lie far below the level)
    ("shot noise 5 %", FaultSpec(noise_shot=0.05 ** 2)),
    ("shot noise 10 %", FaultSpec(noise_shot=0.10 ** 2)),
    ("shot noise 20 %", FaultSpec(noise_shot=0.20 ** 2)),
]


def sweep_html(rows: list[dict], path: str) -> None:
    """faults.html: the true ±10 % share and the cross-validated PSNR against the fault (one
    line per loss; :func:`reports.figures.sweep_panels`), and the table."""
    cases = list(dict.fromkeys(r["fault"] for r in rows))
    panels = []
    for key, title in (("within_10", "share within ±10 % (truth)"), ("cv_psnr", "cross-validated PSNR (dB)")):
        series = {}
        for loss, rounds in dict.fromkeys((r["loss"], r["pose_rounds"]) for r in rows):
            values = [next((r[key] for r in rows if r["fault"] == c and r["loss"] == loss
                            and r["pose_rounds"] == rounds), None) for c in cases]
            values = [np.nan if v is None else v for v in values]
            label = f"robust_loss={loss}" + (f", poses refined ({rounds} rounds)" if rounds else "")
            series[label] = (cases, values, values, values)
        panels.append((title, series))

    def fmt(value) -> str:
        return "-" if value is None else f"{value:.2f}"

    table = "".join(f"<tr><td>{r['fault']}</td><td>{r['loss']}</td><td>{r['pose_rounds']}</td>"
                    f"<td>{r['within_10']:.3f}</td><td>{fmt(r['reprojection_px'][0])}</td><td>{fmt(r['cv_psnr'])}</td>"
                    f"<td>{len(r['warnings'])}</td><td>{r['seconds']:.1f}</td></tr>" for r in rows)
    with open(path, "w") as f:
        f.write("<html><body><h1>Fault sweep (earth-specular)</h1>" + embed_png(sweep_panels("fault", panels), "sweep")
                + "<table border=1><tr><th>fault</th><th>loss</th><th>pose rounds</th><th>±10 %</th>"
                  "<th>median reprojection (px)</th><th>CV PSNR</th>"
                  "<th>warnings</th><th>s</th></tr>" + table + "</table></body></html>")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/bench-faults")
    p.add_argument("--scene", default="earth-specular")
    p.add_argument("--profile")
    p.add_argument("--losses", default="none,cauchy")
    p.add_argument("--holdout", type=int, default=4)
    p.add_argument("--refine-rounds", type=int, default=2, help="pose refinement rounds (0: no refinement rows)")
    p.add_argument("--cases", help="comma-separated fault names to run (default: all)")
    args = p.parse_args()
    clean = os.path.join(args.out, f"{args.scene}-clean")
    if not os.path.isdir(clean):
        generate(load_spec(resolve_scene(args.scene), args.profile), clean)
    rows = []
    true_cameras = [v.camera for v in read_dataset(clean, load_test=False, load_truth=False).data.views]
    wanted = None if args.cases is None else set(args.cases.split(","))
    for k, (name, fault) in enumerate(CASES):
        if wanted is not None and name not in wanted:
            continue
        folder = clean if name == "clean" else os.path.join(args.out, f"{args.scene}-fault-{k}")
        if not os.path.isdir(folder):
            corrupt_dataset(clean, folder, fault, seed=k)
        ds = read_dataset(folder, load_test=False, load_truth=False)
        truth = read_ground_truth(clean, ds.data.mesh.num_faces)
        runs = [(loss, 0) for loss in args.losses.split(",")]
        if args.refine_rounds and (name == "clean" or fault.pose_rotation > 0 or fault.focal_error):
            runs.append(("cauchy", args.refine_rounds))
        for loss, rounds in runs:
            # rows without refinement turn the automatic check off, to show the fault as given
            method, config = estimator_settings(ds.meta, None, {"robust_loss": loss, "pose_rounds": rounds,
                                                                "auto_pose": 1.0 if rounds else 0.0})
            t = time.perf_counter()
            est = estimate(ds.data, method, config)
            seconds = time.perf_counter() - t
            cv = None
            if args.holdout:
                cv = cross_validate(ds.data, args.holdout, lambda d, m=method, c=config: estimate(d, m, c))
            cameras = [v.camera for v in ds.data.views]
            if rounds:
                cameras = [dataclasses.replace(c, c2w=np.array(p["c2w"])) for c, p in zip(cameras, est.info["poses"])]
            errors = reprojection_error(cameras, true_cameras, ds.data.mesh.vertices)
            row = {"fault": name, "loss": loss, "pose_rounds": rounds, "method": method, "seconds": seconds,
                   "within_10": score(ds, truth, est, config.components if config.components != "both"
                                      else "diffuse")["within_10"],
                   "reprojection_px": [float(np.median(errors)), float(errors.max())],
                   "cv_psnr": None if cv is None else cv["psnr"], "warnings": est.info["warnings"]}
            rows.append(row)
            cvs = "-" if row["cv_psnr"] is None else f"{row['cv_psnr']:.2f}"
            print(f"{name:26s} {loss:7s} poses {'refined' if rounds else 'as given':8s} ±10% {row['within_10']:.3f}  "
                  f"reprojection {errors.mean():.2f} px median {np.median(errors):.2f} max {errors.max():.2f}  "
                  f"CV PSNR {cvs:>6s}  warnings {len(row['warnings'])}  {seconds:5.1f} s", flush=True)
            for line in row["warnings"]:
                print(f"    warning: {line}")
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "faults.json")
    if wanted is not None and os.path.isfile(path):   # a subset replaces its own rows of an earlier run
        with open(path) as f:
            rows += [r for r in json.load(f) if r["fault"] not in wanted]
        order = [name for name, _ in CASES]
        rows.sort(key=lambda r: (order.index(r["fault"]), r["pose_rounds"], r["loss"]))
    with open(path, "w") as f:
        json.dump(rows, f, indent=1)
    sweep_html(rows, os.path.join(args.out, "faults.html"))
    print(f"wrote {os.path.join(args.out, 'faults.json')} and faults.html; "
          f"median time {np.median([r['seconds'] for r in rows]):.1f} s")


if __name__ == "__main__":
    main()
