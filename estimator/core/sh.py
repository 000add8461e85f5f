"""Real spherical harmonics: basis, projection, rotation and the Phong lobe filter.

Convention
----------
Real, orthonormal SH on the unit sphere, evaluated on *world* Cartesian
directions (x, y, z) with the polar axis along world +Z and azimuth
phi = atan2(y, x). Coefficient (l, m), -l <= m <= l, is stored at index
l (l + 1) + m; order L has (L + 1)^2 coefficients. With scipy's complex
``sph_harm_y(l, m, theta, phi)`` (Condon-Shortley phase included):

    Y_l0  = Y_l^0
    Y_lm  = sqrt(2) (-1)^m Re Y_l^m      (m > 0)
    Y_lm  = sqrt(2) (-1)^m Im Y_l^|m|    (m < 0)

so the Condon-Shortley phase cancels: Y_1,-1 = +c y, Y_10 = +c z, Y_11 = +c x
with c = sqrt(3 / (4 pi)).
"""
from __future__ import annotations

import functools

import numpy as np
from scipy import special

from . import latlong
from .errors import InputError, is_number, is_whole


def num_coeffs(order: int) -> int:
    """Number of coefficients of an order-``order`` expansion: (L + 1)^2."""
    return (_order(order) + 1) ** 2


def _order(order) -> int:
    """``order`` as an int, refused unless it is a whole number >= 0 (2.5 or True is no order)."""
    if not is_number(order) or not float(order).is_integer() or order < 0:
        raise InputError(f"SH order must be a whole number >= 0, got {order!r}")
    return int(order)


def order_of(count: int) -> int:
    """The order L of an expansion with ``count`` = (L + 1)^2 coefficients."""
    order = int(round(np.sqrt(count))) - 1
    if order < 0 or (order + 1) ** 2 != count:
        raise InputError(f"{count} is not a number of SH coefficients (L + 1)^2")
    return order


def index(l: int, m: int) -> int:
    """Flat index l (l + 1) + m of coefficient (l, m), |m| <= l (past it, the index is another
    coefficient's: (1, 5) would be (2, 1))."""
    if not 0 <= abs(m) <= l:
        raise InputError(f"SH coefficient (l, m) needs |m| <= l, got ({l}, {m})")
    return l * (l + 1) + m


def degrees(order: int) -> np.ndarray:
    """Degree l of every coefficient, shape ((L + 1)^2,)."""
    return np.repeat(np.arange(order + 1), 2 * np.arange(order + 1) + 1)


# directions per block of :func:`basis`: its (coefficients, block) scratch stays in cache
BASIS_BLOCK = 4096


def basis(order: int, dirs: np.ndarray) -> np.ndarray:
    """Real SH basis at unit directions.

    Parameters
    ----------
    order : int, maximum degree L.
    dirs : (N, 3) unit vectors.

    Returns
    -------
    (N, (L + 1)^2) float64.
    """
    d, order = _directions(dirs), _order(order)
    out = np.empty((len(d), num_coeffs(order)))
    for rows, block in _blocks(order, d):
        out[rows] = block.T
    return out


