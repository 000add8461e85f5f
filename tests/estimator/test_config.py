"""The configuration: its flat names (the wire format) pinned, each owned by one section beside
its code, and every bad value refused with the setting named."""
from __future__ import annotations

import copy
import dataclasses
import pickle
from dataclasses import fields

import pytest

from estimator import EstimatorConfig, InputError
from estimator.config import SECTIONS

# the wire format of scene TOML files, suites, run.json and the command line: a change here is
# a change of format, made on purpose
WIRE_NAMES = (
    "sh_order", "diffuse_light", "defilter_order", "phong_exponent", "specular_model", "variant",
    "blas_threads",
    "directions", "min_cos_view", "min_pixels", "pure_pixels", "min_coverage", "negative_tolerance",
    "subpixel_samples", "dense_rows", "light_faces", "iterations", "tol", "components", "lm_damping_start",
    "lm_damping_raise",
    "lm_damping_lower", "lm_damping_max", "robust_loss", "robust_rounds", "glint_ratio", "segment_threshold",
    "uniform_spread", "albedo_prior", "retinex_quantile", "retinex_ridge", "retinex_iterations", "retinex_max_edges",
    "sun_min_gain", "max_suns", "coat_correction", "coat_per_region", "coat_ior", "coat_order", "coat_lobe",
    "coat_level", "coat_min_share", "coat_max_negative",
    "reflected_light", "reflected_regions", "reflected_sun_max_ratio",
    "reflected_sun_max_angle", "reflected_lobe", "interreflection",
    "min_brightness", "bandwidth", "split_bandwidth", "min_cluster_fraction", "recluster_rounds",
    "recluster_min_shading", "recluster_shading_percentile", "diffuse_quantile", "segment_min_shading",
    "tie_regions", "relabel_rounds", "relabel_free_ratio", "retinex_min_uniform_share",
    "region_max_deviation", "region_max_drift", "ad_albedo", "ad_time_budget", "ad_max_steps", "ad_resolution",
    "ad_spp", "ad_learning_rate", "ad_envmap_height", "ad_specular", "ad_texture_size", "ad_tv_weight",
    "pose_rounds", "pose_folds", "auto_pose",
    "view_gains",
)


def test_the_flat_names_and_their_order_are_the_wire_format():
    assert tuple(f.name for f in fields(EstimatorConfig)) == WIRE_NAMES
    assert tuple(EstimatorConfig().to_dict()) == WIRE_NAMES


def test_every_setting_has_one_section_and_one_default():
    owners = {}
    for section in SECTIONS:
        for name in section.__dict__.get("__annotations__", {}):
            assert name not in owners, f"{name} is declared by {owners[name]} and {section.__name__}"
            owners[name] = section.__name__
    assert set(owners) == set(WIRE_NAMES)
    config = EstimatorConfig()
    for section in SECTIONS:   # a section alone builds with the same defaults
        alone = section()
        for f in fields(alone):
            assert getattr(alone, f.name) == getattr(config, f.name)


@pytest.mark.parametrize("settings, named", [
    ({"sh_order": 31}, "sh_order"),
    ({"defilter_order": 5, "sh_order": 3, "diffuse_light": "defiltered"}, "defilter_order"),
    ({"light_faces": 120}, r"light_faces must be at least the light's \(sh_order \+ 1\)\^2 = 121"),
    ({"retinex_max_edges": 8, "sh_order": 2}, r"retinex_max_edges must be at least .* = 9"),
    ({"tol": float("nan")}, "tol"),
    ({"variant": 3}, "variant"),
    ({"blas_threads": -1}, "blas_threads"),
    ({"pure_pixels": 1}, "pure_pixels"),
    ({"subpixel_samples": 0}, "subpixel_samples"),
    ({"robust_loss": "l1"}, "robust_loss"),
    ({"coat_ior": 1.0}, "coat_ior"),
    ({"pose_folds": 1}, "pose_folds"),
    ({"ad_spp": 0}, "ad_spp"),
    ({"diffuse_light": "defiltered", "phong_exponent": 1e-9}, "defilter_order"),
])
def test_a_bad_value_is_refused_naming_the_setting(settings, named):
    with pytest.raises(InputError, match=named):
        EstimatorConfig(**settings)


def test_an_unknown_setting_is_refused_with_the_nearest_names():
    """A misspelt keyword is an InputError naming it and the settings it is near (the
    dataclass alone raises a bare TypeError); copies, pickles and replace() still build."""
    with pytest.raises(InputError, match=r"sh_ordr is not a setting of EstimatorConfig \(did you mean sh_order\?\)"):
        EstimatorConfig(sh_ordr=4)
    with pytest.raises(InputError, match="foo, bar are not settings"):
        EstimatorConfig(foo=1, bar=2)
    config = EstimatorConfig(sh_order=4)
    assert copy.deepcopy(config) == config == pickle.loads(pickle.dumps(config))
    assert dataclasses.replace(config, sh_order=6).sh_order == 6


def test_low_orders_build_with_the_other_defaults():
    """sh_order 0 and 1 with every other setting at its default: defilter_order (2) is read by
    the 'defiltered' light alone, so it does not refuse them; light_faces and retinex_max_edges
    take any count from the light's coefficients up."""
    for order in (0, 1):
        assert EstimatorConfig(sh_order=order).sh_order == order
    assert EstimatorConfig(sh_order=2, light_faces=9, retinex_max_edges=9).light_faces == 9


def test_an_int_is_taken_for_a_float_and_stored_as_float():
    config = EstimatorConfig(phong_exponent=20)
    assert config.phong_exponent == 20.0 and isinstance(config.phong_exponent, float)


def test_the_docs_table_of_settings_matches_the_code():
    """docs/estimator.md lists every setting with its default and the section (and file)
    that owns it: a setting added, renamed, moved or given another default shows here."""
    import inspect
    import os
    import re

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, "docs", "estimator.md"), encoding="utf-8") as f:
        rows = re.findall(r"^\| `(\w+)` \| `([^`]*)` \| `(\w+)` \(`([^`]+)`\) \|$", f.read(), re.MULTILINE)
    documented = {name: (default, section, path) for name, default, section, path in rows}
    expected = {}
    for section in SECTIONS:
        path = os.path.relpath(inspect.getsourcefile(section), root).replace(os.sep, "/")
        alone = section()
        for name in section.__dict__.get("__annotations__", {}):
            expected[name] = (repr(getattr(alone, name)), section.__name__, path)
    assert len(rows) == len(documented), "a setting is listed twice"
    assert documented == expected
