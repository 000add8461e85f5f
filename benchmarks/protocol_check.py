"""Check the Stanford-ORB protocol (reports/protocols.py) against the benchmark's own code.

Three steps, the middle one in another Python environment that has PyTorch, kornia and OpenCV
(the reference's dependencies, which the project does not need) and a checkout of
https://github.com/StanfordORB/Stanford-ORB:

    .venv/bin/python benchmarks/protocol_check.py images DATASET images.npz
    /path/to/env/bin/python benchmarks/protocol_check.py reference images.npz ref.json --orb /path/to/Stanford-ORB
    .venv/bin/python benchmarks/protocol_check.py compare images.npz ref.json

``images`` estimates DATASET with its defaults and writes its test frames' predictions,
references and compared pixels; ``reference`` scores them with Stanford-ORB's ``calc_PSNR``
(PSNR-H and PSNR-L called as its ``compute_similarity`` calls them) and kornia's
``ssim_loss`` on the sRGB images it returns (as its ``ssim`` does, on the CPU); ``compare``
prints both and exits 1 when any differs by more than ``--tolerance`` (dB for PSNR, absolute
for SSIM). LPIPS is not checked: its backbone's weights cannot be downloaded here.
"""
from __future__ import annotations

import argparse
import json
import os
import sys


def _load(path: str) -> tuple[list, list, list]:
    import numpy as np

    data = np.load(path)
    n = len([k for k in data.files if k.startswith("pred")])
    return ([data[f"pred{i}"] for i in range(n)], [data[f"ref{i}"] for i in range(n)],
            [data[f"mask{i}"] for i in range(n)])


def images(dataset: str, out: str) -> None:
    import numpy as np

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from estimator import Predictor, estimate
    from harness.io.dataset import read_dataset
    from harness.io.runs import estimator_settings
    from reports.report import novel_views

    ds = read_dataset(dataset, load_test=True, load_truth=False)
    if not ds.data.test_views:
        raise SystemExit(f"{dataset} has no test frames")
    name, config = estimator_settings(ds.meta, None, {})
    est = estimate(ds.data, name, config)
    images, _, _ = novel_views(Predictor(ds.data.mesh, est), ds.data.test_views)
    arrays = {}
    for i, (p, r, m) in enumerate(zip(images.predictions, images.references, images.masks)):
        arrays.update({f"pred{i}": p.astype(np.float32), f"ref{i}": r.astype(np.float32), f"mask{i}": m})
    np.savez_compressed(out, **arrays)
    print(f"{len(images.predictions)} views written to {out}")


def reference(path: str, out: str, orb: str) -> None:
    import numpy as np
    import torch
    from kornia.losses import ssim_loss

    sys.path.insert(0, orb)
    from orb.utils.metrics import calc_PSNR, erode_mask

    rows = []
    for p, r, m in zip(*_load(path)):
        p = np.maximum(p, 0)   # the reference stops at a negative prediction; the protocol clips it
        mask = m.astype(np.float32)
        psnr_h, _, _ = calc_PSNR(p, r, mask, max_value=4, use_gt_median=True, tonemapping=False,
                                 divide_mask=False, scale_invariant=True)
        psnr_l, p_srgb, r_srgb = calc_PSNR(p, r, mask, max_value=1, use_gt_median=False, tonemapping=True,
                                           divide_mask=False, scale_invariant=True)
        eroded = erode_mask(mask, None)
        a, b = (torch.tensor(x * eroded[..., None], dtype=torch.float32).permute(2, 0, 1)[None]
                for x in (p_srgb, r_srgb))
        rows.append({"psnr_h": float(psnr_h), "psnr_l": float(psnr_l), "ssim": 1 - 2 * ssim_loss(a, b, 3).item()})
    with open(out, "w") as f:
        json.dump(rows, f, indent=1)
    print(f"{len(rows)} views scored by the reference into {out}")


def compare(path: str, ref_path: str, tolerance: float) -> int:
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from reports.protocols import stanford_orb

    with open(ref_path) as f:
        ref = json.load(f)
    ours = stanford_orb(*_load(path))["per_view"]
    worst = 0.0
    print(f"{'view':>4}  {'metric':7} {'reference':>10} {'ours':>10} {'diff':>9}")
    for i, (a, b) in enumerate(zip(ref, ours)):
        for key in ("psnr_h", "psnr_l", "ssim"):
            diff = b[key] - a[key]
            worst = max(worst, abs(diff))
            print(f"{i:4d}  {key:7} {a[key]:10.4f} {b[key]:10.4f} {diff:9.2e}")
    print(f"largest difference {worst:.2e} (tolerance {tolerance:g})")
    return int(worst > tolerance)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="step", required=True)
    a = sub.add_parser("images")
    a.add_argument("dataset")
    a.add_argument("out")
    b = sub.add_parser("reference")
    b.add_argument("images")
    b.add_argument("out")
    b.add_argument("--orb", required=True, help="a checkout of StanfordORB/Stanford-ORB")
    c = sub.add_parser("compare")
    c.add_argument("images")
    c.add_argument("reference")
    c.add_argument("--tolerance", type=float, default=1e-3)
    args = parser.parse_args()
    if args.step == "images":
        images(args.dataset, args.out)
    elif args.step == "reference":
        reference(args.images, args.out, args.orb)
    else:
        return compare(args.images, args.reference, args.tolerance)
    return 0


if __name__ == "__main__":
    sys.exit(main())
