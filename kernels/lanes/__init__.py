"""CPU lanes: lane kernels that compute a lane of :data:`LANES` pixels at a launch index.

Warp compiles a CPU launch as a scalar loop, one launch index at a time, and LLVM does not
vectorise across indices (Warp issues #1309, #1358, #1954): rewriting a scalar body as an unrolled
loop over 16 pixels inside one Warp launch index measured no faster here. A ``wp.func_native``
function written for a lane, in phases, is: its UV arithmetic runs a lane wide in SIMD
registers (16 pixels with AVX-512, 8 without: :func:`host_lanes`), and all the texel addresses of a
lane are known before the first load, so the loads overlap.

Each technique's lane parts sit beside its scalar ones, by name: the lane bodies (``@wp.func``
that read a lane's pixels, call native functions and write its outputs) in this package's module
of the technique (:mod:`.sample`, :mod:`.triplanar`, :mod:`.splat`, :mod:`.stochastic`...), the
native functions' C++ in ``warptex/kernels/native/wt_*.h`` (:mod:`warptex.kernels.native`), and
their texel-gradient twins in :mod:`.scatter` (as :mod:`warptex.kernels.scatter` is to
:mod:`warptex.kernels.filters`).

Each native function computes *exactly* what the scalar ``@wp.func`` blocks it stands for compute,
operation for operation and in the same order (no contraction into fused multiply-adds; Warp's own
``wp::floor`` and ``wp::clamp``), so a lane's outputs are the scalar kernel's bits;
``tests/test_lanes.py`` checks that in every filter, address mode, level and layer case. Only the
CPU compiles a body: on CUDA the native functions are empty and never launched (one pixel per
thread there, from the scalar kernels). The lane kernels themselves are made by
:func:`warptex.kernels.family.lane_kernel`; whether a launch runs them is decided in one place,
:func:`warptex.kernels.family.runs_lanes`.
"""

import os

import warp as wp


def host_lanes() -> int:
    """The lane width for this host: 16 where the CPU has AVX-512 (a lane vector is one 512-bit
    register), 8 elsewhere. With AVX2, 16 took two registers a vector and the lanes ran short of
    registers: 8 was 1.1-1.3× faster on triplanar, biplanar, normal-mapped and trilinear views,
    0.92-0.97× on ``sample``'s gradients and 0.85-0.95× on random UVs' forward
    (docs/performance.md, "Lanes of 8 without AVX-512").
    ``WARPTEX_LANES`` (8 or 16) overrides it; both widths compute the same bits, the scalar
    kernels'."""
    asked = os.environ.get("WARPTEX_LANES", "").strip()
    if asked:
        if asked not in ("8", "16"):
            raise ValueError(f"WARPTEX_LANES={asked!r}: the lanes are 8 or 16 pixels wide")
        return int(asked)
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            flags = next((line.split(":", 1)[1].split() for line in f if line.startswith("flags")), [])
    except OSError:  # not Linux: Warp still compiles for the host, and 8 suits 128- and 256-bit SIMD
        return 8
    return 16 if "avx512f" in flags else 8


#: Pixels per lane: one launch index of a lane kernel computes pixels ``LANES·t .. LANES·t + LANES - 1``
#: (fewer in a launch's last lane): :func:`host_lanes`, fixed at import.
LANES = host_lanes()

#: A lane of floats or ints (one per pixel), and a lane of RGBA values (a row per pixel).
lane_floats = wp.types.vector(length=LANES, dtype=wp.float32)
lane_ints = wp.types.vector(length=LANES, dtype=wp.int32)
lane_colours = wp.types.matrix(shape=(LANES, 4), dtype=wp.float32)
#: Per read (up to 3 per pixel: a triplanar pixel's projections) and lane pixel (column), what is read:
#: rows ``3 q + r`` of read ``r``'s UV ``u`` (``q = 0``) and ``v`` (1), its LOD (2), its weight (3; 0:
#: not read) and the rest of its footprint (footprint.py): step ``u`` (4), step ``v`` (5), taps (6).
lane_reads = wp.types.matrix(shape=(21, LANES), dtype=wp.float32)
#: Per lane pixel (column), a stochastic lookup's four taps: rows ``3 k``, ``3 k + 1`` tap ``k``'s UV,
#: ``3 k + 2`` its weight (0: not read), 12 the pixel's LOD, 13 whether its UV and LOD are finite (1, 0).
lane_taps = wp.types.matrix(shape=(14, LANES), dtype=wp.float32)
