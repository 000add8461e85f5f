"""The reflection matrices of the model R = t_d sum h C + t_s sum h D."""
from __future__ import annotations

import numpy as np

from . import sh
from .data import TriangleMesh
from .visibility import SphereSampling, Visibility


def diffuse_matrix(mesh: TriangleMesh, sampling: SphereSampling, visibility: Visibility, order: int,
                   chunk: int = 4096) -> np.ndarray:
    """C_lm^(i) = (1/pi) int s_i(w) Y_lm(w) max(0, w . n_i) dw, by the sphere-mesh quadrature.

    Returns
    -------
    (F, (L + 1)^2) float64. Computed in chunks of faces (matrix products, no per-face loop).
    """
    y_weighted = sh.basis(order, sampling.directions) * (sampling.weights / np.pi)[:, None]   # (K, M)
    normals = mesh.face_normals
    out = np.empty((mesh.num_faces, sh.num_coeffs(order)))
    for start in range(0, mesh.num_faces, chunk):
        stop = min(start + chunk, mesh.num_faces)
        cos = np.maximum(normals[start:stop] @ sampling.directions.T, 0.0)
        out[start:stop] = (cos * visibility.unpack(slice(start, stop))) @ y_weighted
    return out


def mirror_directions(normals: np.ndarray, view_dir: np.ndarray) -> np.ndarray:
    """r = 2 (n . v) n - v for unit normals (N, 3) and view directions (N, 3) -> (N, 3)."""
    return 2.0 * np.sum(normals * view_dir, axis=1, keepdims=True) * normals - view_dir


def lobe_visibility(faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                    visibility: Visibility, exponent: float, chunk: int = 8192) -> np.ndarray:
    """Unoccluded fraction of the Phong lobe around r, per row.

    s_lobe = sum_k w_k s_i(d_k) max(0, r . d_k)^n / sum_k w_k max(0, r . d_k)^n.
    Directions below the face's plane count as occluded, so a lobe cut by the
    horizon (r far from the normal) or by a shadow boundary is weighted by
    the part that reaches the light.

    Returns
    -------
    (N,) float64 in [0, 1].
    """
    out = np.empty(len(faces))
    dirs = sampling.directions.astype(np.float32)
    w = sampling.weights.astype(np.float32)
    for start in range(0, len(faces), chunk):
        stop = min(start + chunk, len(faces))
        lobe = np.maximum(mirror[start:stop].astype(np.float32) @ dirs.T, 0.0) ** np.float32(exponent) * w
        vis = np.unpackbits(visibility.bits[faces[start:stop]], axis=1, count=visibility.num_directions)
        out[start:stop] = np.sum(lobe * vis, axis=1) / np.maximum(lobe.sum(axis=1), 1e-30)
    return out


def mirror_matrix(faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                  visibility: Visibility, order: int, shadow: str = "nearest",
                  exponent: float = 10.0) -> np.ndarray:
    """D_lm^(i)(r) = Y_lm(r) s_i(r): the mirror term.

    ``shadow='nearest'`` (the paper, Eq. 10) takes s_i at the sample direction
    nearest to r; ``shadow='lobe'`` takes the unoccluded fraction of the Phong
    lobe of ``exponent`` around r (:func:`lobe_visibility`).

    Parameters
    ----------
    faces : (N,) face of each row.
    mirror : (N, 3) unit mirrored view directions.

    Returns
    -------
    (N, (L + 1)^2) float64.
    """
    if shadow == "nearest":
        factor = visibility.lookup(faces, sampling.nearest(mirror)).astype(np.float64)
    elif shadow == "lobe":
        factor = lobe_visibility(faces, mirror, sampling, visibility, exponent)
    else:
        raise ValueError(f"shadow must be 'nearest' or 'lobe', got {shadow!r}")
    return sh.basis(order, mirror) * factor[:, None]
