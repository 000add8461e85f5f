"""The coat's view-independent level from the albedo edges
(:func:`estimator.light.coat_level.level_from_edges`) and with the light found together
(:func:`estimator.methods.retinex_segmented.level.coat_level`): a grey level is recovered, a
matte object keeps none, the cap holds; with ``coat_level`` the level is taken from every colour
before the fits and from the faces a clustered solve extends to; bad inputs are named."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.core.errors import InputError
from estimator.light.coat_level import level_from_edges
from estimator.light.edge_fit import log_shading_fit


def _grid(n: int = 40, seed: int = 0):
    """An n x n grid of faces (4-neighbour edges) under a first-order light of a grey mean level and
    coloured directional part (the shading varies threefold), four albedo quadrants (one of them
    dark) with 1 % log-normal noise; returns
    the shading columns (F, 4), the light (4, 3), the edges, the albedo (F, 3), the quadrant
    labels and the shading (F, 3)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n] / n
    normals = np.stack([np.sin(3 * x + 1), np.cos(2 * y), np.sin(2 * x + 3 * y)], -1).reshape(-1, 3)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    columns = np.column_stack([np.ones(n * n), 0.6 * normals])
    light = np.array([[1.5, 1.5, 1.5], [0.9, 0.6, 0.4], [-0.8, -0.6, -0.4], [0.7, 0.5, 0.3]])
    idx = np.arange(n * n).reshape(n, n)
    edges = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    labels = (2 * (y >= 0.5) + (x >= 0.5)).ravel().astype(np.int64)
    albedo = np.array([[0.6, 0.5, 0.4], [0.05, 0.06, 0.04], [0.3, 0.7, 0.2], [0.5, 0.2, 0.6]])[labels]
    albedo = albedo * np.exp(0.01 * rng.normal(size=albedo.shape))
    shade = columns @ light
    assert shade.min() > 0.1 * shade.max()
    return columns, light, edges, albedo, labels, shade


def test_a_grey_level_is_recovered_under_the_true_light():
    """radiance = albedo x shade + 0.15 k, k a reflection's colour: the fitted level is the one
    added, within 3 %, and it explains the edges far beyond its price."""
    _, _, edges, albedo, _, shade = _grid()
    colour = np.array([0.5, 0.4, 0.3])
    added = 0.15 * colour
    found = level_from_edges(albedo * shade + added, shade, edges, np.ones(len(shade), bool), colour, 0.01)
    np.testing.assert_allclose(found.level, added, rtol=0.03)
    assert found.gain > 10 * found.price


def test_a_matte_object_keeps_no_level():
    """Without a level the albedo edges give nothing for one to explain: it is 0 (the criterion
    refuses what noise alone gains)."""
    _, _, edges, albedo, _, shade = _grid(seed=1)
    found = level_from_edges(albedo * shade, shade, edges, np.ones(len(shade), bool), np.ones(3), 0.01)
    np.testing.assert_array_equal(found.level, 0.0)
    assert found.gain <= found.price


def test_the_level_is_capped_by_the_radiance_it_may_turn_non_positive():
    """3 % of the faces, scattered, show 2 % of their radiance in one channel (a glint's
    shadow, a dark speck): the edges still ask for the level added, but it would leave those
    faces a channel at or below it. The cap binds: at most ``max_negative`` of the usable faces
    have some channel at or below the level found, which is the cap itself."""
    _, _, edges, albedo, _, shade = _grid(seed=2)
    colour = np.array([0.5, 0.4, 0.3])
    added = 0.15 * colour
    radiance = albedo * shade + added
    rng = np.random.default_rng(4)
    dark = rng.choice(len(shade), int(0.03 * len(shade)), replace=False)
    radiance[dark, rng.integers(0, 3, len(dark))] *= 0.02
    found = level_from_edges(radiance, shade, edges, np.ones(len(shade), bool), colour, 0.01)
    cap = np.quantile(np.min(radiance / colour, axis=1), 0.01)
    assert cap * colour[0] < 0.9 * added[0]
    np.testing.assert_allclose(found.level, cap * colour, rtol=1e-9)
    assert np.mean(np.any(radiance <= found.level, axis=1)) <= 0.01 + 1.0 / len(shade)


