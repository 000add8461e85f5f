"""The default method's decision among its light hypotheses (the prediction cost with the BIC's
price per unknown), the direct light's scale against the object's own reflected light, and the
gauge its regions are found in."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from estimator import estimate
from estimator.methods.retinex_segmented.decision import prediction_cost
from estimator.methods.retinex_segmented.shading import at_indirect_scale, in_unit_dc
from estimator.methods.retinex_segmented.values import Shading
from estimator.solvers.segmentation import segment

from .micro import micro_config, micro_scene

FACES, VIEWS = 40, 6


def _problem(seed=0):
    """Observations of FACES faces in VIEWS views under a fixed (F, 3) shading and no gloss."""
    rng = np.random.default_rng(seed)
    shade = rng.uniform(0.5, 1.5, (FACES, 3))
    albedo = rng.uniform(0.1, 0.8, (FACES, 3))
    face = np.repeat(np.arange(FACES), VIEWS)
    rgb = albedo[face] * shade[face] * (1 + 0.01 * rng.normal(size=(len(face), 3)))
    prep = SimpleNamespace(obs=SimpleNamespace(face=face, rgb=rgb), shading=lambda light: shade,
                           gloss=lambda light: np.zeros((len(face), 3)))
    return prep, albedo


def _estimate(albedo, unknowns, observed=None, labels=None):
    return SimpleNamespace(diffuse=albedo, specular=np.zeros_like(albedo), light=np.zeros((1, 3)),
                           observed=np.ones(FACES, bool) if observed is None else observed,
                           labels=np.arange(FACES) if labels is None else labels,
                           info={"degrees_of_freedom": {"unknowns": unknowns}})


def test_the_estimate_that_predicts_the_observations_costs_less():
    prep, albedo = _problem()
    wrong = albedo * np.where(np.arange(FACES)[:, None] % 3 == 0, 1.3, 1.0)   # a third of the faces 30 % off
    cost = prediction_cost(prep, [_estimate(albedo, 120), _estimate(wrong, 120)])
    assert cost.shape == (2,) and cost[0] < cost[1]


def test_each_unknown_costs_half_the_log_of_the_values_compared():
    prep, albedo = _problem()
    cost = prediction_cost(prep, [_estimate(albedo, 10), _estimate(albedo, 130)])
    np.testing.assert_allclose(cost[1] - cost[0], 0.5 * 120 * np.log(3 * FACES * VIEWS), rtol=1e-12)


def test_only_the_faces_every_estimate_holds_are_compared():
    prep, albedo = _problem()
    wrong = albedo.copy()
    wrong[:5] *= 3.0                                  # wrong only where the other estimate holds no face
    held = np.arange(FACES) >= 5
    cost = prediction_cost(prep, [_estimate(albedo, 50, held), _estimate(wrong, 50)])
    np.testing.assert_allclose(cost[0], cost[1], rtol=1e-12)


def test_an_estimate_that_interpolates_does_not_take_the_noise_for_nil():
    """One observation per face (1 % noise): a free albedo per face reproduces every one
    exactly. Held out, its residuals are unknown, so the scale comes from the two-region
    estimate, which fits within the noise and wins; were the interpolating estimate's zero
    residuals the scale, each of the regions' residuals would be priced as an outlier."""
    rng = np.random.default_rng(2)
    shade = rng.uniform(0.5, 1.5, (FACES, 3))
    region = np.arange(FACES) % 2
    albedo = np.array([[0.2, 0.5, 0.3], [0.6, 0.3, 0.1]])[region]
    face = np.arange(FACES)
    rgb = albedo * shade * (1 + 0.01 * rng.normal(size=(FACES, 3)))
    prep = SimpleNamespace(obs=SimpleNamespace(face=face, rgb=rgb), shading=lambda light: shade,
                           gloss=lambda light: np.zeros((FACES, 3)))
    free, tied = _estimate(rgb / shade, 3 * FACES), _estimate(albedo, 6, labels=region)
    cost = prediction_cost(prep, [free, tied])
    assert cost[1] < cost[0]


