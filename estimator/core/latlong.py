"""Latitude-longitude maps in Mitsuba's ``envmap`` orientation.

A map of H rows and W columns samples the sphere on a grid of *vertices*, as
Mitsuba's ``envmap`` does: row i is at polar angle theta_i = pi * i / (H - 1)
from world +Y (row 0 is the zenith +Y, the last row the nadir -Y); column j is
at azimuth phi_j = 2 pi j / W, and the direction is

    d = (sin(theta) sin(phi), cos(theta), -sin(theta) cos(phi)),

so u = j / W = 0.5 looks at +Z and u = 0.25 at +X.
"""
from __future__ import annotations

import numpy as np

from .errors import InputError


def directions(height: int, width: int) -> np.ndarray:
    """Unit directions of every pixel, shape (H, W, 3)."""
    if height < 3 or width < 2:
        raise InputError(f"a lat-long map needs at least 3 rows and 2 columns, got {height}x{width}")
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2.0 * np.pi * np.arange(width) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    return np.stack(np.broadcast_arrays(st * np.sin(phi), ct, -st * np.cos(phi)), axis=-1)


def solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle (sr) of the cell around each pixel, shape (H, W); sums to 4 pi."""
    step = np.pi / (height - 1)
    theta = np.pi * np.arange(height) / (height - 1)
    lo = np.clip(theta - 0.5 * step, 0.0, np.pi)
    hi = np.clip(theta + 0.5 * step, 0.0, np.pi)
    band = 2.0 * np.pi * (np.cos(lo) - np.cos(hi)) / width
    return np.broadcast_to(band[:, None], (height, width)).copy()


def to_uv(dirs: np.ndarray) -> np.ndarray:
    """Directions (..., 3) -> (u, v) in [0, 1)^2 x [0, 1], shape (..., 2)."""
    d = np.asarray(dirs, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2.0 * np.pi), 1.0)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return np.stack([u, v], axis=-1)


def sample_bilinear(image: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a lat-long map (H, W, C) at directions (N, 3) -> (N, C).

    Wraps in azimuth and clamps at the poles, as Mitsuba's ``envmap`` does.
    """
    height, width = image.shape[:2]
    uv = to_uv(dirs)
    x = uv[:, 0] * width
    y = uv[:, 1] * (height - 1)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, height - 2)
    fx, fy = (x - x0)[:, None], np.clip(y - y0, 0.0, 1.0)[:, None]
    x0 %= width
    x1 = (x0 + 1) % width
    return ((1 - fy) * ((1 - fx) * image[y0, x0] + fx * image[y0, x1])
            + fy * ((1 - fx) * image[y0 + 1, x0] + fx * image[y0 + 1, x1]))
