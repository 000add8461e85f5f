"""Two runs of the random family on the same seeds, seed by seed: a design choice measured as
the family's development rule asks (develop on one set of seeds, check on another).

    python benchmarks/paired.py DIR/BASE.json DIR/NEW.json [--method retinex-segmented]
                                [--psnr 0.05] [--share 0.005]

Reads the rows ``random_family.py --name`` wrote for each run (the same renders: the seeds'
datasets are generated once into DIR). Prints every seed whose diffuse PSNR moved by at least
``--psnr`` dB, or whose share within ±10 % or ARI moved by at least ``--share``, then the sums:
the PSNR change summed and its median over the seeds, gains and losses, the seeds with
>= 90 % of faces within ±10 % before and after, and the largest loss of that share. A choice is
worth keeping when it holds on both seed sets; the per-seed rows show whether a sum is one seed
or many. Exits 1 when the two runs share no seed of the method (or a seed is missing a score).
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def by_seed(rows: list[dict], method: str) -> dict[int, dict]:
    """The rows of ``method``, keyed by seed."""
    return {int(r["seed"]): r for r in rows if r["method"] == method}


def paired(base: dict[int, dict], new: dict[int, dict], psnr_step: float, share_step: float
           ) -> tuple[list[str], list[str]]:
    """(rows of the seeds that moved, summary lines) for the seeds both runs scored."""
    seeds = sorted(set(base) & set(new))
    lines = []
    d_psnr, d_share, before, after = [], [], [], []
    for s in seeds:
        b, n = base[s], new[s]
        if b["psnr"] is None or n["psnr"] is None:
            raise ValueError(f"seed {s} has no PSNR in one of the runs (no face evaluated)")
        dp, ds = n["psnr"] - b["psnr"], n["within_10"] - b["within_10"]
        da = None if b["ari"] is None or n["ari"] is None else n["ari"] - b["ari"]
        d_psnr.append(dp)
        d_share.append(ds)
        before.append(b["within_10"])
        after.append(n["within_10"])
        if abs(dp) >= psnr_step or abs(ds) >= share_step or (da is not None and abs(da) >= share_step):
            strata = " ".join(f"{b[k]:>12s}" for k in ("light", "material", "albedo", "geometry", "cameras"))
            ari = "" if da is None else f"  ARI {b['ari']:.3f} -> {n['ari']:.3f}"
            lines.append(f"{s:5d} {strata}  PSNR {b['psnr']:6.2f} -> {n['psnr']:6.2f} ({dp:+6.2f})"
                         f"  ±10% {b['within_10']:.3f} -> {n['within_10']:.3f} ({ds:+.3f}){ari}")
    d_psnr, d_share = np.array(d_psnr), np.array(d_share)
    before, after = np.array(before), np.array(after)
    worst = int(np.argmin(d_share))
    summary = [
        f"seeds {len(seeds)}, moved {len(lines)}",
        f"PSNR change: sum {d_psnr.sum():+.2f} dB, median {np.median(d_psnr):+.2f}, "
        f"{int((d_psnr >= psnr_step).sum())} up, {int((d_psnr <= -psnr_step).sum())} down",
        f"PSNR median {np.median([base[s]['psnr'] for s in seeds]):.2f} -> "
        f"{np.median([new[s]['psnr'] for s in seeds]):.2f} dB",
        f"share within ±10 %: median {np.median(before):.3f} -> {np.median(after):.3f}; "
        f"seeds with >= 0.9: {int((before >= 0.9).sum())} -> {int((after >= 0.9).sum())}; "
        f"largest loss {d_share[worst]:+.3f} (seed {seeds[worst]})",
    ]
    return lines, summary


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("base")
    p.add_argument("new")
    p.add_argument("--method", default="retinex-segmented")
    p.add_argument("--psnr", type=float, default=0.05, help="dB: smaller PSNR moves are not listed")
    p.add_argument("--share", type=float, default=0.005, help="smaller moves of the share or ARI are not listed")
    args = p.parse_args()
    runs = []
    for path in (args.base, args.new):
        with open(path) as f:
            runs.append(by_seed(json.load(f), args.method))
    if not set(runs[0]) & set(runs[1]):
        sys.exit(f"{args.base} and {args.new} share no seed of {args.method}")
    try:
        lines, summary = paired(runs[0], runs[1], args.psnr, args.share)
    except ValueError as e:
        sys.exit(str(e))
    print("\n".join(lines + [""] + summary))


if __name__ == "__main__":
    main()
