"""When the default method offers its reflection hypotheses, on a fitted coat map given directly
(:class:`ReflectionFits`), so each condition is tested by its own rule."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from estimator import EstimatorConfig
from estimator.light.coat_map import ReflectedLight
from estimator.methods.retinex_segmented.coat import coat_map_candidate, coated_diffuse
from estimator.methods.retinex_segmented.values import (
    FitContext,
    Hypothesis,
    LightSource,
    ReflectionFits,
    Shading,
)

FACES = 5


def _context(flags, explained, determined, diffuse=None, through=None):
    map_diffuse = np.full((FACES, 3), 0.3) if diffuse is None else diffuse
    fits = ReflectionFits(observations=None, coat_map=ReflectedLight(
        np.zeros((4, 8, 3)), map_diffuse, np.array(explained), 100, determined))
    model = SimpleNamespace(diffuse_matrix=lambda mesh, sampling, visibility, coat_ior=None: through * (coat_ior or 0))
    prep = SimpleNamespace(data=SimpleNamespace(mesh=None), sampling=None, visibility=None, caster=None,
                           c_matrix=np.ones((FACES, 9)))
    return FitContext(prep, EstimatorConfig(sh_order=2, **flags), model, "cauchy", fits,
                      np.zeros((0, 2), np.int64), np.ones(FACES, bool))


@pytest.mark.parametrize("flags, determined, regions, used", [
    ({}, True, False, True),
    ({}, True, True, True),                       # uniform regions take it too
    ({"reflected_regions": False}, True, True, False),
    ({"reflected_regions": False}, True, False, True),
    ({}, False, False, False),                    # not determined
    ({"reflected_light": False}, True, False, False),
])
def test_the_coat_maps_light_is_a_candidate_when_determined_and_asked_for(flags, determined, regions, used):
    ctx = _context(flags, [0.5] * 3, determined)   # how much it explains is no gate: the decision weighs it
    assert (coat_map_candidate(ctx, regions) is ctx.fits.coat_map) == used


@pytest.mark.parametrize("flags, determined, used", [
    ({}, True, True),
    ({}, False, False),                            # not determined
    ({"reflected_light": False}, True, False),
])
def test_the_coat_maps_diffuse_is_offered_when_determined(flags, determined, used):
    diffuse = np.full((FACES, 3), 0.3)
    diffuse[4] = np.nan                         # a face the map did not see keeps its own radiance
    through = np.full((FACES, 9), 0.7)
    ctx = _context(flags, [0.5] * 3, determined, diffuse, through)
    edges = Hypothesis(np.full((FACES, 3), 0.5), np.zeros((9, 3)), Shading(ctx.prep.c_matrix), np.zeros((FACES, 3)),
                       np.ones(FACES, bool), np.full(FACES, -1), 0, 0.0, LightSource.EDGES, None)
    out = coated_diffuse(ctx, edges)
    assert (out is not None) == used
    if used:
        radiance, shading = out
        np.testing.assert_allclose(radiance[:4], 0.3)
        np.testing.assert_allclose(radiance[4], 0.5)
        np.testing.assert_allclose(shading.columns, through * ctx.config.coat_ior)   # through the coat
        assert shading.sun is None
