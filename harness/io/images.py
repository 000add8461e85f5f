"""Reading image assets (PNG/JPEG textures, Radiance .hdr probes) as linear float arrays."""
from __future__ import annotations

import os
import re

import numpy as np
import OpenEXR
from PIL import Image

from estimator import InputError, backend
from harness.io.exr import read_exr

# images larger than this (16384 x 8192: 1.5 GiB as float32 RGB) are refused before they are
# decoded: textures and light probes never need more, and decoding 20000^2 needs ~5 GiB
MAX_IMAGE_PIXELS = 1 << 27


def image_size(path: str) -> tuple[int, int] | None:
    """(width, height) from an image file's header without decoding it: EXR, Radiance HDR, or
    any format Pillow opens lazily (PNG, JPEG, ...); None when the header is not understood
    (the decoder then names the problem)."""
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".exr":
            lo, hi = OpenEXR.File(path, header_only=True).header()["dataWindow"]
            return int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
        if ext in (".hdr", ".pic", ".rgbe"):
            with open(path, "rb") as f:
                head = f.read(1 << 16)
            found = re.search(rb"\n[-+]Y (\d+) [-+]X (\d+)", head)
            return (int(found.group(2)), int(found.group(1))) if found else None
        with Image.open(path) as image:
            return image.size
    except Exception:   # an unreadable header: the decoder's own error names the file
        return None


def check_image_size(path: str) -> None:
    """Refuse an image above :data:`MAX_IMAGE_PIXELS` before decoding it (one line, naming the file)."""
    size = image_size(path)
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:
        raise InputError(f"image {path} is {size[0]}x{size[1]} pixels, above the limit of {MAX_IMAGE_PIXELS} "
                         f"({MAX_IMAGE_PIXELS / 2 ** 20:.0f} Mpx, e.g. 16384x8192): downscale it first")


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
    check_image_size(path)
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
