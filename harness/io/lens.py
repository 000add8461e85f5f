"""Lens distortion of nerfstudio's camera models, and undistortion of images on reading.

A real capture that went through COLMAP or nerfstudio stores its cameras as a pinhole
(``fl_x, fl_y, cx, cy``) plus distortion coefficients. Everything downstream (the
estimator's rays, Mitsuba's ``perspective`` sensor) is a pinhole camera, so a distorted
image is resampled on reading into the pinhole image of the same intrinsics.

Coordinates are OpenCV's normalised image coordinates, ``x = (u - cx) / fx`` and
``y = (v - cy) / fy``, with ``(u, v)`` continuous pixel coordinates (pixel centres at
``i + 0.5``, ``v`` down the rows, :mod:`estimator.core.camera`). The models are
nerfstudio's (``nerfstudio.cameras.camera_utils``):

* ``OPENCV``: ``r2 = x^2 + y^2``, ``d = 1 + k1 r2 + k2 r2^2 + k3 r2^3 + k4 r2^4``,
  ``x_d = d x + 2 p1 x y + p2 (r2 + 2 x^2)``, ``y_d = d y + p1 (r2 + 2 y^2) + 2 p2 x y``
  (COLMAP's OPENCV uses k1, k2, p1, p2; k3, k4 are 0 there).
* ``OPENCV_FISHEYE``: ``theta = atan(r)``, ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 +
  k3 theta^6 + k4 theta^8)``, ``(x_d, y_d) = (theta_d / r) (x, y)`` (p1, p2 must be 0).

The code is written here (not OpenCV's ``initUndistortRectifyMap``) to keep OpenCV out
of the dependencies for a dozen lines of arithmetic; tests check it against rays traced
by Mitsuba through the distorted pixels.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from estimator import InputError

CAMERA_MODELS = ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV", "OPENCV_FISHEYE")
COEFFICIENTS = ("k1", "k2", "k3", "k4", "p1", "p2")


@dataclass(frozen=True)
class Lens:
    """A distortion model and its coefficients (``COEFFICIENTS`` order)."""

    model: str = "OPENCV"
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self):
        if self.model not in ("OPENCV", "OPENCV_FISHEYE"):
            raise InputError(f"lens model {self.model!r} is not one of OPENCV, OPENCV_FISHEYE")
        for key in COEFFICIENTS:
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise InputError(f"lens distortion {key} must be a finite number, got {value!r}")
        if self.model == "OPENCV_FISHEYE" and (self.p1 or self.p2):
            raise InputError("OPENCV_FISHEYE has no tangential distortion: p1 and p2 must be 0")

    @property
    def is_identity(self) -> bool:
        """True for OPENCV without distortion (a pinhole); a fisheye is never one."""
        return self.model == "OPENCV" and not any(getattr(self, key) for key in COEFFICIENTS)

    def as_json(self) -> dict:
        """The transforms.json keys of this lens: ``camera_model`` and the coefficients."""
        return {"camera_model": self.model, **{key: float(getattr(self, key)) for key in COEFFICIENTS}}


def distort(x: np.ndarray, y: np.ndarray, lens: Lens) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted normalised coordinates (any shape) -> distorted ones (same shape)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    r2 = x * x + y * y
    if lens.model == "OPENCV_FISHEYE":
        r = np.sqrt(r2)
        theta = np.arctan(r)
        t2 = theta * theta
        theta_d = theta * (1 + t2 * (lens.k1 + t2 * (lens.k2 + t2 * (lens.k3 + t2 * lens.k4))))
        scale = np.where(r > 1e-12, theta_d / np.maximum(r, 1e-12), 1.0)
        return scale * x, scale * y
    d = 1 + r2 * (lens.k1 + r2 * (lens.k2 + r2 * (lens.k3 + r2 * lens.k4)))
    return (d * x + 2 * lens.p1 * x * y + lens.p2 * (r2 + 2 * x * x),
            d * y + lens.p1 * (r2 + 2 * y * y) + 2 * lens.p2 * x * y)


def undistort(xd: np.ndarray, yd: np.ndarray, lens: Lens, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Distorted normalised coordinates -> undistorted ones: the inverse of :func:`distort`
    by Newton's method with a finite-difference Jacobian (no closed form exists), started
    at the distorted point, until no point moves by 1e-12 (a handful of steps for the
    mild distortion of real lenses) or ``iterations`` steps."""
    xd, yd = np.asarray(xd, np.float64), np.asarray(yd, np.float64)
    x, y = xd.copy(), yd.copy()
    h = 1e-7
    for _ in range(iterations):
        fx, fy = distort(x, y, lens)
        ex, ey = fx - xd, fy - yd
        ax, ay = distort(x + h, y, lens)
        bx, by = distort(x, y + h, lens)
        j11, j21, j12, j22 = (ax - fx) / h, (ay - fy) / h, (bx - fx) / h, (by - fy) / h
        det = j11 * j22 - j12 * j21
        det = np.where(np.abs(det) > 1e-12, det, 1e-12)
        step_x, step_y = (j22 * ex - j12 * ey) / det, (j11 * ey - j21 * ex) / det
        x, y = x - step_x, y - step_y
        if max(np.max(np.abs(step_x), initial=0.0), np.max(np.abs(step_y), initial=0.0)) < 1e-12:
            break
    return x, y