@pytest.mark.parametrize("scale", [[2.0, 3.0, 0.5], [1.0, 1.0, 1.0]])
def test_the_direct_light_is_scaled_to_the_indirect_shadings_units(scale):
    """Faces of one albedo on a chain: radiance = s * direct + indirect; the scale s of each
    channel is recovered from the albedo edges (1e-6 relative)."""
    rng = np.random.default_rng(3)
    direct = rng.uniform(0.2, 1.0, (FACES, 1))
    indirect = rng.uniform(0.05, 0.3, (FACES, 3))
    radiance = np.asarray(scale) * direct + indirect
    edges = np.stack([np.arange(FACES - 1), np.arange(1, FACES)], axis=1)
    ctx = SimpleNamespace(extra=indirect, usable=np.ones(FACES, bool), edges=edges,
                          plain_fit={"loss": "none", "ridge": 0.0, "iterations": 50})
    light = at_indirect_scale(ctx, Shading(direct), radiance, np.ones((1, 3)))
    np.testing.assert_allclose(light[0], scale, rtol=1e-6)


def test_without_an_indirect_term_the_light_is_unchanged():
    ctx = SimpleNamespace(extra=0.0)
    light = np.arange(6.0).reshape(2, 3)
    assert at_indirect_scale(ctx, Shading(np.ones((FACES, 2))), np.ones((FACES, 3)), light) is light


def test_a_term_added_to_the_prediction_is_judged_with_its_unknowns():
    """Observations that hold a coat's reflection on top of the diffuse: the estimate whose
    prediction has it added back costs less, although it pays for three more unknowns; the
    same term added where the observations lack it costs more."""
    prep, albedo = _problem()
    coat = np.full((len(prep.obs.face), 3), 0.05) * (1 + np.arange(len(prep.obs.face)) % VIEWS)[:, None]
    bare = prep.obs.rgb.copy()
    prep.obs.rgb = bare + coat
    est = _estimate(albedo, 120)
    with_coat, without = prediction_cost(prep, [est, est], [coat, None], [3, 0])
    assert with_coat < without
    prep.obs.rgb = bare
    with_coat, without = prediction_cost(prep, [est, est], [coat, None], [3, 0])
    assert with_coat > without


def test_the_regions_found_do_not_depend_on_the_lights_colour():
    """The segmentation compares colours; the light's per-channel scale (which only the faint
    interreflection pins) must not enter them: albedos under a light k times brighter per
    channel (so 1/k the albedos) are segmented exactly alike, where without the unit-DC gauge
    a red light 20 times too dim merges two regions that differ in red."""
    rng = np.random.default_rng(1)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    edges = np.asarray(mesh.face_adjacency)
    top = mesh.triangles_center[:, 1] > 0
    albedo = np.where(top[:, None], [0.6, 0.3, 0.3], [0.3, 0.3, 0.3]) * (1 + 0.005 * rng.normal(size=(len(top), 3)))
    light = np.array([[1.0, 1.0, 1.0], [0.3, 0.2, 0.1]])
    valid = np.ones(len(top), bool)
    k = np.array([20.0, 1.0, 1.0])
    plain, _ = segment(in_unit_dc(albedo, light), edges, valid)
    scaled, _ = segment(in_unit_dc(albedo / k, light * k), edges, valid)
    np.testing.assert_array_equal(plain, scaled)
    assert len(np.unique(plain[plain >= 0])) == 2
    merged, _ = segment(albedo / k, edges, valid)
    assert len(np.unique(merged[merged >= 0])) == 1


@pytest.mark.parametrize("overrides, as_regions", [({}, True), ({"segment_threshold": 1e-6}, False)])
def test_the_unknowns_priced_are_the_estimates_own(overrides, as_regions):
    """The micro scene as regions and, with no neighbours joined, as a texture: a diffuse
    albedo per region and per free face, a specular per region, or one the free faces share
    (their fits' median), and the light less its DC (the gauge), per channel. (Its two albedos
    under a strong Phong lobe and no noise sit at the segmentation's threshold: whether the
    lobe parts them further changes with the last digits of the light, so the test takes the
    partition the estimate found.)"""
    data, _ = micro_scene()
    est = estimate(data, None, micro_config(**overrides))
    regions = est.info["uniform_regions"]
    free = int((est.observed & (est.labels >= regions)).sum())
    assert (regions >= 2 and free == 0) if as_regions else (regions == 0 and free > 0)
    light = est.light.shape[0] - 1
    assert est.info["degrees_of_freedom"]["unknowns"] == 3 * (regions + free + (regions or 1) + light)


