"""Time and peak memory of `pseudolight generate earth-specular` (the default scene), in a child
process, and its ratio to the bare-ray limit: the shadow rays the render needs (views x pixels x
spp x delta lights) divided by the rate of a bare ``scene.ray_test`` on the same mesh (measured
here: 4M rays from random face centroids into random directions of their upper hemisphere, as
shadow rays go, best of three after a warm-up)."""
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


def bare_ray_rate(scene: str, profile: str | None, rays: int = 4_000_000) -> float:
    """Shadow rays per second of a bare ``ray_test`` on the scene's mesh (best of 3)."""
    sys.path.insert(0, ROOT)
    import numpy as np

    from estimator.rays.raycast import RayCaster
    from harness.scene.generate import build_mesh
    from harness.scene.spec import load_spec, resolve_scene

    mesh, _ = build_mesh(load_spec(resolve_scene(scene), profile))
    caster = RayCaster(mesh)
    rng = np.random.default_rng(0)
    faces = rng.integers(0, mesh.num_faces, rays)          # shadow rays: from the surface, into the upper hemisphere
    n = mesh.face_normals[faces]
    d = rng.normal(size=(rays, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d *= np.sign(np.sum(d * n, axis=1))[:, None]
    ray = caster._rays(mesh.centroids[faces] + 1e-4 * caster.scale * n, d)
    best = 0.0
    for _ in range(4):   # the first call compiles
        t = time.perf_counter()
        np.asarray(caster.scene.ray_test(ray))
        best = max(best, rays / (time.perf_counter() - t))
    return best


def shadow_rays(scene: str, profile: str | None) -> int:
    """Shadow rays of a render: train and test views x pixels x spp x delta lights."""
    sys.path.insert(0, ROOT)
    from harness.scene.illumination import build_illumination
    from harness.scene.spec import load_spec, resolve_scene

    spec = load_spec(resolve_scene(scene), profile)
    lights = len(build_illumination(spec.illumination, spec.seed).to_light)
    c = spec.cameras
    return (c.count + c.test_count) * c.width * c.height * spec.render.spp * lights


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--scene", default="earth-specular")
    p.add_argument("--profile")
    args = p.parse_args()
    extra = ["--profile", args.profile] if args.profile else []
    out = os.path.join(ROOT, "out", "bench", args.scene + (f"-{args.profile}" if args.profile else ""))
    result = measure(args.scene, out, extra)
    rays, rate = shadow_rays(args.scene, args.profile), bare_ray_rate(args.scene, args.profile)
    render = result["stages_s"].get("render", result["wall_s"])
    result.update({"shadow_rays": rays, "bare_rays_per_s": round(rate), "bare_ray_limit_s": round(rays / rate, 2),
                   "render_over_limit": round(render / (rays / rate), 2),
                   "wall_over_limit": round(result["wall_s"] / (rays / rate), 2)})
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
