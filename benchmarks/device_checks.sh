#!/usr/bin/env bash
# The GPU checks of issue 51 in one run, for a session that is lent a GPU for minutes: run once, keep
# the output. Every step writes $OUT/<step>.log (and .json where it measures); a failed step is
# reported and the others still run; the exit status is the number of failed steps.
#
#   1. tests_cuda: tests/test_cuda.py, CUDA against the CPU: every technique's outputs and gradients,
#      texel gradients the same bits over five runs (fixed-point sums, hand-written gradients and
#      Warp's generated adjoints), a small call in a CUDA graph, the torch bridge in torch.cuda.graphs.
#   2. call_cost: what a call costs when it computes little, against torch (bench_samplers --call-cost).
#   3. bilinear: bilinear forward and forward+backward on 2^20 UVs and a 1024² view, against torch,
#      3 interleaved runs (the 1.0x-torch bar).
#   4. atomics: what the same-bits texel gradients cost against float atomics, per technique.
#
# Prepare it here, without a GPU (the device tool's machine reaches no package index):
#   bash ../shared/tools/gpu/prepare.sh                                  # warp-lang in two halves: .gpu/a, .gpu/b
#   .venv/bin/python .ci/compile_cuda.py --arch 90 --keep .gpu/kernels   # every module for sm_90, as Warp's cache
# then three calls of the device tool, on one warm machine: carry .gpu/a and run `bash .gpu/a/stage.sh`;
# carry .gpu/b and run `source .gpu/b/install.sh`; carry .gpu/kernels and run
#   source .gpu/b/install.sh && OUT=$OUT bash benchmarks/device_checks.sh
# (`install.sh` again is cheap). The kernels load from .gpu/kernels where Warp there builds for sm_90
# with the same Warp release; anything else compiles there, one module at a time (minutes).
#
# Arguments name the steps to run (default: all four): the device tool runs a command for at most
# 10 minutes, so `... device_checks.sh tests_cuda call_cost`, then `... bilinear atomics` (about
# 4 and 3 minutes on this project's 2-core CPU; a GPU's share is its launches and its compiles).
#
# DEVICE=cpu runs the same steps on the CPU (tests_cuda against the CPU itself, no atomics step):
# a check of this script, not a measurement of a GPU.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-device_checks}
DEVICE=${DEVICE:-cuda:0}
PY=${PYTHON:-python3}
mkdir -p "$OUT"
if [ -d .gpu/kernels ]; then
    export WARP_CACHE_PATH="$PWD/.gpu/kernels"
fi
if [ "$DEVICE" = cpu ]; then
    export WARPTEX_TEST_DEVICE=cpu
fi

STEPS=" ${*:-tests_cuda call_cost bilinear atomics} "
for name in $STEPS; do
    case $name in
        tests_cuda | call_cost | bilinear | atomics) ;;
        *) echo "device_checks: no step $name (the steps: tests_cuda call_cost bilinear atomics)" >&2; exit 2 ;;
    esac
done

failed=0
step() {
    local name=$1 start=$SECONDS rc=0
    shift
    [[ $STEPS == *" $name "* ]] || return 0
    echo "device_checks: $name: $*"
    "$@" > "$OUT/$name.log" 2>&1 || rc=$?
    if [ "$rc" -eq 0 ]; then
        echo "device_checks: $name: ok in $((SECONDS - start)) s"
    else
        echo "device_checks: $name: FAILED (exit $rc) in $((SECONDS - start)) s; the end of $OUT/$name.log:"
        tail -n 25 "$OUT/$name.log"
        failed=$((failed + 1))
    fi
}

{ nvidia-smi 2>&1 || echo "no nvidia-smi"; "$PY" -c "import warp, torch; print('warp', warp.config.version, 'torch', torch.__version__)" 2>&1; } > "$OUT/machine.txt"
step tests_cuda "$PY" -m pytest -q -rs -p no:cacheprovider tests/test_cuda.py
step call_cost "$PY" benchmarks/bench_samplers.py --device "$DEVICE" --call-cost --peers torch --json "$OUT/call_cost.json"
step bilinear "$PY" benchmarks/bench_samplers.py --device "$DEVICE" --techniques bilinear --peers torch --no-scaling --runs 3 --json "$OUT/bilinear.json"
if [ "$DEVICE" != cpu ]; then
    step atomics "$PY" benchmarks/bench_samplers.py --device "$DEVICE" --techniques bilinear trilinear triplanar splat4 --peers --no-scaling --atomics --json "$OUT/atomics.json"
fi
echo "device_checks: $failed step(s) failed; outputs in $OUT"
exit "$failed"
