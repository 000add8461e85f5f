"""The project's one error type for bad input.

Every error a user can cause (a malformed file, an out-of-range option, data the
method cannot use) is an :class:`InputError` whose message names the file, key,
flag or array. The command line turns it into one line and exit code 2; any
other exception is a bug and keeps its traceback.
"""
from __future__ import annotations

import numbers

import numpy as np


class InputError(ValueError):
    """Bad input; the message names the file, key, flag or array at fault."""


def is_number(value) -> bool:
    """Whether ``value`` is a real number: Python's or numpy's, not a bool (True is no 1.0
    here), not text."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_whole(value) -> bool:
    """Whether ``value`` is an integer (Python's or numpy's), not a bool and not a float."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
