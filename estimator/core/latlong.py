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
from scipy import sparse

from .errors import InputError


def directions(height: int, width: int, rows: slice = slice(None)) -> np.ndarray:
    """Unit directions of every pixel, shape (H, W, 3); of the ``rows`` only when given."""
    if height < 3 or width < 2:
        raise InputError(f"a lat-long map needs at least 3 rows and 2 columns, got {height}x{width}")
    theta = np.pi * np.arange(height)[rows] / (height - 1)
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


def _row_edges(height: int) -> np.ndarray:
    """(H + 1,) polar angles bounding each row's cell (the quadrature of :func:`solid_angles`)."""
    return np.clip(np.pi * (np.arange(height + 1) - 0.5) / (height - 1), 0.0, np.pi)


def _overlap(old_edges: np.ndarray, new_edges: np.ndarray, measure) -> sparse.csr_array:
    """(n', n) measure of the overlap of each new cell with each old one (sparse: a cell
    overlaps a few), cells given by their sorted edges (n + 1,) and (n' + 1,) in a 1-D
    coordinate; ``measure`` maps coordinates to the cumulative measure (identity for
    azimuth, -cos for the polar angle)."""
    first = np.clip(np.searchsorted(old_edges, new_edges[:-1], side="right") - 1, 0, len(old_edges) - 2)
    last = np.clip(np.searchsorted(old_edges, new_edges[1:], side="left"), 1, len(old_edges) - 1)
    count = last - first
    row = np.repeat(np.arange(len(new_edges) - 1), count)
    starts = np.cumsum(count) - count
    col = first[row] + np.arange(len(row)) - starts[row]
    lo = np.maximum(new_edges[row], old_edges[col])
    hi = np.minimum(new_edges[row + 1], old_edges[col + 1])
    value = np.where(hi > lo, measure(hi) - measure(lo), 0.0)
    return sparse.csr_array((value, (row, col)), shape=(len(new_edges) - 1, len(old_edges) - 1))


def downsample(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """A lat-long map (H, W, C) averaged over the cells of a coarser (height, width) grid,
    each new cell the solid-angle weighted mean of the old cells it overlaps, so the
    integral of the map over any new cell, and over the sphere, is kept.

    Written here (not scikit-image's ``resize``) because the cells of a lat-long map have
    unequal solid angles and wrap in azimuth; the result is ``(height, width, C)`` float64.
    """
    h, w, c = image.shape
    polar = _overlap(_row_edges(h), _row_edges(height), lambda t: -np.cos(t))       # (height, H) solid-angle bands
    # azimuth cells are centred on phi_j = 2 pi j / W: edges half a cell before; the old cells
    # are repeated one turn earlier so that the first new cell wraps past phi = 0
    old = 2.0 * np.pi * (np.arange(-w, w + 1) - 0.5) / w
    new = 2.0 * np.pi * (np.arange(width + 1) - 0.5) / width
    azimuth = _overlap(old, new, lambda p: p)
    azimuth = azimuth[:, :w] + azimuth[:, w:]
    polar = sparse.diags_array(1.0 / polar.sum(axis=1)) @ polar
    azimuth = sparse.diags_array(1.0 / azimuth.sum(axis=1)) @ azimuth
    rows = polar @ np.asarray(image, np.float64).reshape(h, w * c)                   # (height, W * C)
    cols = azimuth @ rows.reshape(height, w, c).transpose(1, 0, 2).reshape(w, height * c)
    return cols.reshape(width, height, c).transpose(1, 0, 2)
