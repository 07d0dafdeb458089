"""Vectorised NumPy peers: every technique as whole-array float32 operations on a flat mip chain.

The texels of all levels (and layers) sit in one ``(T, C)`` array, as warptex stores them, so a
bilinear read is four fancy-indexed gathers whatever level each sample reads, and trilinear with a
per-sample LOD is two of them. Per-pixel branches become boolean compression: a projection, layer
or tap with zero weight is not read, as in the kernels. Forward only (NumPy has no autodiff).
"""

from __future__ import annotations

import numpy as np

from . import Peer, PeerUnavailable
from .common import SPLAT_LAYERS, layer_tiling, lod_kind, options, sample_lod

IMPORTED, UNAVAILABLE = True, None
F32 = np.float32
PLANES = ((2, 1), (0, 2), (0, 1))  # X plane: p.zy, Y plane: p.xz, Z plane: p.xy
BIPLANAR_EDGE = F32(0.5773)


def set_device(device: str) -> None:
    if device != "cpu":
        raise PeerUnavailable("NumPy runs on the CPU only")


def synchronize() -> None:
    pass


def set_threads(count: int) -> None:
    """NumPy's element-wise kernels are single-threaded; nothing to set."""


class Chain:
    """A mip chain of ``L`` layers flattened level by level: ``index = offset[k] + (layer·h + row)·w + col``."""

    def __init__(self, levels):
        arrays = [np.asarray(a, F32) for a in levels]
        arrays = [a[None] if a.ndim == 3 else a for a in arrays]
        self.layers, _, _, self.channels = arrays[0].shape
        self.texels = np.concatenate([a.reshape(-1, self.channels) for a in arrays])
        self.offset = np.cumsum([0] + [a.shape[0] * a.shape[1] * a.shape[2] for a in arrays])[:-1]
        self.height = np.array([a.shape[1] for a in arrays])
        self.width = np.array([a.shape[2] for a in arrays])
        self.top = len(arrays) - 1


def wrap(u):
    """``u - floor(u)``: one period of the wrap mode, exactly."""
    return u - np.floor(u)


def bilinear(chain: Chain, u, v, level, layer=0, clamp=False):
    """Bilinear read of ``level`` (an int or an int array) at reduced ``u, v``: ``(N, C)``."""
    w, h = chain.width[level], chain.height[level]
    x = u * w.astype(F32) - F32(0.5)
    y = (F32(1) - v) * h.astype(F32) - F32(0.5)
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    i, j = x0.astype(np.int64), y0.astype(np.int64)
    if clamp:
        i0, i1, j0, j1 = np.clip(i, 0, w - 1), np.clip(i + 1, 0, w - 1), np.clip(j, 0, h - 1), np.clip(j + 1, 0, h - 1)
    else:
        i0, i1, j0, j1 = i % w, (i + 1) % w, j % h, (j + 1) % h
    base = chain.offset[level] + layer * h * w
    r0, r1 = base + j0 * w, base + j1 * w
    t = chain.texels
    top = t[r0 + i0] * (F32(1) - fx) + t[r0 + i1] * fx
    bottom = t[r1 + i0] * (F32(1) - fx) + t[r1 + i1] * fx
    return top * (F32(1) - fy) + bottom * fy


def lod_from_derivatives(chain: Chain, dx, dy):
    """``0.5 log2(max(|dx·size|², |dy·size|², 1e-30))``, size = level 0's ``(w, h)``."""
    size = np.array([chain.width[0], chain.height[0]], F32)
    a, b = dx * size, dy * size
    rho2 = np.maximum(np.maximum((a * a).sum(-1), (b * b).sum(-1)), F32(1e-30))
    return F32(0.5) * np.log2(rho2)


def sample(chain: Chain, u, v, lod, layer=0):
    """Wrap-addressed read at ``u, v``: bilinear on level 0 when ``lod`` is None, else trilinear."""
    u, v = wrap(u), wrap(v)
    if lod is None:
        return bilinear(chain, u, v, 0, layer)
    l = np.clip(lod, F32(0), F32(chain.top))
    base = np.floor(l)
    f = l - base
    level = base.astype(np.int64)
    out = bilinear(chain, u, v, level, layer)
    coarse = np.flatnonzero(f > 0)
    if coarse.size:
        fc = f[coarse, None]
        out[coarse] = out[coarse] * (F32(1) - fc) + bilinear(chain, u[coarse], v[coarse], level[coarse] + 1, layer) * fc
    return out


def _sample_lod(state):
    """The per-sample LOD of a sample technique (None: bilinear on level 0)."""
    return sample_lod(state, lambda dx, dy: lod_from_derivatives(state["chain"], dx, dy))


# -- bilinear, trilinear -------------------------------------------------------------------------------


def _prepare_sample(data, technique="trilinear"):
    state = {k: np.ascontiguousarray(data[k], F32) for k in ("uv", "lod", "uv_dx", "uv_dy") if k in data}
    state["chain"] = Chain(data["levels"][:1] if technique == "bilinear" else data["levels"])
    state["lod_kind"] = "none" if technique == "bilinear" else lod_kind(data)
    state["options"] = options(data, technique)
    return state


