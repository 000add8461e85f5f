"""Screenshots of the three pages in headless Chromium, at 1400 px wide, to look at.

    .venv/bin/python benchmarks/page_screenshots.py [--out DIR] [--chromium /usr/bin/chromium]

Makes the README's pages at the tiny profile (a report of earth-specular, a comparison of it
with sparse-colored, and `bench smoke`'s sweep and comparison) and writes report.png,
compare.png, sweep.png and sweep-compare.png beside them. Chromium is Debian's package
(`apt-get install chromium`); it is started with no network of its own (the flags below),
as this machine has none.
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars"]


def pseudolight(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "harness.cli", *args], check=True, stdout=subprocess.DEVNULL)


def screenshot(chromium: str, page: str, png: str, height: int) -> None:
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size=1400,{height}",
                        f"--screenshot={png}", f"file://{os.path.abspath(page)}"], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)
    print(f"{png} <- {page}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out/pages")
    parser.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = parser.parse_args()
    if not os.path.isfile(args.chromium):
        raise SystemExit(f"no Chromium at {args.chromium}: apt-get install chromium, or pass --chromium PATH")
    o = args.out
    os.makedirs(o, exist_ok=True)
    for scene in ("earth-specular", "sparse-colored"):
        pseudolight("generate", scene, "--profile", "tiny", "-o", f"{o}/{scene}", "--overwrite")
        pseudolight("estimate", f"{o}/{scene}", "-o", f"{o}/{scene}-run", "--overwrite")
        pseudolight("report", f"{o}/{scene}-run", "-o", f"{o}/{scene}-report", "--cross-check-spp", "16", "--overwrite")
    pseudolight("compare", f"{o}/earth-specular-report", f"{o}/sparse-colored-report", "-o", f"{o}/compare",
                "--overwrite")
    pseudolight("bench", "smoke", "-o", f"{o}/smoke", "--no-mitsuba")
    for page, png, height in ((f"{o}/earth-specular-report/report.html", "report.png", 4200),
                              (f"{o}/compare/compare.html", "compare.png", 1600),
                              (f"{o}/smoke/compare/sweep.html", "sweep.png", 1500),
                              (f"{o}/smoke/compare/compare.html", "sweep-compare.png", 1600)):
        screenshot(args.chromium, page, os.path.join(o, png), height)
    return 0


if __name__ == "__main__":
    sys.exit(main())
