"""The coat's view-independent level, found with the light (:mod:`estimator.light.coat_level`).

The level a glossy layer adds to every view of a face also flattens the light fitted to the
edges: a constant added to every radiance brings the ratios of neighbouring faces nearer 1.
So the level fitted under the first fit's light comes out too small. The two are found
together by alternation: the level under the light, then the light again on the radiance
less that level (started from the light before) and the level under it, :data:`ROUNDS` level
fits in all.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse

from ...light import edge_fit
from ...light.coat_level import CoatLevel, level_from_edges
from .values import Hypothesis

# level fits, with the light fitted again before each but the first: each closes a share of the
# gap the flattened light leaves (in tests/estimator/test_coat_level.py the first light gives 0.6
# of the level, six fits 0.96), and each costs one edge fit per channel
ROUNDS = 6


def coat_level(h: Hypothesis, edges: np.ndarray, reached: np.ndarray, transfer: sparse.csr_matrix | None,
               fit: dict[str, Any], max_negative: float) -> CoatLevel:
    """The level (:func:`level_from_edges`) of hypothesis ``h``'s radiance, alternated with its
    light (:func:`edge_fit.log_shading_fit` on ``h``'s columns, its regions tied when it has any).

    Parameters
    ----------
    h : the first fit's hypothesis: its radiance (F, 3), columns and light.
    edges : (E, 2) pairs of neighbouring faces.
    reached : (F,) bool, faces some direction of the light reaches.
    transfer : the interreflection's operator (:func:`estimator.light.indirect.indirect_transfer`;
        None without), applied to the radiance less the level.
    fit : the edge fit's keyword arguments without the indirect shading.
    max_negative : the level's cap.

    The level's colour (:func:`level_from_edges`) is the median shading's under each round's
    light: with ``transfer`` the light is at its own scale, whose colour is the environment's,
    the colour a dielectric or a white lobe reflects (on a convex object, where the transfer
    reflects nothing, the light keeps a unit DC per channel and the level the unit-DC
    shading's colour).

    Returns
    -------
    The last round's :class:`CoatLevel`: a round whose level the criterion refuses ends the
    alternation with none.
    """
    radiance, columns, light = h.radiance, h.shading.columns, h.light
    base = np.all(np.isfinite(radiance) & (radiance > 0), axis=1) & reached
    labels = h.labels if h.regions else None
    level = np.zeros(3)
    found = CoatLevel(level, 0.0, 0.0)
    for k in range(ROUNDS):
        less = radiance - level
        usable = base & np.all(less > 0, axis=1)   # faces the level leaves some radiance
        # the light the object reflects onto each face, from the radiance less the level
        indirect = {} if transfer is None else {"indirect": transfer @ np.where(usable[:, None], less, 0.0)}
        if k:   # the light again, on the radiance less the level
            light = edge_fit.log_shading_fit(np.where(usable[:, None], less, 1.0), columns, edges, usable, labels,
                                             initial=light, **fit, **indirect)[0]
        shade = columns @ light + indirect.get("indirect", 0.0)
        lit = base & np.all(shade > 0, axis=1)
        if not lit.any():
            return CoatLevel(np.zeros(3), 0.0, 0.0)
        found = level_from_edges(radiance, shade, edges, lit, np.median(shade[lit], axis=0), max_negative)
        if not found.level.any():
            break
        level = found.level
    return found