def bilinear_forward(state):
    uv = state["uv"]
    return bilinear(state["chain"], wrap(uv[:, 0]), wrap(uv[:, 1]), 0)


def trilinear_forward(state):
    uv = state["uv"]
    return sample(state["chain"], uv[:, 0], uv[:, 1], _sample_lod(state))


# -- triplanar, biplanar, triplanar normal ------------------------------------------------------------


def sign_or_one(x):
    return np.where(x < 0, F32(-1), F32(1))


def power_weight(r, exponent):
    """``r^exponent`` with ``0^0 = 1`` and ``0^k = 0``."""
    if exponent == 0:
        return np.ones_like(r)
    with np.errstate(divide="ignore"):
        return np.where(r > 0, np.exp(F32(exponent) * np.log(r)), F32(0))


def triplanar_weights(n, sharpness):
    a = np.abs(n)
    m = a.max(axis=1)
    valid = np.isfinite(n).all(axis=1) & (m > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = power_weight(a / np.where(valid, m, F32(1))[:, None], sharpness)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), F32(1e-20))
    return np.where(valid[:, None], w, F32(0))


def biplanar_weights(n, sharpness):
    length = np.sqrt((n * n).sum(axis=1))
    valid = np.isfinite(n).all(axis=1) & (length > 0)
    a = np.abs(n) / np.where(valid, length, F32(1))[:, None]
    minor = np.where((a[:, 2] <= a[:, 0]) & (a[:, 2] <= a[:, 1]), 2, np.where(a[:, 1] <= a[:, 0], 1, 0))
    r = np.clip((a - BIPLANAR_EDGE) / (F32(1) - BIPLANAR_EDGE), F32(0), F32(1))
    w = np.where(np.arange(3) != minor[:, None], power_weight(r, F32(sharpness) / F32(8)), F32(0))
    w = w / np.maximum(w.sum(axis=1, keepdims=True), F32(1e-20))
    return np.where(valid[:, None], w, F32(0))


def u_sign(n, axis):
    """The right-handed mirror fix: ``-sign(n.x)``, ``-sign(n.y)``, ``+sign(n.z)``."""
    s = sign_or_one(n[:, axis])
    return s if axis == 2 else -s


def project(state, axis, rows, tiling):
    """``(uv, lod)`` of projection ``axis`` at pixels ``rows``."""
    plane = list(PLANES[axis])
    uv = state["position"][rows][:, plane] * F32(tiling)
    uv[:, 0] *= u_sign(state["normal"][rows], axis)
    lod = lod_from_derivatives(state["chain"], state["position_dx"][rows][:, plane] * F32(tiling), state["position_dy"][rows][:, plane] * F32(tiling))
    return uv, lod


def _prepare_gbuffer(technique):
    def prepare(data):
        state = {k: np.ascontiguousarray(data[k], F32) for k in ("position", "normal", "position_dx", "position_dy", "mask", "uv", "uv_dx", "uv_dy") if k in data}
        state["options"] = options(data, technique)
        if technique in SPLAT_LAYERS:
            state["chain"] = Chain(data["layer_levels"])
            state["maps"] = Chain([data["maps"]])
            state["tiling"] = layer_tiling(data, state["chain"].layers)
        else:
            state["chain"] = Chain(data["levels"])
        return state

    return prepare


def _planar(state, biplanar):
    opts = state["options"]
    n = state["normal"]
    w = (biplanar_weights if biplanar else triplanar_weights)(n, opts["sharpness"])
    covered = state["mask"] != 0
    out = np.zeros((len(n), state["chain"].channels), F32)
    for axis in range(3):
        rows = np.flatnonzero(covered & (w[:, axis] > 0))
        uv, lod = project(state, axis, rows, opts["tiling"])
        out[rows] += w[rows, axis, None] * sample(state["chain"], uv[:, 0], uv[:, 1], lod)
    return out


def triplanar_forward(state):
    return _planar(state, False)


def biplanar_forward(state):
    return _planar(state, True)


def normalize(v):
    length = np.sqrt((v * v).sum(axis=-1, keepdims=True))
    return np.where(length > 0, v / np.where(length > 0, length, F32(1)), F32(0))


def blend_projected(t, b, kind):
    if kind == "udn":
        return np.stack([t[:, 0] + b[:, 0], t[:, 1] + b[:, 1], b[:, 2]], axis=1)
    if kind == "rnm":
        n1 = np.stack([b[:, 0], b[:, 1], np.abs(b[:, 2]) + F32(1)], axis=1)
        n2 = t * np.array([-1, -1, 1], F32)
        r = n1 * ((n1 * n2).sum(axis=1, keepdims=True) / n1[:, 2:3]) - n2
        return r * np.stack([np.ones_like(b[:, 2]), np.ones_like(b[:, 2]), sign_or_one(b[:, 2])], axis=1)
    return np.stack([t[:, 0] + b[:, 0], t[:, 1] + b[:, 1], t[:, 2] * b[:, 2]], axis=1)


