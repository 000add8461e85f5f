"""The project's one error type for bad input.

Every error a user can cause (a malformed file, an out-of-range option, data the
method cannot use) is an :class:`InputError` whose message names the file, key,
flag or array. The command line turns it into one line and exit code 2; any
other exception is a bug and keeps its traceback.
"""
from __future__ import annotations


class InputError(ValueError):
    """Bad input; the message names the file, key, flag or array at fault."""
