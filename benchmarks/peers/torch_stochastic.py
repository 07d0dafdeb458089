"""PyTorch peers of the stochastic techniques (hash4, cheap2, hex): pcg4d on int64 tensors holding
uint32 values, taps read through :func:`torch_peer.sample` (``grid_sample``); zero-weight taps are
not read (rows compressed)."""

from __future__ import annotations

import numpy as np
import torch

from .torch_peer import MASK32, _sample_lod, sample


def _mul32(a, b):
    """``a · b mod 2^32`` for int64 tensors holding uint32 values (no int64 overflow)."""
    return (a * (b & 0xFFFF) + (((a * (b >> 16)) & 0xFFFF) << 16)) & MASK32


def pcg4d(a, b, c, d):
    lanes = torch.broadcast_tensors(*(torch.as_tensor(t, dtype=torch.int64) & MASK32 for t in (a, b, c, d)))
    x, y, z, w = ((t * 1664525 + 1013904223) & MASK32 for t in lanes)
    for rnd in range(2):
        x = (x + _mul32(y, w)) & MASK32
        y = (y + _mul32(z, x)) & MASK32
        z = (z + _mul32(x, y)) & MASK32
        w = (w + _mul32(y, z)) & MASK32
        if rnd == 0:
            x, y, z, w = (t ^ (t >> 16) for t in (x, y, z, w))
    return x, y, z, w


def hash4_unit(x, y, seed, stream):
    return [(h >> 8).to(torch.float32) * (2.0**-24) for h in pcg4d(x, y, seed, stream)]


def _smoothstep(lo, hi, x):
    lo32, hi32 = np.float32(lo), np.float32(hi)
    t = torch.clamp((x - float(lo32)) / float(hi32 - lo32), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _periodic_base(uv):
    return uv - 2.0 * torch.floor(0.5 * uv)


def _offset_tap(base, h, mirror):
    su = torch.where(h[2] < 0.5, -1.0, 1.0) if mirror else 1.0
    sv = torch.where(h[3] < 0.5, -1.0, 1.0) if mirror else 1.0
    return base[:, 0] * su + h[0], base[:, 1] * sv + h[1]


def stochastic(technique):
    """The body (``(state, padded) -> (N, C)``) of ``technique``'s torch peer."""
    def run(state, padded):
        opts, uv = state["options"], state["uv"]
        tex = padded["texture"]
        lod = _sample_lod(state, (tex[0].shape[-1] - 2, tex[0].shape[-2] - 2))
        base = _periodic_base(uv)
        out = torch.zeros((len(uv), tex[0].shape[1]))

        def tap(rows, u, v, weight):
            nonlocal out
            out = out.index_add(0, rows, weight[:, None] * sample(tex, u, v, None if lod is None else lod[rows]))

        if technique == "hash4":
            cell = torch.floor(uv)
            b = _smoothstep(*opts["blend"], uv - cell)
            icell = cell.long()
            for dy in (0, 1):
                for dx in (0, 1):
                    w = (b[:, 0] if dx else 1.0 - b[:, 0]) * (b[:, 1] if dy else 1.0 - b[:, 1])
                    rows = torch.nonzero(w > 0).squeeze(1)
                    h = hash4_unit(icell[rows, 0] + dx, icell[rows, 1] + dy, opts["seed"], 0)
                    tap(rows, *_offset_tap(base[rows], h, opts["mirror"]), w[rows])
        elif technique == "cheap2":
            p = uv * float(np.float32(opts["noise_frequency"]))
            cell = torch.floor(p)
            f = p - cell
            ix, iy = cell[:, 0].long(), cell[:, 1].long()
            a, b, c, d = (hash4_unit(ix + i, iy + j, opts["seed"], 2)[0] for j in (0, 1) for i in (0, 1))
            sx, sy = _smoothstep(0.0, 1.0, f[:, 0]), _smoothstep(0.0, 1.0, f[:, 1])
            lerp = lambda p, q, t: p * (1.0 - t) + q * t  # noqa: E731
            l = lerp(lerp(a, b, sx), lerp(c, d, sx), sy) * float(np.float32(opts["noise_levels"]))
            index = torch.floor(l)
            t = _smoothstep(*opts["blend"], l - index)
            ia = index.long()
            for k, w in ((0, 1.0 - t), (1, t)):
                rows = torch.nonzero(w > 0).squeeze(1)
                h = hash4_unit(ia[rows] + k, 0, opts["seed"], 1)
                tap(rows, *_offset_tap(base[rows], h, opts["mirror"]), w[rows])
        else:  # hex: lattice in float64, as the kernel
            p = uv.double() * 3.4641016151377544
            s = torch.stack([p[:, 0] - p[:, 1] * 0.5773502691896258, 2.0 * 0.5773502691896258 * p[:, 1]], dim=1)
            bl = torch.floor(s)
            f = (s - bl).float()
            i, j = bl[:, 0].long(), bl[:, 1].long()
            upper = f[:, 0] + f[:, 1] >= 1.0
            bary = torch.where(upper[:, None], torch.stack([f[:, 0] + f[:, 1] - 1.0, 1.0 - f[:, 1], 1.0 - f[:, 0]], 1), torch.stack([1.0 - f[:, 0] - f[:, 1], f[:, 0], f[:, 1]], 1))
            pw = torch.where(bary > 0, torch.pow(bary.clamp(min=0.0), float(opts["contrast"])), 0.0)
            w = pw / pw.sum(dim=1, keepdim=True)
            verts = ((torch.where(upper, i + 1, i), torch.where(upper, j + 1, j)), (i + 1, j), (i, j + 1))
            for k, (vi, vj) in enumerate(verts):
                rows = torch.nonzero(w[:, k] > 0).squeeze(1)
                h = hash4_unit(vi[rows], vj[rows], opts["seed"], 3)
                tap(rows, base[rows, 0] + h[0], base[rows, 1] + h[1], w[rows, k])
        return out

    return run
