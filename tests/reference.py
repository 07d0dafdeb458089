"""Small NumPy references of the sampling formulas, written independently of the kernels.

They follow the formulas in the docstrings and the OpenGL specification in float64 and in a different form from the
Warp code (coordinate folding instead of index addressing, overlap matrices instead of loops), so
agreement means the formula is right, not merely that it was written twice the same way.
"""

import numpy as np

MODES = ("wrap", "clamp", "mirror", "border")


def texel_centres(h: int, w: int) -> np.ndarray:
    """UVs of every texel centre of an ``h × w`` image, shape ``(h, w, 2)``, float32."""
    i, j = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    return np.stack([(j + 0.5) / w, 1.0 - (i + 0.5) / h], axis=-1).astype(np.float32)


def _fold(u: np.ndarray, mode: str) -> np.ndarray:
    """Fold a coordinate into [0, 1] for wrap (sawtooth) and mirror (triangle wave)."""
    if mode == "wrap":
        return np.mod(u, 1.0)
    if mode == "mirror":
        m = np.mod(u, 2.0)
        return np.where(m > 1.0, 2.0 - m, m)
    return u


def _lookup(img: np.ndarray, rows: np.ndarray, cols: np.ndarray, mode: str, border) -> np.ndarray:
    """Texels at integer ``rows, cols``; wrap repeats, clamp/mirror clamp (mirror was folded), border pads."""
    h, w, c = img.shape
    if mode == "wrap":
        return img[np.mod(rows, h), np.mod(cols, w)]
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    values = img[np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)]
    if mode == "border":
        values = np.where(inside[..., None], values, np.asarray(border, np.float64)[:c])
    return values


def bilinear(img, uv, mode="wrap", border=(0.0, 0.0, 0.0, 0.0)) -> np.ndarray:
    """Bilinear sample of ``img`` (``[h, w, C]``) at ``uv`` (``[N, 2]``), float64 ``[N, C]``."""
    img = np.asarray(img, np.float64)
    h, w, _ = img.shape
    uv = np.asarray(uv, np.float64)
    u, v = _fold(uv[:, 0], mode), _fold(uv[:, 1], mode)
    x = u * w - 0.5
    y = (1.0 - v) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    c0, r0 = x0.astype(np.int64), y0.astype(np.int64)

    def at(r, c):
        return _lookup(img, r, c, mode, border)

    return (at(r0, c0) * (1 - fx) + at(r0, c0 + 1) * fx) * (1 - fy) + (at(r0 + 1, c0) * (1 - fx) + at(r0 + 1, c0 + 1) * fx) * fy


def nearest(img, uv, mode="wrap", border=(0.0, 0.0, 0.0, 0.0)) -> np.ndarray:
    """Nearest-texel sample, float64 ``[N, C]``."""
    img = np.asarray(img, np.float64)
    h, w, _ = img.shape
    uv = np.asarray(uv, np.float64)
    u, v = _fold(uv[:, 0], mode), _fold(uv[:, 1], mode)
    cols = np.floor(u * w).astype(np.int64)
    rows = np.floor((1.0 - v) * h).astype(np.int64)
    return _lookup(img, rows, cols, mode, border)


def _overlap(n_src: int, n_dst: int) -> np.ndarray:
    """``[n_dst, n_src]`` matrix: fraction of destination cell ``d`` covered by source cell ``s``."""
    scale = n_src / n_dst
    lo = np.arange(n_dst)[:, None] * scale
    s = np.arange(n_src)[None, :]
    return np.clip(np.minimum(lo + scale, s + 1) - np.maximum(lo, s), 0.0, None) / scale


def box_downsample(img) -> np.ndarray:
    """One box-filtered mip step (sides halved, rounded down, at least 1), by area overlap."""
    img = np.asarray(img, np.float64)
    h, w, _ = img.shape
    ay, ax = _overlap(h, max(1, h // 2)), _overlap(w, max(1, w // 2))
    return np.einsum("ah,hwc,bw->abc", ay, img, ax, optimize=True)


def mip_chain(img) -> list:
    """Every level of the box-filtered chain down to 1 × 1."""
    chain = [np.asarray(img, np.float64)]
    while chain[-1].shape[:2] != (1, 1):
        chain.append(box_downsample(chain[-1]))
    return chain


def trilinear(chain, uv, lod, mode="wrap") -> np.ndarray:
    """Trilinear sample with per-sample ``lod`` (already biased/clamped by the caller's rules)."""
    lod = np.clip(np.broadcast_to(np.asarray(lod, np.float64), (len(uv),)), 0.0, len(chain) - 1)
    lo = np.floor(lod).astype(np.int64)
    hi = np.minimum(lo + 1, len(chain) - 1)
    f = (lod - lo)[:, None]
    levels = [bilinear(level, uv, mode) for level in chain]
    pick = lambda idx: np.stack([levels[k][n] for n, k in enumerate(idx)])  # noqa: E731
    return pick(lo) * (1 - f) + pick(hi) * f


def lod_from_derivatives(uv_dx, uv_dy, h: int, w: int) -> np.ndarray:
    """``log2`` of the longer screen-space derivative measured in level-0 texels."""
    size = np.array([w, h], np.float64)
    a = np.linalg.norm(np.asarray(uv_dx, np.float64) * size, axis=-1)
    b = np.linalg.norm(np.asarray(uv_dy, np.float64) * size, axis=-1)
    return np.log2(np.maximum(a, b))


def anisotropic_footprint(uv_dx, uv_dy, h: int, w: int, max_aniso: int = 16):
    """``(lod, step, taps)`` of the anisotropic filter, in float64: the ellipse of the Jacobian
    ``J = [uv_dx · size, uv_dy · size]`` by its singular values (an SVD here, not the kernels'
    closed form), the LOD of the minor axis raised to ``major / max_aniso``, ``ceil(major / 2^lod)``
    taps along the major axis ``2^lod`` apart at most, ``step`` in UV."""
    size = np.array([w, h], np.float64)
    a = np.asarray(uv_dx, np.float64) * size
    b = np.asarray(uv_dy, np.float64) * size
    jac = np.stack([a, b], axis=-1)  # [..., 2 (u, v), 2 (dx, dy)]
    u, s, _ = np.linalg.svd(jac)
    major, minor = s[..., 0], s[..., 1]
    extent = np.maximum(minor, major / max_aniso)
    taps = np.clip(np.ceil(major / extent - 1e-3), 1, max_aniso)
    step = u[..., :, 0] * (major / taps)[..., None] / size
    return np.log2(extent), step, taps.astype(np.int64)


def anisotropic(chain, uv, uv_dx, uv_dy, mode="wrap", max_aniso: int = 16) -> np.ndarray:
    """The anisotropic filter: the mean of ``taps`` trilinear samples at ``uv + step · (k + 1/2 -
    taps/2)``, all at the footprint's LOD."""
    h, w = chain[0].shape[:2]
    lod, step, taps = anisotropic_footprint(uv_dx, uv_dy, h, w, max_aniso)
    uv = np.asarray(uv, np.float64)
    out = np.zeros((len(uv), chain[0].shape[2]))
    for k in range(int(taps.max())):
        live = k < taps
        at = uv[live] + step[live] * (k + 0.5 - 0.5 * taps[live])[:, None]
        out[live] += trilinear(chain, at, lod[live], mode)
    return out / taps[:, None]
