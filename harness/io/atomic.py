"""Output folders that appear whole or not at all, and never at the cost of an input.

Rules (``check_output``), checked before any work starts and again on writing:

* an output may not be, contain or lie inside any input;
* an existing output is replaced only with ``overwrite``, and only when it is empty
  or pseudolight wrote it as the same kind of output (the marker file :data:`MARKER` says
  which: a run never replaces a dataset);
* the parent folder must be creatable and writable (tried, not just asked of the
  permissions: as root they allow what a read-only file system refuses).

Writing goes to a temporary ``.NAME.pseudolight-partial-PID-XXXX`` folder beside the output,
renamed into place when complete. The writing process holds an exclusive ``fcntl`` lock on
the file :data:`LOCK` inside it, which the operating system releases when the process dies
(even by SIGKILL); the next write into the same parent removes only partial folders whose
lock it can take, so no process deletes another's live work, whatever host or PID namespace
it runs in (on a shared file system the lock is the file system's). A partial folder without
a lock file (an older version's) is removed only when its PID is gone on this host and it
has not changed for :data:`UNLOCKED_STALE_S` seconds.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import tempfile
import threading
import time

from estimator import InputError

MARKER = ".pseudolight-output"
LOCK = ".pseudolight-lock"
UNLOCKED_STALE_S = 60.0
_LOCKS = threading.Lock()     # this process's threads take and check locks one at a time
_HELD: dict[str, int] = {}   # lock file -> descriptor, held by this process (closing any descriptor
#                              of a file would release this process's POSIX lock on it: never opened twice)
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


def check_output(path: str | os.PathLike, inputs: tuple | list = (), overwrite: bool = False,
                 kind: str | None = None) -> str:
    """Refuse an output that would destroy an input or a folder pseudolight did not write.

    Parameters
    ----------
    path : the output folder.
    inputs : files and folders the command reads (datasets, runs, specs, assets).
    overwrite : whether an existing output may be replaced.
    kind : what the command writes (dataset, run, report, ...; :func:`atomic_directory`'s
        ``kind``): an existing output of another kind is never replaced. None: not checked.

    Returns the absolute output path. Raises :class:`OutputError` naming the folder.
    """
    if not str(path).strip():   # an empty -o would resolve to the working directory
        raise OutputError("the output path is empty; give -o a folder")
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
        if entries and kind is not None and (held := output_kind(out)) != kind:
            what = f"kind {held!r}" if held else f"unknown kind (its {MARKER} is unreadable)"
            raise OutputError(f"refusing to replace {out}: it holds pseudolight output of {what} and this command "
                              f"writes kind {kind!r}; remove it yourself or choose another -o")
    parent = os.path.dirname(out)
    existing = parent
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise OutputError(f"cannot create {out}: {existing} is a file, not a folder")
    writable(existing, out)
    return out


def writable(folder: str, target: str) -> None:
    """Raise :class:`OutputError` naming ``target`` unless a folder can be made in ``folder``:
    tried, not asked of the permission bits, which allow root what a read-only file system or
    a kernel folder refuses."""
    try:   # named as a partial folder: one left by a killed process is cleaned like any other
        os.rmdir(tempfile.mkdtemp(prefix=f".probe.pseudolight-partial-{os.getpid()}-", dir=folder))
    except OSError as exc:
        raise OutputError(f"cannot write {target}: {folder} is not writable ({exc.strerror or exc})") from None


def output_kind(folder: str) -> str | None:
    """The kind of output pseudolight wrote in ``folder`` (its :data:`MARKER`'s ``kind``), or None
    where the marker is missing or unreadable."""
    try:
        with open(os.path.join(folder, MARKER)) as f:
            kind = json.load(f).get("kind")
    except (OSError, ValueError, AttributeError, RecursionError):
        return None
    return kind if isinstance(kind, str) else None


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # when in doubt, keep the folder
    return True


def _hold_lock(folder: str) -> None:
    """Take the exclusive lock of a partial folder for this process's lifetime (or until released).
    The lock file is locked under a private name and then renamed into place, so no cleaner sees
    it unlocked. Where the file system has no locks (ENOLCK, EOPNOTSUPP) the folder goes
    without one, and the PID-and-age rule protects it."""
    path = os.path.join(folder, LOCK)
    private = f"{path}.{os.getpid()}-{threading.get_ident()}"
    with _LOCKS:
        fd = os.open(private, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            os.remove(private)
            return
        os.replace(private, path)
        _HELD[path] = fd


def _release_lock(folder: str, published: str | None = None) -> None:
    """Give up a partial folder's lock and remove its lock file; ``published``: the folder was
    renamed there while the lock was held (a cleaner that opened the old name then finds
    nothing to remove)."""
    with _LOCKS:
        fd = _HELD.pop(os.path.join(folder, LOCK), None)
        with contextlib.suppress(FileNotFoundError):
            os.remove(os.path.join(published or folder, LOCK))
        if fd is not None:
            os.close(fd)


def _owner_alive(folder: str, pid: int) -> bool:
    """Whether the process that writes ``folder`` still runs: it holds the folder's lock."""
    path = os.path.join(folder, LOCK)
    with _LOCKS:
        if path in _HELD:
            return True
        return _lock_is_held(folder, path, pid)


def _lock_is_held(folder: str, path: str, pid: int) -> bool:
    """:func:`_owner_alive` for a lock this process does not hold (called under ``_LOCKS``)."""
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:   # no lock (yet, or an older version's folder): PID and age decide
        try:
            recent = time.time() - os.stat(folder).st_mtime < UNLOCKED_STALE_S
        except OSError:
            return False
        return recent or _process_alive(pid)
    except OSError:
        return True   # when in doubt, keep the folder
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True   # its writer holds the lock
    finally:
        os.close(fd)  # releases the lock this check took
    return False


def remove_stale_partials(parent: str) -> list[str]:
    """Remove ``.NAME.pseudolight-partial-PID-*`` / ``.NAME.pseudolight-old-PID-*`` folders in
    ``parent`` whose writer is gone (only names this module makes); returns them."""
    removed = []
    try:
        names = os.listdir(parent)
    except OSError:
        return removed
    for name in names:
        match = _PARTIAL.match(name)
        folder = os.path.join(parent, name)
        if match and not _owner_alive(folder, int(match.group(1))):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
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
    path = check_output(path, inputs, overwrite, kind)
    parent = os.path.dirname(path)
    try:
        os.makedirs(parent, exist_ok=True)
        remove_stale_partials(parent)
        tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(path)}.pseudolight-partial-{os.getpid()}-", dir=parent)
        _hold_lock(tmp)
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
                check_output(path, inputs, overwrite=True, kind=kind)
                trash = tempfile.mkdtemp(prefix=f".{os.path.basename(path)}.pseudolight-old-{os.getpid()}-",
                                         dir=parent)
                os.replace(path, os.path.join(trash, "old"))
                os.replace(tmp, path)
                _release_lock(tmp, path)   # held through the rename: no cleaner can take it before
                shutil.rmtree(trash, ignore_errors=True)
            else:
                os.replace(tmp, path)
                _release_lock(tmp, path)
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        except InputError as exc:
            message = str(exc)
            if tmp in message:
                raise type(exc)(message.replace(tmp, path)) from None
            raise
    except BaseException:
        _release_lock(tmp)
        shutil.rmtree(tmp, ignore_errors=True)
        raise
