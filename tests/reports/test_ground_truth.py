"""Which faces a synthetic scene's truth lets a report judge: lit faces (true irradiance above a
share of its 95th percentile) with a non-negligible albedo, among the observed."""
import numpy as np

from reports.ground_truth import GroundTruth, evaluation_mask, lit_faces


def _truth(albedo: np.ndarray) -> GroundTruth:
    return GroundTruth(albedo, np.zeros_like(albedo), np.zeros((1, 3)), {}, {})


def test_faces_the_light_leaves_dark_are_not_lit():
    """Twenty faces at irradiance 1 and a grey light, one at 4 % and one at 6 % of it, one at 0
    (turned to a sky's dark underside): at the default 5 % the 4 % and the 0 faces are unlit. The
    luminance decides, so a face lit in one channel only counts by that channel's weight."""
    irradiance = np.vstack([np.ones((20, 3)), [[0.04] * 3, [0.06] * 3, [0.0] * 3, [0.0, 0.0, 0.9]]])
    lit = lit_faces(irradiance)
    assert lit[:20].all()
    assert lit[20:].tolist() == [False, True, False, True]           # blue 0.9 x 0.0722 = 0.065 > 0.05
    assert lit_faces(irradiance, 0.07)[20:].tolist() == [False, False, False, False]


def test_the_evaluation_mask_is_the_observed_lit_faces_of_non_negligible_albedo():
    irradiance = np.vstack([np.ones((20, 3)), np.zeros((2, 3))])
    albedo = np.full((22, 3), 0.5)
    albedo[3] = 0.001                                                 # below 2 % of the 99th percentile
    observed = np.ones(22, bool)
    observed[5] = False
    mask = evaluation_mask(_truth(albedo), irradiance, observed, "diffuse")
    expected = np.ones(22, bool)
    expected[[3, 5, 20, 21]] = False
    np.testing.assert_array_equal(mask, expected)
    irradiance[20] = 0.06                                             # lit at 5 %, not at 7 %
    assert evaluation_mask(_truth(albedo), irradiance, observed, "diffuse")[20]
    assert not evaluation_mask(_truth(albedo), irradiance, observed, "diffuse", min_light=0.07)[20]
