"""How much of the default's error on coated seeds of the random family is the coat's reflection.

    python benchmarks/coat_share.py --seeds 1000-1039 [--profile tiny] [--out DIR]

For each seed whose material reflects more than a diffuse surface (plastic, roughplastic, Phong,
mixed), Mitsuba renders the same scene again with every diffuse albedo set to 0: the coat's (or
lobe's) reflection alone, with the same plugins, light and cameras. Subtracting it from each
image leaves the diffuse light alone (up to the render noise of both images and the paths
that meet both a coat and a diffuse surface, which max_depth 3 allows). The default method
estimates the images as rendered and the images without the coat, and the script prints both
scores per seed: where the second is far better, the error is the coat's reflection left in
the diffuse radiance (a modelling target for ``coat_correction``); where both are poor, it lies
elsewhere (the light, the partition). Seeds of a plain diffuse material are skipped. The
datasets go to DIR (reused when present): random-NNNN, random-NNNN-coat (the coat alone) and
random-NNNN-nocoat (the difference; the ground truth of random-NNNN).

It also measures the coat correction's weight against the truth. The reflection rows
(``coat_rows`` of the light the default finds before any correction, degree ``coat_order``) and
the weight fitted to the colours' changes across views (``fit_coat``) are computed as the
correction computes them; the true weight is the least-squares slope of the coat-only
render's colours at the same (face, view) pairs on the same rows, each face's mean over views
removed, as the fit sees them. A fit that matches the true slope while the applied weight
(after the cap ``admissible_scale``) falls short says the cap limits the correction; a fit far
from the true slope says the fit itself does.
"""
from __future__ import annotations

import argparse
import copy
import glob
import os
import shutil
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
from random_family import seeds  # noqa: E402
from scoring import score  # noqa: E402

from estimator import InputError, estimate  # noqa: E402
from estimator.light import coat  # noqa: E402
from estimator.methods import get_method  # noqa: E402
from estimator.pipeline.prepared import prepare  # noqa: E402
from estimator.rays.raycast import RayCaster  # noqa: E402
from harness.io.atomic import atomic_directory  # noqa: E402
from harness.io.dataset import read_dataset, read_ground_truth  # noqa: E402
from harness.io.exr import read_exr, write_exr  # noqa: E402
from harness.io.runs import estimator_settings  # noqa: E402
from harness.scene.generate import generate  # noqa: E402
from harness.scene.random_family import draw  # noqa: E402
from harness.scene.spec import SCENES_DIR, parse_spec  # noqa: E402


def without_diffuse(raw: dict) -> dict:
    """The raw spec of :func:`draw` with every diffuse albedo (uniform, per region or textured) 0."""
    out = copy.deepcopy(raw)
    material = out["material"]
    if "diffuse" in material:                  # the whole object's albedo: a table
        material["diffuse"] = {"value": [0.0, 0.0, 0.0]}
    for region in material.get("regions", []):
        region["diffuse"] = [0.0, 0.0, 0.0]
        region.pop("albedo", None)             # a region's texture
    return out


def difference(dataset: str, coat: str, out: str) -> None:
    """``out``: a copy of the dataset folder whose images have the coat-only images' colours
    subtracted (alpha kept), written atomically."""
    with atomic_directory(out, kind="dataset") as tmp:
        shutil.copytree(dataset, tmp, dirs_exist_ok=True, ignore=shutil.ignore_patterns(".pseudolight*"))
        for path in glob.glob(os.path.join(tmp, "images", "*.exr")):
            image = read_exr(path)
            image[..., :3] -= read_exr(os.path.join(coat, "images", os.path.basename(path)))[..., :3]
            write_exr(path, image)


def scored(folder: str, truth_folder: str) -> dict:
    ds = read_dataset(folder, load_test=False, load_truth=False)
    truth = read_ground_truth(truth_folder, ds.data.mesh.num_faces)
    name, config = estimator_settings(ds.meta, "retinex-segmented", None)
    t = time.perf_counter()
    try:
        est = estimate(ds.data, name, config)
    except InputError as exc:
        return {"psnr": None, "within_10": 0.0, "error": str(exc), "seconds": time.perf_counter() - t}
    return {**score(ds, truth, est), "seconds": time.perf_counter() - t}


