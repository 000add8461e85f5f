"""Peak signal-to-noise ratio, one convention for every figure the project reports."""
from __future__ import annotations

import numpy as np

from .errors import InputError

PSNR_CAP_DB = 100.0   # an error at or below 1e-10 of the peak's square (zero included) reads as identical


def psnr_db(mse: float, peak: float) -> float:
    """10 log10(peak^2 / mse) in dB, capped at :data:`PSNR_CAP_DB` (``peak`` > 0)."""
    if not (np.isfinite(mse) and mse >= 0):
        raise InputError(f"PSNR needs a finite mean squared error >= 0, got {mse!r}")
    if not (np.isfinite(peak) and peak > 0):
        raise InputError(f"PSNR needs a finite peak > 0, got {peak!r}")
    if mse <= peak * peak * 1e-10:
        return PSNR_CAP_DB
    return float(10 * np.log10(peak * peak / mse))
