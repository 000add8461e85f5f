"""Segmentation on the face graph, per-face quantiles, and region ties."""
import numpy as np

from estimator.core.reductions import group_quantile
from estimator.methods.segmented import BilinearSegmented
from estimator.solvers.segmentation import (
    albedo_features,
    assign_to_regions,
    bridge_faces,
    segment,
    split_modes,
    split_regions,
    two_modes,
)

from .meshes import sphere


def test_group_quantile_matches_numpy():
    rng = np.random.default_rng(0)
    face = rng.integers(0, 7, 80)
    rgb = rng.random((80, 3))
    out = group_quantile(face, rgb, 9, 0.25)
    for f in range(9):
        rows = rgb[face == f]
        if len(rows) == 0:
            assert np.all(np.isnan(out[f]))
        else:
            expected = np.sort(rows, axis=0)[int(np.floor(0.25 * (len(rows) - 1)))]
            np.testing.assert_array_equal(out[f], expected)


def test_features_ignore_dark_channels_but_not_brightness():
    yellow = np.array([[0.75, 0.55, 0.06]])
    noisy = yellow * [1.0, 1.0, 1.5]           # the blue channel of a yellow is noise-sized
    brown = yellow / 10                          # same hue, 10x darker
    d_noise = np.abs(albedo_features(yellow) - albedo_features(noisy)).max()
    d_brown = np.abs(albedo_features(yellow) - albedo_features(brown)).max()
    assert d_noise < 0.05 and d_brown > 2.0


def test_segment_finds_regions_of_one_albedo_apart_and_together():
    mesh = sphere(3)
    c = mesh.centroids
    truth = np.where(c[:, 1] > 0.4, 0, np.where(c[:, 1] < -0.4, 0, np.where(c[:, 0] > 0, 1, 2)))  # caps share albedo
    palette = np.array([[0.7, 0.5, 0.06], [0.07, 0.05, 0.006], [0.1, 0.2, 0.6]])
    rng = np.random.default_rng(1)
    albedo = palette[truth] * np.exp(0.02 * rng.standard_normal((mesh.num_faces, 3)))
    labels, medians = segment(albedo, mesh.face_adjacency, np.ones(mesh.num_faces, bool))
    assert labels.min() >= 0 and labels.max() == 2            # both caps are one region
    for r in range(3):
        assert len(np.unique(truth[labels == r])) == 1
    np.testing.assert_allclose(np.sort(medians[:, 0]), np.sort(palette[:, 0]), rtol=0.05)


def test_complete_merge_joins_regions_apart_only_when_their_albedos_agree():
    mesh = sphere(3)
    band = np.digitize(mesh.centroids[:, 1], [-0.6, -0.2, 0.2, 0.6])   # five bands, none touching the next but one
    red, blue = np.array([0.9, 0.6, 0.3]), np.array([0.1, 0.2, 0.6])
    # bands 0, 2, 4: one red in steps of 6 % (log brightness 0, 0.06, 0.12); bands 1 and 3: two
    # blues 20 % apart (0.2 in log brightness, beyond a uniform region's scatter of 0.08)
    albedo = np.select([band[:, None] == b for b in range(4)],
                       [red * 0.5, blue, red * 0.5 * np.exp(0.06), blue * np.exp(0.2)], red * 0.5 * np.exp(0.12))
    labels, _ = segment(albedo, mesh.face_adjacency, np.ones(mesh.num_faces, bool), merge="complete")
    first = [int(labels[band == b][0]) for b in range(5)]
    assert all(len(np.unique(labels[band == b])) == 1 for b in range(5))
    assert first[1] != first[3]                                  # 20 % apart: two regions
    assert first[0] != first[4]                                  # 12 % apart: no chain through the 6 % step
    assert first[2] in (first[0], first[4])                      # 6 % apart: one region with a neighbour step
    generous, _ = segment(albedo, mesh.face_adjacency, np.ones(mesh.num_faces, bool))   # the mean shift's merge
    assert generous[band == 1][0] == generous[band == 3][0]     # ties the blues; the light fit's split parts them