def coat_weights(folder: str, coat_folder: str) -> dict:
    """The coat correction's weights on ``folder`` against the true reflection (the coat-only
    render ``coat_folder``): 'fitted' (3,) the fit's weight, 'applied' (3,) after the cap,
    'true' (3,) the true colours' slope on the same rows, 'rows' the (face, view) pairs compared
    (module docstring); {'error': ...} where the estimate fails."""
    ds = read_dataset(folder, load_test=False, load_truth=False)
    name, config = estimator_settings(ds.meta, "retinex-segmented", {"coat_correction": False})
    caster = RayCaster(ds.data.mesh, config.variant)   # the estimate's buffers and shadow function, reused
    try:
        light = estimate(ds.data, name, config, caster=caster).light   # the light the correction starts from
    except InputError as exc:
        return {"error": str(exc)}
    obs = prepare(ds.data, config, caster=caster).obs
    bare = prepare(read_dataset(coat_folder, load_test=False, load_truth=False).data, config).obs
    keys = obs.face * obs.num_views + obs.view
    _, mine, theirs = np.intersect1d(keys, bare.face * bare.num_views + bare.view, return_indices=True)
    normals = ds.data.mesh.face_normals[obs.face]
    rows = coat.coat_rows(normals, obs.view_dir, light, config.coat_order, config.coat_ior)
    fitted = coat.fit_coat(obs.face, obs.rgb, rows, obs.num_faces, get_method(name)(config).loss)[0]
    applied = fitted * coat.admissible_scale(obs.rgb, fitted * rows, config.coat_max_negative)[0]
    true = coat.fit_coat(obs.face[mine], bare.rgb[theirs], rows[mine], obs.num_faces, "none")[0]
    return {"fitted": fitted.tolist(), "applied": applied.tolist(), "true": true.tolist(), "rows": int(len(mine))}


def run_seed(seed: int, out: str, profile: str | None) -> dict | None:
    raw, strata = draw(seed)
    if strata["material"] == "diffuse":
        return None
    folders = {kind: os.path.join(out, f"random-{seed:04d}{kind}") for kind in ("", "-coat", "-nocoat")}
    if not os.path.isdir(folders[""]):
        generate(parse_spec(raw, SCENES_DIR, profile, None), folders[""])
    if not os.path.isdir(folders["-coat"]):
        generate(parse_spec(without_diffuse(raw), SCENES_DIR, profile, None), folders["-coat"])
    if not os.path.isdir(folders["-nocoat"]):
        difference(folders[""], folders["-coat"], folders["-nocoat"])
    rendered, bare = scored(folders[""], folders[""]), scored(folders["-nocoat"], folders[""])
    weights = coat_weights(folders[""], folders["-coat"])
    row = {"seed": seed, **strata, "rendered": rendered, "without_coat": bare, "coat_weights": weights}
    psnr = [r["psnr"] or 0.0 for r in (rendered, bare)]
    print(f"{seed:5d} {strata['light']:>8s} {strata['material']:>12s} {strata['albedo']:>8s} "
          f"PSNR {psnr[0]:6.2f} -> {psnr[1]:6.2f} dB without the coat   "
          f"±10% {rendered['within_10']:.3f} -> {bare['within_10']:.3f}   coat weight / true: fitted "
          f"{over_true(weights, 'fitted'):5.2f}, applied {over_true(weights, 'applied'):5.2f}", flush=True)
    return row


def over_true(weights: dict, kind: str) -> float:
    """The mean over channels of a :func:`coat_weights` weight ('fitted' or 'applied') over that
    of the true slope; NaN where the estimate failed or the true reflection has no slope."""
    if "error" in weights or not np.mean(weights["true"]) > 0:
        return float("nan")
    return float(np.mean(weights[kind]) / np.mean(weights["true"]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", default="1000-1039")
    p.add_argument("--profile", help="'tiny' for a quick look (128², 16 spp)")
    p.add_argument("--out", default="out/bench-coat-share")
    args = p.parse_args()
    rows = [row for seed in seeds(args.seeds) if (row := run_seed(seed, args.out, args.profile))]
    if not rows:
        print("no coated seed among these")
        return
    before = np.array([r["rendered"]["psnr"] or 0.0 for r in rows])
    after = np.array([r["without_coat"]["psnr"] or 0.0 for r in rows])
    print(f"\n{len(rows)} coated seeds: PSNR median {np.median(before):.2f} -> {np.median(after):.2f} dB without "
          f"the coat; gain median {np.median(after - before):.2f}, max {np.max(after - before):.2f} dB; "
          f"without the coat still below 35 dB on {int(np.sum(after < 35))}")
    ratios = [np.array([over_true(r["coat_weights"], kind) for r in rows]) for kind in ("fitted", "applied")]
    print("coat weight over the true reflection's slope, median (5th-95th percentile) over the seeds: fitted "
          + ", applied ".join(f"{np.nanmedian(v):.2f} ({np.nanpercentile(v, 5):.2f}-{np.nanpercentile(v, 95):.2f})"
                              for v in ratios))


if __name__ == "__main__":
    main()
