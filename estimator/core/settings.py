"""The base of every configuration section.

Each component of the estimator owns one section: a dataclass of its settings, beside the
code that reads them, with its own checks (``check``). :class:`estimator.config.EstimatorConfig`
composes every section by inheritance, so the flat setting names (the wire format of scene
TOML files, suites, ``run.json`` and the command line) stay one namespace, and a section's
reader may be handed the whole configuration.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, fields

from .errors import InputError, is_number, is_whole


@dataclass
class Section:
    """A configuration section: typed, finite fields with defaults, checked on creation."""

    def __new__(cls, *args, **kwargs):
        """Refuse a keyword that names no setting of ``cls`` (:class:`InputError` with the
        nearest names), where the dataclass's own ``__init__`` raises a bare TypeError. Runs
        before it with the same arguments; copies and pickles pass none."""
        known = [f.name for f in fields(cls)]
        unknown = [key for key in kwargs if key not in known]
        if unknown:
            near = sorted({n for key in unknown for n in difflib.get_close_matches(key, known, n=3)})
            verb = "is not a setting" if len(unknown) == 1 else "are not settings"
            raise InputError(f"estimator config: {', '.join(unknown)} {verb} of {cls.__name__}"
                             + (f" (did you mean {', '.join(near)}?)" if near else ""))
        return super().__new__(cls)

    def __post_init__(self):
        self._check_types()
        for cls in reversed(type(self).__mro__):   # every section's own checks, in field order
            own = cls.__dict__.get("check")
            if own is not None:
                for ok, message in own(self):
                    if not ok:
                        raise InputError(f"estimator config: {message}")

    def check(self) -> list[tuple[bool, str]]:
        """(condition, message) pairs; a false condition is refused with its message."""
        return []

    def _check_types(self) -> None:
        """Each field has its default's type: int, float (an int is taken), bool or str (a
        field whose default is None takes None or a string); floats must be finite."""
        for f in fields(self):
            value, default = getattr(self, f.name), f.default
            if default is None:
                ok = value is None or isinstance(value, str)
            elif isinstance(default, bool):
                ok = isinstance(value, bool)
            elif isinstance(default, int):   # numpy's integers too, held as int
                ok = is_whole(value)
                if ok:
                    object.__setattr__(self, f.name, int(value))
            elif isinstance(default, float):
                ok = is_number(value) and math.isfinite(value)
                if ok:
                    object.__setattr__(self, f.name, float(value))
            else:
                ok = isinstance(value, type(default))
            if not ok:
                kind = ("a string or null" if default is None else
                        "a finite number" if isinstance(default, float) else type(default).__name__)
                raise InputError(f"estimator config: {f.name} must be {kind}, got {value!r}")
