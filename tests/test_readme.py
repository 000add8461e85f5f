"""The README's command walkthrough runs in order, as written, at the tiny profile.

Each line of the "Command line" block is run through the CLI's ``main`` in one folder,
with ``out/`` under it. To keep the test small every scene is generated at its ``tiny``
profile (a line that names a profile keeps it), mitsuba-ad's budget is 2 s, the sweeps'
reports are written without the Mitsuba cross-check, and those of ``suite`` without figures
(the report lines and ``bench smoke`` draw them); the Dask line needs a cluster and is left
out. Every other line must exit 0, except the ones the README says may not: ``--strict``
exits 3 when the estimate warns. The report against a baseline made at full size says that
it does not compare them (exit 0), not 'regression'.
"""
from __future__ import annotations

import os
import re
import shlex

from harness.cli.main import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def walkthrough() -> list[list[str]]:
    """The README's command lines (argv without 'pseudolight'), comments removed."""
    text = open(os.path.join(ROOT, "README.md")).read()
    block = text.split("## Command line", 1)[1].split("```", 2)[1]
    lines = []
    for line in block.splitlines():
        line = line.split("#", 1)[0].strip()
        if line.startswith("pseudolight "):
            lines.append(shlex.split(line)[1:])
    return lines


def tiny(argv: list[str], out: str) -> list[str] | None:
    """The command as the test runs it: ``out/`` moved under ``out``, tiny sizes; None to skip."""
    if "--executor" in argv and "dask" in argv:
        return None
    argv = [re.sub(r"^out/", out + "/", a) for a in argv]
    command = argv[0]
    if (command in ("generate", "suite") or (command == "bench" and "--dry-run" not in argv)) \
            and "--profile" not in argv:
        argv += ["--profile", "tiny"]
    if "--time-budget" in argv:
        argv[argv.index("--time-budget") + 1] = "2"
    if command in ("report", "suite", "bench") and "--dry-run" not in argv:
        argv += ["--cross-check-spp", "4"] if command == "report" else ["--no-mitsuba"]
    if command == "suite":
        argv += ["--no-figures"]
    return argv


def test_the_readme_walkthrough_runs_in_order(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)    # the shipped scenes and baselines are read from the checkout
    out = str(tmp_path / "out")
    lines = walkthrough()
    assert len(lines) >= 25
    for argv in lines:
        run = tiny(argv, out)
        if run is None:
            continue
        code = main(run)
        err = capsys.readouterr().err
        allowed = {0, 3} if "--strict" in run else {0}   # --strict: 3 when the estimate warned
        assert code in allowed, f"{' '.join(run)} exited {code}: {err[-2000:]}"
        assert "Traceback" not in err, err
        if "--baseline" in run:
            assert "not compared" in err and "REGRESSION" not in err, err
