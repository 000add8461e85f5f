"""Ground truth brought into the estimate's terms: filtered illumination and which faces count."""
from __future__ import annotations

import numpy as np

from estimator import sh
from estimator.data import GroundTruth, TriangleMesh
from estimator.raycast import RayCaster
from estimator.reflection import diffuse_matrix
from estimator.visibility import compute_visibility, sphere_sampling

from .metrics import LUMINANCE


def filtered_illumination(truth: GroundTruth, order: int) -> np.ndarray:
    """The true pseudo illumination: radiance SH x Phong filter (Ramamoorthi & Hanrahan),
    order ``order``, unit DC per channel -- the estimate's gauge. Shape ((order+1)^2, 3)."""
    return sh.pseudo_illumination(truth.sh, truth.brdf["exponent"], order)


def true_irradiance(mesh: TriangleMesh, truth: GroundTruth, order: int = 10, directions: int = 1164) -> np.ndarray:
    """(F, 3) direct irradiance / pi reaching each face centroid from the true light
    (its SH to ``order``), with self-shadowing: sum_lm L_lm C_lm."""
    caster = RayCaster(mesh)
    sampling = sphere_sampling(directions)
    c = diffuse_matrix(mesh, sampling, compute_visibility(caster, sampling), order)
    return c @ truth.sh[: sh.num_coeffs(order)]


def evaluation_mask(truth: GroundTruth, irradiance: np.ndarray, observed: np.ndarray, component: str,
                    min_albedo: float = 0.02, min_light: float = 0.05) -> np.ndarray:
    """Faces where an albedo can be judged.

    A face counts when the estimate observed it, its true albedo (luminance) of
    ``component`` is above ``min_albedo`` x the 99th percentile (non-negligible),
    and it receives light: true irradiance above ``min_light`` x the 95th
    percentile (faces unlit in every view carry no information); ``irradiance`` (F, 3) is
    :func:`true_irradiance`.
    """
    albedo = (truth.diffuse if component == "diffuse" else truth.specular) @ LUMINANCE
    light = irradiance @ LUMINANCE
    big = albedo > min_albedo * max(np.percentile(albedo, 99), 1e-300)
    lit = light > min_light * max(np.percentile(light, 95), 1e-300)
    return observed & big & lit
