"""Reading plugin properties the way Mitsuba's own plugins do."""
from __future__ import annotations

from estimator import backend

mi = backend.set_variant()


def texture_property(props, name: str, default: float):
    """The texture ``name`` of ``props``: a nested texture, a float or RGB triple
    (made a constant ``rgb`` texture), or ``default`` grey when absent.

    Raises ValueError naming the property when the value is negative or not a number.
    """
    if name not in props:
        return mi.load_dict({"type": "rgb", "value": [default] * 3})
    value = props[name]
    if isinstance(value, mi.Texture):
        return value
    try:
        rgb = [float(value)] * 3 if isinstance(value, (int, float)) else [float(v) for v in value]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a texture, a float or an RGB triple, got {value!r}") from None
    if len(rgb) != 3 or min(rgb) < 0:
        raise ValueError(f"{name}: expected a non-negative float or RGB triple, got {value!r}")
    return mi.load_dict({"type": "rgb", "value": rgb})