def test_split_regions_parts_a_region_of_two_albedos_only():
    mesh = sphere(3)
    band = np.digitize(mesh.centroids[:, 1], [-0.6, -0.2, 0.2, 0.6])
    red, blue = np.array([0.9, 0.6, 0.3]), np.array([0.1, 0.2, 0.6])
    albedo = np.where((band % 2 == 0)[:, None], red, blue) * np.where((band == 4)[:, None], 1.25, 1.0)
    rng = np.random.default_rng(4)
    albedo = albedo * np.exp(0.01 * rng.standard_normal(albedo.shape))
    # a generous merge tied the three red bands (the top one 25 % brighter) into region 0
    labels = np.where(band % 2 == 0, 0, 1)
    labels[band == 3] = -1                               # faces outside every region stay outside
    valid = np.ones(mesh.num_faces, bool)
    split = split_regions(labels, albedo, valid, mesh.face_adjacency, 0.12, 0.08)
    assert np.all(split[band == 3] == -1)
    assert len({int(split[band == b][0]) for b in (0, 2, 4)}) == 2     # the brighter band leaves
    assert split[band == 0][0] == split[band == 2][0] and split.max() == 2
    assert all(len(np.unique(split[band == b])) == 1 for b in range(5))
    same = split_regions(np.where(band % 2 == 0, 0, 1), albedo * np.where((band == 4)[:, None], 0.8, 1.0), valid,
                         mesh.face_adjacency, 0.12, 0.08)
    assert same.max() == 1                                # one albedo per region: nothing to split
    nothing = split_regions(np.full(mesh.num_faces, -1), albedo, valid, mesh.face_adjacency, 0.12, 0.08)
    assert np.all(nothing == -1)                          # no region: nothing to part


def test_split_modes_parts_two_close_albedos_tied_as_one():
    mesh = sphere(3)
    band = np.digitize(mesh.centroids[:, 1], [-0.2, 0.2])          # three bands
    green = np.array([0.30, 0.45, 0.27])
    rng = np.random.default_rng(5)
    # bands 0 and 1: two greens 10 % apart in brightness, within segment_threshold (0.12) of each
    # other, tied into region 0 with 1 % noise; band 2 another region of one albedo, 3 % noise
    albedo = green * np.where(band[:, None] == 1, 1.1, 1.0) * np.exp(0.01 * rng.standard_normal((mesh.num_faces, 3)))
    albedo[band == 2] = np.array([0.1, 0.2, 0.6]) * np.exp(0.03 * rng.standard_normal((np.sum(band == 2), 3)))
    labels = np.where(band == 2, 1, 0)
    labels[np.nonzero(band == 2)[0][:5]] = -1                 # faces outside every region stay outside
    valid = np.ones(mesh.num_faces, bool)
    split = split_modes(labels, albedo, valid, mesh.face_adjacency)
    assert np.all(split[labels < 0] == -1)
    assert split.max() == 2 and all(len(np.unique(split[(band == b) & (labels >= 0)])) == 1 for b in range(3))
    assert len({int(split[band == b][0]) for b in (0, 1)}) == 2
    # the same 10 % apart on an invalid half: too few valid faces to show a mode there
    few = valid & ~((band == 1) & (np.arange(mesh.num_faces) % 40 != 0))
    assert split_modes(labels, albedo, few, mesh.face_adjacency).max() == 1


def test_split_modes_parts_each_part_again_and_numbers_regions_by_first_face():
    mesh = sphere(3)
    band = np.digitize(mesh.centroids[:, 1], [-0.3, 0.3])          # three bands, 10 % steps, no noise
    albedo = np.array([0.3, 0.45, 0.27]) * (1.1 ** band)[:, None]
    split = split_modes(np.zeros(mesh.num_faces, dtype=np.int64), albedo, np.ones(mesh.num_faces, bool),
                        mesh.face_adjacency)
    assert split.max() == 2 and all(len(np.unique(split[band == b])) == 1 for b in range(3))
    _, first = np.unique(split, return_index=True)
    assert np.all(np.diff(first) > 0)                              # label k's first face precedes label k + 1's


