"""Per-stage times of the estimator on the default earth dataset, and the shadow-ray
throughput of its visibility stage next to a bare `scene.ray_test` on the same rays."""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from estimator import backend  # noqa: E402
from harness.cli.heap import keep_freed_memory  # noqa: E402


def bare_ray_test(caster, sampling, repeats: int = 5) -> tuple[int, float]:
    """(rays, best seconds) of scene.ray_test alone on the visibility stage's rays (built beforehand)."""
    mesh = caster.mesh
    up = mesh.face_normals @ sampling.directions.T > 0
    fi, di = np.nonzero(up)
    o = mesh.centroids[fi] + 1e-4 * caster.scale * mesh.face_normals[fi]
    d = sampling.directions[di]
    ray = caster._rays(o, d)
    import drjit as dr

    dr.eval(ray)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        hit = caster.scene.ray_test(ray)
        dr.eval(hit)
        dr.sync_thread()
        best = min(best, time.perf_counter() - t)
    return len(fi), best


def main() -> None:
    keep_freed_memory()   # the heap the command line runs with
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--dataset", default=os.path.join(ROOT, "out", "bench", "earth-specular"))
    p.add_argument("--profile", help="scene profile when the dataset must be generated")
    p.add_argument("--variant")
    args = p.parse_args()
    backend.set_variant(args.variant)
    from estimator import estimate
    from estimator.config import EstimatorConfig
    from estimator.rays.raycast import RayCaster
    from estimator.rays.visibility import compute_visibility, sphere_sampling
    from harness.io.dataset import read_dataset
    from harness.scene.generate import generate
    from harness.scene.spec import load_spec, resolve_scene

    if not os.path.isdir(args.dataset):
        generate(load_spec(resolve_scene("earth-specular"), args.profile), args.dataset)
    ds = read_dataset(args.dataset)
    caster = RayCaster(ds.data.mesh)
    sampling = sphere_sampling(1164)
    compute_visibility(caster, sampling)  # warm-up: kernel compilation
    stage = np.inf
    for _ in range(5):  # best of 5, as for the bare figure
        t = time.perf_counter()
        compute_visibility(caster, sampling)
        stage = min(stage, time.perf_counter() - t)
    rays, bare = bare_ray_test(caster, sampling)
    est = estimate(ds.data, "bilinear-per-face", EstimatorConfig(components="specular"))
    out = {
        "dataset": args.dataset, "variant": backend.active_variant(), "faces": ds.data.mesh.num_faces,
        "views": len(ds.data.views),
        "estimate_stages_s": {k: round(v, 3) for k, v in est.info["timings"].items()},
        "shadow_rays": rays,
        "visibility_stage_s": round(stage, 3),
        "visibility_stage_rays_per_s": round(rays / stage),
        "bare_ray_test_s": round(bare, 3),
        "bare_ray_test_rays_per_s": round(rays / bare),
        "stage_over_bare": round(stage / bare, 2),
        "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
