"""The one place that chooses the Mitsuba/Dr.Jit variant.

Dr.Jit's CPU backend (``llvm_ad_rgb``) needs libLLVM >= 16: with an older
libLLVM, drjit 1.5 aborts the whole process (``LLVM ERROR: Cannot select ...
fminimum``), which no Python exception can catch. :func:`set_variant` therefore
points ``DRJIT_LIBLLVM_PATH`` at a libLLVM >= 16 *before* Dr.Jit starts, and
refuses with :class:`BackendError` (naming the fix) when none exists.
"""
from __future__ import annotations

import ctypes
import glob
import os
import re
from dataclasses import dataclass

from ..core.errors import InputError
from ..core.interrupt import signals_deferred
from ..core.settings import Section

MIN_LLVM = 16
VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb")
_LLVM_GLOBS = (
    "/usr/lib/*-linux-gnu/libLLVM.so.*",
    "/usr/lib/*-linux-gnu/libLLVM-*.so",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
)
_chosen: str | None = None


@dataclass
class BackendConfig(Section):
    """Where the work runs: the Mitsuba variant of the ray queries and the threads of the
    estimate's dense linear algebra.

    Attributes
    ----------
    variant : 'cuda_ad_rgb' or 'llvm_ad_rgb'; None: CUDA when a GPU is usable, else LLVM
        (:func:`resolve_variant`, which also reads ``$PSEUDOLIGHT_VARIANT``).
    blas_threads : BLAS threads during an estimate (:mod:`estimator.core.blas`): 1, because its
        products are small and a second thread waits on the first when other work shares the
        cores; more for a large problem on idle cores; 0 leaves the process's own setting.
        Estimates running at once in one process (threads) share the first one's count.
    """

    variant: str | None = None
    blas_threads: int = 1

    def check(self):
        return [(self.variant in (None, "", "auto", *VARIANTS),
                 f"variant must be one of {', '.join(VARIANTS)} or 'auto', got {self.variant!r}"),
                (self.blas_threads >= 0, f"blas_threads must be >= 0 (0: the process's setting), "
                                         f"got {self.blas_threads}")]


class BackendError(InputError):
    """No usable Dr.Jit backend for the requested variant."""


def llvm_major_version(path: str) -> int | None:
    """Major version of a libLLVM shared library, read from its file name."""
    match = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(os.path.realpath(path)))
    if match is None:
        match = re.search(r"llvm-(\d+)", path)
    return int(match.group(1)) if match else None


def find_libllvm(min_version: int = MIN_LLVM) -> str | None:
    """Newest libLLVM shared library on this machine with major >= ``min_version``."""
    found = []
    for pattern in _LLVM_GLOBS:
        for path in glob.glob(pattern):
            version = llvm_major_version(path)
            if version is not None and version >= min_version and os.path.isfile(path):
                found.append((version, path))
    return max(found)[1] if found else None


def cuda_device_count() -> int:
    """CUDA devices the driver reports (0 when the driver does not load or fails)."""
    try:
        lib = ctypes.CDLL("libcuda.so.1")
    except OSError:
        return 0
    count = ctypes.c_int(0)
    if lib.cuInit(0) != 0 or lib.cuDeviceGetCount(ctypes.byref(count)) != 0:
        return 0
    return int(count.value)


def cuda_available() -> bool:
    """True when the CUDA driver loads and reports at least one device."""
    return cuda_device_count() > 0


def _prepare_llvm() -> None:
    path = os.environ.get("DRJIT_LIBLLVM_PATH")
    if path:
        version = llvm_major_version(path)
        if not os.path.isfile(path):
            raise BackendError(f"DRJIT_LIBLLVM_PATH={path} does not exist.")
        if version is not None and version < MIN_LLVM:
            raise BackendError(
                f"DRJIT_LIBLLVM_PATH={path} is libLLVM {version}; Dr.Jit 1.5 needs >= {MIN_LLVM}. "
                "Install Debian's libllvm19 (apt-get install libllvm19) and point DRJIT_LIBLLVM_PATH at it.")
        return
    path = find_libllvm()
    if path is None:
        raise BackendError(
            f"No libLLVM >= {MIN_LLVM} found: the llvm_ad_rgb variant would abort the process. "
            "Install one (as root: apt-get update && apt-get install libllvm19, which "
            "scripts/setup.sh does) or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16.")
    # Dr.Jit loads libLLVM when the LLVM backend is first used, not at import,
    # so setting the variable here takes effect even if drjit is already imported.
    os.environ["DRJIT_LIBLLVM_PATH"] = path


def resolve_variant(variant: str | None = None) -> str:
    """The variant to use: the argument, else ``$PSEUDOLIGHT_VARIANT``, else auto.

    Auto picks ``cuda_ad_rgb`` when a CUDA GPU is usable, else ``llvm_ad_rgb``.
    """
    source = "variant"
    if not variant and os.environ.get("PSEUDOLIGHT_VARIANT"):
        variant, source = os.environ["PSEUDOLIGHT_VARIANT"], "$PSEUDOLIGHT_VARIANT"
    if variant in (None, "", "auto"):
        return "cuda_ad_rgb" if cuda_available() else "llvm_ad_rgb"
    if variant not in VARIANTS:
        raise BackendError(f"unknown {source} {variant!r}; choose one of {', '.join(VARIANTS)} or 'auto'")
    return variant


def set_variant(variant: str | None = None):
    """Select the Mitsuba variant once per process and return the ``mitsuba`` module.

    Parameters
    ----------
    variant : {'cuda_ad_rgb', 'llvm_ad_rgb', 'auto', None}
        ``None`` reads ``$PSEUDOLIGHT_VARIANT`` and falls back to auto.
    """
    global _chosen
    resolved = resolve_variant(variant)
    if _chosen is not None:
        if variant not in (None, "auto") and resolved != _chosen:
            raise BackendError(f"variant {_chosen} is already active in this process; cannot switch to {resolved}")
        import mitsuba as mi
        return mi
    if resolved == "cuda_ad_rgb" and not cuda_available():
        raise BackendError("variant cuda_ad_rgb asked for, but no CUDA GPU is usable here; use llvm_ad_rgb")
    if resolved.startswith("llvm"):
        _prepare_llvm()
    with signals_deferred():   # Ctrl-C inside Dr.Jit's native import would crash the process
        import mitsuba as mi

        mi.set_variant(resolved)
    _chosen = resolved
    return mi


def active_variant() -> str | None:
    """The variant chosen in this process, or None before :func:`set_variant`."""
    return _chosen


def set_thread_count(threads: int) -> None:
    """Dr.Jit's worker threads for the CPU variant (one pool per process; a benchmark worker
    of N sharing C cores takes C // N)."""
    import drjit as dr

    dr.set_thread_count(max(1, int(threads)))
