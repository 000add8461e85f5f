"""Output folders that appear whole or not at all, and never at the cost of an input.

Rules (``check_output``), checked before any work starts and again on writing:

* an output may not be, contain or lie inside any input;
* an existing output is replaced only with ``overwrite``, and only when it is empty
  or pseudolight wrote it (it holds the marker file :data:`MARKER`);
* the parent folder must be creatable and writable.

Writing goes to a temporary ``.NAME.pseudolight-partial-PID-XXXX`` folder beside the output,
renamed into place when complete; partial folders whose process is gone (killed
by SIGKILL) are removed by the next write into the same parent.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
import time

from estimator import InputError

MARKER = ".pseudolight-output"
_PARTIAL = re.compile(r"^\..+\.pseudolight-(?:partial|old)-(\d{1,9})-")


class OutputError(InputError):
    """An output folder that cannot or must not be written; the message names it."""


class OutputExistsError(OutputError):
    """The output folder exists and overwriting was not asked for."""


def _inside(inner: str, outer: str) -> bool:
    return inner == outer or inner.startswith(outer.rstrip(os.sep) + os.sep)


def refuse_inputs(out: str, inputs) -> None:
    """Raise :class:`OutputError` when ``out`` is, contains or lies inside any of ``inputs``."""
    for item in inputs:
        if item is None or item == "":
            continue
        source = os.path.realpath(os.path.abspath(str(item)))
        if _inside(out, source) or _inside(source, out):
            relation = "is" if out == source else ("lies inside" if _inside(out, source) else "contains")
            raise OutputError(f"output {out} {relation} the input {source}; choose another -o")


def check_output(path: str | os.PathLike, inputs: tuple | list = (), overwrite: bool = False) -> str:
    """Refuse an output that would destroy an input or a folder pseudolight did not write.

    Parameters
    ----------
    path : the output folder.
    inputs : files and folders the command reads (datasets, runs, specs, assets).
    overwrite : whether an existing output may be replaced.

    Returns the absolute output path. Raises :class:`OutputError` naming the folder.
    """
    out = os.path.realpath(os.path.abspath(str(path)))
    refuse_inputs(out, inputs)
    if os.path.lexists(out):
        if not os.path.isdir(out) or os.path.islink(out):
            raise OutputError(f"output {out} exists and is not a folder")
        if not overwrite:
            raise OutputExistsError(f"{out} exists; pass --overwrite to replace it")
        entries = os.listdir(out)
        if entries and MARKER not in entries:
            raise OutputError(f"refusing to replace {out}: it was not written by pseudolight (no {MARKER}) "
                              "and is not empty; remove it yourself or choose another -o")
    parent = os.path.dirname(out)
    existing = parent
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise OutputError(f"cannot create {out}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {out}: {existing} is not writable")
    return out


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # when in doubt, keep the folder
    return True


def remove_stale_partials(parent: str) -> list[str]:
    """Remove ``.NAME.pseudolight-partial-PID-*`` / ``.NAME.pseudolight-old-PID-*`` folders in
    ``parent`` whose process no longer runs (only names this module makes); returns them."""
    removed = []
    try:
        names = os.listdir(parent)
    except OSError:
        return removed
    for name in names:
        match = _PARTIAL.match(name)
        if match and int(match.group(1)) != os.getpid() and not _process_alive(int(match.group(1))):
            shutil.rmtree(os.path.join(parent, name), ignore_errors=True)
            removed.append(os.path.join(parent, name))
    return removed


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, overwrite: bool = False, inputs: tuple | list = (),
                     kind: str = "output"):
    """Yield a temporary folder beside ``path``; rename it to ``path`` on success.

    On any exception (including KeyboardInterrupt) the temporary folder is
    removed and ``path`` is left as it was. The rules of :func:`check_output`
    apply; the finished folder holds the marker :data:`MARKER` (``kind`` says
    what it is: dataset, run, report, ...). Filesystem errors (read-only, disk
    full) become :class:`OutputError` naming ``path``, never the temporary folder.
    """
    path = check_output(path, inputs, overwrite)
    parent = os.path.dirname(path)
    try:
        os.makedirs(parent, exist_ok=True)
        remove_stale_partials(parent)
        tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(path)}.pseudolight-partial-{os.getpid()}-", dir=parent)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the output is an ordinary folder
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        try:
            yield tmp
            with open(os.path.join(tmp, MARKER), "w") as f:
                json.dump({"kind": kind, "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "pid": os.getpid()}, f)
            if os.path.exists(path):
                if not overwrite:  # another process wrote it meanwhile
                    raise OutputExistsError(f"{path} appeared while this output was being written")
                check_output(path, inputs, overwrite=True)
                trash = tempfile.mkdtemp(prefix=f".{os.path.basename(path)}.pseudolight-old-{os.getpid()}-",
                                         dir=parent)
                os.replace(path, os.path.join(trash, "old"))
                os.replace(tmp, path)
                shutil.rmtree(trash, ignore_errors=True)
            else:
                os.replace(tmp, path)
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        except InputError as exc:
            message = str(exc)
            if tmp in message:
                raise type(exc)(message.replace(tmp, path)) from None
            raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