def evaluate(order: int, dirs: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """The functions with SH coefficients ``coeffs`` at unit directions: ``basis(order, dirs)
    @ coeffs``, block by block, without the (N, (L + 1)^2) basis (at order 10 it is 121
    values per direction, written and read again for a few products).

    Parameters
    ----------
    order : int, maximum degree L.
    dirs : (N, 3) unit vectors.
    coeffs : ((L + 1)^2, C) coefficients of C functions.

    Returns
    -------
    (N, C) float64.
    """
    d, order = _directions(dirs), _order(order)
    m = num_coeffs(order)
    coeffs = np.asarray(coeffs, dtype=np.float64)
    if coeffs.ndim != 2 or coeffs.shape[0] != m:
        raise InputError(f"coeffs must have shape ({m}, C) for order {order}, got {coeffs.shape}")
    out = np.empty((len(d), coeffs.shape[1]))
    for rows, block in _blocks(order, d):
        out[rows] = block.T @ coeffs
    return out


def _directions(dirs: np.ndarray) -> np.ndarray:
    """``dirs`` as an (N, 3) float64 array, or an InputError naming its shape."""
    d = np.asarray(dirs, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise InputError(f"dirs must have shape (N, 3), got {d.shape}")
    # the basis is a polynomial of degree l in the direction: a vector of length r scales its
    # degree-l terms by r^l, so a direction that is not unit gives a wrong value, not an error
    length = np.einsum("ij,ij->i", d, d)
    if np.any(np.abs(length - 1.0) > 1e-5):
        worst = int(np.argmax(np.abs(length - 1.0)))
        raise InputError(f"dirs must be unit vectors: row {worst} has length {np.sqrt(length[worst]):.6g}")
    return d


def _blocks(order: int, d: np.ndarray):
    """Yield (slice of rows, ((L + 1)^2, B) basis of those directions) over blocks of up to
    :data:`BASIS_BLOCK` directions of ``d`` (N, 3); the block is one scratch array, refilled.

    Each coefficient is written as a contiguous row of the (coefficients, block) scratch, which
    the caller transposes or multiplies: writing the columns of an (N, M) array directly touches
    N cache lines per coefficient (2.3x slower at order 10)."""
    n = len(d)
    scratch = np.empty((num_coeffs(order), min(BASIS_BLOCK, n)))
    scale, first = _normalisation(order)
    for start in range(0, n, BASIS_BLOCK):
        stop = min(start + BASIS_BLOCK, n)
        block = scratch[:, : stop - start]
        _basis_rows(order, *(d[start:stop, k].copy() for k in range(3)), scale, first, block)
        yield slice(start, stop), block


@functools.lru_cache(maxsize=None)
def _normalisation(order: int) -> tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]:
    """``scale[m][l]``, the normalisation of (l, m), and ``first[m]`` = (2m - 1)!!, Q_m^m, for
    degrees up to ``order``: kept per order (scipy's special functions cost more per call
    than a block of the recurrence)."""
    scale = tuple(tuple(float(np.sqrt((2 * l + 1) / (4 * np.pi) * np.exp(special.gammaln(l - m + 1)
                                                                          - special.gammaln(l + m + 1))))
                        for l in range(order + 1)) for m in range(order + 1))
    first = tuple(float(special.factorial2(2 * m - 1, exact=False)) if m else 1.0 for m in range(order + 1))
    return scale, first


def _basis_rows(order: int, x: np.ndarray, y: np.ndarray, z: np.ndarray, scale: tuple, first: tuple,
                out: np.ndarray) -> None:
    """Fill ``out`` ((L + 1)^2, N) with the basis at directions (x, y, z) (N,) each;
    ``scale[m][l]`` is the normalisation of (l, m), ``first[m]`` = (2m - 1)!!."""
    re, im = np.ones_like(x), np.zeros_like(x)   # (x + i y)^m
    for m in range(order + 1):
        # Q_l^m(z) = P_l^m(z) / sin^m(theta) without Condon-Shortley phase.
        q_prev, q = None, np.full_like(z, first[m])
        for l in range(m, order + 1):
            if l == m + 1:
                q_prev, q = q, (2 * m + 1) * z * q
            elif l > m + 1:
                q_prev, q = q, ((2 * l - 1) * z * q - (l + m - 1) * q_prev) / (l - m)
            if m == 0:
                np.multiply(q, scale[m][l], out=out[index(l, 0)])
            else:
                kq = (np.sqrt(2.0) * scale[m][l]) * q
                np.multiply(kq, re, out=out[index(l, m)])
                np.multiply(kq, im, out=out[index(l, -m)])
        re, im = re * x - im * y, re * y + im * x


def rotation_matrix(order: int, rotation: np.ndarray) -> np.ndarray:
    """SH rotation: coefficients of f(R^T w) are ``M @ c`` when c are those of f(w).

    Parameters
    ----------
    order : int
    rotation : (3, 3) proper rotation R (the function is carried along by R).

    Returns
    -------
    M : ((L + 1)^2, (L + 1)^2), block diagonal by degree, orthogonal.
    """
    rotation = np.asarray(rotation, dtype=np.float64)
    if rotation.shape != (3, 3) or not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-8):
        raise InputError("rotation must be a 3x3 orthogonal matrix")
    pts = fibonacci_sphere(4 * num_coeffs(order) + 64)
    y = basis(order, pts)
    y_rot = basis(order, pts @ rotation)  # rows: Y(R^T p)
    m = np.linalg.lstsq(y, y_rot, rcond=None)[0]
    # Exact block structure: entries between different degrees are round-off.
    deg = degrees(order)
    m[deg[:, None] != deg[None, :]] = 0.0
    return m


