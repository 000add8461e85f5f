"""Registering pseudolight's Python plugins with Mitsuba, once per process."""
from __future__ import annotations

from typing import Callable

from estimator import backend

_registered: set[str] = set()


def register_plugin(kind: str, name: str, make_class: Callable) -> None:
    """Register ``make_class(mi, dr)`` as a Mitsuba ``kind`` ('bsdf' or 'integrator') plugin
    called ``name``; idempotent, and selects the variant first if needed."""
    if name in _registered:
        return
    mi = backend.set_variant()
    import drjit as dr

    cls = make_class(mi, dr)
    registrar = {"bsdf": mi.register_bsdf, "integrator": mi.register_integrator}[kind]
    registrar(name, lambda props: cls(props))
    _registered.add(name)
