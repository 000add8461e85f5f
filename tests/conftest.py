"""Shared fixtures: tiny synthetic datasets rendered once per test session."""
from __future__ import annotations

import os

import pytest

from estimator.rays import backend

backend.set_variant()  # picks llvm_ad_rgb here (points DRJIT_LIBLLVM_PATH at libLLVM >= 16)


def _generate(tmp_path_factory, scene: str, **overrides):
    from harness.scene.generate import generate
    from harness.scene.spec import load_spec, resolve_scene

    out = tmp_path_factory.mktemp("datasets") / scene
    spec = load_spec(resolve_scene(scene), profile="tiny", overrides=overrides or None)
    generate(spec, str(out))
    return str(out)


@pytest.fixture(scope="session")
def tiny_earth(tmp_path_factory) -> str:
    """earth-specular at the 'tiny' profile: 1280 faces, 16 views of 96x96, spp 1."""
    return _generate(tmp_path_factory, "earth-specular")


@pytest.fixture(scope="session")
def tiny_sparse(tmp_path_factory) -> str:
    """sparse-colored at the 'tiny' profile: 1280 faces, 16 views of 96x96."""
    return _generate(tmp_path_factory, "sparse-colored")


@pytest.fixture(scope="session")
def tiny_earth_data(tiny_earth):
    from harness.io.dataset import read_dataset
    return read_dataset(tiny_earth)


@pytest.fixture(scope="session")
def tiny_sparse_data(tiny_sparse):
    from harness.io.dataset import read_dataset
    return read_dataset(tiny_sparse)


@pytest.fixture
def repo_root() -> str:
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
