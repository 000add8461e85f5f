"""The reflection matrices of the model R = t_d sum h C + t_s sum h D."""
from __future__ import annotations

import hashlib

import numpy as np

from ..core import sh
from ..core.data import TriangleMesh
from ..core.errors import InputError, is_number
from ..rays.visibility import SphereSampling, Visibility


def diffuse_matrix(mesh: TriangleMesh, sampling: SphereSampling, visibility: Visibility, order: int,
                   faces: np.ndarray | None = None, coat_ior: float | None = None, chunk: int = 4096) -> np.ndarray:
    """C_lm^(i) = (1/pi) int s_i(w) Y_lm(w) max(0, w . n_i) dw, by the sphere-mesh quadrature.

    Parameters
    ----------
    faces : (n,) the faces whose rows are wanted; None: every face.
    coat_ior : the light reaches the diffuse layer through a smooth dielectric coat of this
        index: the cosine is weighted by the coat's transmission 1 - F(w . n_i) (Mitsuba's
        ``plastic``; grazing light is mostly reflected). None: a bare diffuse surface.

    Returns
    -------
    (n, (L + 1)^2) float64 (n = F without ``faces``). Computed in chunks of faces
    (matrix products, no per-face loop). Every face's rows are kept on ``visibility``
    (read-only), keyed by the order, the coat and the mesh's normals: a pose refinement asks
    for them again for each held-out estimate and prediction.
    """
    if faces is None:
        key = ("diffuse rows", order, coat_ior, hashlib.blake2b(np.ascontiguousarray(mesh.face_normals)).digest(),
               hashlib.blake2b(np.ascontiguousarray(sampling.directions)).digest())
        held = visibility.derived.get(key)
        if held is None:
            held = diffuse_matrix(mesh, sampling, visibility, order, np.arange(mesh.num_faces), coat_ior, chunk)
            held.flags.writeable = False
            visibility.derived[key] = held
        return held
    y_weighted = sh.basis(order, sampling.directions) * (sampling.weights / np.pi)[:, None]   # (K, M)
    faces = np.asarray(faces)
    normals = mesh.face_normals
    out = np.empty((len(faces), sh.num_coeffs(order)))
    for start in range(0, len(faces), chunk):
        part = faces[start:start + chunk]
        cos = np.maximum(normals[part] @ sampling.directions.T, 0.0)
        if coat_ior is not None:   # the Fresnel term only where the cosine is positive (about half)
            facing = cos > 0
            cos[facing] *= 1.0 - fresnel_dielectric(cos[facing], coat_ior)
        out[start:start + len(part)] = (cos * visibility.unpack(part)) @ y_weighted
    return out


def fresnel_dielectric(cos_theta: np.ndarray, ior: float) -> np.ndarray:
    """(N,) unpolarised Fresnel reflectance of a dielectric of index ``ior`` (from air) at
    incidence cosines (N,) (clamped to (0, 1])."""
    if not (is_number(ior) and np.isfinite(ior) and ior > 0):
        raise InputError(f"fresnel_dielectric: the index of refraction must be a finite number > 0, got {ior!r}")
    c = np.clip(cos_theta, 1e-6, 1.0)
    t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) * (1.0 / ior) ** 2, 0.0))   # 1/ior first: no overflow
    rs = (c - ior * t) / (c + ior * t)
    rp = (ior * c - t) / (ior * c + t)
    return 0.5 * (rs * rs + rp * rp)


def mirror_directions(normals: np.ndarray, view_dir: np.ndarray) -> np.ndarray:
    """r = 2 (n . v) n - v for unit normals (N, 3) and view directions (N, 3) -> (N, 3)."""
    return 2.0 * np.sum(normals * view_dir, axis=1, keepdims=True) * normals - view_dir


def mirror_shadow(faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                  visibility: Visibility) -> np.ndarray:
    """(N,) bool: the shadow function of face ``faces`` (N,) at the sample direction nearest to
    each unit mirror direction (N, 3): True where it escapes the object."""
    return visibility.lookup(faces, sampling.nearest(mirror))


def mirror_matrix(faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling,
                  visibility: Visibility, order: int) -> np.ndarray:
    """D_lm^(i)(r) = Y_lm(r) s_i(r), the paper's mirror term (Eq. 10): the shadow
    is taken at the sample direction nearest to r.

    Parameters
    ----------
    faces : (N,) face of each row.
    mirror : (N, 3) unit mirrored view directions.

    Returns
    -------
    (N, (L + 1)^2) float64, multiplying the pseudo illumination h.
    """
    return sh.basis(order, mirror) * mirror_shadow(faces, mirror, sampling, visibility)[:, None]


def phong_lobe(mirror: np.ndarray, directions: np.ndarray, exponent: float) -> np.ndarray:
    """(N, K) the normalised Phong lobe (n + 1)/(2 pi) max(0, r . w)^n of mirror directions
    (N, 3) at directions (K, 3)."""
    return (exponent + 1.0) / (2.0 * np.pi) * np.maximum(mirror @ directions.T, 0.0) ** exponent


def lobe_matrix(faces: np.ndarray, mirror: np.ndarray, sampling: SphereSampling, visibility: Visibility,
                order: int, exponent: float, chunk: int = 4096) -> np.ndarray:
    """The specular term with the Phong lobe integrated exactly, cut by the horizon and shadows.

    E_lm^(i)(r) = int Y_lm(w) (n + 1)/(2 pi) max(0, r . w)^n s_i(w) dw, by the sphere
    quadrature (s_i = 0 below the face's plane). It multiplies the *radiance* SH
    L = h / Lambda rho, so the specular term needs no pseudo-illumination
    approximation: E . L = D . h wherever the lobe is whole and unshadowed.

    Returns
    -------
    (N, (L + 1)^2) float64.
    """
    y = sh.basis(order, sampling.directions)                                     # (K, M)
    out = np.empty((len(faces), y.shape[1]))
    for start in range(0, len(faces), chunk):
        stop = min(start + chunk, len(faces))
        lobe = phong_lobe(mirror[start:stop], sampling.directions, exponent)
        vis = visibility.unpack(faces[start:stop])
        out[start:stop] = (lobe * vis * sampling.weights) @ y
    return out
