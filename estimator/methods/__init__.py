"""The methods, one file each, registered by name on import (:mod:`estimator.methods.base`)."""
from . import (  # noqa: F401  (each module registers its method)
    clustered,
    known_illumination,
    median_color,
    mitsuba_ad,
    per_face,
    retinex_segmented,
    segmented,
)
from .base import REGISTRY, Method, get_method, register_method

__all__ = ["REGISTRY", "Method", "get_method", "register_method"]
