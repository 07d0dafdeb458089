"""NumPy references of the stochastic samplers, in float64, written apart from the kernels.

Different in form from the Warp code on purpose: taps use the full UV (``s * uv + o``) where the
kernels use a reduced base coordinate, the four hash4 weights come from an outer product, and the
hex triangle and its barycentric weights come from solving a 2 × 2 system with the vertex
positions instead of the closed form. Texture reads use :mod:`reference` (bilinear/trilinear).
"""

import numpy as np

import reference as ref

U32 = np.uint32
STREAM_HASH4_CELL, STREAM_CHEAP2_OFFSET, STREAM_CHEAP2_NOISE, STREAM_HEX_VERTEX = 0, 1, 2, 3
HEX_SCALE = 2.0 * np.sqrt(3.0)


def pcg4d(a, b, c, d) -> np.ndarray:
    """Jarzynski & Olano's pcg4d on uint32 arrays; returns ``[..., 4]`` uint32."""
    v = [np.asarray(x).astype(np.int64).astype(U32) for x in np.broadcast_arrays(a, b, c, d)]
    with np.errstate(over="ignore"):
        v = [x * U32(1664525) + U32(1013904223) for x in v]
        for rnd in range(2):
            v[0] = v[0] + v[1] * v[3]
            v[1] = v[1] + v[2] * v[0]
            v[2] = v[2] + v[0] * v[1]
            v[3] = v[3] + v[1] * v[2]
            if rnd == 0:
                v = [x ^ (x >> U32(16)) for x in v]
    return np.stack(v, axis=-1)


def hash4_unit(x, y, seed, stream) -> np.ndarray:
    """Four uniform numbers in [0, 1) per lattice point: top 24 bits of each pcg4d lane."""
    return (pcg4d(x, y, seed, stream) >> U32(8)).astype(np.float64) / 2.0**24


def smoothstep(lo, hi, x):
    t = np.clip((np.asarray(x, np.float64) - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _read(chain, uv, lod, filt):
    """Sample the float64 mip chain at ``uv`` [N, 2] (wrap): bilinear on level round(lod) or trilinear."""
    if filt == "trilinear":
        return ref.trilinear(chain, uv, lod)
    level = int(np.floor(np.clip(lod, 0, len(chain) - 1) + 0.5))
    return ref.bilinear(chain[level], uv, "wrap")


def _offset_tap(uv, h, mirror):
    s = np.where(h[:, 2:4] < 0.5, -1.0, 1.0) if mirror else np.ones_like(uv)
    return s * uv + h[:, :2]


def hash4(chain, uv, *, seed=0, blend=(0.25, 0.75), mirror=False, lod=0.0, filt="bilinear"):
    """hash4 at ``uv`` [N, 2]: Σ over the 4 cells (i + di, j + dj) of outer-product weights × taps."""
    uv = np.asarray(uv, np.float64)
    cell = np.floor(uv).astype(np.int64)
    b = smoothstep(blend[0], blend[1], uv - cell)
    w1d = np.stack([1.0 - b, b], axis=1)  # [N, 2 (which corner), 2 (axis)]
    out = 0.0
    for di in (0, 1):
        for dj in (0, 1):
            h = hash4_unit(cell[:, 0] + di, cell[:, 1] + dj, seed, STREAM_HASH4_CELL)
            w = w1d[:, di, 0] * w1d[:, dj, 1]
            out = out + w[:, None] * _read(chain, _offset_tap(uv, h, mirror), lod, filt)
    return out


def value_noise(p, seed):
    """Smooth value noise: bilinear interpolation of hashed lattice values with smoothstep weights."""
    cell = np.floor(p).astype(np.int64)
    s = smoothstep(0.0, 1.0, p - cell)
    corner = lambda dx, dy: hash4_unit(cell[:, 0] + dx, cell[:, 1] + dy, seed, STREAM_CHEAP2_NOISE)[:, 0]  # noqa: E731
    bottom = corner(0, 0) + (corner(1, 0) - corner(0, 0)) * s[:, 0]
    top = corner(0, 1) + (corner(1, 1) - corner(0, 1)) * s[:, 0]
    return bottom + (top - bottom) * s[:, 1]


def cheap2(chain, uv, *, seed=0, blend=(0.2, 0.8), mirror=False, frequency=0.5, levels=8.0, lod=0.0, filt="bilinear"):
    """cheap2: taps of offset indices floor(l) and floor(l) + 1, ``l = noise(uv * frequency) * levels``."""
    uv = np.asarray(uv, np.float64)
    l = value_noise(uv * frequency, seed) * levels
    ia = np.floor(l).astype(np.int64)
    t = smoothstep(blend[0], blend[1], l - ia)[:, None]
    ha = hash4_unit(ia, 0, seed, STREAM_CHEAP2_OFFSET)
    hb = hash4_unit(ia + 1, 0, seed, STREAM_CHEAP2_OFFSET)
    return (1.0 - t) * _read(chain, _offset_tap(uv, ha, mirror), lod, filt) + t * _read(chain, _offset_tap(uv, hb, mirror), lod, filt)


def hex_vertex_uv(v):
    """UV of triangle-grid vertices ``v`` [..., 2]: ``i * e1 + j * e2`` with unit equilateral edges, scaled."""
    e1, e2 = np.array([1.0, 0.0]), np.array([0.5, np.sqrt(3.0) / 2.0])
    return (v[..., :1] * e1 + v[..., 1:] * e2) / HEX_SCALE


def hex_triangle(uv):
    """Vertices [N, 3, 2] of the triangle containing ``uv`` and barycentric weights [N, 3] by a linear solve."""
    uv = np.asarray(uv, np.float64)
    # Lattice coordinates: solve uv = hex_vertex_uv(st) for real st, then pick the triangle.
    basis = np.stack([hex_vertex_uv(np.array([1.0, 0.0])), hex_vertex_uv(np.array([0.0, 1.0]))], axis=1)
    st = np.linalg.solve(basis, uv.T).T
    b = np.floor(st).astype(np.int64)
    upper = (st - b).sum(axis=1) >= 1.0
    offsets = np.where(upper[:, None, None], [[1, 1], [1, 0], [0, 1]], [[0, 0], [1, 0], [0, 1]])
    verts = b[:, None, :] + offsets
    # Barycentric weights: [p1 - p0, p2 - p0] λ = uv - p0.
    p = hex_vertex_uv(verts.astype(np.float64))
    m = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=-1)
    lam = np.linalg.solve(m, (uv - p[:, 0])[..., None])[..., 0]
    return verts, np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)


