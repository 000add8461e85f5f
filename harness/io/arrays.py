"""NumPy ``.npz`` archives as the project reads them (a run's estimate, a dataset's ground
truth, another method's per-face results): every array, no pickles, and real numbers only.

Each reader names the file and key of what it refuses, with the caller's error class (the
command line turns any :class:`estimator.InputError` into one line and exit code 2)."""
from __future__ import annotations

import zipfile

import numpy as np

from estimator import InputError


def read_npz(path: str, error: type[InputError] = InputError) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` archive at ``path``. A missing, unreadable or truncated file,
    one that holds pickled objects, and a bare ``.npy`` array saved under the name raise
    ``error`` naming the path."""
    try:
        loaded = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise error(f"{path} not found") from None
    except (PermissionError, IsADirectoryError) as exc:
        raise error(f"{path}: cannot read it ({exc.strerror})") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):   # a truncated archive is a BadZipFile; a file
        raise error(f"{path}: unreadable (not a .npz archive)") from None   # of no known kind is read as a pickle
    if not isinstance(loaded, np.lib.npyio.NpzFile):   # np.load of a .npy file gives the array itself
        raise error(f"{path}: unreadable (a single .npy array, not a .npz archive of named arrays)")
    try:
        with loaded as archive:
            return {k: archive[k] for k in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        reason = "holds pickled objects" if "pickle" in str(exc) else "a damaged .npz archive"   # object arrays
        raise error(f"{path}: unreadable ({reason})") from None


def real_array(where: str, value, error: type[InputError] = InputError) -> np.ndarray:
    """``value`` as a float64 array when it holds integers or real floating-point numbers;
    text, booleans, complex numbers and objects raise ``error`` naming ``where`` and the dtype."""
    array = np.asarray(value)
    if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)):
        raise error(f"{where} must hold real numbers, got dtype {array.dtype}")
    return array.astype(np.float64)
