"""The ``pseudolight`` command's entry point: Ctrl-C is honoured from the first instant.

Importing the command line (numpy, trimesh, Mitsuba) takes about a second, and trimesh's
optional imports catch ``BaseException``, so a Ctrl-C that lands inside them would be
swallowed and the command would run to the end. The handler installed here, before those
imports, records the signal as well as raising ``KeyboardInterrupt``; a recorded signal ends
the command with exit code 130 before it writes anything. It stays in place until
:func:`.main.main` installs its own, after parsing the arguments.
"""
from __future__ import annotations

import os
import signal
import sys

INTERRUPTED, TERMINATED = 130, 143


def run(argv: list[str] | None = None) -> int:
    """Import the command line under a recording SIGINT handler, then run it (:func:`.main.main`)."""
    seen: list[int] = []

    def on_sigint(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)
    try:
        from harness.cli.main import main
        if not seen:
            return _exit(main(argv))
    except BaseException as exc:   # a swallowed Ctrl-C can surface as any error of the import it broke
        if not (seen or isinstance(exc, KeyboardInterrupt)):
            raise
    print("pseudolight: interrupted; no partial output was left", file=sys.stderr)
    return _exit(INTERRUPTED)


def _exit(code: int) -> int:
    """``code``; an interrupted command leaves at once (an import cut short can leave Dr.Jit half
    set up, and its teardown at the interpreter's exit then aborts the process)."""
    if code in (INTERRUPTED, TERMINATED):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code
