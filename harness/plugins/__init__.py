"""pseudolight's Mitsuba plugins: the Phong BSDF, the diffuse + mirror BSDF (the
paper's model as a material) and the deterministic direct integrator.

Each plugin is a module-level class on the active variant's ``mi.BSDF`` or
``mi.SamplingIntegrator``, configured from its properties and validated in
``__init__``, as Mitsuba's own Python plugins are. Mitsuba's classes depend on
the variant, so the plugin modules are imported only by :func:`register_all`,
after the variant is chosen (:mod:`estimator.rays.backend`).
"""
from __future__ import annotations

import importlib

from estimator import backend

PHONG = "pseudolight_phong"
DIFFUSE_MIRROR = "pseudolight_diffuse_mirror"
DIRECT = "pseudolight_direct"

# plugin name -> (kind, module, class)
PLUGINS = {
    PHONG: ("bsdf", "phong_bsdf", "PhongBSDF"),
    DIFFUSE_MIRROR: ("bsdf", "diffuse_mirror_bsdf", "DiffuseMirrorBSDF"),
    DIRECT: ("integrator", "direct_integrator", "DirectDeltaIntegrator"),
}
_registered: set[str] = set()


def register_all(variant: str | None = None) -> None:
    """Select the variant (if not yet chosen) and register every plugin with Mitsuba; idempotent."""
    mi = backend.set_variant(variant)
    for name, (kind, module, cls_name) in PLUGINS.items():
        if name in _registered:
            continue
        cls = getattr(importlib.import_module(f"{__name__}.{module}"), cls_name)
        registrar = {"bsdf": mi.register_bsdf, "integrator": mi.register_integrator}[kind]
        registrar(name, lambda props, cls=cls: cls(props))
        _registered.add(name)
