"""The cross-check takes its render's own Monte Carlo noise out in quadrature."""
import numpy as np

from reports.evaluate import ImageSet


def test_the_noise_free_disagreement_is_the_bias_whatever_the_noise():
    """Two independent noisy renders of a prediction 2 % too bright: their difference gives
    the noise of their mean, and removing it in quadrature leaves the 2 % (to 3e-3 over
    10^5 pixels), at a noise level 3.5x the bias."""
    rng = np.random.default_rng(0)
    reference = rng.uniform(0.5, 1.5, (200, 500, 3))
    mask = np.ones((200, 500), bool)
    halves = [reference * 1.02 + rng.normal(0.0, 0.1, reference.shape) for _ in range(2)]
    mean = 0.5 * (halves[0] + halves[1])
    noise = 0.5 * np.linalg.norm(halves[0] - halves[1]) / np.linalg.norm(reference)
    view = ImageSet(["v"], [mean], [reference], [mask], align=False, noise=[noise]).metrics()["per_view"][0]
    assert view["relative_l2"] > 0.05
    assert abs(view["relative_l2_noise_free"] - 0.02) < 3e-3