def test_the_default_reports_its_stages_as_it_goes():
    """Progress lines of the solve: the light's source when the first fit is done."""
    data, _ = micro_scene()
    lines = []
    estimate(data, None, micro_config(), log=lines.append)
    stages = [line.split(" ")[0] for line in lines]
    assert "light" in stages and stages.index("observations:") < stages.index("light")


@pytest.mark.parametrize("level, lobe", [(0.0, False), (2.0, False), (2.0, True)])
def test_the_coat_correction_keeps_the_cheapest_of_its_reflections(level, lobe):
    """The matte micro scene's colours with a coat's reflection of an even environment of
    ``level`` added (the Fresnel factor where the mirror direction escapes the object): the
    coat's reflections of the environment's mean level (degree 0) and of the light's low orders
    (and, with ``coat_lobe``, a Phong lobe's) are each removed and judged with the uncorrected
    fit by the prediction cost; the cheapest is kept and reported. Without a reflection the
    correction is not applied."""
    from dataclasses import replace

    from estimator.light.coat import LOBE_EXPONENTS, mirror_escapes
    from estimator.methods.retinex_segmented.method import RetinexSegmented
    from estimator.model.reflection import fresnel_dielectric
    from estimator.pipeline.prepared import prepare

    config = replace(micro_config(), coat_lobe=lobe)
    data, _ = micro_scene(config, specular=0.0)
    prep = prepare(data, config)
    obs = prep.obs
    normals = data.mesh.face_normals[obs.face]
    reflection = level * fresnel_dielectric(np.sum(normals * obs.view_dir, axis=1), config.coat_ior) * mirror_escapes(
        obs.face, normals, obs.view_dir, prep.sampling, prep.visibility)
    prep = replace(prep, obs=replace(obs, rgb=obs.rgb + reflection[:, None]))
    info = RetinexSegmented(config).solve_held(prep).estimate.info
    costs = info["coat_costs"]
    names = {"none", "degree 0", f"degree {config.coat_order}"} | {f"lobe {n:g}" for n in LOBE_EXPONENTS}
    assert costs is None or (set(costs) <= names and "none" in costs)
    if level == 0:   # nothing reflects: no correction is tried, or none is kept
        assert costs is None or min(costs, key=costs.get) == "none"
        assert info["coat_degree"] is None and info["coat_exponent"] is None and not np.any(info["coat_weight"])
    else:
        kept = min(costs, key=costs.get)
        assert {"none", "degree 0", f"degree {config.coat_order}"} <= set(costs) and kept != "none"
        assert any(name.startswith("lobe") for name in costs) == lobe   # the lobe is tried only when asked for
        exponent = info["coat_exponent"]
        assert kept == (f"degree {info['coat_degree']}" if exponent is None else f"lobe {exponent:g}")
        assert np.all(np.array(info["coat_weight"]) > 0)


def test_a_refit_offers_the_first_fits_regions_and_the_glossy_micro_scene_gains():
    """The micro scene reflects its light through a Phong lobe (specular 0.2). Removing the
    coat's low orders leaves the corrected colours noisier than the segmentation holds, so the
    refit's own regions may fail; the first fit's regions, tied as they are, are offered beside
    them (``light_from`` "edges and the first fit's regions"), and the correction brings the
    albedos nearer the truth. How much depends on the rounding: the segmentation of this small,
    noisy scene (two true regions) finds 5 uniform regions with two BLAS threads and 4 with one,
    and the gain measured is 17.7 -> 20.9 dB with two, 18.4 -> 18.9 dB with one. So the test
    asks for the gain of the worse of the two, 0.3 dB, and holds for either thread count."""
    from dataclasses import replace

    from estimator.methods.retinex_segmented.method import RetinexSegmented
    from estimator.pipeline.prepared import prepare
    from reports.metrics import albedo_psnr

    config = micro_config()
    data, truth = micro_scene(config)
    psnr = {}
    for correct in (True, False):
        c = replace(config, coat_correction=correct)
        est = RetinexSegmented(c).solve_held(prepare(data, c)).estimate
        psnr[correct] = albedo_psnr(est.diffuse, truth.diffuse, est.observed)
        if correct:
            offered = [h["light_from"] for h in est.info["hypotheses"]]
            assert "edges and the first fit's regions" in offered and est.info["coat_degree"] is not None
    assert psnr[True] > psnr[False] + 0.3


