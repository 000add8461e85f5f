"""JSON files as the project writes and reads them: strict JSON (no NaN tokens), and
errors that name the file."""
from __future__ import annotations

import json
import math

import numpy as np

from estimator import InputError


def strict(value, where: str = "", reasons: dict | None = None):
    """A copy of ``value`` that is valid JSON: numpy scalars and arrays become Python
    values, and every non-finite float becomes None, its dotted path and value noted
    in ``reasons`` (when given)."""
    if isinstance(value, dict):
        return {k: strict(v, f"{where}.{k}" if where else str(k), reasons) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict(v, f"{where}[{i}]", reasons) for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        return strict(value.tolist(), where, reasons)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        if reasons is not None:
            reasons[where] = f"not a finite number ({value})"
        return None
    return value


def dump_json(path: str, value: dict) -> None:
    """Write ``value`` as strict JSON; non-finite numbers are written as null and listed
    with their reason under the top-level key ``null_reasons``."""
    reasons: dict = {}
    out = strict(value, "", reasons)
    if reasons:
        out["null_reasons"] = {**out.get("null_reasons", {}), **reasons}
    with open(path, "w") as f:
        json.dump(out, f, indent=1, allow_nan=False)


def load_json(path: str, what: str, error: type[InputError] = InputError) -> dict:
    """A JSON object from ``path``. A missing, unreadable or malformed file, or a top level
    that is not an object, raise ``error`` naming the file and ``what`` it is. NaN and
    Infinity tokens are read (Python writes them): the readers validate values where
    they matter and name the key."""
    try:
        with open(path) as f:
            value = json.load(f)
    except FileNotFoundError:
        raise error(f"{path} not found ({what})") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise error(f"{path} is not valid JSON ({what}): {exc}") from None
    except RecursionError:   # Python's parser recurses once per nesting level
        raise error(f"{path} cannot be read ({what}): its JSON is nested too deeply") from None
    except OSError as exc:
        raise error(f"cannot read {path} ({what}): {exc.strerror or exc}") from None
    if not isinstance(value, dict):
        raise error(f"{path} must hold a JSON object ({what}), got {type(value).__name__}")
    return value
