#!/usr/bin/env bash
# The GPU check: one prepared script for a machine with an NVIDIA GPU, run from the
# repository root. In about five minutes it
#   1. runs the test suite with PSEUDOLIGHT_VARIANT=cuda_ad_rgb (stopped after $TEST_BUDGET s;
#      verbose, so a log cut at the budget still names each test passed or failed);
#   2. generates and estimates shipped scenes at full size on llvm_ad_rgb and on cuda_ad_rgb,
#      on the same machine, and tabulates the times (generation wall-clock; the estimate's
#      own stage timings from run.json). Where llvm_ad_rgb cannot start (no libLLVM >= 16,
#      as on many GPU images) its columns read "not run";
#   3. runs `bench smoke` on cuda_ad_rgb, which spawns one worker per GPU.
# Everything lands in OUT (default out/gpu-check): gpu.txt, tests.log, times.json,
# summary.md, bench/. Exit 0 when every step passed, 1 when one failed, 3 without a GPU.
#
# Usage: benchmarks/gpu_check.sh [OUT]
#   PYTHON=...        interpreter with the project's dependencies (default .venv/bin/python,
#                     else python3)
#   SCENES="a b"      shipped scenes to time (default: real-light real-light-textured earth-specular)
#   TEST_BUDGET=150   seconds for step 1 (then pytest and any xdist workers are stopped)
#   STEP_BUDGET=300   seconds for each generation or estimate of step 2
#   PYTEST_ARGS=      extra pytest arguments for step 1, e.g. "-n 8" where pytest-xdist is installed
#   VARIANT=cuda_ad_rgb  the variant under check; VARIANT=llvm_ad_rgb rehearses the script on a
#                     machine without a GPU (with PROFILE=tiny and a small TEST_BUDGET)
#   PROFILE=          a scene profile for step 2 (default: none, full size)
set -uo pipefail
cd "$(dirname "$0")/.."

OUT=${1:-out/gpu-check}
PY=${PYTHON:-$([ -x .venv/bin/python ] && echo .venv/bin/python || echo python3)}
SCENES=${SCENES:-real-light real-light-textured earth-specular}
TEST_BUDGET=${TEST_BUDGET:-150}
STEP_BUDGET=${STEP_BUDGET:-300}
PYTEST_ARGS=${PYTEST_ARGS:-}
VARIANT=${VARIANT:-cuda_ad_rgb}
PROFILE=${PROFILE:+--profile $PROFILE}
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"
failed=0

if [ "$VARIANT" = cuda_ad_rgb ]; then
    if ! nvidia-smi -L >"$OUT/gpu.txt" 2>&1; then
        echo "gpu_check: no NVIDIA GPU here (nvidia-smi failed); nothing checked" >&2
        exit 3
    fi
else
    echo "no GPU: a rehearsal on $VARIANT" >"$OUT/gpu.txt"
fi
cat "$OUT/gpu.txt"
JOBS=$(grep -c '^GPU' "$OUT/gpu.txt" || true)
JOBS=$((JOBS > 0 ? JOBS : 1))
if ! "$PY" -c "import mitsuba as mi; mi.set_variant('$VARIANT')" 2>>"$OUT/gpu.txt"; then
    echo "gpu_check: Mitsuba cannot start $VARIANT with $PY (see $OUT/gpu.txt)" >&2
    exit 3
fi

echo "== 1. test suite on $VARIANT (budget ${TEST_BUDGET} s)"
PSEUDOLIGHT_VARIANT=$VARIANT timeout -k 10 "$TEST_BUDGET" "$PY" -m pytest -o addopts= -v -p no:cacheprovider $PYTEST_ARGS tests \
    >"$OUT/tests.log" 2>&1
rc=$?
echo "$(grep -c ' PASSED' "$OUT/tests.log") passed, $(grep -c ' FAILED' "$OUT/tests.log") failed before the end or the budget"
grep ' FAILED' "$OUT/tests.log" | grep -o 'tests/[^ ]*' | sort -u | head -n 20
case $rc in
    0) echo "tests: passed" ;;
    124|137) echo "tests: stopped at the budget (see $OUT/tests.log for how far they got)" ;;
    *) echo "tests: FAILED (rc $rc)"; failed=1 ;;
