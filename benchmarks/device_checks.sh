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
#   bash ../shared/tools/gpu/prepare.sh 1.19.0                           # warp-lang in two halves: .gpu/a, .gpu/b
#   .venv/bin/python .ci/compile_cuda.py --arch 90 --keep .gpu/kernels   # every module for sm_90, as Warp's cache
#   tar --exclude='*.cu' -cJf .gpu/kernels.tar.xz -C .gpu/kernels .       # 1 MB (21 MB unpacked)
# then two calls of the device tool, the second within the 30 s the machine stays warm (each call
# takes at most 64 MiB: .gpu/a and .gpu/b are ~51 MB each, the checkout ~6 MB):
#   carry .gpu/a and .gpu/kernels.tar.xz, run
#     bash .gpu/a/stage.sh && mkdir -p /tmp/gpu-stage/kernels && tar -xJf .gpu/kernels.tar.xz -C /tmp/gpu-stage/kernels
#   carry .gpu/b, run
#     source .gpu/b/install.sh && WARP_CACHE_PATH=/tmp/gpu-stage/kernels bash benchmarks/device_checks.sh
# The CUDA kernels load from that cache where Warp there builds for sm_90 with the same Warp
# release. Before the steps, every module is loaded on every device in parallel processes, one
# per core: the CPU's compile there (the CUDA tests compare with it), 34 s on an H200 machine's
# 16 cores where the tests alone compiled them one at a time.
#
# Arguments name the steps to run (default: all four). On an H200 machine (2026-11-30) the whole
# script took about 3 minutes (tests 54 s, call_cost 27 s, bilinear 15 s, atomics 38 s), well
# inside the device tool's 10 minutes a command. $OUT brings back at most 8 files: the steps
# write 8.
#
# DEVICE=cpu runs the same steps on the CPU (tests_cuda against the CPU itself, no atomics step):
# a check of this script, not a measurement of a GPU.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-device_checks}
DEVICE=${DEVICE:-cuda:0}
PY=${PYTHON:-python3}
mkdir -p "$OUT"
if [ -z "${WARP_CACHE_PATH:-}" ] && [ -d .gpu/kernels ]; then
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

{ nvidia-smi 2>&1 || echo "no nvidia-smi"; "$PY" -c "import warp, torch; print('warp', warp.config.version, 'torch', torch.__version__)" 2>&1; lscpu 2>&1 | grep -E "^Model name|^CPU\(s\)"; } > "$OUT/machine.txt"

# Every module loaded on every device, one process per core (module names: warptex.kernels).
start=$SECONDS
"$PY" -c "import warp as wp; wp.config.quiet = True; from warptex.kernels import all_kernels; print('\n'.join(sorted({k.module.name for k in all_kernels()})))" 2>/dev/null |
    xargs -P "$(nproc)" -I{} "$PY" -c "import warp as wp; wp.config.quiet = True; from warptex.kernels import all_kernels; all_kernels(); wp.load_module('{}')" > /dev/null 2>&1
echo "device_checks: every module loaded (exit $?) in $((SECONDS - start)) s" | tee -a "$OUT/machine.txt"
step tests_cuda "$PY" -m pytest -q -rs -p no:cacheprovider tests/test_cuda.py
step call_cost "$PY" benchmarks/bench_samplers.py --device "$DEVICE" --call-cost --peers torch --json "$OUT/call_cost.json"
step bilinear "$PY" benchmarks/bench_samplers.py --device "$DEVICE" --techniques bilinear --peers torch --no-scaling --runs 3 --json "$OUT/bilinear.json"
if [ "$DEVICE" != cpu ]; then
    step atomics "$PY" benchmarks/bench_samplers.py --device "$DEVICE" --techniques bilinear trilinear triplanar splat4 --peers --no-scaling --atomics --json "$OUT/atomics.json"
fi
echo "device_checks: $failed step(s) failed; outputs in $OUT"
exit "$failed"
