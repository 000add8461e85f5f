"""The gates of the default method's light hypotheses, on a fitted coat map given directly
(:class:`ReflectionFits`), so each gate is tested by its own rule."""
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


@pytest.mark.parametrize("flags, explained, determined, regions, used", [
    ({}, [0.99, 0.99, 0.975], True, False, True),     # mean 0.985: one channel below is fine
    ({}, [0.99, 0.99, 0.975], True, True, True),      # uniform regions take it too
    ({"reflected_regions": False}, [0.99] * 3, True, True, False),
    ({"reflected_regions": False}, [0.99] * 3, True, False, True),
    ({}, [0.974, 0.976, 0.977], True, False, False),  # below reflected_min_explained (0.982)
    ({}, [0.99] * 3, False, False, False),            # not determined
    ({"interreflection": True}, [0.99] * 3, True, False, False),
    ({"reflected_light": False}, [0.99] * 3, True, False, False),
])
def test_the_coat_maps_light_is_a_candidate_only_past_its_gate(flags, explained, determined, regions, used):
    ctx = _context(flags, explained, determined)
    assert (coat_map_candidate(ctx, regions) is ctx.fits.coat_map) == used


@pytest.mark.parametrize("flags, explained, determined, used", [
    ({}, [0.974, 0.976, 0.977], True, True),      # the map's light fails its gate, its diffuse serves
    ({}, [0.958, 0.952, 0.952], True, True),
    ({}, [0.6, 0.77, 0.5], True, False),          # no coat: below reflected_diffuse_min_explained (0.9)
    ({}, [0.99] * 3, False, False),               # not determined
    ({"interreflection": True}, [0.99] * 3, True, False),
    ({"reflected_light": False}, [0.99] * 3, True, False),
])
def test_the_coat_maps_diffuse_serves_past_its_own_gate(flags, explained, determined, used):
    diffuse = np.full((FACES, 3), 0.3)
    diffuse[4] = np.nan                         # a face the map did not see keeps its own radiance
    through = np.full((FACES, 9), 0.7)
    ctx = _context(flags, explained, determined, diffuse, through)
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
