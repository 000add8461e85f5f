"""Camera conventions: the one module that converts between them.

Dataset cameras are pinhole cameras with a camera-to-world matrix in the
OpenGL convention (camera +X right, +Y up, looking down -Z), as in nerfstudio's
``transforms.json``. Mitsuba's camera space is +X left, +Y up, +Z forward, and
OpenCV/COLMAP's is +X right, +Y down, +Z forward:

    c2w_gl = to_world_mitsuba @ diag(-1, 1, -1, 1)
    c2w_cv = c2w_gl @ diag(1, -1, -1, 1)

Pixel coordinates are continuous: pixel (col i, row j) covers [i, i+1) x [j, j+1)
with its centre at (i + 0.5, j + 0.5); row 0 is the top of the image.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import InputError, is_number, is_whole

_GL_FROM_MITSUBA = np.diag([-1.0, 1.0, -1.0, 1.0])
_CV_FROM_GL = np.diag([1.0, -1.0, -1.0, 1.0])
_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_BOTTOM_TOLERANCE = 1e-8 + 1e-5 * _BOTTOM_ROW   # np.allclose's default atol + rtol x |expected|
_IDENTITY = np.eye(3)


def mitsuba_to_gl(to_world: np.ndarray) -> np.ndarray:
    """Mitsuba sensor ``to_world`` (4, 4) -> OpenGL camera-to-world (4, 4)."""
    return np.asarray(to_world, dtype=np.float64) @ _GL_FROM_MITSUBA


def gl_to_mitsuba(c2w_gl: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) -> Mitsuba sensor ``to_world`` (4, 4)."""
    return np.asarray(c2w_gl, dtype=np.float64) @ _GL_FROM_MITSUBA


