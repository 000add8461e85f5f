"""The ``pseudolight`` command line."""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

from estimator.backend import VARIANTS, BackendError

from .atomic import OutputExistsError
from .dataset import DatasetError
from .scene_spec import SpecError, load_spec, resolve_scene, shipped_scenes

DEFAULT_SCENE = "earth-specular"
USER_ERRORS = (SpecError, DatasetError, BackendError, OutputExistsError, FileNotFoundError, ValueError)


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _overrides(args) -> dict:
    out = {}
    if args.resolution:
        out["cameras.width"] = out["cameras.height"] = args.resolution
    if args.views is not None:
        out["cameras.count"] = args.views
    if args.test_views is not None:
        out["cameras.test_count"] = args.test_views
    if args.spp is not None:
        out["render.spp"] = args.spp
    if args.seed is not None:
        out["seed"] = args.seed
    return out


def cmd_scenes(args) -> int:
    for name, path in shipped_scenes().items():
        spec = load_spec(path)
        c = spec.cameras
        print(f"{name:16s} {c.count:3d} views {c.width}x{c.height} spp {spec.render.spp:<4d} "
              f"profiles: {', '.join(spec.profiles) or '-'}\n{'':16s} {spec.description}")
    return 0


def cmd_generate(args) -> int:
    from .generate import generate

    spec = load_spec(resolve_scene(args.scene), args.profile, _overrides(args))
    summary = generate(spec, args.output, overwrite=args.overwrite, variant=args.variant)
    summary["peak_rss_mib"] = _peak_rss_mib()
    print(json.dumps(summary, indent=1) if args.json else
          f"dataset {summary['scene']}: {summary['views']} views + {summary['test_views']} test views, "
          f"{summary['faces']} faces, {summary['seconds']['total']:.1f} s, peak {summary['peak_rss_mib']:.0f} MiB\n"
          f"written to {summary['path']}")
    return 0


def cmd_demo(args) -> int:
    from .generate import generate

    spec = load_spec(resolve_scene(DEFAULT_SCENE))
    out = os.path.join(args.output, DEFAULT_SCENE)
    t0 = time.perf_counter()
    if os.path.exists(out) and not args.overwrite:
        print(f"reusing dataset {out} (pass --overwrite to render it again)")
    else:
        summary = generate(spec, out, overwrite=args.overwrite, variant=args.variant)
        print(f"generated {DEFAULT_SCENE}: {summary['views']} views in {summary['seconds']['total']:.1f} s")
    print(f"dataset: {os.path.abspath(out)}  ({time.perf_counter() - t0:.1f} s, peak {_peak_rss_mib():.0f} MiB)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pseudolight", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("scenes", help="list the shipped scene specs")
    s.set_defaults(func=cmd_scenes)

    g = sub.add_parser("generate", help="render a scene spec into a dataset folder")
    g.add_argument("scene", help="scene spec TOML, or the name of a shipped scene")
    g.add_argument("-o", "--output", required=True, help="dataset folder to create")
    g.add_argument("--profile", help="a [profiles.NAME] table of the spec, e.g. benchmark")
    g.add_argument("--resolution", type=int, help="image width and height in pixels")
    g.add_argument("--views", type=int, help="number of training views")
    g.add_argument("--test-views", type=int, help="number of held-out test views")
    g.add_argument("--spp", type=int, help="samples per pixel")
    g.add_argument("--seed", type=int)
    g.add_argument("--variant", choices=VARIANTS + ("auto",))
    g.add_argument("--overwrite", action="store_true", help="replace an existing dataset folder")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    g.set_defaults(func=cmd_generate)

    d = sub.add_parser("demo", help="the main job on the default scene (earth-specular)")
    d.add_argument("-o", "--output", default="out")
    d.add_argument("--variant", choices=VARIANTS + ("auto",))
    d.add_argument("--overwrite", action="store_true")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except USER_ERRORS as exc:
        print(f"pseudolight: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("pseudolight: interrupted; no partial output was left", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