def test_the_light_and_the_level_are_found_together():
    """The level flattens a light fitted to the edges, so under that light the level comes out
    too small; alternated with the light (:func:`coat_level`), it comes near the level added,
    of the shading's colour (the light's mean level is grey here, as the fit's unit-DC gauge
    takes it)."""
    from estimator.methods.retinex_segmented.level import coat_level
    from estimator.methods.retinex_segmented.values import Hypothesis, LightSource, Shading

    columns, _, edges, albedo, labels, shade = _grid(seed=3)
    colour = np.median(shade, axis=0)
    added = 0.15 * colour
    radiance = albedo * shade + added
    usable = np.ones(len(shade), bool)
    fit = dict(loss="cauchy", ridge=1e-9, iterations=30)
    first, _ = log_shading_fit(radiance, columns, edges, usable, labels, **fit)
    under_first = level_from_edges(radiance, columns @ first, edges, usable, colour, 0.01).level
    h = Hypothesis(radiance, first, Shading(columns), radiance / (columns @ first), usable, labels, 4, 1.0,
                   LightSource.EDGES_AND_REGIONS, None)
    together = coat_level(h, edges, usable, None, fit, 0.01).level
    assert np.all(under_first < 0.7 * added)
    np.testing.assert_allclose(together, added, rtol=0.1)


@pytest.mark.parametrize("change, match", [
    (dict(radiance=np.ones((5, 2))), "radiance and shade must be"),
    (dict(usable=np.ones(4, bool)), "radiance and shade must be"),
    (dict(edges=np.zeros((3, 3), np.int64)), "edges must be"),
    (dict(edges=np.array([[0, 5]])), "edges must be"),
    (dict(edges=np.zeros((2, 2))), "edges must be"),
    (dict(colour=np.zeros(3)), "colour must be"),
    (dict(colour=np.array([1.0, -1.0, 1.0])), "colour must be"),
    (dict(max_negative=1.0), "max_negative"),
])
def test_bad_inputs_are_named(change, match):
    """Each malformed input raises an InputError that names it."""
    args = dict(radiance=np.ones((5, 3)), shade=np.ones((5, 3)), edges=np.zeros((2, 2), np.int64),
                usable=np.ones(5, bool), colour=np.ones(3), max_negative=0.01)
    args.update(change)
    with pytest.raises(InputError, match=match):
        level_from_edges(**args)


def test_a_level_found_is_subtracted_from_every_colour_before_the_fits(monkeypatch):
    """With ``coat_level`` on a glossy object, the level the stage finds (here a fixed one) is
    taken from every view's colour before the light is fitted again and the coat corrected: the
    kept hypothesis' diffuse radiance (a quantile over the views) is that of the colours less
    the level and less the coat's reflection kept, and the run records the level. Off, nothing
    is subtracted but the reflection."""
    from dataclasses import replace

    from estimator.core.reductions import group_quantile
    from estimator.light import coat
    from estimator.light.coat_level import CoatLevel
    from estimator.methods.retinex_segmented import method as method_module
    from estimator.pipeline.prepared import prepare

    from .micro import micro_config, micro_scene

    level = np.array([0.004, 0.003, 0.002])
    monkeypatch.setattr(method_module, "coat_level", lambda *a, **k: CoatLevel(level, 50.0, 3.0))
    config = micro_config()
    data, _ = micro_scene(config)
    for on in (True, False):
        c = replace(config, coat_level=on)
        prep = prepare(data, c)
        solution = method_module.RetinexSegmented(c).solve_held(prep)
        obs = prep.obs
        rgb = obs.rgb - level * on
        if solution.coat is not None:
            normals = prep.data.mesh.face_normals[obs.face]
            escapes = coat.mirror_escapes(obs.face, normals, obs.view_dir, prep.sampling, prep.visibility)
            rgb = rgb - solution.coat.weight[0] * solution.coat.rows(normals, obs.view_dir, c.coat_ior, escapes)
        radiance = group_quantile(obs.face, rgb, prep.data.mesh.num_faces, c.retinex_quantile)
        np.testing.assert_allclose(solution.hypothesis.radiance, radiance, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(solution.level, level * on)
        assert solution.estimate.info["coat_level"] == (level * on).tolist()


def test_the_faces_of_a_clustered_solve_lose_its_level_as_its_colours_did():
    """Extending a clustered solve's light to every face (:func:`.clusters.extend`) subtracts
    the solve's level from every colour: the same estimate as extending a solve without a level
    to colours already less it."""
    from dataclasses import replace

    from estimator.methods.retinex_segmented.clusters import extend
    from estimator.methods.retinex_segmented.method import RetinexSegmented
    from estimator.pipeline.prepared import prepare

    from .micro import micro_config, micro_scene

    config = micro_config(coat_correction=False)
    data, _ = micro_scene(config)
    prep = prepare(data, config)
    method = RetinexSegmented(config)
    part = method.solve_held(prep)
    level = np.array([0.004, 0.003, 0.002])
    with_level = extend(method, prep, replace(part, level=level))
    less = extend(method, replace(prep, obs=replace(prep.obs, rgb=prep.obs.rgb - level)), part)
    np.testing.assert_array_equal(with_level.diffuse, less.diffuse)
    assert np.abs(with_level.diffuse - extend(method, prep, part).diffuse).max() > 1e-4
