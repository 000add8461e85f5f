import numpy as np

from reports.report import cross_check_images


def test_a_view_without_a_comparable_pixel_is_left_out_of_the_cross_check():
    """Faces about a pixel leave some views no pixel covered by one face alone: those views are
    left out (counted in the note) and the others compared as they are; with none left the set
    has no view, so the report keeps the note alone instead of failing."""
    rng = np.random.default_rng(0)
    images = [rng.uniform(0.1, 1.0, (16, 16, 3)) for _ in range(3)]
    masks = [np.ones((16, 16), bool), np.zeros((16, 16), bool), np.eye(16, 16, dtype=bool)]
    cross = cross_check_images(["a", "b", "c"], images, [1.1 * x for x in images], masks, [0.01, 0.02, 0.03])
    assert cross.names == ["a", "c"] and cross.noise == [0.01, 0.03] and "1 view(s)" in cross.note
    m = cross.metrics()
    assert m["views"] == 2 and all(abs(v["relative_l2"] - 0.1 / 1.1) < 1e-9 for v in m["per_view"])
    none = cross_check_images(["b"], images[1:2], images[1:2], masks[1:2], None)
    assert none.names == [] and none.noise is None and "1 view(s)" in none.note