def hex_taps(uv, *, seed=0, contrast=1.0, rotation=0.0):
    """Weights [N, 3] (barycentric ** contrast, normalised), vertices [N, 3, 2], tap UVs [N, 3, 2] (full UV)."""
    uv = np.asarray(uv, np.float64)
    verts, bary = hex_triangle(uv)
    w = np.clip(bary, 0.0, None) ** contrast
    w /= w.sum(axis=1, keepdims=True)
    taps = np.empty(verts.shape)
    for k in range(3):
        h = hash4_unit(verts[:, k, 0], verts[:, k, 1], seed, STREAM_HEX_VERTEX)
        c = hex_vertex_uv(verts[:, k].astype(np.float64))
        theta = (2.0 * h[:, 2] - 1.0) * np.pi * rotation
        rot = np.stack([np.stack([np.cos(theta), -np.sin(theta)], -1), np.stack([np.sin(theta), np.cos(theta)], -1)], -2)
        taps[:, k] = np.einsum("nij,nj->ni", rot, uv - c) + c + h[:, :2]
    return w, verts, taps


def hex_sample(chain, uv, *, seed=0, contrast=1.0, rotation=0.0, lut=None, basis=None, centre=None, lod=0.0, filt="bilinear"):
    """hex: linear blend of the 3 taps, or (``lut`` [levels, C, n]) the variance-preserving Gaussian
    blend and the inverse LUT of the level(s) read (one constant ``lod``)."""
    w, _, taps = hex_taps(uv, seed=seed, contrast=contrast, rotation=rotation)
    values = np.stack([_read(chain, taps[:, k], lod, filt) for k in range(3)], axis=1)  # [N, 3, C]
    if lut is None:
        return np.einsum("nk,nkc->nc", w, values)
    g = np.einsum("nk,nkc->nc", w, values - 0.5) / np.sqrt((w**2).sum(axis=1, keepdims=True)) + 0.5
    n = lut.shape[-1]
    grid = -0.5 + (np.arange(n) + 0.5) / n * 2.0  # the LUT spans mean ± 6 std = [-0.5, 1.5]
    invert = lambda k: np.stack([np.interp(g[:, c], grid, lut[k, c]) for c in range(lut.shape[1])], axis=1)  # noqa: E731
    level = float(np.clip(lod, 0, len(chain) - 1))
    if filt == "trilinear":  # the LUTs of the two levels read, blended like the texels
        k, f = int(np.floor(level)), level - np.floor(level)
        out = invert(k) if f == 0 else (1 - f) * invert(k) + f * invert(k + 1)
    else:
        out = invert(int(np.floor(level + 0.5)))
    if basis is not None:
        out[:, :3] = out[:, :3] @ np.asarray(basis, np.float64).T + centre
    return out
