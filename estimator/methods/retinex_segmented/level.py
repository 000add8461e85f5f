"""The coat's view-independent level, found with the light (:mod:`estimator.light.coat_level`).

The level a glossy layer adds to every view of a face also flattens the light fitted to the
edges: a constant added to every radiance brings the ratios of neighbouring faces nearer 1.
So the level fitted under the first fit's light comes out too small. The two are found
together by alternation: the level under the light, then the light again on the radiance
less that level (started from the light before), :data:`ROUNDS` times.
"""
from __future__ import annotations

import numpy as np
from scipy import sparse

from ...light import edge_fit
from ...light.coat_level import CoatLevel, level_from_edges
from .values import Hypothesis

# alternations of level and light: each closes a share of the gap the flattened light leaves
# (on a Phong-lobed development seed the level's channels reached 0.036-0.054 after 6, 0.037-0.054
# after 8), and each costs one edge fit per channel
ROUNDS = 6


def coat_level(h: Hypothesis, edges: np.ndarray, reached: np.ndarray, transfer: sparse.csr_matrix | None,
               fit: dict, max_negative: float) -> CoatLevel:
    """The level (:func:`level_from_edges`) of hypothesis ``h``'s radiance, alternated with its
    light (:func:`edge_fit.log_shading_fit` on ``h``'s columns, its regions tied when it has
    any). ``reached`` (F,): faces some direction of the light reaches; ``transfer``: the
    interreflection's operator (:func:`estimator.light.indirect.indirect_transfer`; None
    without), applied to the radiance less the level; ``fit``: the edge fit's keyword
    arguments without the indirect shading; ``max_negative``: the level's cap."""
    radiance, columns, light = h.radiance, h.shading.columns, h.light
    base = np.all(np.isfinite(radiance) & (radiance > 0), axis=1) & reached
    labels = h.labels if h.regions else None
    level = np.zeros(3)
    found = CoatLevel(level, 0.0, 0.0)
    for k in range(ROUNDS):
        less = radiance - level
        if k:   # the light again, on the radiance less the level
            usable = base & np.all(less > 0, axis=1)
            indirect = {} if transfer is None else {"indirect": transfer @ np.where(usable[:, None], less, 0.0)}
            light = edge_fit.log_shading_fit(np.where(usable[:, None], less, 1.0), columns, edges, usable, labels,
                                             initial=light, **fit, **indirect)[0]
        shade = columns @ light
        if transfer is not None:
            shade = shade + transfer @ np.where(base[:, None], less, 0.0)
        found = level_from_edges(radiance, shade, edges, base & np.all(shade > 0, axis=1), max_negative)
        if not found.level.any():
            break
        level = found.level
    return found
