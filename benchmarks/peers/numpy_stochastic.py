"""NumPy peers of the stochastic techniques (hash4, cheap2, hex): pcg4d hashing on uint32 arrays,
taps read through :func:`numpy_peer.sample`; zero-weight taps are not read (rows compressed)."""

from __future__ import annotations

import numpy as np

from .numpy_peer import F32, _sample_lod, sample


U32 = np.uint32


def pcg4d(a, b, c, d):
    """Jarzynski & Olano's pcg4d on uint32 lanes (wrapping), each update using the updated lanes."""
    x, y, z, w = (np.asarray(t).astype(np.int64).astype(U32) * U32(1664525) + U32(1013904223) for t in np.broadcast_arrays(a, b, c, d))
    for rnd in range(2):
        x = x + y * w
        y = y + z * x
        z = z + x * y
        w = w + y * z
        if rnd == 0:
            x, y, z, w = (t ^ (t >> U32(16)) for t in (x, y, z, w))
    return x, y, z, w


def hash4_unit(x, y, seed, stream):
    """Four floats in [0, 1) from the top 24 bits of each lane."""
    return [(h >> U32(8)).astype(F32) * F32(2.0**-24) for h in pcg4d(x, y, U32(seed), U32(stream))]


def smoothstep(lo, hi, x):
    t = np.clip((x - F32(lo)) / (F32(hi) - F32(lo)), F32(0), F32(1))
    return t * t * (F32(3) - F32(2) * t)


def periodic_base(uv):
    return uv - F32(2) * np.floor(F32(0.5) * uv)


def offset_tap(base, h, mirror):
    tap = base.copy()
    if mirror:
        tap[:, 0] *= np.where(h[2] < 0.5, F32(-1), F32(1))
        tap[:, 1] *= np.where(h[3] < 0.5, F32(-1), F32(1))
    tap[:, 0] += h[0]
    tap[:, 1] += h[1]
    return tap


def _taps(state, rows, tap, lod):
    return sample(state["chain"], tap[:, 0], tap[:, 1], None if lod is None else lod[rows])


def hash4_forward(state):
    opts, uv = state["options"], state["uv"]
    lod = _sample_lod(state)
    cell = np.floor(uv)
    b = smoothstep(*opts["blend"], uv - cell)
    base = periodic_base(uv)
    icell = cell.astype(np.int64)
    out = np.zeros((len(uv), state["chain"].channels), F32)
    for dy in (0, 1):
        for dx in (0, 1):
            w = (b[:, 0] if dx else F32(1) - b[:, 0]) * (b[:, 1] if dy else F32(1) - b[:, 1])
            rows = np.flatnonzero(w > 0)
            h = hash4_unit(icell[rows, 0] + dx, icell[rows, 1] + dy, opts["seed"], 0)
            out[rows] += w[rows, None] * _taps(state, rows, offset_tap(base[rows], h, opts["mirror"]), lod)
    return out


def value_noise(p, seed):
    cell = np.floor(p)
    f = p - cell
    ix, iy = cell[:, 0].astype(np.int64), cell[:, 1].astype(np.int64)
    a, b, c, d = (hash4_unit(ix + i, iy + j, seed, 2)[0] for j in (0, 1) for i in (0, 1))
    sx, sy = smoothstep(0.0, 1.0, f[:, 0]), smoothstep(0.0, 1.0, f[:, 1])
    lerp = lambda p, q, t: p * (F32(1) - t) + q * t  # noqa: E731
    return lerp(lerp(a, b, sx), lerp(c, d, sx), sy)


def cheap2_forward(state):
    opts, uv = state["options"], state["uv"]
    lod = _sample_lod(state)
    l = value_noise(uv * F32(opts["noise_frequency"]), opts["seed"]) * F32(opts["noise_levels"])
    index = np.floor(l)
    t = smoothstep(*opts["blend"], l - index)
    base = periodic_base(uv)
    ia = index.astype(np.int64)
    out = np.zeros((len(uv), state["chain"].channels), F32)
    for k, w in ((0, F32(1) - t), (1, t)):
        rows = np.flatnonzero(w > 0)
        h = hash4_unit(ia[rows] + k, 0, opts["seed"], 1)
        out[rows] += w[rows, None] * _taps(state, rows, offset_tap(base[rows], h, opts["mirror"]), lod)
    return out


HEX_SCALE = 3.4641016151377544
INV_SQRT3 = 0.5773502691896258


def hex_forward(state):
    """Three taps on the skewed triangle grid, barycentric weights ^ contrast, linear blend (no
    histogram, no rotation)."""
    opts, uv = state["options"], state["uv"]
    lod = _sample_lod(state)
    p = uv.astype(np.float64) * HEX_SCALE  # the lattice in float64, as the kernel does
    s = np.stack([p[:, 0] - p[:, 1] * INV_SQRT3, 2.0 * INV_SQRT3 * p[:, 1]], axis=1)
    b = np.floor(s)
    f = (s - b).astype(F32)
    i, j = b[:, 0].astype(np.int64), b[:, 1].astype(np.int64)
    upper = f[:, 0] + f[:, 1] >= 1
    bary = np.where(upper[:, None], np.stack([f[:, 0] + f[:, 1] - 1, 1 - f[:, 1], 1 - f[:, 0]], 1), np.stack([1 - f[:, 0] - f[:, 1], f[:, 0], f[:, 1]], 1))
    with np.errstate(divide="ignore"):
        pw = np.where(bary > 0, np.power(np.maximum(bary, F32(0)), F32(opts["contrast"])), F32(0))
    w = pw / pw.sum(axis=1, keepdims=True)
    verts = ((np.where(upper, i + 1, i), np.where(upper, j + 1, j)), (i + 1, j), (i, j + 1))
    base = periodic_base(uv)
    out = np.zeros((len(uv), state["chain"].channels), F32)
    for k, (vi, vj) in enumerate(verts):
        rows = np.flatnonzero(w[:, k] > 0)
        h = hash4_unit(vi[rows], vj[rows], opts["seed"], 3)
        tap = base[rows] + np.stack([h[0], h[1]], axis=1)
        out[rows] += w[rows, k, None] * _taps(state, rows, tap, lod)
    return out