def _first_fit_context(recorded: bool = True):
    """The matte micro scene's first fit (its chosen hypothesis) and a fit context on its lit
    faces with the method's edge fit arguments; with the mesh's faces above y = 0.2 (F,)."""
    from estimator.methods.retinex_segmented.method import RetinexSegmented
    from estimator.methods.retinex_segmented.values import FitContext, ReflectionFits
    from estimator.pipeline.prepared import prepare

    config = micro_config()
    data, _ = micro_scene(config, specular=0.0)
    prep = prepare(data, config)
    method = RetinexSegmented(config)
    _, first, _ = method._fit(prep, ReflectionFits(prep.obs))
    ctx = FitContext(prep, config, method.model, method.loss, ReflectionFits(prep.obs), prep.edges, first.lit,
                     method._edge_fit_arguments(), recorded=recorded)
    return first, ctx, data.mesh.centroids[:, 1] > 0.2


def test_kept_regions_ties_the_given_regions_as_they_are():
    """Regions without a lit face are dropped and the others renumbered in order; every lit
    face of a region takes its region's albedo."""
    from estimator.methods.retinex_segmented.edges import kept_regions

    first, ctx, top = _first_fit_context()
    labels = np.where(top, 5, 2)          # ids 2 and 5 only: 0, 1, 3, 4 empty
    h = kept_regions(ctx, first, labels)
    assert h.regions == 2 and h.source.value == "edges and the first fit's regions"
    lit = h.lit
    assert set(np.unique(h.labels[lit])) == {0, 1}
    assert np.all(h.labels[lit & top] == 1) and np.all(h.labels[lit & ~top] == 0)
    for k in (0, 1):
        inside = lit & (h.labels == k)
        np.testing.assert_allclose(h.albedo[inside], h.albedo[inside][:1].repeat(inside.sum(), 0))
    assert kept_regions(ctx, first, np.full(len(labels), -1)) is None


@pytest.mark.parametrize("recorded", [True, False])
def test_parted_regions_seeks_two_modes_only_in_the_colours_as_recorded(recorded):
    """One region tied over two albedos 6 % apart (within segment_threshold, so the
    threshold's split keeps them together) whose faces scatter by 0.5 %: on the colours as
    recorded the parted hypothesis finds the two modes, one part each; on colours less a
    coat's reflection (a refit's) the modes are not sought and nothing parts."""
    from dataclasses import replace

    from estimator.methods.retinex_segmented.edges import parted_regions

    first, ctx, top = _first_fit_context(recorded)
    shade = first.shading.columns @ first.light
    rng = np.random.default_rng(0)
    radiance = shade * 0.5 * np.where(top, 1.06, 1.0)[:, None] * np.exp(0.005 * rng.standard_normal(shade.shape))
    tied = replace(first, radiance=radiance, labels=np.where(first.lit, 0, -1), regions=1)
    h = parted_regions(ctx, tied)
    if not recorded:
        assert h is None
        return
    inside = h.lit & (h.labels >= 0)
    assert h.regions == 2 and h.source.value == "edges and parted regions"
    assert len(np.unique(h.labels[inside & top])) == 1 and len(np.unique(h.labels[inside & ~top])) == 1
    assert h.labels[inside & top][0] != h.labels[inside & ~top][0]


def test_only_the_first_fit_sees_the_colours_as_recorded(monkeypatch):
    """The first fit is on the colours as recorded; the refit after the coat's level and each
    coat's refit are on colours less a fitted term, where the parted regions' modes are not
    sought (``recorded`` False). The coat's level is made to be found (the micro scene's is 0)."""
    from dataclasses import replace

    import estimator.methods.retinex_segmented.method as method_module
    from estimator.methods.retinex_segmented.method import RetinexSegmented
    from estimator.pipeline.prepared import prepare

    monkeypatch.setattr(method_module, "coat_level",
                        lambda *args: SimpleNamespace(level=np.full(3, 1e-4), gain=1.0, price=0.0))
    calls = []
    original = RetinexSegmented._fit

    def spy(self, prep, fits, found=None, labels=None, recorded=True):
        calls.append(recorded)
        return original(self, prep, fits, found, labels, recorded)

    monkeypatch.setattr(RetinexSegmented, "_fit", spy)
    config = replace(micro_config(), coat_level=True)
    data, _ = micro_scene(config)
    info = RetinexSegmented(config).solve_held(prepare(data, config)).estimate.info
    assert info["coat_costs"] is not None and any(info["coat_level"])   # both refits ran
    assert calls[0] is True and len(calls) >= 3 and not any(calls[1:])


