#!/usr/bin/env bash
# Creates (or reuses) the local virtual environment .venv and makes sure a
# libLLVM >= 16 is present for Dr.Jit's CPU backend (llvm_ad_rgb).
set -euo pipefail
cd "$(dirname "$0")/.."

have_llvm() {  # true when any libLLVM >= 16 shared library is installed
    local f
    for f in /usr/lib/*-linux-gnu/libLLVM.so.{16,17,18,19,20,21}* \
             /usr/lib/*-linux-gnu/libLLVM-{16,17,18,19,20,21}.so \
             /usr/lib/llvm-{16,17,18,19,20,21}/lib/libLLVM*.so*; do
        [ -e "$f" ] && return 0
    done
    return 1
}
if [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && ! have_llvm; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "setup: installing libllvm19 (Dr.Jit's LLVM backend needs libLLVM >= 16)" >&2
        apt-get update -qq >/dev/null
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null
    else
        echo "setup: no libLLVM >= 16 found and cannot apt-get install libllvm19 (not root);" \
             "install it or set DRJIT_LIBLLVM_PATH. The CUDA variant still works on a GPU machine." >&2
    fi
fi

PY=${PYTHON:-python3}
stamp=.venv/.pseudolight-installed
want=$(sha256sum pyproject.toml | cut -c1-16)
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    .venv/bin/python -m pip install -q --upgrade pip >/dev/null 2>&1 || true
    .venv/bin/python -m pip install -q -e ".[test]"
    echo "$want" > "$stamp"
fi
