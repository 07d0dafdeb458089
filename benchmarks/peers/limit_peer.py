"""The limit: a plain C loop of the bilinear lookup, compiled here at run time.

Not a peer a user would pick: a yardstick of what this machine allows for the same work. The loop
is what a compiler makes of a straightforward lookup (``-O3 -march=native -fopenmp``, no
intrinsics, one OpenMP ``parallel for`` over the samples), so warptex's distance to it is the
distance to the hardware's pace. It computes warptex's wrap-addressed bilinear read of level 0
(``x = u·w - ½``, ``y = (1 - v)·h - ½``, row 0 at the top), the formula of ``numpy_peer.bilinear``.

Only ``bilinear`` and only the CPU. Unavailable (with the reason) when no C compiler with OpenMP is
found: ``$CC``, else ``cc``.

:func:`load_latency` measures, with the same compiled library, how long one load waits on memory
for working sets of growing size (a pointer chase): where the cache this process actually gets
ends. That is what decides whether a texture's texels are read from cache or from DRAM at random
UVs, and it need not be the L3 the CPU reports (a virtual machine may get a few MB of it).
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from . import Peer, PeerUnavailable

SOURCE = r"""
#include <math.h>
#include <omp.h>
#include <stddef.h>
#include <stdint.h>

static inline void lookup(const float *tex, int w, int h, const int c, const float *uv, float *out) {
    float u = uv[0] - floorf(uv[0]), v = uv[1] - floorf(uv[1]);
    float x = u * (float)w - 0.5f, y = (1.0f - v) * (float)h - 0.5f;
    float x0 = floorf(x), y0 = floorf(y);
    float fx = x - x0, fy = y - y0;
    int i0 = (int)x0, j0 = (int)y0, i1 = i0 + 1, j1 = j0 + 1;
    i0 = i0 < 0 ? i0 + w : i0 >= w ? i0 - w : i0;
    i1 = i1 >= w ? i1 - w : i1;
    j0 = j0 < 0 ? j0 + h : j0 >= h ? j0 - h : j0;
    j1 = j1 >= h ? j1 - h : j1;
    const float *r0 = tex + (size_t)j0 * w * c, *r1 = tex + (size_t)j1 * w * c;
    for (int k = 0; k < c; ++k) {
        float top = r0[i0 * c + k] * (1.0f - fx) + r0[i1 * c + k] * fx;
        float bottom = r1[i0 * c + k] * (1.0f - fx) + r1[i1 * c + k] * fx;
        out[k] = top * (1.0f - fy) + bottom * fy;
    }
}

/* Nanoseconds per load of a chase through `lines` 64-byte lines of `buf` (8 int64s each) in one
   random cycle: each load's address is the previous load's value, so no two are in flight at once. */
double chase(int64_t *buf, int64_t lines, int64_t steps) {
    const int64_t S = 8;
    for (int64_t i = 0; i < lines; ++i) buf[i * S + 1] = i; /* the lines' order, in their second words */
    uint64_t state = 0x9E3779B97F4A7C15ull;
    for (int64_t i = lines - 1; i > 0; --i) { /* shuffled (Fisher-Yates, a 64-bit LCG) */
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        int64_t j = (int64_t)((state >> 33) % (uint64_t)(i + 1)), t = buf[i * S + 1];
        buf[i * S + 1] = buf[j * S + 1], buf[j * S + 1] = t;
    }
    for (int64_t i = 0; i < lines; ++i) /* each line, in that order, points at the next */
        buf[buf[i * S + 1] * S] = buf[((i + 1) % lines) * S + 1] * S;
    int64_t k = 0;
    for (int64_t i = 0; i < lines; ++i) k = buf[k]; /* one round to warm */
    double t = omp_get_wtime();
    for (int64_t i = 0; i < steps; ++i) k = buf[k];
    t = omp_get_wtime() - t;
    return k < 0 ? -1.0 : t / (double)steps * 1e9;
}

