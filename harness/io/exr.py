"""OpenEXR reading and writing (the one module that touches EXR files)."""
from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import tempfile
import threading

import numpy as np
import OpenEXR

from estimator import InputError


def write_exr(path: str | os.PathLike, image: np.ndarray, half: bool = False) -> None:
    """Write an (H, W, 3) RGB or (H, W, 4) RGBA linear image, ZIP compressed.

    ``half=True`` stores float16, else float32.
    """
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise InputError(f"EXR image must be (H, W, 3) or (H, W, 4), got {image.shape}")
    if not np.all(np.isfinite(image)):
        raise InputError(f"refusing to write NaN/Inf pixels to {path}")
    kind = np.float16 if half else np.float32
    largest, limit = float(np.max(np.abs(image), initial=0.0)), float(np.finfo(kind).max)
    if largest > limit:   # it would be stored as Inf
        raise InputError(f"refusing to write {path}: a pixel of magnitude {largest:.3g} exceeds the "
                         f"{np.dtype(kind).name} EXR's range ({limit:.3g})")
    data = np.ascontiguousarray(image, dtype=kind)
    name = "RGBA" if data.shape[2] == 4 else "RGB"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    try:
        with OpenEXR.File(header, {name: data}) as f:
            f.write(str(path))
    except RuntimeError as exc:   # OpenEXR reports a full disk or an unwritable file as a RuntimeError
        reason = str(exc).rsplit(". ", 1)[-1].rstrip(".") if ". " in str(exc) else str(exc)
        raise OSError(f"{os.path.basename(str(path))}: {reason}") from None


_HOLDING = threading.Lock()   # one thread at a time moves the process's file descriptors


def _flush_c_streams() -> None:
    """fflush(NULL): write out the C library's buffered streams (a C++ library's std::cout is
    buffered there when stdout is not a terminal)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):   # no C library to call (not a POSIX host): nothing buffered to move
        pass


@contextlib.contextmanager
def _library_output():
    """Hold what the OpenEXR library prints while the block runs: on a corrupt file it writes
    its own lines to standard output and error (Python's streams and the process's file
    descriptors 1 and 2) before raising, which would come before the one-line error. Yields a
    two-element list that holds the text of each after the block: the caller puts it in its
    error, else passes it on."""
    said = ["", ""]
    with _HOLDING:
        try:
            for stream in (sys.stdout, sys.stderr):
                stream.flush()
            saved = [os.dup(1), os.dup(2)]
        except (OSError, ValueError):   # no such file descriptors (an embedding host): nothing to hold
            saved = None
        if saved is None:
            yield said
            return
        # the binding prints through Python's sys.stdout, the library below it to the descriptors
        texts = [io.StringIO(), io.StringIO()]
        with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err, \
                contextlib.redirect_stdout(texts[0]), contextlib.redirect_stderr(texts[1]):
            os.dup2(out.fileno(), 1)
            os.dup2(err.fileno(), 2)
            try:
                yield said
            finally:
                _flush_c_streams()   # the library's buffered lines go to the held files, not after them
                for fd, held in ((1, out), (2, err)):
                    os.dup2(saved[fd - 1], fd)
                    os.close(saved[fd - 1])
                    held.seek(0)
                    said[fd - 1] = texts[fd - 1].getvalue() + held.read().decode("utf-8", "replace")


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR as float32 (H, W, C) with C = 4 (RGBA) when it has alpha, else 3."""
    path = str(path)
    if not os.path.isfile(path):
        raise InputError(f"EXR file not found: {path}")
    with _library_output() as said:
        try:
            with OpenEXR.File(path) as f:
                channels = {k: v.pixels for k, v in f.channels().items()}
        except Exception as exc:  # OpenEXR raises a bare Exception on corrupt files
            failure = str(exc)    # the text only: the exception's frames would keep the file open past the block
        else:
            failure = None
    if failure is None:   # a warning on a file that reads: passed on as it was
        sys.stdout.write(said[0])
        sys.stderr.write(said[1])
    else:
        detail = said[1].splitlines()[0] if said[1].strip() else ""
        detail = detail.split(": ", 1)[-1] if detail.startswith(path) else detail
        raise InputError(f"cannot read EXR file {path} (truncated or not an EXR?): {failure}"
                         + (f"; OpenEXR: {detail}" if detail else "")) from None
    for name in ("RGBA", "RGB"):
        if name in channels:
            return np.asarray(channels[name], dtype=np.float32)
    if all(c in channels for c in "RGB"):
        planes = [channels[c] for c in ("R", "G", "B", "A") if c in channels]
        return np.stack(planes, axis=-1).astype(np.float32)
    raise InputError(f"EXR file {path} has no RGB channels (found {sorted(channels)})")
