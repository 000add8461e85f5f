"""Reading image assets (PNG/JPEG textures, Radiance .hdr probes) as linear float arrays."""
from __future__ import annotations

import os

import numpy as np

from estimator import InputError, backend
from harness.io.exr import read_exr


def read_linear_rgb(path: str | os.PathLike, raw: bool = False, alpha: bool = False) -> np.ndarray:
    """Any image Mitsuba reads (PNG of 8 or 16 bits, JPEG, HDR, EXR) as linear Rec.709 float32
    (H, W, 3), or (H, W, 4) with ``alpha`` when the file has an alpha channel (kept linear).

    LDR images are taken as sRGB-encoded and linearised, unless ``raw`` (Mitsuba's
    ``bitmap`` option of that name): then their stored values are used as they are.
    Mitsuba's reader keeps a 16-bit PNG's depth (Pillow reduces 16-bit RGB to 8 bits and
    16-bit grey to 0/1 when converting it).
    """
    path = str(path)
    if not os.path.isfile(path):
        raise InputError(f"image file not found: {path}")
    if path.lower().endswith(".exr"):
        return read_exr(path) if alpha else read_exr(path)[..., :3]
    mi = backend.set_variant()
    try:
        bitmap = mi.Bitmap(path)
    except Exception as exc:
        raise InputError(f"cannot read image {path}: {exc}") from exc
    formats = mi.Bitmap.PixelFormat
    keep = alpha and bitmap.pixel_format() in (formats.RGBA, formats.YA)
    linear = bitmap.convert(formats.RGBA if keep else formats.RGB, mi.Struct.Type.Float32,
                            srgb_gamma=bool(raw and bitmap.srgb_gamma()))
    image = np.array(linear, dtype=np.float32)
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    if not np.all(np.isfinite(image)):
        raise InputError(f"image {path} contains NaN or Inf pixels")
    return image
