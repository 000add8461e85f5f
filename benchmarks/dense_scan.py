"""The default method on a mesh denser than its photos: random-family draws with their mesh
subdivided until a face covers about a pixel, one fresh process per estimate so each peak RSS
is that case's own.

    python benchmarks/dense_scan.py [--seeds 1047,1029,1006] [--subdivisions 2] [--views 30]
                                    [--resolution N] [--out DIR] [--set KEY=VALUE ...]

Each seed's light, material, albedo and camera layout are kept
(:func:`harness.scene.random_family.draw`); its mesh is subdivided ``--subdivisions`` times
(4^s x the faces): the shipped bunny (3,674 faces) or teapot by midpoints (the bunny twice:
58,784 faces, about one pixel each at 256²), the bumpy blob generated at ``4 + s``
subdivisions (the same surface, 5,120 x 4^s faces). It is seen from ``--views`` cameras
(``--resolution``: their width and height instead of the draw's, e.g. 1024 to score the same
scene at 4x the resolution). Prints per seed: faces, the faces no pure pixel resolves, observed
through the pixels they cover (``info["unresolved_faces"]``), the estimated share, of all faces,
of the faces some pixel centre hits and of those that receive light, diffuse PSNR after a
per-channel least-squares scale, the share within ±10 %, ARI on uniform regions, time per
stage and peak RSS. Rows go to DIR/dense_scan.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from random_family import seeds  # noqa: E402
from scoring import setting  # noqa: E402

ESTIMATE = r"""
import json, resource, sys
sys.path.insert(0, {root!r}); sys.path.insert(0, {root!r} + "/benchmarks")
from scoring import score, seen_faces
from estimator import estimate
from harness.io.dataset import read_dataset, read_ground_truth
from harness.io.runs import estimator_settings
ds = read_dataset({folder!r}, load_test=False, load_truth=False)
truth = read_ground_truth({folder!r}, ds.data.mesh.num_faces)
method, config = estimator_settings(ds.meta, None, {overrides!r})
from estimator.rays.raycast import RayCaster
caster = RayCaster(ds.data.mesh, config.variant)
est = estimate(ds.data, method, config, caster=caster)
seen = seen_faces(caster, ds.data.views)
print(json.dumps({{"faces": ds.data.mesh.num_faces, "method": method, **score(ds, truth, est, seen=seen),
                  "seen_faces": int(seen.sum()),
                  "unresolved_faces": est.info["unresolved_faces"], "timings": est.info["timings"],
                  "light_from": est.info.get("light_from"),
                  "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}}))
"""


def dense_mesh(folder: str, name: str, subdivisions: int) -> str:
    """The shipped mesh ``name`` (bunny, teapot) subdivided ``subdivisions`` times (face
    order: trimesh's), written once."""
    import trimesh

    path = os.path.join(folder, f"{name}-s{subdivisions}.ply")
    if not os.path.exists(path):
        mesh = trimesh.load(os.path.join(ROOT, "scenes", "assets", f"{name}.ply"), process=False)
        vertices, faces = mesh.vertices, mesh.faces
        for _ in range(subdivisions):
            vertices, faces = trimesh.remesh.subdivide(vertices, faces)
        os.makedirs(folder, exist_ok=True)
        trimesh.Trimesh(vertices, faces, process=False).export(path)
    return path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", default="1047,1029,1006")
    p.add_argument("--subdivisions", type=int, default=2)
    p.add_argument("--views", type=int, default=30)
    p.add_argument("--resolution", type=int, default=None, help="image width and height (default: the draw's)")
    p.add_argument("--out", default="out/bench-dense")
    p.add_argument("--set", type=setting, action="append", default=[], metavar="KEY=VALUE")
    args = p.parse_args()
    from harness.scene.generate import generate
    from harness.scene.random_family import draw, random_spec

    out = os.path.abspath(args.out)
    rows = []
    for seed in seeds(args.seeds):
        raw, strata = draw(seed)
        size = "" if args.resolution is None else f"-{args.resolution}px"
        folder = os.path.join(out, f"dense-s{args.subdivisions}-{seed:04d}{size}")
        if not os.path.isdir(folder):
            overrides = {"cameras.count": args.views}
            if strata["geometry"] == "blob":
                overrides["geometry.subdivisions"] = raw["geometry"]["subdivisions"] + args.subdivisions
            else:
                overrides["geometry.file"] = dense_mesh(out, strata["geometry"], args.subdivisions)
            if args.resolution is not None:
                overrides.update({"cameras.width": args.resolution, "cameras.height": args.resolution})
            generate(random_spec(seed, None, overrides), folder)
        run = subprocess.run([sys.executable, "-c", ESTIMATE.format(root=ROOT, folder=folder,
                                                                    overrides=dict(args.set))],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise SystemExit(f"seed {seed}: the estimate failed ({run.returncode}):\n{run.stderr[-3000:]}")
        row = {"seed": seed, **strata, **json.loads(run.stdout.strip().splitlines()[-1])}
        rows.append(row)
        t = row["timings"]
        ari = "-" if row["ari"] is None or strata["albedo"] != "regions" else f"{row['ari']:.3f}"
        print(f"{seed:5d} {strata['geometry']:>6s} {strata['light']:>8s} {strata['material']:>12s} "
              f"{strata['albedo']:>8s} {strata['cameras']:>9s}  {row['faces']} faces, "
              f"{row['unresolved_faces']} unresolved; "
              f"estimated {row['estimated_share']:.3f} ({row['estimated_of_seen']:.3f} of the seen, "
              f"{row['estimated_of_seen_lit']:.3f} of the seen lit)  "
              f"PSNR {row['psnr']:6.2f} dB  ±10% {row['within_10']:.3f}  "
              f"ARI {ari}  {t['total']:.1f} s (shared {t['observations'] + t['visibility'] + t['reflection']:.1f}, "
              f"solve {t['solve']:.1f}, trust {t['trust']:.1f})  peak {row['peak_mib']:.0f} MiB", flush=True)
    with open(os.path.join(out, "dense_scan.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
