"""OpenEXR reading and writing (the one module that touches EXR files)."""
from __future__ import annotations

import os

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


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR as float32 (H, W, C) with C = 4 (RGBA) when it has alpha, else 3."""
    path = str(path)
    if not os.path.isfile(path):
        raise InputError(f"EXR file not found: {path}")
    try:
        with OpenEXR.File(path) as f:
            channels = {k: v.pixels for k, v in f.channels().items()}
    except Exception as exc:  # OpenEXR raises a bare Exception on corrupt files
        raise InputError(f"cannot read EXR file {path}: {exc}") from exc
    for name in ("RGBA", "RGB"):
        if name in channels:
            return np.asarray(channels[name], dtype=np.float32)
    if all(c in channels for c in "RGB"):
        planes = [channels[c] for c in ("R", "G", "B", "A") if c in channels]
        return np.stack(planes, axis=-1).astype(np.float32)
    raise InputError(f"EXR file {path} has no RGB channels (found {sorted(channels)})")
