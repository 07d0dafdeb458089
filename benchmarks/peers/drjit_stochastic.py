"""Dr.Jit peers of the stochastic techniques (hash4, cheap2, hex): pcg4d on ``UInt32`` (wrapping),
taps read through :func:`drjit_peer.sample` (``Texture2f``); zero-weight taps are masked off."""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.llvm.ad import Float, Float64, Int32, UInt32

from .drjit_peer import _add, _sample_lod, _zeros, sample


def pcg4d(a, b, c, d):
    x, y, z, w = (t * 1664525 + 1013904223 for t in (a, b, c, d))
    for rnd in range(2):
        x += y * w
        y += z * x
        z += x * y
        w += y * z
        if rnd == 0:
            x, y, z, w = (t ^ (t >> 16) for t in (x, y, z, w))
    return x, y, z, w


def hash4_unit(x, y, seed, stream):
    """``x, y`` Int32 lattice coordinates (reinterpreted as uint32)."""
    lanes = (dr.reinterpret_array(UInt32, x), dr.reinterpret_array(UInt32, y), UInt32(seed) + 0 * UInt32(0), UInt32(stream))
    return [Float(h >> 8) * (2.0**-24) for h in pcg4d(*lanes)]


def _smoothstep(lo, hi, x):
    lo32, hi32 = np.float32(lo), np.float32(hi)
    t = dr.clip((x - float(lo32)) / float(hi32 - lo32), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _offset_tap(base, h, mirror):
    su = dr.select(h[2] < 0.5, -1.0, 1.0) if mirror else 1.0
    sv = dr.select(h[3] < 0.5, -1.0, 1.0) if mirror else 1.0
    return base[0] * su + h[0], base[1] * sv + h[1]


def stochastic(technique):
    """The body (``(state, textures) -> channels``) of ``technique``'s Dr.Jit peer."""
    def run(state, tex):
        opts = state["options"]
        u, v = state["uv"]
        chain = tex["texture"]
        lod = _sample_lod(state, chain.size)
        base = (u - 2.0 * dr.floor(0.5 * u), v - 2.0 * dr.floor(0.5 * v))
        out = _zeros(chain.channels)

        def tap(tu, tv, weight):
            nonlocal out
            out = _add(out, weight > 0.0, weight, sample(chain, tu, tv, lod, weight > 0.0))

        if technique == "hash4":
            cu, cv = dr.floor(u), dr.floor(v)
            bx, by = _smoothstep(*opts["blend"], u - cu), _smoothstep(*opts["blend"], v - cv)
            iu, iv = Int32(cu), Int32(cv)
            for dy in (0, 1):
                for dx in (0, 1):
                    weight = (bx if dx else 1.0 - bx) * (by if dy else 1.0 - by)
                    h = hash4_unit(iu + dx, iv + dy, opts["seed"], 0)
                    tap(*_offset_tap(base, h, opts["mirror"]), weight)
        elif technique == "cheap2":
            freq = float(np.float32(opts["noise_frequency"]))
            pu, pv = u * freq, v * freq
            cu, cv = dr.floor(pu), dr.floor(pv)
            iu, iv = Int32(cu), Int32(cv)
            a, b, c, d = (hash4_unit(iu + i, iv + j, opts["seed"], 2)[0] for j in (0, 1) for i in (0, 1))
            sx, sy = _smoothstep(0.0, 1.0, pu - cu), _smoothstep(0.0, 1.0, pv - cv)
            lerp = lambda p, q, t: p * (1.0 - t) + q * t  # noqa: E731
            l = lerp(lerp(a, b, sx), lerp(c, d, sx), sy) * float(np.float32(opts["noise_levels"]))
            index = dr.floor(l)
            t = _smoothstep(*opts["blend"], l - index)
            ia = Int32(index)
            for k, weight in ((0, 1.0 - t), (1, t)):
                h = hash4_unit(ia + k, Int32(0), opts["seed"], 1)
                tap(*_offset_tap(base, h, opts["mirror"]), weight)
        else:  # hex: lattice in float64, as the kernel
            pu, pv = Float64(u) * 3.4641016151377544, Float64(v) * 3.4641016151377544
            su, sv = pu - pv * 0.5773502691896258, 2.0 * 0.5773502691896258 * pv
            bu, bv = dr.floor(su), dr.floor(sv)
            fu, fv = Float(su - bu), Float(sv - bv)
            i, j = Int32(bu), Int32(bv)
            upper = fu + fv >= 1.0
            bary = [dr.select(upper, fu + fv - 1.0, 1.0 - fu - fv), dr.select(upper, 1.0 - fv, fu), dr.select(upper, 1.0 - fu, fv)]
            contrast = float(opts["contrast"])
            pw = [dr.select(x > 0.0, dr.power(dr.maximum(x, 1e-38), contrast), 0.0) for x in bary]
            total = pw[0] + pw[1] + pw[2]
            verts = ((dr.select(upper, i + 1, i), dr.select(upper, j + 1, j)), (i + 1, j), (i, j + 1))
            for k, (vi, vj) in enumerate(verts):
                h = hash4_unit(vi, vj, opts["seed"], 3)
                tap(base[0] + h[0], base[1] + h[1], pw[k] / total)
        return out

    return run
