"""Turning an HDR lat-long light probe into a few directional lights."""
from __future__ import annotations

import numpy as np

from estimator import latlong
from reports.metrics import LUMINANCE


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 luminance of linear RGB (..., 3) -> (...)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE


def cluster_probe(image: np.ndarray, count: int = 40, white: bool = False, seed: int = 0,
                  iterations: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Cluster a lat-long probe into ``count`` directional lights.

    Directions are clustered by weighted spherical k-means (k-means++ seeding),
    each pixel weighted by luminance x solid angle. A light points at its
    cluster's weighted mean direction and carries the cluster's integral of
    radiance over solid angle as irradiance, so the lights' total irradiance
    equals the probe's integral exactly, and low-order SH are nearly preserved.

    Parameters
    ----------
    image : (H, W, 3) linear radiance in Mitsuba's envmap orientation.
    count : number of lights K.
    white : replace each light's colour by its luminance (R = G = B).

    Returns
    -------
    to_light : (K, 3) unit directions towards the lights.
    irradiance : (K, 3) irradiance of each light.
    """
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"probe must be (H, W, 3), got {image.shape}")
    if count < 1:
        raise ValueError(f"illumination.count must be >= 1, got {count}")
    if np.any(image < 0) or not np.all(np.isfinite(image)):
        raise ValueError("probe radiance must be finite and non-negative")
    h, w = image.shape[:2]
    dirs = latlong.directions(h, w).reshape(-1, 3)
    omega = latlong.solid_angles(h, w).reshape(-1)
    radiance = image.reshape(-1, 3)
    weight = luminance(radiance) * omega
    keep = weight > 0
    if keep.sum() < count:
        raise ValueError(f"the probe has only {keep.sum()} lit pixels, fewer than {count} lights")
    dirs_k, weight_k = dirs[keep], weight[keep]

    rng = np.random.default_rng(seed)
    centers = np.empty((count, 3))
    centers[0] = dirs_k[rng.choice(len(dirs_k), p=weight_k / weight_k.sum())]
    dist = np.maximum(1.0 - dirs_k @ centers[0], 0.0)
    for k in range(1, count):  # k-means++: far and bright pixels first
        p = weight_k * dist
        centers[k] = dirs_k[rng.choice(len(dirs_k), p=p / p.sum())]
        dist = np.minimum(dist, np.maximum(1.0 - dirs_k @ centers[k], 0.0))

    assign = np.full(len(dirs_k), -1)
    for _ in range(iterations):
        new_assign = np.argmax(dirs_k @ centers.T, axis=1)
        if np.array_equal(new_assign, assign):
            break
        assign = new_assign
        sums = np.stack([np.bincount(assign, weight_k * dirs_k[:, i], minlength=count) for i in range(3)], axis=1)
        norms = np.linalg.norm(sums, axis=1)
        centers = np.where(norms[:, None] > 0, sums / np.maximum(norms, 1e-300)[:, None], centers)

    # Every pixel (lit or not) goes to its nearest light, so the integral is exact.
    assign_all = np.argmax(dirs @ centers.T, axis=1)
    irradiance = np.stack([np.bincount(assign_all, radiance[:, i] * omega, minlength=count)
                           for i in range(3)], axis=1)
    if white:
        irradiance = np.repeat(luminance(irradiance)[:, None], 3, axis=1)
    return centers, irradiance
