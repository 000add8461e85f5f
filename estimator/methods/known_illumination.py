"""``known-illumination``: the oracle, the light fixed to the truth."""
from __future__ import annotations

import numpy as np

from ..core import sh
from ..core.errors import InputError
from ..core.gauge import unit_dc
from .base import Method, register_method


@register_method
class KnownIllumination(Method):
    """The oracle: the light fixed to the truth (the pseudo illumination h, or the radiance L
    for the lobe model), per-face albedos by linear least squares."""

    name = "known-illumination"
    needs_illumination = True
    streams = True

    def solve(self, prep):
        known, what = self.model.known_light(self.known_sh, self.known_radiance)
        if known is None:
            raise InputError(f"known-illumination needs {what} for the {self.model.name!r} reflection model")
        m = sh.num_coeffs(self.config.sh_order)
        fixed = np.zeros((m, 3))
        k = min(m, known.shape[0])
        fixed[:k] = known[:k]
        fixed = unit_dc(fixed)[0]
        return self._solve_per_face(prep, fixed)