def source_pixels(lens: Lens, width: int, height: int, fx: float, fy: float, cx: float, cy: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Where each pixel centre of the pinhole image lies in the distorted one.

    Returns
    -------
    (H, W) u and (H, W) v: continuous pixel coordinates in the distorted image.

    Raises
    ------
    InputError: when the distortion folds over inside the image (its Jacobian changes
    sign from one pixel to the next), which no real lens calibration does.
    """
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    xd, yd = distort((u - cx) / fx, (v - cy) / fy, lens)
    ud, vd = fx * xd + cx, fy * yd + cy
    du_dx, dv_dx = np.diff(ud, axis=1)[:-1], np.diff(vd, axis=1)[:-1]
    du_dy, dv_dy = np.diff(ud, axis=0)[:, :-1], np.diff(vd, axis=0)[:, :-1]
    if np.any(du_dx * dv_dy - dv_dx * du_dy <= 0):
        raise InputError(f"lens distortion {lens.as_json()} folds over inside the {width}x{height} image: the "
                         "coefficients cannot come from a lens calibration")
    return ud, vd


def undistort_image(image: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                    lens: Lens) -> tuple[np.ndarray, np.ndarray]:
    """Resample a distorted image into the pinhole image of the same intrinsics.

    Each output pixel centre is distorted into the input and read bilinearly (linear
    radiance: a bilinear read is the exact average for content linear within a pixel).

    Parameters
    ----------
    image : (H, W, C) float image as the lens recorded it.
    fx, fy, cx, cy : pinhole intrinsics in pixels, shared by input and output.

    Returns
    -------
    (H, W, C) float32 undistorted image, and (H, W) bool: the pixels whose source lies
    inside the input (the others are 0 and carry no observation).

    Raises
    ------
    InputError: the distortion folds over inside the image (:func:`source_pixels`).
    """
    h, w = image.shape[:2]
    ud, vd = source_pixels(lens, w, h, fx, fy, cx, cy)
    rows, cols = vd - 0.5, ud - 0.5
    inside = (rows >= -0.5) & (rows <= h - 0.5) & (cols >= -0.5) & (cols <= w - 0.5)
    rows, cols = np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)
    out = np.stack([ndimage.map_coordinates(image[..., c], [rows, cols], order=1, mode="nearest")
                    for c in range(image.shape[2])], axis=2)
    out[~inside] = 0.0
    return out.astype(np.float32), inside
