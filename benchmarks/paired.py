"""Two runs of the random family on the same seeds, seed by seed: a design choice measured as
the family's development rule asks (develop on one set of seeds, check on another).

    python benchmarks/paired.py DIR/BASE.json DIR/NEW.json [--method retinex-segmented]
                                [--psnr 0.05] [--share 0.005]

Reads the rows ``random_family.py --name`` wrote for each run (the same renders: the seeds'
datasets are generated once into DIR). Prints every seed whose diffuse PSNR moved by at least
``--psnr`` dB, or whose share within ±10 % or ARI moved by at least ``--share`` (an ARI that
one run has and the other not counts as moved), then for the seeds both runs scored: the PSNR
change summed, its median and the seeds up and down; the same sum over the seeds below 30 dB
in BASE (the target's 5th percentile: a change of a few dB on a seed at 50 dB weighs as much
in the plain sum); the PSNR median and the share's median before and after, the seeds with
>= 90 % of faces within ±10 % before and after, and the largest loss of that share. Seeds
that only one run holds, and seeds a run refused (no PSNR: the row's ``error``) or scored
non-finite, are listed apart and left out of the sums. Exits 1 with a message on an unreadable
file, rows without the fields ``random_family.py`` writes, a seed twice in one run, or no seed
of the method in both runs.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

# random_family.STRATA, restated: importing that module loads Mitsuba and the estimator, which
# comparing two JSON files does not need
STRATA = ("light", "material", "albedo", "geometry", "cameras")
FIELDS = ("seed", "method", "psnr", "within_10", "ari", *STRATA)
LOW_PSNR = 30.0   # dB: the family's 5th-percentile target


class RunError(Exception):
    """A run's rows cannot be read or compared; the message names the file and the problem."""


def read_run(path: str, method: str) -> tuple[dict[int, dict], set[str]]:
    """The rows of ``method`` in one ``random_family.py`` output, keyed by seed, and every
    method the file holds."""
    try:
        with open(path) as f:
            rows = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        raise RunError(f"{path}: cannot read it as JSON ({e})") from e
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise RunError(f"{path}: expected a list of rows (objects), as random_family.py writes")
    out: dict[int, dict] = {}
    for r in rows:
        missing = [k for k in FIELDS if k not in r]
        if missing:
            raise RunError(f"{path}: a row lacks {', '.join(missing)}")
        if r["method"] != method:
            continue
        if int(r["seed"]) in out:
            raise RunError(f"{path}: seed {r['seed']} of {method} appears twice")
        out[int(r["seed"])] = r
    return out, {r["method"] for r in rows}


def scored(row: dict) -> bool:
    """True where the row holds a finite PSNR and share (not refused, some face evaluated)."""
    return row["psnr"] is not None and math.isfinite(row["psnr"]) and row["within_10"] is not None


def paired(base: dict[int, dict], new: dict[int, dict], psnr_step: float, share_step: float
           ) -> tuple[list[str], list[str]]:
    """(rows of the seeds that moved and of the seeds left out, summary lines)."""
    lines, apart = [], []
    for name, run, other in (("BASE", base, new), ("NEW", new, base)):
        only = sorted(set(run) - set(other))
        if only:
            apart.append(f"only in {name}: seeds {', '.join(map(str, only))}")
    seeds = []
    for s in sorted(set(base) & set(new)):
        b, n = base[s], new[s]
        bad = [(name, r) for name, r in (("BASE", b), ("NEW", n)) if not scored(r)]
        if bad:
            apart.extend(f"seed {s}: not scored in {name} ({r.get('error') or 'PSNR ' + str(r['psnr'])})"
                         for name, r in bad)
            continue
        seeds.append(s)
        dp, ds = n["psnr"] - b["psnr"], n["within_10"] - b["within_10"]
        aris = (b["ari"], n["ari"])
        if None in aris:
            ari_moved = aris != (None, None)
        else:
            ari_moved = abs(aris[1] - aris[0]) >= share_step
        if abs(dp) >= psnr_step or abs(ds) >= share_step or ari_moved:
            strata = " ".join(f"{b[k]:>12s}" for k in STRATA)
            ari = "" if aris == (None, None) else "  ARI " + " -> ".join("-" if a is None else f"{a:.3f}" for a in aris)
            lines.append(f"{s:5d} {strata}  PSNR {b['psnr']:6.2f} -> {n['psnr']:6.2f} ({dp:+6.2f})"
                         f"  ±10% {b['within_10']:.3f} -> {n['within_10']:.3f} ({ds:+.3f}){ari}")
    if not seeds:
        return lines + apart, ["no seed scored in both runs"]
    before = np.array([base[s]["psnr"] for s in seeds])
    after = np.array([new[s]["psnr"] for s in seeds])
    d_psnr = after - before
    share_before = np.array([base[s]["within_10"] for s in seeds])
    share_after = np.array([new[s]["within_10"] for s in seeds])
    d_share = share_after - share_before
    low = before < LOW_PSNR
    worst = int(np.argmin(d_share))
    loss = f"{d_share[worst]:+.3f} (seed {seeds[worst]})" if d_share[worst] < 0 else "none"
    summary = [
        f"seeds scored in both {len(seeds)}, listed as moved {len(lines)}",
        f"PSNR change: sum {d_psnr.sum():+.2f} dB, median {np.median(d_psnr):+.2f}, "
        f"{int(((d_psnr > 0) & (d_psnr >= psnr_step)).sum())} up, "
        f"{int(((d_psnr < 0) & (d_psnr <= -psnr_step)).sum())} down (by {psnr_step:g} dB or more)",
        f"PSNR change over the {int(low.sum())} seeds below {LOW_PSNR:g} dB in BASE: sum {d_psnr[low].sum():+.2f} dB",
        f"PSNR median {np.median(before):.2f} -> {np.median(after):.2f} dB",
        f"share within ±10 %: median {np.median(share_before):.3f} -> {np.median(share_after):.3f}; "
        f"seeds with >= 0.9: {int((share_before >= 0.9).sum())} -> {int((share_after >= 0.9).sum())}; "
        f"largest loss {loss}",
    ]
    return lines + apart, summary


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("base")
    p.add_argument("new")
    p.add_argument("--method", default="retinex-segmented")
    p.add_argument("--psnr", type=float, default=0.05, help="dB (>= 0): smaller PSNR moves are not listed")
    p.add_argument("--share", type=float, default=0.005, help="(>= 0) smaller moves of the share or ARI are not listed")
    args = p.parse_args()
    if not (args.psnr >= 0 and args.share >= 0):
        p.error("--psnr and --share must be >= 0")
    try:
        (base, base_methods), (new, new_methods) = read_run(args.base, args.method), read_run(args.new, args.method)
    except RunError as e:
        sys.exit(str(e))
    if not set(base) & set(new):
        sys.exit(f"{args.base} and {args.new} share no seed of {args.method} (methods in them: "
                 f"{', '.join(sorted(base_methods | new_methods)) or 'none'})")
    lines, summary = paired(base, new, args.psnr, args.share)
    print("\n".join(lines + ["", f"{args.method}, {args.base} -> {args.new}"] + summary))


if __name__ == "__main__":
    main()
