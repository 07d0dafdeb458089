"""The limit: a plain C loop of the bilinear lookup, compiled here at run time.

Not a peer a user would pick: a yardstick of what this machine allows for the same work. The loop
is what a compiler makes of a straightforward lookup (``-O3 -march=native -fopenmp``, no
intrinsics, one OpenMP ``parallel for`` over the samples), so warptex's distance to it is the
distance to the hardware's pace. It computes warptex's wrap-addressed bilinear read of level 0
(``x = u·w - ½``, ``y = (1 - v)·h - ½``, row 0 at the top), the formula of ``numpy_peer.bilinear``.

Only ``bilinear`` and only the CPU. Unavailable (with the reason) when no C compiler with OpenMP is
found: ``$CC``, else ``cc``.
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


def peers() -> dict[str, Peer]:
    note = f"a plain C loop ({COMPILER}, OpenMP), forward only: the hardware's pace, not a peer"
    return {"bilinear": Peer("limit", "bilinear", _prepare, _forward, None, lambda out: out, None, note)}