def decode_normal(texel, strength):
    """Tangent-space normal of ``[0, 1]`` texels (2 channels: ``z`` rebuilt), slopes × strength, unit."""
    x, y = texel[:, 0] * F32(2) - F32(1), texel[:, 1] * F32(2) - F32(1)
    if texel.shape[1] >= 3:
        z = texel[:, 2] * F32(2) - F32(1)
    else:
        r = F32(1) - x * x - y * y
        z = np.sqrt(np.maximum(r, F32(0)))
    return normalize(np.stack([x * F32(strength), y * F32(strength), z], axis=1))


#: Columns of a projection's (u, v, axis) frame in world order: X -> .zyx, Y -> .xzy, Z -> .xyz.
TO_WORLD = ((2, 1, 0), (0, 2, 1), (0, 1, 2))


def triplanar_normal_forward(state):
    """Whiteout (or UDN / RNM) triplanar normal mapping of a 3- or 4-channel normal map."""
    opts = state["options"]
    n = state["normal"]
    w = triplanar_weights(n, opts["sharpness"])
    unit = normalize(n)
    covered = state["mask"] != 0
    total = np.zeros((len(n), 3), F32)
    for axis in range(3):
        rows = np.flatnonzero(covered & (w[:, axis] > 0))
        uv, lod = project(state, axis, rows, opts["tiling"])
        texel = sample(state["chain"], uv[:, 0], uv[:, 1], lod)
        t = decode_normal(texel, opts["strength"])
        t[:, 0] *= u_sign(unit[rows], axis)
        b = unit[rows][:, list(PLANES[axis]) + [axis]]
        total[rows] += w[rows, axis, None] * blend_projected(t, b, opts["blend"])[:, list(TO_WORLD[axis])]
    length = np.sqrt((total * total).sum(axis=1, keepdims=True))
    out = np.where(length > F32(1e-12), total / np.where(length > 0, length, F32(1)), unit)
    return np.where((covered & np.isfinite(n).all(axis=1) & (np.abs(n).max(axis=1) > 0))[:, None], out, F32(0))


# -- splat ---------------------------------------------------------------------------------------------


def splat_forward(state):
    """Splat maps (bilinear, clamp, level 0, in UV0) weight the layers (trilinear, wrap, UV0 × tiling)."""
    layers, maps = state["chain"], state["maps"]
    uv, dx, dy = state["uv"], state["uv_dx"], state["uv_dy"]
    covered = np.flatnonzero(state["mask"] != 0)
    u, v = (np.clip(uv[covered, c], F32(-1), F32(2)) for c in (0, 1))
    count = layers.layers
    w = np.concatenate([bilinear(maps, u, v, 0, m, clamp=True) for m in range(-(-count // maps.channels))], axis=1)[:, :count]
    w = np.maximum(w, F32(0))
    w = w / np.maximum(w.sum(axis=1, keepdims=True), F32(1e-20))
    colour = np.zeros((len(covered), layers.channels), F32)
    for j in range(count):
        rows = np.flatnonzero(w[:, j] > 0)
        t = state["tiling"][j]
        px = covered[rows]
        luv = uv[px] * t
        value = sample(layers, luv[:, 0], luv[:, 1], lod_from_derivatives(layers, dx[px] * t, dy[px] * t), layer=j)
        colour[rows] += w[rows, j, None] * value
    out = np.zeros((len(uv), layers.channels), F32)
    out[covered] = colour
    return out


def _peer(technique, prepare, forward):
    note = "vectorised float32 NumPy, fancy-indexed gathers from a flat mip chain; forward only"
    return Peer("numpy", technique, prepare, forward, None, lambda r: np.asarray(r, F32), None, note)


def peers() -> dict[str, Peer]:
    from .numpy_stochastic import cheap2_forward, hash4_forward, hex_forward

    sample_prep = lambda t: (lambda data: _prepare_sample(data, t))  # noqa: E731
    table = {
        "bilinear": (sample_prep("bilinear"), bilinear_forward),
        "trilinear": (sample_prep("trilinear"), trilinear_forward),
        "triplanar": (_prepare_gbuffer("triplanar"), triplanar_forward),
        "biplanar": (_prepare_gbuffer("biplanar"), biplanar_forward),
        "triplanar_normal": (_prepare_gbuffer("triplanar_normal"), triplanar_normal_forward),
        "splat4": (_prepare_gbuffer("splat4"), splat_forward),
        "splat8": (_prepare_gbuffer("splat8"), splat_forward),
        "hash4": (sample_prep("hash4"), hash4_forward),
        "cheap2": (sample_prep("cheap2"), cheap2_forward),
        "hex": (sample_prep("hex"), hex_forward),
    }
    return {t: _peer(t, p, f) for t, (p, f) in table.items()}