def gl_to_opencv(c2w_gl: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) -> OpenCV/COLMAP camera-to-world (4, 4)."""
    return np.asarray(c2w_gl, dtype=np.float64) @ _CV_FROM_GL


def opencv_to_gl(c2w_cv: np.ndarray) -> np.ndarray:
    """OpenCV/COLMAP camera-to-world (4, 4) -> OpenGL camera-to-world (4, 4)."""
    return np.asarray(c2w_cv, dtype=np.float64) @ _CV_FROM_GL


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 1.0, 0.0)) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) of a camera at ``eye`` looking at ``target``.

    When ``up`` is parallel to the view direction, world +Z (or +X) is used instead.
    """
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    if eye.shape != (3,) or target.shape != (3,) or up.shape != (3,) \
            or not all(np.all(np.isfinite(v)) for v in (eye, target, up)):
        raise InputError(f"look_at needs finite 3-vectors, got eye {eye.shape}, target {target.shape}, up {up.shape}")
    forward = target - eye
    if not np.linalg.norm(forward) > 0:
        raise InputError(f"look_at: the eye and the target are one point {eye.tolist()}: no view direction")
    forward /= np.linalg.norm(forward)
    for candidate in (up, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
        right = np.cross(forward, candidate)
        if np.linalg.norm(right) > 1e-6:
            break
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, true_up, -forward, eye
    return c2w


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Attributes
    ----------
    c2w : (4, 4) float64, OpenGL camera-to-world.
    fx, fy : focal lengths in pixels.
    cx, cy : principal point in pixels (continuous coordinates, see module doc).
    width, height : image size in pixels.
    """

    c2w: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self):
        c2w = np.asarray(self.c2w, dtype=np.float64)
        if c2w.shape != (4, 4):
            raise InputError(f"camera c2w must be a 4x4 matrix, got shape {c2w.shape}")
        if not np.all(np.isfinite(c2w)):
            raise InputError("camera c2w contains NaN or Inf")
        rot = c2w[:3, :3]
        # np.allclose's tolerances written out (each camera a pose refinement tries is checked:
        # np.allclose costs ten times more than the arithmetic)
        if np.max(np.abs(c2w[3] - _BOTTOM_ROW) - _BOTTOM_TOLERANCE) > 0 \
                or np.max(np.abs(rot.T @ rot - _IDENTITY) - (1e-3 + 1e-5 * _IDENTITY)) > 0 \
                or np.dot(rot[0], np.cross(rot[1], rot[2])) < 0:
            raise InputError("camera c2w is not a rigid camera-to-world transform (its rotation part must be "
                             "orthonormal with determinant +1 and its last row 0 0 0 1)")
        for name in ("width", "height"):   # pixel counts: 40.0 or True would fail deep in a render
            value = getattr(self, name)
            if not is_whole(value):
                raise InputError(f"camera {name} must be an integer number of pixels, got {value!r}")
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if not is_number(value):
                raise InputError(f"camera {name} must be a number, got {value!r}")
        values = (self.fx, self.fy, self.cx, self.cy, self.width, self.height)
        if not all(np.isfinite(v) for v in values):
            raise InputError(f"camera intrinsics must be finite, got fx={self.fx}, fy={self.fy}, "
                             f"cx={self.cx}, cy={self.cy}, w={self.width}, h={self.height}")
        if min(self.width, self.height) < 1 or min(self.fx, self.fy) <= 0:
            raise InputError(f"camera needs positive size and focal length, got "
                             f"{self.width}x{self.height}, fx={self.fx}, fy={self.fy}")
        object.__setattr__(self, "c2w", c2w)

    @classmethod
    def from_fov(cls, c2w: np.ndarray, fov_x_deg: float, width: int, height: int) -> "Camera":
        """Square-pixel camera with the principal point at the image centre."""
        if not is_number(fov_x_deg) or not 0.0 < fov_x_deg < 180.0:
            raise InputError(f"fov_x must lie in (0, 180) degrees, got {fov_x_deg}")
        f = 0.5 * width / np.tan(0.5 * np.radians(fov_x_deg))
        return cls(c2w, f, f, 0.5 * width, 0.5 * height, int(width), int(height))

    @property
    def fov_x_deg(self) -> float:
        return float(np.degrees(2.0 * np.arctan(0.5 * self.width / self.fx)))

    @property
    def center(self) -> np.ndarray:
        """(3,) camera position in world space."""
        return self.c2w[:3, 3]

    def pixel_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Rays through every pixel centre, row-major from the top-left.

        Returns
        -------
        origins : (H*W, 3) float64
        directions : (H*W, 3) float64, unit length, world space.
        """
        d = np.ascontiguousarray(self.pixel_directions().T)
        return np.broadcast_to(self.center, d.shape).copy(), d

    def pixel_directions(self) -> np.ndarray:
        """(3, H*W) float64 unit world directions through every pixel centre, row-major from
        the top-left, one row per axis (what a ray query takes, without an (H*W, 3) transpose)."""
        x = (np.arange(self.width) + 0.5 - self.cx) / self.fx
        y = -(np.arange(self.height) + 0.5 - self.cy) / self.fy
        return self._unit_directions(x[None, :], y[:, None]).reshape(3, -1)

    def subpixel_directions(self, pixels: np.ndarray, samples: int) -> np.ndarray:
        """(3, P*samples^2) float64 unit world directions through the centres of a ``samples`` x
        ``samples`` grid over each of ``pixels`` (P,) (row-major indices), pixel by pixel, the
        grid row-major within each."""
        s = int(samples)
        offset = (np.arange(s) + 0.5) / s
        col, row = np.divmod(np.asarray(pixels, dtype=np.int64), self.width)[::-1]
        x = ((col[:, None, None] + offset[None, None, :]) - self.cx) / self.fx      # (P, 1, s)
        y = -((row[:, None, None] + offset[None, :, None]) - self.cy) / self.fy     # (P, s, 1)
        return self._unit_directions(x, y).reshape(3, -1)

    def _unit_directions(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(3, *shape) unit world directions x * right + y * up - forward (OpenGL camera) of
        image-plane coordinates x, y at unit depth, broadcast to one shape."""
        x, y = np.broadcast_arrays(x, y)
        axes = (slice(None),) + (None,) * x.ndim
        rot = self.c2w[:3, :3]
        d = y[None] * rot[:, 1][axes] + x[None] * rot[:, 0][axes] - rot[:, 2][axes]
        d /= np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        return d

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points (N, 3) to continuous pixel coordinates.

        Returns
        -------
        xy : (N, 2) float64, (column, row) coordinates.
        depth : (N,) float64, distance along the viewing axis (> 0 in front).
        """
        w2c = np.linalg.inv(self.c2w)
        p = np.asarray(points, dtype=np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
        depth = -p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.fx * p[:, 0] / depth + self.cx
            y = -self.fy * p[:, 1] / depth + self.cy
        return np.stack([x, y], axis=1), depth


def multijitter_count(spp: int) -> int:
    """The samples per pixel Mitsuba's ``multijitter`` sampler takes for ``spp``: a grid of
    floor(sqrt(spp)) columns and as many rows as cover ``spp`` (it rounds any other count up
    itself, with a warning on the console; 32 becomes 35)."""
    columns = max(1, math.isqrt(int(spp)))
    return columns * -(-int(spp) // columns)


def mitsuba_sensor(mi, camera: "Camera", spp: int) -> dict:
    """The Mitsuba ``perspective`` sensor dict of ``camera`` (square pixels), with an RGBA
    ``hdrfilm`` (box filter) and a ``multijitter`` sampler of :func:`multijitter_count`
    (``spp``) samples; ``mi`` is the mitsuba module with a variant set."""
    if abs(camera.fx - camera.fy) > 1e-6 * camera.fx:
        raise InputError("rendering needs square pixels (fl_x == fl_y)")
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": camera.fov_x_deg,
        "principal_point_offset_x": (0.5 * camera.width - camera.cx) / camera.width,
        "principal_point_offset_y": (0.5 * camera.height - camera.cy) / camera.height,
        "near_clip": 1e-3,
        "far_clip": 1e5,
        "to_world": mi.ScalarTransform4f(gl_to_mitsuba(camera.c2w)),
        "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                 "pixel_format": "rgba", "rfilter": {"type": "box"}},
        "sampler": {"type": "multijitter", "sample_count": multijitter_count(spp)},
    }
