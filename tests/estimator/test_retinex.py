"""The edge (Retinex) light fit: exact on noise-free piecewise-uniform data, with and
without uniform regions; shapes and bad inputs."""
import numpy as np
import pytest

from estimator.core.errors import InputError
from estimator.light.edge_fit import log_shading_fit


def _grid(n: int = 24, seed: int = 0):
    """An n x n grid of faces (4-neighbour edges) with smooth random normals, first-order
    diffuse rows C_f = [1, n_f / 2], two albedo halves and a coloured light."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n] / n
    normals = np.stack([np.sin(3 * x + 1) + 0.3 * rng.normal(size=x.shape), np.cos(2 * y),
                        np.sin(2 * x + 3 * y)], -1).reshape(-1, 3)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    c_matrix = np.column_stack([np.ones(n * n), 0.5 * normals])
    idx = np.arange(n * n).reshape(n, n)
    edges = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    labels = (x.ravel() >= 0.5).astype(np.int64)
    albedo = np.array([[0.2, 0.5, 0.05], [0.7, 0.1, 0.6]])[labels]
    light = np.array([[2.0, 1.0, 0.5], [0.3, -0.2, 0.1], [-0.4, 0.1, 0.2], [0.5, 0.3, -0.1]])
    radiance = albedo * (c_matrix @ light)
    return c_matrix, edges, labels, albedo, light, radiance


@pytest.mark.parametrize("with_regions", [False, True])
def test_recovers_the_shading_up_to_scale(with_regions):
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    usable = np.ones(len(radiance), dtype=bool)
    fit, region_albedo = log_shading_fit(radiance, c_matrix, edges, usable, labels if with_regions else None)
    assert fit.shape == (4, 3)
    np.testing.assert_allclose(fit[0], 1.0)                                    # the gauge: unit DC
    np.testing.assert_allclose(fit, light / light[0], rtol=1e-4, atol=1e-5)      # boundary edges are outliers
    if with_regions:
        assert region_albedo.shape == (2, 3)
        np.testing.assert_allclose(region_albedo[1] / region_albedo[0], albedo[-1] / albedo[0], rtol=1e-4)
    else:
        assert region_albedo.shape == (0, 3)


@pytest.mark.parametrize("channel", [0, 2])
def test_one_channel_alone_is_fitted_as_within_three(channel):
    """A (F, 1) radiance (one channel, as a reflection's light is scaled per channel) gives that
    channel's light and region albedos as the channel does beside the others: the channels are
    fitted apart."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    usable = np.ones(len(radiance), dtype=bool)
    alone, alone_albedo = log_shading_fit(radiance[:, [channel]], c_matrix, edges, usable, labels)
    beside, beside_albedo = log_shading_fit(radiance, c_matrix, edges, usable, labels)
    assert alone.shape == (4, 1) and alone_albedo.shape == (2, 1)
    np.testing.assert_allclose(alone[:, 0], beside[:, channel], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(alone_albedo[:, 0], beside_albedo[:, channel], rtol=1e-9)
    indirect = 0.05 * radiance.mean(axis=1, keepdims=True) * np.ones((1, 3))   # a faint additive shading
    alone, _ = log_shading_fit(radiance[:, [channel]], c_matrix, edges, usable, indirect=indirect[:, [channel]])
    beside, _ = log_shading_fit(radiance, c_matrix, edges, usable, indirect=indirect)
    np.testing.assert_allclose(alone[:, 0], beside[:, channel], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("max_edges", [40, 300])
def test_a_random_subset_of_the_edges_recovers_the_light_and_every_regions_albedo(max_edges):
    """Beyond ``max_edges`` the fit draws that many edges (of 1,104) and their faces' region
    rows; a region none of whose faces is drawn (a lone face) takes its median under the light."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    labels, albedo = labels.copy(), albedo.copy()
    labels[0], albedo[0] = 2, [0.3, 0.3, 0.3]                  # a third region of one face
    radiance = albedo * (c_matrix @ light)
    usable = np.ones(len(radiance), dtype=bool)
    fit, region_albedo = log_shading_fit(radiance, c_matrix, edges, usable, labels, max_edges=max_edges)
    full, _ = log_shading_fit(radiance, c_matrix, edges, usable, labels)
    np.testing.assert_allclose(fit, light / light[0], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(fit, full, rtol=1e-4, atol=1e-5)
    truth = albedo[[labels.tolist().index(r) for r in range(3)]]
    np.testing.assert_allclose(region_albedo / region_albedo[0], truth / truth[0], rtol=1e-4)


def test_least_squares_is_biased_by_albedo_edges():
    """Without a robust loss the boundary's jump pulls the light: the robust loss is what
    lets albedo edges go."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    usable = np.ones(len(radiance), dtype=bool)
    plain, _ = log_shading_fit(radiance, c_matrix, edges, usable, loss="none")
    assert np.abs(plain - light / light[0]).max() > 1e-2


def test_unusable_faces_are_ignored():
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    usable = np.ones(len(radiance), dtype=bool)
    usable[::7] = False
    radiance[~usable] = -1.0                                                   # junk where unusable
    fit, _ = log_shading_fit(radiance, c_matrix, edges, usable)
    np.testing.assert_allclose(fit, light / light[0], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("change, match", [
    (lambda a: {**a, "radiance": a["radiance"][:, :0]}, "radiance must be"),
    (lambda a: {**a, "radiance": a["radiance"][:, :, None]}, "radiance must be"),
    (lambda a: {**a, "usable": a["usable"][:-1]}, "radiance must be"),
    (lambda a: {**a, "edges": a["edges"] + len(a["usable"])}, "edges must be"),
    (lambda a: {**a, "labels": np.zeros(3, dtype=int)}, "labels must be"),
    (lambda a: {**a, "radiance": a["radiance"][:, :1], "initial": np.ones((4, 3))}, "initial must be"),
    (lambda a: {**a, "radiance": a["radiance"][:, :1], "indirect": np.ones((len(a["usable"]), 3))},
     "indirect must be"),
    (lambda a: {**a, "usable": np.zeros_like(a["usable"])}, "needs two usable"),
])
def test_bad_inputs_are_named(change, match):
    c_matrix, edges, labels, albedo, light, radiance = _grid(8)
    args = {"radiance": radiance, "c_matrix": c_matrix, "edges": edges, "usable": np.ones(len(radiance), bool),
            "labels": None}
    with pytest.raises(InputError, match=match):
        log_shading_fit(**change(args))


def test_an_additive_indirect_shading_fixes_the_scale():
    """With a known indirect term the shading is C L + I: the light's DC is no longer a
    gauge, and the fit recovers the light itself."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    extra = 0.3 + 0.2 * np.sin(np.arange(len(radiance)))[:, None] * np.ones(3)
    radiance = albedo * (c_matrix @ light + extra)
    fit, _ = log_shading_fit(radiance, c_matrix, edges, np.ones(len(radiance), bool), indirect=extra)
    np.testing.assert_allclose(fit, light, rtol=1e-3, atol=1e-4)


@pytest.mark.parametrize("scale", [1e-7, 1e-3, 1e4])
def test_with_an_indirect_term_images_of_any_scale_give_the_same_fit_scaled(scale):
    """The indirect term is linear in the radiance, so radiance and term scaled by s scale the
    light by s and leave the regions' albedos: the fit runs in each channel's radiance unit
    (before, images at 1e-5 started a light 10^10 times too bright, whose shape never moved)."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    extra = 0.01 * (1 + 0.5 * np.sin(np.arange(len(radiance))))[:, None] * np.ones(3)
    radiance = albedo * (c_matrix @ light + extra)
    usable = np.ones(len(radiance), bool)
    fit, regions = log_shading_fit(radiance, c_matrix, edges, usable, labels, indirect=extra)
    scaled, scaled_regions = log_shading_fit(radiance * scale, c_matrix, edges, usable, labels,
                                             initial=None, indirect=extra * scale)
    np.testing.assert_allclose(scaled / scale, fit, rtol=1e-6, atol=1e-9 * np.abs(fit).max())
    np.testing.assert_allclose(scaled_regions, regions, rtol=1e-6)
    # a start given in the radiance's unit is scaled with it
    started, _ = log_shading_fit(radiance * scale, c_matrix, edges, usable, labels, initial=fit * scale,
                                 indirect=extra * scale)
    np.testing.assert_allclose(started / scale, fit, rtol=1e-5, atol=1e-8 * np.abs(fit).max())


def test_an_indirect_term_nil_on_every_face_leaves_the_dc_the_gauge():
    """A convex object reflects nothing onto itself: a term that is 0 on every usable face
    fixes no scale, so the fit is the one without it (unit DC); fitted as free, the DC drifted
    towards 0 and a cube's creases were read as albedo edges."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    usable = np.ones(len(radiance), bool)
    start = 2.0 * light           # started off the unit DC: only the gauge brings it back
    nil, _ = log_shading_fit(radiance, c_matrix, edges, usable, labels, initial=start,
                             indirect=np.zeros_like(radiance))
    plain, _ = log_shading_fit(radiance, c_matrix, edges, usable, labels, initial=start)
    np.testing.assert_array_equal(nil, plain)
    np.testing.assert_allclose(nil[0], 1.0)


def test_the_ridge_weighs_the_light_relative_to_its_dc():
    """A faint indirect term (1-1.5 % of the direct) fixes the light's scale only weakly: the
    ridge must weigh the light's shape as it does without that term (relative to the DC),
    not its coefficients themselves, which it would shrink, whole light and all, until the
    faint term bends the shape (measured: 0.12 off in a coefficient at ridge 1e-3)."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    extra = 0.01 * (1 + 0.5 * np.sin(np.arange(len(radiance))))[:, None] * np.ones(3)
    radiance = albedo * (c_matrix @ light + extra)
    usable = np.ones(len(radiance), bool)
    fit, _ = log_shading_fit(radiance, c_matrix, edges, usable, indirect=extra, ridge=1e-3)
    plain, _ = log_shading_fit(radiance, c_matrix, edges, usable, ridge=1e-3)
    np.testing.assert_allclose(fit / fit[0], plain / plain[0], atol=0.03)   # measured: 0.017


def test_a_dc_only_light_has_nothing_to_fit():
    """One column (SH order 0, the gauge) and no regions: the light is the unit DC, with no
    division by the empty system's size."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    with np.errstate(all="raise"):
        fit, region_albedo = log_shading_fit(radiance, c_matrix[:, :1], edges, np.ones(len(radiance), dtype=bool))
    np.testing.assert_array_equal(fit, np.ones((1, 3)))
    assert region_albedo.shape == (0, 3)


def test_faces_no_light_reaches_are_left_out():
    """A face that sees no sky (an all-zero diffuse row, e.g. inside a spout) but has a
    positive radiance (light from the object itself) cannot be explained by the light: it
    is left out instead of turning the normal equations into NaN."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    usable = np.ones(len(radiance), dtype=bool)
    dark = np.arange(5, len(radiance), 37)
    c_matrix[dark] = 0.0
    radiance[dark] = 0.01                                                        # interreflected light
    with np.errstate(all="raise"):
        fit, _ = log_shading_fit(radiance, c_matrix, edges, usable)
    np.testing.assert_allclose(fit, light / light[0], rtol=1e-4, atol=1e-5)


def test_reusing_the_light_block_reaches_the_same_light_with_fewer_blocks(monkeypatch):
    """The light's block of the Gauss-Newton matrix is kept while steps are small
    (:data:`edge_fit.BLOCK_REUSE`): the gradient stays exact, so the fit ends at the light of a
    fit that forms the block at every step, within the stopping tolerance, having formed it
    fewer times. Noisy radiance, so the optimum is not an exact fit."""
    from estimator.light import edge_fit
    c_matrix, edges, labels, albedo, light, radiance = _grid(32, seed=3)
    radiance = radiance * np.exp(0.05 * np.random.default_rng(1).normal(size=radiance.shape))
    usable = np.ones(len(radiance), dtype=bool)
    formed = []
    block = edge_fit._light_block
    monkeypatch.setattr(edge_fit, "_light_block", lambda *a: formed.append(1) or block(*a))
    reused, reused_albedo = log_shading_fit(radiance, c_matrix, edges, usable, labels)
    n_reused = len(formed)
    formed.clear()
    monkeypatch.setattr(edge_fit, "BLOCK_REUSE", 0.0)   # a fresh block at every step
    fresh, fresh_albedo = log_shading_fit(radiance, c_matrix, edges, usable, labels)
    assert n_reused < len(formed)
    shading = np.log(c_matrix @ reused) - np.log(c_matrix @ fresh)
    assert np.abs(shading).max() < 3 * edge_fit.SHADING_TOLERANCE
    np.testing.assert_allclose(reused_albedo, fresh_albedo, rtol=3 * edge_fit.SHADING_TOLERANCE)


@pytest.mark.parametrize("iterations, loss", [(1, "cauchy"), (1, "huber"), (1, "tukey"), (2, "cauchy"),
                                             (30, "cauchy"), (30, "tukey")])
def test_the_regions_albedos_hold_under_the_returned_light(iterations, loss):
    """Where a faint indirect term alone fixes the light's scale, a Gauss-Newton step along
    that scale is long and moves the log shading by log(1 + t) where the linearised region
    albedos moved by -t. Whatever the steps taken, the returned albedos are the regions'
    under the returned light: on noise-free data each face's radiance over its shading is its
    region's albedo (to 1e-3 here; without the final update, 0.6 off after one step, and with
    Tukey's loss, which rejects every row of a region that far off, also after 30)."""
    c_matrix, edges, labels, albedo, light, radiance = _grid()
    extra = 0.01 * (1 + 0.5 * np.sin(np.arange(len(radiance))))[:, None] * np.ones(3)
    radiance = albedo * (c_matrix @ light + extra)
    usable = np.ones(len(radiance), bool)
    fit, region_albedo = log_shading_fit(radiance, c_matrix, edges, usable, labels, initial=4.0 * light,
                                         indirect=extra, iterations=iterations, loss=loss)
    ratio = np.log(radiance / (c_matrix @ fit + extra) / region_albedo[labels])
    for region in range(2):
        np.testing.assert_allclose(np.median(ratio[labels == region], axis=0), 0.0, atol=1e-3)
