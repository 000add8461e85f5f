"""Suite TOML files: scenes with sweep axes, methods with parameters, seeds; expanded into
dataset jobs and run jobs.

A suite::

    name = "smoke"
    profile = "tiny"                      # optional, for every scene
    seeds = [0, 1]                        # optional: each dataset once per seed (spec seed)
    scenes = ["earth-specular", { scene = "sparse-colored", sweep = { "cameras.count" = [6, 12] } }]
    methods = ["bilinear-clustered", { method = "bilinear-clustered", label = "order-4",
                                       params = { sh_order = 4 } }]

A sweep axis is any dotted scene-spec key (views, resolution, Phong exponent, probe,
rotation, the ``faults.*`` keys); the points of a scene are the Cartesian product of its
axes. Method ``params`` are ``EstimatorConfig`` fields.
"""
from __future__ import annotations

import dataclasses
import itertools
import json
import os

from estimator import REGISTRY, EstimatorConfig
from harness.scene.spec import (
    SCENES_DIR,
    SpecError,
    load_spec,
    read_toml,
    resolve_scene,
)

SUITE_KEYS = {"name", "scenes", "methods", "profile", "seeds"}


@dataclasses.dataclass(frozen=True)
class DatasetJob:
    """One dataset to generate: a scene spec with overrides (sweep point and seed)."""

    scene: str             # the scene's name as listed in the suite
    spec_path: str
    profile: str | None
    overrides: dict        # dotted keys -> values (sweep point and seed)
    axes: dict             # the sweep point alone (axis -> value), for the plots
    seed: int | None


@dataclasses.dataclass(frozen=True)
class MethodEntry:
    label: str
    method: str
    params: dict


def _table_or_name(where: str, entry, name_key: str) -> dict:
    if isinstance(entry, str):
        return {name_key: entry}
    if not isinstance(entry, dict):
        raise SpecError(f"{where} must be a name or a table, got {entry!r}")
    return dict(entry)


def load_suite(path_or_name: str, profile: str | None = None) -> dict:  # noqa: C901  (one check per key)
    """Read and validate a suite (path, or a name under scenes/suites/); ``profile``, when
    given, replaces every scene's profile. Returns a dict with
    ``name``, ``path``, ``datasets`` (list of DatasetJob) and ``methods`` (list of MethodEntry)."""
    path = path_or_name
    if not os.path.isfile(path):
        path = os.path.join(SCENES_DIR, "suites", f"{path_or_name}.toml")
    if not os.path.isfile(path):
        raise SpecError(f"suite not found: {path_or_name}")
    raw = read_toml(path, "suite")
    unknown = sorted(set(raw) - SUITE_KEYS)
    if unknown:
        raise SpecError(
            f"{path}: unknown suite key(s): {', '.join(unknown)} (allowed: {', '.join(sorted(SUITE_KEYS))})"
        )
    for key in ("scenes", "methods"):
        if not isinstance(raw.get(key), list) or not raw[key]:
            raise SpecError(f"{path}: suite.{key} must be a non-empty list")
    if not isinstance(raw.get("name", ""), str):
        raise SpecError(f"{path}: suite.name must be a string, got {raw['name']!r}")
    forced, profile = profile, raw.get("profile")
    if profile is not None and not isinstance(profile, str):
        raise SpecError(f"{path}: suite.profile must be a string")
    seeds = raw.get("seeds", [None])
    if not isinstance(seeds, list) or not seeds or not all(
            s is None or (isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 2 ** 31) for s in seeds):
        raise SpecError(f"{path}: suite.seeds must be a non-empty list of integers in [0, 2^31)")
    if len(set(seeds)) != len(seeds):
        raise SpecError(f"{path}: suite.seeds must be distinct, got {seeds}")
    methods = []
    for i, entry in enumerate(raw["methods"]):
        where = f"{path}: methods[{i}]"
        m = _table_or_name(where, entry, "method")
        bad = sorted(set(m) - {"method", "label", "params"})
        if bad:
            raise SpecError(f"{where}: unknown key(s) {', '.join(bad)}")
        if m.get("method") not in REGISTRY:
            raise SpecError(f"{where}: {m.get('method')!r} is not a registered method ({', '.join(REGISTRY)})")
        params = m.get("params", {})
        if not isinstance(params, dict):
            raise SpecError(f"{where}: params must be a table")
        known = {f.name for f in dataclasses.fields(EstimatorConfig)}
        unknown = sorted(set(params) - known)
        if unknown:
            raise SpecError(f"{where}: params: unknown estimator parameter(s) {', '.join(unknown)}")
        try:
            EstimatorConfig(**params)
        except ValueError as exc:
            raise SpecError(f"{where}: params: {exc}") from None
        label = m.get("label", m["method"])
        if not isinstance(label, str) or not label.strip():
            raise SpecError(f"{where}: label must be a non-empty string, got {label!r}")
        methods.append(MethodEntry(label, m["method"], params))
    labels = [m.label for m in methods]
    if len(set(labels)) != len(labels):
        raise SpecError(f"{path}: method labels must be distinct, got {labels} (give each a 'label')")
    datasets = []
    for i, entry in enumerate(raw["scenes"]):
        where = f"{path}: scenes[{i}]"
        s = _table_or_name(where, entry, "scene")
        bad = sorted(set(s) - {"scene", "sweep", "set", "profile"})
        if bad:
            raise SpecError(f"{where}: unknown key(s) {', '.join(bad)}")
        if not isinstance(s.get("scene"), str) or not s["scene"]:
            raise SpecError(f"{where}: scene must be a scene name or a spec path, got {s.get('scene')!r}")
        local = os.path.join(os.path.dirname(os.path.abspath(path)), s["scene"])
        try:
            spec_path = local if os.path.isfile(local) else resolve_scene(s["scene"])
        except SpecError as exc:
            raise SpecError(f"{where}: {exc}") from None
        sweep, fixed = s.get("sweep", {}), s.get("set", {})
        if not isinstance(sweep, dict) or not all(isinstance(v, list) and v for v in sweep.values()):
            raise SpecError(f"{where}: sweep must map dotted spec keys to non-empty lists of values")
        if not isinstance(fixed, dict):
            raise SpecError(f"{where}: set must map dotted spec keys to values")
        both = sorted(set(sweep) & set(fixed))
        if both:
            raise SpecError(f"{where}: {', '.join(both)} both swept and set: the sweep's values would replace the "
                            "set one; keep it in one of them")
        axes = sorted(sweep)
        for axis in axes:
            if len({json.dumps(v, sort_keys=True) for v in sweep[axis]}) != len(sweep[axis]):
                raise SpecError(f"{where}: sweep {axis!r} repeats a value: {sweep[axis]}")
        for point in itertools.product(*(sweep[a] for a in axes)):
            values = dict(zip(axes, point))
            for seed in seeds:
                overrides = {**fixed, **values, **({} if seed is None else {"seed": seed})}
                job = DatasetJob(s["scene"], spec_path, forced or s.get("profile", profile), overrides, values, seed)
                try:
                    load_spec(job.spec_path, job.profile, job.overrides)   # every point must be a valid spec
                except SpecError as exc:
                    raise SpecError(f"{where}: {values or 'its scene'}: {exc}") from None
                datasets.append(job)
    return {"name": raw.get("name", os.path.splitext(os.path.basename(path))[0]), "path": os.path.abspath(path),
            "datasets": datasets, "methods": methods}