def test_split_modes_keeps_a_strip_of_blended_faces_with_no_face_inside_it():
    mesh = sphere(3)
    y = mesh.vertices[mesh.faces][:, :, 1]
    strip = (y.min(axis=1) < 0) & (y.max(axis=1) > 0)              # the faces across the equator
    rng = np.random.default_rng(7)
    # a boundary's blends: 20 % darker than the region, a mode of their own by the features
    albedo = np.array([0.4, 0.3, 0.2]) * np.where(strip, 0.8, 1.0)[:, None] \
        * np.exp(0.01 * rng.standard_normal((mesh.num_faces, 3)))
    labels, valid = np.zeros(mesh.num_faces, dtype=np.int64), np.ones(mesh.num_faces, bool)
    features = albedo_features(albedo)
    assert strip.sum() >= 20 and two_modes(features, 10) is not None
    assert split_modes(labels, albedo, valid, mesh.face_adjacency).max() == 0
    band = np.abs(mesh.centroids[:, 1]) < 0.35                       # a band some faces wide has an inside
    wide = np.array([0.4, 0.3, 0.2]) * np.where(band, 0.8, 1.0)[:, None] \
        * np.exp(0.01 * rng.standard_normal((mesh.num_faces, 3)))
    split = split_modes(labels, wide, valid, mesh.face_adjacency)
    assert split.max() == 1 and len(np.unique(split[band])) == 1 and split[band][0] != split[~band][0]


