"""Peak signal-to-noise ratio, one convention for every figure the project reports."""
from __future__ import annotations

import numpy as np

PSNR_CAP_DB = 100.0   # an error at or below 1e-10 of the peak's square (zero included) reads as identical


def psnr_db(mse: float, peak: float) -> float:
    """10 log10(peak^2 / mse) in dB, capped at :data:`PSNR_CAP_DB` (``peak`` > 0)."""
    if mse <= peak * peak * 1e-10:
        return PSNR_CAP_DB
    return float(10 * np.log10(peak * peak / mse))
