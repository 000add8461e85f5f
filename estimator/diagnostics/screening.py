"""Faces whose albedo the observations do not determine: found after the solve, marked
unestimated with a reason, and never reported as a number.

Five reasons, each a property of the data or of physics, none fitted to a scene:

* ``non-finite``: the solve gave NaN or infinity.
* ``beyond physical range``: a channel of the albedo is negative, or exceeds
  :data:`MAX_ALBEDO_RATIO` times that channel's median over the estimated faces where it is
  not zero. Albedos lie in (0, 1] and no real surface reflects less than about 1 %
  (:data:`DARKEST_ALBEDO`), so no face can be more than 100 times brighter than the median
  face in any channel, whatever the unknown scale each channel has (the gauge is per channel,
  so channels are compared only with themselves).
* ``undetermined``: the standard error of the albedo the face takes (its own, or its group's
  when the method shares one albedo over a region) is at least :data:`MAX_RELATIVE_SE` times
  the face's whole albedo (diffuse plus specular): at one sigma the observations cannot tell
  it from zero.
* ``contradicted by its observations``: the face shares one albedo with others (a region),
  it has observations, and every one of them is an outlier under the estimate: its own data
  reject the albedo its region gave it. A face joined to a region by its neighbours whose
  colour is another region's is one such face; more often it is a face whose views the model
  misfits, where the object shades itself (its shadows and interreflections are what the
  light's order and the shadow function's directions resolve least).
* ``left out by the method``: the face has observations in kept views, but the method gave
  it no albedo (``bilinear-clustered`` leaves out faces whose median colour over the views is
  below ``min_brightness`` times the 95th percentile of the faces' medians, as in a point
  light's shadow). Counted so that
  the warning states every face without an estimate that a view shows.
"""
from __future__ import annotations

import numpy as np

from ..model.estimate import Estimate

DARKEST_ALBEDO = 0.01                  # black velvet, carbon black: the darkest real reflectances
MAX_ALBEDO_RATIO = 1.0 / DARKEST_ALBEDO
MAX_RELATIVE_SE = 1.0
REASONS = ("non-finite", "beyond physical range", "undetermined", "contradicted by its observations",
           "left out by the method")


def left_out(est: Estimate, seen: np.ndarray) -> np.ndarray:
    """(F,) int8 reason code of the faces a kept view shows (``seen`` (F,) bool) that the
    method gave no albedo."""
    return np.where(seen & ~est.observed, REASONS.index("left out by the method") + 1, 0).astype(np.int8)


def out_of_range(est: Estimate) -> np.ndarray:
    """(F,) int8 reason code (1-based index into :data:`REASONS`, 0: kept) of the faces whose
    albedo is non-finite or beyond the physical range."""
    albedo = est.diffuse + est.specular                                    # (F, 3)
    code = np.zeros(len(albedo), np.int8)
    finite = np.all(np.isfinite(albedo), axis=1)
    code[est.observed & ~finite] = 1
    kept = est.observed & finite
    values = np.where(kept[:, None], albedo, 0.0)
    beyond = np.any(values < 0, axis=1)
    for c in range(values.shape[1]):
        positive = values[:, c] > 0
        if positive.any():   # a zero channel carries no level (the SE test judges a face that is all zero)
            beyond |= values[:, c] > MAX_ALBEDO_RATIO * float(np.median(values[positive, c]))
    code[kept & beyond] = 2
    return code


def undetermined(est: Estimate, precision: np.ndarray) -> np.ndarray:
    """(F,) bool faces whose albedo's relative standard error is at least :data:`MAX_RELATIVE_SE`.

    ``precision`` (F, 3): each face's precision of the albedo it estimates (the diffuse, or the
    specular for specular-only data) with the light fixed (:func:`trust.albedo_precision`);
    faces sharing a label share one albedo, whose precision is the sum of theirs. The error is
    relative to the face's whole albedo: a face whose light the specular term carries has a
    determined appearance even where its diffuse part is zero."""
    albedo = est.diffuse + est.specular
    observed = est.observed & (est.labels >= 0)
    if not observed.any():
        return np.zeros(len(albedo), bool)
    _, group = np.unique(est.labels[observed], return_inverse=True)
    summed = np.stack([np.bincount(group, precision[observed, k]) for k in range(3)], axis=1)
    with np.errstate(divide="ignore"):
        se = 1.0 / np.sqrt(summed[group])                                 # (n, 3), inf without information
    relative = np.linalg.norm(se, axis=1) / np.maximum(np.linalg.norm(albedo[observed], axis=1), 1e-300)
    out = np.zeros(len(albedo), bool)
    out[np.nonzero(observed)[0]] = relative >= MAX_RELATIVE_SE
    return out


def contradicted(est: Estimate, precision: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(F,) bool faces that share their label with other faces, have observations (``rows``
    (F,) their count) and no inlier among them: ``precision`` (F, 3), the face's own precision
    (:func:`trust.albedo_precision`, inlier rows only), is zero in every channel."""
    labels = np.where(est.observed, est.labels, -1)
    sizes = np.bincount(labels[labels >= 0], minlength=1)
    shared = (labels >= 0) & (sizes[np.maximum(labels, 0)] > 1)
    return shared & (rows > 0) & np.all(precision <= 0, axis=1)


def mark_unestimated(est: Estimate, code: np.ndarray) -> dict[str, int]:
    """Mark the faces with a reason code unestimated in place (albedos 0, label -1, not
    observed) and record the codes in ``face_stats['unestimated_reason']``; returns the count
    per reason (only reasons that occur)."""
    marked = code > 0
    est.diffuse[marked] = 0.0
    est.specular[marked] = 0.0
    est.labels[marked] = -1
    est.observed[marked] = False
    previous = est.face_stats.get("unestimated_reason")
    est.face_stats["unestimated_reason"] = code if previous is None else np.maximum(previous, code)
    return {REASONS[k - 1]: int(np.sum(code == k)) for k in range(1, len(REASONS) + 1) if np.any(code == k)}