void bilinear_wrap(const float *tex, int w, int h, int c, const float *uv, int64_t n, float *out, int threads) {
    if (c == 4) {  /* the benchmark's case, with the channel loop unrolled by the compiler */
        #pragma omp parallel for num_threads(threads) schedule(static)
        for (int64_t s = 0; s < n; ++s) lookup(tex, w, h, 4, uv + 2 * s, out + 4 * s);
    } else {
        #pragma omp parallel for num_threads(threads) schedule(static)
        for (int64_t s = 0; s < n; ++s) lookup(tex, w, h, c, uv + 2 * s, out + (size_t)c * s);
    }
}
"""
FLAGS = ("-O3", "-march=native", "-fopenmp", "-shared", "-fPIC")
IMPORTED = True
_THREADS = os.cpu_count() or 1


def _compile() -> tuple[ctypes.CDLL | None, str | None]:
    """The compiled loop, or ``(None, why not)``."""
    cc = shutil.which(os.environ.get("CC", "cc"))
    if cc is None:
        return None, f"no C compiler ({os.environ.get('CC', 'cc')!r} is not on PATH)"
    with tempfile.TemporaryDirectory(prefix="warptex-limit-") as tmp:  # the loaded library outlives its file
        folder = Path(tmp)
        (folder / "limit.c").write_text(SOURCE)
        done = subprocess.run([cc, *FLAGS, "limit.c", "-o", "limit.so", "-lm"], cwd=folder, capture_output=True, text=True)
        if done.returncode != 0:
            errors = [line for line in done.stderr.splitlines() if "error" in line] or done.stderr.strip().splitlines() or ["?"]
            return None, f"{Path(cc).name} {' '.join(FLAGS)} failed: {errors[0].strip()}"
        lib = ctypes.CDLL(str(folder / "limit.so"))
    f32 = ctypes.POINTER(ctypes.c_float)
    lib.bilinear_wrap.argtypes = (f32, ctypes.c_int, ctypes.c_int, ctypes.c_int, f32, ctypes.c_int64, f32, ctypes.c_int)
    lib.bilinear_wrap.restype = None
    lib.chase.argtypes = (ctypes.POINTER(ctypes.c_int64), ctypes.c_int64, ctypes.c_int64)
    lib.chase.restype = ctypes.c_double
    return lib, None


LIB, UNAVAILABLE = _compile()
COMPILER = f"{Path(shutil.which(os.environ.get('CC', 'cc')) or 'cc').name} {' '.join(FLAGS[:3])}"


def set_device(device: str) -> None:
    if device != "cpu":
        raise PeerUnavailable("the C loop runs on the CPU only")


def synchronize() -> None:
    pass


def set_threads(count: int) -> None:
    global _THREADS
    _THREADS = count


def _pointer(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_float))


def _prepare(data):
    tex = np.ascontiguousarray(data["levels"][0], np.float32)
    uv = np.ascontiguousarray(data["uv"], np.float32).reshape(-1, 2)
    return {"tex": tex, "uv": uv, "out": np.empty((len(uv), tex.shape[2]), np.float32)}


def _forward(state):
    tex, uv, out = state["tex"], state["uv"], state["out"]
    h, w, c = tex.shape
    LIB.bilinear_wrap(_pointer(tex), w, h, c, _pointer(uv), len(uv), _pointer(out), _THREADS)
    return out


def load_latency(sizes_mb, steps: int = 1 << 21) -> dict[int, float]:
    """``{MB: nanoseconds}``: how long one load waits on memory when the loads wander at random over
    that many MB (a pointer chase, one thread, 4 KB pages as NumPy's and Warp's arrays get).

    Raises:
        PeerUnavailable: without the compiled library (the reason :data:`UNAVAILABLE` gives).
    """
    if LIB is None:
        raise PeerUnavailable(UNAVAILABLE)
    result = {}
    for mb in sizes_mb:
        lines = mb * 2**20 // 64
        buf = np.empty(lines * 8, np.int64)
        result[mb] = LIB.chase(buf.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), lines, steps)
    return result


def cache_end(latency: dict[int, float]) -> tuple[int | None, int | None]:
    """``(largest inside, smallest outside)`` the cache, in MB, from :func:`load_latency`: a working
    set is outside where its load waits over 3× the smallest's (None where no size is, or all are)."""
    fastest = min(latency.values())
    outside = [mb for mb, ns in sorted(latency.items()) if ns > 3 * fastest]
    if not outside:
        return max(latency), None
    inside = [mb for mb in latency if mb < outside[0]]
    return (max(inside) if inside else None), outside[0]


def peers() -> dict[str, Peer]:
    note = f"a plain C loop ({COMPILER}, OpenMP), forward only: the hardware's pace, not a peer"
    return {"bilinear": Peer("limit", "bilinear", _prepare, _forward, None, lambda out: out, None, note)}
