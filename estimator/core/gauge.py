"""The unit-DC gauge of the light.

Albedo and light enter every colour as a product, so their common scale per channel is not
determined by the images: every method reports the light with its DC coefficient (SH index 0)
equal to 1 per channel, and its albedos carry the scale.
"""
from __future__ import annotations

import numpy as np

DC_FLOOR = 1e-300   # a channel whose DC is no larger in magnitude holds no light: it is left as it is


def unit_dc(light: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, C) ``light`` with DC 1 in every channel, and (C,) the DC it was divided by (1 where
    the DC is within :data:`DC_FLOOR` of zero); multiply albedos by the second to keep the
    product. Negative DCs are divided out too (the sign goes to the albedos)."""
    dc = np.where(np.abs(light[0]) > DC_FLOOR, light[0], 1.0)
    return light / dc, dc