def test_a_light_that_models_the_coat_is_weighed_again_against_the_corrected_fits(monkeypatch):
    """Where the first fit keeps a light that models the coat, the cheapest hypothesis that does
    not is corrected for the coat, and the kept light is judged beside those corrections in
    the same call. Here the kept light is made a stand-in (the plain estimate relabelled as the
    coat map's): it predicts as the uncorrected fit does, so it costs exactly as much, and the
    coat added to the micro scene's colours makes a correction cheaper than both. Made the
    cheapest (the cost patched), or with no reflection to try, the stand-in is kept as it is."""
    from dataclasses import replace

    from estimator.light.coat import mirror_escapes
    from estimator.methods.retinex_segmented.method import RetinexSegmented
    from estimator.methods.retinex_segmented.values import LightSource
    from estimator.model.reflection import fresnel_dielectric
    from estimator.pipeline.prepared import prepare

    original = RetinexSegmented._fit

    def first_keeps_the_map(self, prep, fits, found=None, labels=None, recorded=True):
        est, h, plain = original(self, prep, fits, found, labels, recorded)
        if not recorded:
            return est, h, plain
        stand_in = replace(est, info={**est.info, "light_from": LightSource.COAT_MAP_DIFFUSE.value})
        return stand_in, replace(h, source=LightSource.COAT_MAP_DIFFUSE), (est, h)

    monkeypatch.setattr(RetinexSegmented, "_fit", first_keeps_the_map)
    config = micro_config()
    data, _ = micro_scene(config, specular=0.0)
    prep = prepare(data, config)
    obs = prep.obs
    normals = data.mesh.face_normals[obs.face]
    reflection = 0.2 * fresnel_dielectric(np.sum(normals * obs.view_dir, axis=1), config.coat_ior) * mirror_escapes(
        obs.face, normals, obs.view_dir, prep.sampling, prep.visibility)
    prep = replace(prep, obs=replace(obs, rgb=obs.rgb + reflection[:, None]))
    info = RetinexSegmented(config).solve_held(prep).estimate.info
    costs = info["coat_costs"]
    rival = LightSource.COAT_MAP_DIFFUSE.value
    assert {"none", rival} <= set(costs) and len(costs) >= 3
    assert costs[rival] == pytest.approx(costs["none"], rel=1e-12)
    kept = min(costs, key=costs.get)
    assert kept not in ("none", rival) and info["light_from"] != rival and info["coat_degree"] is not None

    # the stand-in made the cheapest in that call: kept as it is, with no coat subtracted
    import estimator.methods.retinex_segmented.method as method_module
    cost = method_module.prediction_cost

    def rival_cheapest(*args):
        costs = cost(*args)
        costs[-1] = costs.min() - 1.0
        return costs

    monkeypatch.setattr(method_module, "prediction_cost", rival_cheapest)
    solution = RetinexSegmented(config).solve_held(prep)
    assert solution.estimate.info["light_from"] == rival and solution.coat is None
    assert min(solution.estimate.info["coat_costs"], key=solution.estimate.info["coat_costs"].get) == rival

    # no coat's reflection worth trying: the first choice stands
    monkeypatch.setattr(RetinexSegmented, "_coat_candidates", lambda self, prep, est: [])
    solution = RetinexSegmented(config).solve_held(prep)
    assert solution.estimate.info["light_from"] == rival and solution.coat is None
    monkeypatch.undo()

    with_level = replace(config, coat_level=True)   # its refits judge the colours less a level: not weighed
    monkeypatch.setattr(RetinexSegmented, "_fit", first_keeps_the_map)
    info = RetinexSegmented(with_level).solve_held(prepare(data, with_level)).estimate.info
    assert info["light_from"] == rival and info.get("coat_costs") is None
