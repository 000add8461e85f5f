"""A UV atlas of a mesh (xatlas) and per-face means of a texture over it, in Mitsuba's
``bitmap`` lookup (uv (0, 0) is the top-left texel's corner; texel centres at
((j + 0.5) / W, (i + 0.5) / H); bilinear between them, clamped at the border).

The atlas keeps the mesh's faces and their order (a face's identity): xatlas only splits
vertices along its seams.
"""
from __future__ import annotations

import numpy as np

from .data import TriangleMesh
from .errors import InputError


def uv_atlas(mesh: TriangleMesh, uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (V', 3), faces (F, 3), uv (V', 2) in [0, 1]) with face order kept.

    ``uv``: the mesh's own per-vertex texture coordinates (V, 2), used when given;
    otherwise the mesh is unwrapped with xatlas, which splits vertices along seams
    but keeps the faces and their order.
    """
    if uv is not None:
        if uv.shape != (len(mesh.vertices), 2) or not np.all(np.isfinite(uv)):
            raise InputError(f"texture coordinates must be finite (V, 2), got {uv.shape}")
        return mesh.vertices, mesh.faces, np.asarray(uv, dtype=np.float64)
    import xatlas

    vmapping, indices, uvs = xatlas.parametrize(mesh.vertices.astype(np.float32), mesh.faces.astype(np.uint32))
    if indices.shape != mesh.faces.shape or not np.array_equal(vmapping[indices], mesh.faces):
        raise RuntimeError("xatlas changed the faces of the mesh")  # a bug, never bad input
    return mesh.vertices[vmapping], indices.astype(np.int64), uvs.astype(np.float64)


def sample_bilinear(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, C) values of ``texture`` (H, W, C) at ``uv`` (N, 2), as Mitsuba's ``bitmap``
    (filter ``bilinear``, wrap ``clamp``) evaluates them."""
    h, w = texture.shape[:2]
    x = np.clip(uv[:, 0] * w - 0.5, 0.0, w - 1.0)
    y = np.clip(uv[:, 1] * h - 0.5, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(h - 2, 0))
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    return ((1 - fy) * ((1 - fx) * texture[y0, x0] + fx * texture[y0, x1])
            + fy * ((1 - fx) * texture[y1, x0] + fx * texture[y1, x1]))


def barycentric_grid(k: int) -> np.ndarray:
    """(S, 3) barycentric points of a triangle's regular subdivision into k^2 triangles:
    the centroids of its sub-triangles, S = k^2 (each stands for an equal area)."""
    if k < 1:
        raise InputError(f"the barycentric grid needs k >= 1, got {k}")
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    up = i + j <= k - 1                       # upward sub-triangles: corners (i,j), (i+1,j), (i,j+1)
    down = i + j <= k - 2                     # downward ones: (i+1,j), (i,j+1), (i+1,j+1)
    points = np.concatenate([np.column_stack([i[up] + 1 / 3, j[up] + 1 / 3]),
                             np.column_stack([i[down] + 2 / 3, j[down] + 2 / 3])]) / k
    return np.column_stack([points, 1.0 - points.sum(axis=1)])


def face_means(texture: np.ndarray, faces: np.ndarray, uv: np.ndarray, k: int = 4) -> np.ndarray:
    """(F, C) area mean of ``texture`` (H, W, C) over each face of ``faces`` (F, 3) with
    per-vertex ``uv`` (V', 2), by :func:`sample_bilinear` at the k^2 points of
    :func:`barycentric_grid` (UV maps are affine over a face, so equal areas in UV are
    equal areas on the surface)."""
    weights = barycentric_grid(k)                                           # (S, 3)
    points = np.einsum("sk,fkd->fsd", weights, uv[faces])                   # (F, S, 2)
    values = sample_bilinear(texture, points.reshape(-1, 2))
    return values.reshape(len(faces), len(weights), -1).mean(axis=1)