def axis_angle_matrix(axis, degrees_: float) -> np.ndarray:
    """(3, 3) rotation about ``axis`` ('x', 'y', 'z' or a 3-vector) by an angle in degrees."""
    if isinstance(axis, str):
        lookup = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}
        if axis.lower() not in lookup:
            raise InputError(f"axis must be x, y, z or a 3-vector, got {axis!r}")
        axis = lookup[axis.lower()]
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    t = np.radians(degrees_)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` nearly uniform unit directions (golden-spiral lattice), shape (n, 3)."""
    if not is_whole(n) or n < 4:
        raise InputError(f"need a whole number of at least 4 directions, got {n!r}")
    i = np.arange(n) + 0.5
    y = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - y * y)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1)


def project_directional(order: int, to_light: np.ndarray, irradiance: np.ndarray) -> np.ndarray:
    """SH of distant light made of delta directions, L(w) = sum_k E_k delta(w - d_k).

    Parameters
    ----------
    to_light : (K, 3) unit directions towards each light.
    irradiance : (K, C) irradiance on a surface facing the light (W/m^2 per channel).

    Returns
    -------
    ((L + 1)^2, C) radiance coefficients.
    """
    return basis(order, np.asarray(to_light, dtype=np.float64)).T @ np.asarray(irradiance, dtype=np.float64)


PROJECTION_PIXELS = 1 << 16   # pixels per block of project_latlong: ~100 MB of basis values at order 12
# a wider map is first averaged onto a grid this wide (latlong.downsample): its cells of 0.18 degrees
# change coefficients of order 12 by ~1e-4, and an 8k map projects in seconds instead of minutes
PROJECTION_WIDTH = 2048


def project_latlong(order: int, image: np.ndarray) -> np.ndarray:
    """SH of a lat-long radiance map (H, W, C) in Mitsuba's envmap orientation.

    Returns ((L + 1)^2, C); quadrature over the map's cells (see :mod:`latlong`), in blocks
    of rows of :data:`PROJECTION_PIXELS` pixels, after averaging a map wider than
    :data:`PROJECTION_WIDTH` onto a grid that wide.
    """
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[0] < 3 or image.shape[1] < 2:
        raise InputError(f"a lat-long map must be (H, W, C) with H >= 3 rows and W >= 2, got shape {image.shape}")
    h, w = image.shape[:2]
    if w > PROJECTION_WIDTH:
        h, w = max(3, round((h - 1) * PROJECTION_WIDTH / w) + 1), PROJECTION_WIDTH
        image = latlong.downsample(image, h, w)
    out = np.zeros((num_coeffs(order), image.shape[2]))
    rows = max(1, PROJECTION_PIXELS // w)   # a block of rows at a time: memory independent of the map's size
    weights = latlong.solid_angles(h, w)
    for top in range(0, h, rows):
        dirs = latlong.directions(h, w, slice(top, top + rows)).reshape(-1, 3)
        y = basis(order, dirs) * weights[top:top + rows].reshape(-1, 1)
        out += y.T @ image[top:top + rows].reshape(-1, image.shape[2]).astype(np.float64)
    return out


def to_latlong(coeffs: np.ndarray, height: int, width: int) -> np.ndarray:
    """Evaluate SH coefficients (M, C) on a lat-long map, shape (H, W, C)."""
    coeffs = np.asarray(coeffs, dtype=np.float64)
    order = order_of(coeffs.shape[0])
    if num_coeffs(order) != coeffs.shape[0]:
        raise InputError(f"{coeffs.shape[0]} is not a square number of SH coefficients")
    dirs = latlong.directions(height, width).reshape(-1, 3)
    return (basis(order, dirs) @ coeffs).reshape(height, width, -1)


LARGE_EXPONENT = 1e5  # above it phong_filter uses its asymptotic form (the two agree within 3e-9 there)


def phong_filter(order: int, exponent: float) -> np.ndarray:
    """Per-degree filter of the normalised Phong lobe (n + 1)/(2 pi) max(0, r.w)^n.

    Lambda_l rho_l = (n + 1) * int_0^1 x^n P_l(x) dx (Ramamoorthi & Hanrahan 2001),
    in closed form:
        int_0^1 x^n P_l(x) dx = sqrt(pi) 2^(-n-1) Gamma(n+1)
                                / (Gamma(1 + (n-l)/2) Gamma((n+l+3)/2)).
    The pseudo illumination's SH are the radiance SH times this filter.

    Returns
    -------
    (L + 1,) float64, one value per degree; value 1 at l = 0.
    """
    n = float(exponent)
    if not n > -1.0 or not np.isfinite(n):
        raise InputError(f"Phong exponent must be finite and > -1, got {exponent}")
    l = np.arange(order + 1, dtype=np.float64)
    if n > LARGE_EXPONENT:
        # the log-gamma differences lose their digits; the lobe is then nearly a delta and
        # Lambda_l = E[P_l(x)] under (n + 1) x^n = 1 - l(l+1)/(2(n+2)) + O(n^-2)
        return np.exp(-l * (l + 1) / (2.0 * (n + 2.0)))
    a = 1.0 + 0.5 * (n - l)
    log_common = (
        0.5 * np.log(np.pi) - (n + 1) * np.log(2.0) + special.gammaln(n + 1) - special.gammaln(0.5 * (n + l + 3))
    )
    positive = a > 0
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):  # both branches are evaluated
        value = np.where(positive, np.exp(log_common - special.gammaln(np.where(positive, a, 1.0))),
                         np.exp(log_common) * special.rgamma(a))
    return (n + 1.0) * value


def expand_per_degree(per_degree: np.ndarray) -> np.ndarray:
    """(L + 1,) per-degree values -> ((L + 1)^2,) per coefficient."""
    per_degree = np.asarray(per_degree)
    return per_degree[degrees(per_degree.shape[0] - 1)]


def phong_filtered(radiance: np.ndarray, exponent: float, order: int | None = None) -> np.ndarray:
    """Radiance SH (M, C) filtered by the Phong lobe of ``exponent`` (per degree, no
    renormalisation: the DC is kept), truncated to ``order`` (default: the radiance's)."""
    radiance = np.asarray(radiance, dtype=np.float64)
    if radiance.ndim != 2:
        raise InputError(f"radiance SH must be (M, C) coefficients per channel, got shape {radiance.shape}")
    have = order_of(radiance.shape[0])
    order = have if order is None else order
    if order > have:
        raise InputError(f"the radiance SH have order {have}, cannot filter to order {order}")
    return radiance[: num_coeffs(order)] * expand_per_degree(phong_filter(order, exponent))[:, None]


def pseudo_illumination(radiance: np.ndarray, exponent: float, order: int | None = None) -> np.ndarray:
    """Radiance SH (M, C) -> pseudo illumination SH, filtered by the Phong lobe of
    ``exponent``, truncated to ``order`` and normalised to unit DC per channel
    (the estimate's gauge)."""
    out = phong_filtered(radiance, exponent, order)
    dc = np.where(np.abs(out[0]) > 0, out[0], 1.0)
    return out / dc
