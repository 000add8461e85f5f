import os
import subprocess
import sys

import pytest

from estimator.rays import backend


def test_llvm_version_from_file_names():
    assert backend.llvm_major_version("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1") == 19
    assert backend.llvm_major_version("/usr/lib/x86_64-linux-gnu/libLLVM-15.so") == 15
    assert backend.llvm_major_version("/usr/lib/llvm-17/lib/libLLVM.so") == 17


def test_a_usable_variant_is_active():
    assert backend.active_variant() in backend.VARIANTS


def test_unknown_variant_is_refused():
    with pytest.raises(backend.BackendError, match="unknown variant"):
        backend.resolve_variant("scalar_spectral")


def _run(code: str, **env):
    full = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    full.update(env)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=full, timeout=120)


def test_old_libllvm_gives_a_clear_error_not_an_abort(tmp_path):
    fake = tmp_path / "libLLVM-15.so"
    fake.write_bytes(b"")
    r = _run("from estimator import backend\ntry:\n backend.set_variant('llvm_ad_rgb')\n"
             "except backend.BackendError as e:\n print('ERR', e)", DRJIT_LIBLLVM_PATH=str(fake))
    assert r.returncode == 0, r.stderr
    assert "ERR" in r.stdout and "libllvm19" in r.stdout


def test_fresh_process_finds_libllvm_itself():
    r = _run("from estimator import backend; import os\nmi = backend.set_variant('llvm_ad_rgb')\n"
             "print(mi.variant(), os.environ['DRJIT_LIBLLVM_PATH'])\n"
             "import drjit as dr; print(dr.sum(mi.Float([1, 2, 3]))[0])")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("llvm_ad_rgb") and r.stdout.strip().endswith("6.0")