esac

echo "== 2. generation and estimation, llvm_ad_rgb against $VARIANT"
for variant in $(echo llvm_ad_rgb $VARIANT | tr " " "\n" | sort -u); do
    mkdir -p "$OUT/data"
    # The comparison variant is optional: a GPU image often has no libLLVM >= 16.
    if [ "$variant" != "$VARIANT" ] && ! "$PY" -c "from estimator.rays.backend import set_variant; set_variant('$variant')" \
            >/dev/null 2>"$OUT/data/$variant.skipped"; then
        echo "$variant cannot start here, so its columns stay empty: $(tail -n 1 "$OUT/data/$variant.skipped")"
        continue
    fi
    rm -f "$OUT/data/$variant.skipped"
    for scene in $SCENES; do
        d="$OUT/data/$variant/$scene"
        mkdir -p "$(dirname "$d")"
        t0=$(date +%s.%N)
        if ! timeout -k 10 "$STEP_BUDGET" "$PY" -m harness.cli generate "$scene" -o "$d" $PROFILE --variant "$variant" --overwrite >/dev/null 2>"$d.err"; then
            echo "generate $scene on $variant: FAILED ($(tail -n 1 "$d.err"))"; failed=1; continue
        fi
        t1=$(date +%s.%N)
        echo "$t0 $t1" >"$d.generate_seconds"
        if ! timeout -k 10 "$STEP_BUDGET" "$PY" -m harness.cli estimate "$d" -o "$d-run" --variant "$variant" --overwrite >/dev/null 2>"$d-run.err"; then
            echo "estimate $scene on $variant: FAILED ($(tail -n 1 "$d-run.err"))"; failed=1
        fi
    done
done
"$PY" - "$OUT" "$VARIANT" $SCENES <<'EOF'
"""Tabulate the times of step 2 into times.json and summary.md."""
import json
import os
import sys

out, checked, scenes = sys.argv[1], sys.argv[2], sys.argv[3:]
rows = []
for scene in scenes:
    row = {"scene": scene}
    for variant in ("llvm_ad_rgb", checked):
        d = os.path.join(out, "data", variant, scene)
        if os.path.exists(d + ".generate_seconds"):
            t0, t1 = map(float, open(d + ".generate_seconds").read().split())
            row[f"generate_{variant}"] = t1 - t0
        if os.path.exists(os.path.join(d + "-run", "run.json")):
            timings = json.load(open(os.path.join(d + "-run", "run.json"))).get("timings", {})
            row[f"estimate_{variant}"] = timings.get("total")
    rows.append(row)
json.dump(rows, open(os.path.join(out, "times.json"), "w"), indent=1)


def cell(v, variant):
    if v is not None:
        return f"{v:.1f}"
    return "not run" if os.path.exists(os.path.join(out, "data", variant + ".skipped")) else "failed"



lines = [f"| scene | generate llvm_ad_rgb (s) | generate {checked} (s) | estimate llvm_ad_rgb (s) "
         f"| estimate {checked} (s) |", "|---|---|---|---|---|"]
lines += [f"| {r['scene']} | {cell(r.get('generate_llvm_ad_rgb'), 'llvm_ad_rgb')} | "
          f"{cell(r.get(f'generate_{checked}'), checked)} | {cell(r.get('estimate_llvm_ad_rgb'), 'llvm_ad_rgb')} | "
          f"{cell(r.get(f'estimate_{checked}'), checked)} |" for r in rows]
gpu = open(os.path.join(out, "gpu.txt")).read().strip()
open(os.path.join(out, "summary.md"), "w").write(f"GPU: {gpu}\n\n" + "\n".join(lines) + "\n")
print("\n".join(lines))
EOF

echo "== 3. bench smoke on $VARIANT (on cuda_ad_rgb: one worker per GPU)"
if "$PY" -m harness.cli bench smoke -o "$OUT/bench" --variant "$VARIANT" --jobs "$JOBS" --no-mitsuba --force \
        >"$OUT/bench.log" 2>&1; then
    echo "bench smoke: passed"; tail -n 2 "$OUT/bench.log"
else
    echo "bench smoke: FAILED (see $OUT/bench.log)"; tail -n 5 "$OUT/bench.log"; failed=1
fi
exit $failed
