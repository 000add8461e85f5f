"""Per-face albedo from textures, constants and regions."""
from __future__ import annotations

import numpy as np

from estimator import TriangleMesh, latlong


def _barycentric_grid(k: int) -> np.ndarray:
    """Centroids of the k^2 equal-area sub-triangles of a triangle: (k^2, 3) weights."""
    pts = []
    for i in range(k):
        for j in range(k - i):
            pts.append(((i + 1 / 3) / k, (j + 1 / 3) / k))          # upward triangles
            if i + j < k - 1:
                pts.append(((i + 2 / 3) / k, (j + 2 / 3) / k))      # downward triangles
    a = np.array(pts)
    return np.column_stack([a, 1.0 - a.sum(axis=1)])


def spherical_texture_average(mesh: TriangleMesh, texture: np.ndarray, samples_per_edge: int = 4,
                              center: np.ndarray | None = None) -> np.ndarray:
    """Area average over each face of a lat-long texture projected from ``center``.

    The texture (H, W, C) is indexed in Mitsuba's envmap orientation by the
    direction from ``center`` (default: bounding-box centre) to the surface point.

    Returns
    -------
    (F, C) float64.
    """
    bary = _barycentric_grid(samples_per_edge)                     # (S, 3)
    points = np.einsum("sk,fkd->fsd", bary, mesh.corners)            # (F, S, 3)
    if center is None:
        center = mesh.bounds_centre
    dirs = (points - center).reshape(-1, 3)
    values = latlong.sample_bilinear(np.asarray(texture, dtype=np.float64), dirs)
    return values.reshape(mesh.num_faces, len(bary), -1).mean(axis=1)


def uv_texture_average(mesh: TriangleMesh, uv: np.ndarray, texture: np.ndarray,
                       samples_per_edge: int = 4, nearest: bool = False) -> np.ndarray:
    """Area average over each face of an image texture through per-vertex UVs.

    u runs left to right, v bottom to top (OBJ/PLY convention), wrapping
    (repeat); bilinear lookup between pixel centres (``nearest``: the texel's value).

    Parameters
    ----------
    uv : (V, 2) texture coordinates; texture : (H, W, C).

    Returns
    -------
    (F, C) float64.
    """
    bary = _barycentric_grid(samples_per_edge)
    coords = np.einsum("sk,fkd->fsd", bary, uv[mesh.faces]).reshape(-1, 2)
    return sample_uv(texture, coords, nearest).reshape(mesh.num_faces, len(bary), -1).mean(axis=1)


def sample_uv(texture: np.ndarray, coords: np.ndarray, nearest: bool = False) -> np.ndarray:
    """(N, C) bilinear lookup of ``texture`` (H, W, C) at texture coordinates (N, 2): u left
    to right, v bottom to top (OBJ/PLY convention), wrapping; pixel centres at half-texels.
    ``nearest``: the value of the texel that holds the point (Mitsuba's ``filter_type``)."""
    h, w = texture.shape[:2]
    x = np.mod(coords[:, 0], 1.0) * w - 0.5
    y = (1.0 - np.mod(coords[:, 1], 1.0)) * h - 0.5
    if nearest:
        col = np.floor(x + 0.5).astype(np.int64) % w
        row = np.clip(np.floor(y + 0.5).astype(np.int64), 0, h - 1)
        return np.asarray(texture, dtype=np.float64)[row, col]
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, x1 = x0 % w, (x0 + 1) % w
    y0, y1 = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    t = np.asarray(texture, dtype=np.float64)
    return (1 - fy) * ((1 - fx) * t[y0, x0] + fx * t[y0, x1]) + fy * ((1 - fx) * t[y1, x0] + fx * t[y1, x1])


def region_labels(mesh: TriangleMesh, rules: list[tuple[np.ndarray, list[tuple[float, float]]]]) -> np.ndarray:
    """Region of each face from direction bands; later rules override earlier ones.

    Each rule is (axis (3,), ranges): a face belongs to it when the unit
    direction from the bounding-box centre to its centroid, dotted with the
    axis, lies in one of the [lo, hi] ranges. An empty range list matches all
    faces (the base region).

    Returns
    -------
    (F,) int64 index of the rule that won (0 when none matched).
    """
    d = mesh.centroids - mesh.bounds_centre
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    labels = np.zeros(mesh.num_faces, dtype=np.int64)
    for index, (axis, ranges) in enumerate(rules):
        axis = np.asarray(axis, dtype=np.float64)
        t = d @ (axis / np.linalg.norm(axis))
        inside = np.ones(mesh.num_faces, bool) if not ranges else np.zeros(mesh.num_faces, bool)
        for lo, hi in ranges:
            inside |= (t >= lo) & (t <= hi)
        labels[inside] = index
    return labels


def pattern_albedo(mesh: TriangleMesh, pattern: str, colors, frequency: float, axis, seed: int = 0) -> np.ndarray:
    """(F, 3) a procedural albedo between ``colors`` (2, 3), by the direction d from the bounding-box
    centre to each face's centroid (so it wraps any body).

    'stripes': bands of width 1 / ``frequency`` in d . axis, alternating; 'checks': cells of
    180 / ``frequency`` degrees in polar and azimuthal angle, alternating; 'gradient': a smooth
    ramp along d . axis; 'noise': a smooth random field (real SH of degrees 1 to ``frequency``,
    seeded by ``seed``), mapped through a logistic so both colours occur.
    """
    d = mesh.centroids - mesh.bounds_centre
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    if pattern == "stripes":
        t = np.floor(frequency * (d @ a + 1.0)) % 2
    elif pattern == "checks":
        polar = np.arccos(np.clip(d[:, 1], -1.0, 1.0))
        azimuth = np.arctan2(d[:, 0], d[:, 2]) + np.pi
        t = (np.floor(frequency * polar / np.pi) + np.floor(frequency * azimuth / np.pi)) % 2
    elif pattern == "gradient":
        t = 0.5 * (d @ a + 1.0)
    elif pattern == "noise":
        from estimator import sh

        order = max(int(round(frequency)), 1)
        coeffs = np.random.default_rng(seed).standard_normal(sh.num_coeffs(order))
        coeffs[0] = 0.0
        field = sh.basis(order, d) @ coeffs
        t = 1.0 / (1.0 + np.exp(-3.0 * field / max(float(np.std(field)), 1e-12)))
    else:
        raise ValueError(f"unknown pattern {pattern!r}")
    c = np.asarray(colors, float)
    return c[0] * (1.0 - t)[:, None] + c[1] * t[:, None]