def test_two_modes_keeps_one_albedo_spread_smoothly_or_with_heavy_tails():
    rng = np.random.default_rng(6)
    n = 2000
    gaussian = rng.standard_normal((n, 4)) * [0.05, 0.01, 0.01, 0.01]
    smooth = np.column_stack([np.linspace(-0.3, 0.3, n), np.zeros((n, 3))])          # a shading misfit's ramp
    heavy = rng.standard_cauchy((n, 4)) * 0.02
    for features in (gaussian, smooth, heavy):
        assert two_modes(features, 10) is None
    apart = gaussian.copy()
    apart[: n // 4, 0] += 6 * 0.05                                 # a quarter 6 standard deviations brighter
    side = two_modes(apart, 10)
    assert side is not None
    brighter = side if np.mean(side[: n // 4]) > 0.5 else ~side
    # 2-means parts them midway, 3 standard deviations from each: 0.13 % of either side cross
    assert np.mean(brighter[: n // 4]) > 0.99 and np.mean(brighter[n // 4:]) < 0.01
    closer = gaussian.copy()
    closer[: n // 4, 0] += 4 * 0.05                                # 4 standard deviations: under 2 x 2.576
    assert two_modes(closer, 10) is None
    small = gaussian.copy()
    small[:9, 0] += 1.0                                            # 9 faces far off: below min_size
    assert two_modes(small, 10) is None


def test_textured_faces_stay_out_of_uniform_regions():
    mesh = sphere(3)
    rng = np.random.default_rng(2)
    albedo = rng.uniform(0.05, 0.9, (mesh.num_faces, 3))
    labels, _ = segment(albedo, mesh.face_adjacency, np.ones(mesh.num_faces, bool))
    assert np.mean(labels >= 0) < 0.05


def test_assigned_groups_keep_region_ids_and_centre_on_seen_finite_faces():
    # faces on a path: region 0 (two faces at 0.2, four seen with no usable albedo), a free
    # face at 0.21, region 1 entirely unseen, region 2 at an orange, three textured faces
    grey, nan = [0.2, 0.2, 0.2], [np.nan] * 3
    albedo = np.array([grey, grey, nan, nan, nan, nan, [0.21] * 3, nan, nan, [0.6, 0.3, 0.1], [0.6, 0.3, 0.1],
                       [0.02, 0.3, 0.9], [0.9, 0.05, 0.4], [0.5, 0.9, 0.05]])
    labels = np.array([0, 0, 0, 0, 0, 0, -1, 1, 1, 2, 2, -1, -1, -1])
    seen = np.ones(14, bool)
    seen[[7, 8]] = False
    edges = np.column_stack([np.arange(13), np.arange(1, 14)])
    group = assign_to_regions(labels, albedo, seen, edges, reach=0.2)
    np.testing.assert_array_equal(group[:7], 0)          # the centre is 0.2, not the stand-in 1 of the NaN faces
    np.testing.assert_array_equal(group[[9, 10]], 2)     # region 2 keeps its id though region 1 has no seen face
    assert np.all(group[11:] >= 3) and len(set(group[11:])) == 3   # textured faces: groups of their own, past R
    np.testing.assert_array_equal(group[[7, 8]], 0)      # unseen: group 0, no rows


def test_region_ties_follow_the_boundary_ratio():
    # two regions; the second's albedo is wrong by 2x (a light estimate it alone constrains),
    # its boundary says the ratio is 0.25: the tie restores it
    mesh = sphere(2)
    group = (mesh.centroids[:, 1] < 0).astype(np.int64)
    true = np.array([[0.8, 0.6, 0.4], [0.2, 0.15, 0.1]])
    albedo = true[group]
    start = true * np.array([[1.0], [2.0]])
    tied = BilinearSegmented._tie_regions(start, albedo, np.ones(mesh.num_faces, bool), group,
                                          mesh.face_adjacency, 2)
    np.testing.assert_allclose(tied[1] / tied[0], true[1] / true[0], rtol=0.01)   # the weak anchor: 0.2 % off


def _path(levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grey albedos (n, 3) at log brightness ``levels`` (n,) on a path graph's edges (n - 1, 2)."""
    n = len(levels)
    return 0.5 * np.exp(levels)[:, None] * np.ones(3), np.column_stack([np.arange(n - 1), np.arange(1, n)])


def test_a_blend_on_a_boundary_is_a_bridge_and_joins_neither_side():
    """Two regions 0.22 apart in log brightness, one face between them at the blend of both
    (0.11 from each, within the 0.12 threshold of both): joined, it chains the regions into one
    component whose spread (0.11) is not uniform, so no region is found; left out as a bridge,
    both regions are found whole and the blend in neither. A sharp boundary has no bridge."""
    levels = np.concatenate([np.zeros(20), [-0.11], np.full(20, -0.22)])
    albedo, edges = _path(levels)
    valid = np.ones(len(levels), bool)
    chained, _ = segment(albedo, edges, valid, 0.12, 0.08, merge="complete")
    assert np.all(chained == -1)
    parted, _ = segment(albedo, edges, valid, 0.12, 0.08, merge="complete", bridges=True)
    assert parted[20] == -1 and parted.max() == 1
    assert len(np.unique(parted[:20])) == 1 and len(np.unique(parted[21:])) == 1 and parted[0] != parted[40]
    feat = albedo_features(albedo)
    close = edges[np.max(np.abs(feat[edges[:, 0]] - feat[edges[:, 1]]), axis=1) < 0.12]
    np.testing.assert_array_equal(np.nonzero(bridge_faces(feat, close, 0.12))[0], [20])
    sharp, sharp_edges = _path(np.concatenate([np.zeros(20), np.full(20, -0.22)]))
    feat = albedo_features(sharp)
    close = sharp_edges[np.max(np.abs(feat[sharp_edges[:, 0]] - feat[sharp_edges[:, 1]]), axis=1) < 0.12]
    assert not bridge_faces(feat, close, 0.12).any()


def test_bridges_leave_noisy_uniform_regions_whole():
    """On a sphere of two albedos 0.2 apart in log brightness with 1 % noise and a band of
    blended faces along their boundary (halfway, within the 0.12 threshold of both sides;
    complete linkage, which keeps the two sides apart), the band chains the two into one
    component too wide to be uniform; with bridges left out the bridges lie on the band or
    touch it (noise far below the threshold makes none elsewhere) and both regions are found."""
    mesh = sphere(4)
    y = mesh.centroids[:, 1]
    level = np.where(y > 0, 0.0, -0.2)
    band = np.abs(y) < 0.02
    level[band] = -0.1
    rng = np.random.default_rng(5)
    albedo = 0.5 * np.exp(level + 0.01 * rng.standard_normal(mesh.num_faces))[:, None] * np.ones(3)
    valid = np.ones(mesh.num_faces, bool)
    chained, _ = segment(albedo, mesh.face_adjacency, valid, merge="complete")
    assert np.mean(chained >= 0) < 0.05
    labels, _ = segment(albedo, mesh.face_adjacency, valid, merge="complete", bridges=True)
    assert labels.max() == 1 and np.mean(labels[~band] >= 0) > 0.99
    assert len(np.unique(labels[(y > 0) & ~band & (labels >= 0)])) == 1
    feat = albedo_features(albedo)
    a, b = mesh.face_adjacency.T
    close = mesh.face_adjacency[np.max(np.abs(feat[a] - feat[b]), axis=1) < 0.12]
    bridges = bridge_faces(feat, close, 0.12)
    near = band.copy()                                   # the band and the faces that touch it
    near[a[band[b]]] = near[b[band[a]]] = True
    assert bridges[band].mean() > 0.5 and not bridges[~near].any()


def test_a_component_whose_parts_agree_is_not_cut():
    """Noise near the threshold inside one region: every other face has close neighbours 0.14
    apart (a bridge by :func:`bridge_faces`), but cut there the region falls into pieces too
    small to be parts (and of one albedo), so nothing is cut and the region stays whole."""
    levels = np.tile([0.0, 0.07, 0.0, -0.07], 10)
    albedo, edges = _path(levels)
    feat = albedo_features(albedo)
    assert bridge_faces(feat, edges, 0.12)[2::2].all()                     # all but the path's end
    labels, _ = segment(albedo, edges, np.ones(len(levels), bool), 0.12, 0.08, merge="complete", bridges=True)
    assert np.all(labels == 0)


def test_only_the_component_of_two_albedos_is_cut_among_several_with_invalid_faces():
    """Two components apart (a gap of 0.5) and an invalid face: the first chains two albedos
    through a blend and is cut; the second, noisy near the threshold, keeps its bridges; the
    invalid face stays outside every region."""
    chained = np.concatenate([np.zeros(20), [-0.11], np.full(20, -0.22)])
    noisy = -0.72 + np.tile([0.0, 0.07, 0.0, -0.07], 5)
    levels = np.concatenate([chained, [5.0], noisy])
    albedo, edges = _path(levels)
    valid = np.ones(len(levels), bool)
    valid[41] = False
    labels, _ = segment(albedo, edges, valid, 0.12, 0.08, merge="complete", bridges=True)
    assert labels[20] == -1 and labels[41] == -1
    assert len({int(labels[0]), int(labels[40]), int(labels[42])}) == 3
    assert np.all(labels[:20] == labels[0]) and np.all(labels[21:41] == labels[40])
    assert np.all(labels[42:] == labels[42])


def test_faces_blend_albedos_in_clusters_of_several_or_when_smaller_than_pixels():
    """:attr:`Prepared.blends_albedos` turns the bridge rule on for clustered problems whose
    clusters hold several faces and for faces observed through their pixel centres only."""
    from types import SimpleNamespace

    from estimator.pipeline.prepared import Prepared
    blends = Prepared.blends_albedos.fget
    resolved, unresolved = SimpleNamespace(unresolved=None), SimpleNamespace(unresolved=np.ones(4, bool))
    assert not blends(SimpleNamespace(merged_faces=False, all_obs=resolved))
    assert blends(SimpleNamespace(merged_faces=True, all_obs=resolved))
    assert blends(SimpleNamespace(merged_faces=False, all_obs=unresolved))


def test_a_small_region_chained_to_a_large_one_is_parted():
    """30 faces of one albedo, a blend, 10 faces of another 0.22 apart: the chained component's
    median spread is 0 (uniform, so a spread test alone would keep the two tied), but cut at
    the blend it leaves two parts of different albedos: two regions."""
    albedo, edges = _path(np.concatenate([np.zeros(30), [-0.11], np.full(10, -0.22)]))
    valid = np.ones(41, bool)
    tied, _ = segment(albedo, edges, valid, 0.12, 0.08, merge="complete")
    assert np.all(tied[:30] == tied[0]) and np.all(tied[31:] == tied[0]) and tied[0] >= 0
    labels, _ = segment(albedo, edges, valid, 0.12, 0.08, merge="complete", bridges=True)
    assert labels[30] == -1 and labels[0] != labels[40] and labels.max() == 1
    assert np.all(labels[:30] == labels[0]) and np.all(labels[31:] == labels[40])
