"""NumPy reference of triplanar / biplanar mapping and triplanar normal mapping, in float64.

Written from the formulas (Golus 2017, with warptex's right-handed mirror signs), not
from the kernels, and in a different form: every pixel at once, the three projections stacked on a
leading axis, masks and index arrays instead of per-pixel branches and swizzle cases. Sampling uses
:mod:`reference` (box mip chain, bilinear, trilinear).

Conventions. Projection ``a`` (0 = X, 1 = Y, 2 = Z) sees the plane coordinates
``PLANES[a] = (zy, xz, xy)``; its ``u`` is multiplied by the mirror sign
``MIRROR[a] · sign(n[a])`` (``sign(0) = +1``), i.e. ``-sign(n.x)``, ``-sign(n.y)``, ``+sign(n.z)``.
"""

from __future__ import annotations

import numpy as np

import reference as ref

#: World components of the (u, v, axis) frame of each projection: X -> (z, y, x), Y -> (x, z, y), Z -> (x, y, z).
FRAMES = np.array([[2, 1, 0], [0, 2, 1], [0, 1, 2]])
PLANES = FRAMES[:, :2]
MIRROR = np.array([-1.0, -1.0, 1.0])
BIPLANAR_EDGE = 0.5773
EPS = 1e-20


def _f64(a) -> np.ndarray:
    return np.asarray(a, np.float64)


def sign_or_one(x: np.ndarray) -> np.ndarray:
    """``sign`` with ``sign(0) = +1`` (and +1 for NaN, which only ever meets a zero weight)."""
    return np.where(x < 0, -1.0, 1.0)


def triplanar_weights(n, sharpness) -> np.ndarray:
    """``|n|^k / Σ|n|^k`` per pixel, ``[N, 3]``; 0 for zero or non-finite normals.

    ``|n|`` is scaled by its largest component first (the ratio is unchanged; only the underflow
    of ``|n|^k`` for tiny normals or huge ``k`` is avoided). ``0^0 = 1``.
    """
    n = _f64(n)
    a = np.abs(n)
    valid = np.isfinite(n).all(axis=1) & (np.nan_to_num(a, nan=0.0, posinf=0.0).max(axis=1) > 0)
    a = np.where(valid[:, None], a, 0.0)
    m = np.where(valid, a.max(axis=1), 1.0)
    w = np.power(a / m[:, None], float(sharpness))  # numpy: 0.0 ** 0.0 == 1.0
    w = w / np.maximum(w.sum(axis=1, keepdims=True), EPS)
    return np.where(valid[:, None], w, 0.0)


def biplanar_weights(n, sharpness) -> np.ndarray:
    """Quilez' biplanar weights, ``[N, 3]``: major and median axes remapped, minor axis 0."""
    n = _f64(n)
    valid = np.isfinite(n).all(axis=1)
    n = np.where(valid[:, None], n, 0.0)
    length = np.linalg.norm(n, axis=1)
    valid &= length > 0
    a = np.abs(n) / np.where(valid, length, 1.0)[:, None]
    # The minor axis is the smallest component; among ties the last one (a stable sort, reversed).
    minor = 2 - np.argmin(a[:, ::-1], axis=1)
    keep = np.arange(3)[None, :] != minor[:, None]
    r = np.clip((a - BIPLANAR_EDGE) / (1.0 - BIPLANAR_EDGE), 0.0, 1.0)
    w = np.where(keep, np.power(r, float(sharpness) / 8.0), 0.0)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), EPS)
    return np.where(valid[:, None], w, 0.0)


def to_object(p, n, dpdx, dpdy, object_to_world=None):
    """Positions and derivatives by ``M⁻¹``, normals by ``Lᵀ`` (the inverse transpose of ``M⁻¹``)."""
    p, n, dpdx, dpdy = (_f64(x) for x in (p, n, dpdx, dpdy))
    if object_to_world is None:
        return p, n, dpdx, dpdy
    m = _f64(np.asarray(object_to_world, np.float32))  # the API takes the matrix as float32
    inv = np.linalg.inv(m)
    lin = inv[:3, :3]
    return p @ lin.T + inv[:3, 3], n @ m[:3, :3], dpdx @ lin.T, dpdy @ lin.T


def _tilings(tiling) -> np.ndarray:
    return np.broadcast_to(_f64(tiling).reshape(-1), (3,)).copy()


def projection_uvs(p, n, tiling=1.0, offsets=None, mirror_fix=True) -> np.ndarray:
    """UVs of the three projections, ``[3, N, 2]``."""
    t = _tilings(tiling)
    off = np.zeros((3, 2)) if offsets is None else _f64(offsets).reshape(3, 2)
    coords = p[:, PLANES].transpose(1, 0, 2) * t[:, None, None]  # [3, N, 2]
    s = MIRROR[:, None] * sign_or_one(n).T if mirror_fix else np.ones((3, len(p)))
    return np.stack([coords[..., 0] * s, coords[..., 1]], axis=-1) + off[:, None, :]


def projection_lods(dpdx, dpdy, tiling, sizes) -> np.ndarray:
    """Unclamped LOD of each projection, ``[3, N]``; ``sizes[a] = (H, W)`` of projection a's level 0."""
    t = _tilings(tiling)
    out = []
    for a in range(3):
        h, w = sizes[a]
        with np.errstate(divide="ignore"):
            out.append(ref.lod_from_derivatives(dpdx[:, PLANES[a]] * t[a], dpdy[:, PLANES[a]] * t[a], h, w))
    return np.stack(out)


def sample_projections(chains, uvs, lods, *, filter="trilinear", address="wrap", lod_bias=0.0, min_lod=0.0, max_lod=np.inf) -> np.ndarray:
    """Sample every projection ``a`` from ``chains[a]`` (a reference mip chain), ``[3, N, C]``."""
    out = []
    for a in range(3):
        lod = np.clip(np.nan_to_num(lods[a] + lod_bias, neginf=-1e30), min_lod, max_lod)
        if filter == "trilinear":
            out.append(ref.trilinear(chains[a], uvs[a], lod, address))
        elif filter == "bilinear":
            level = np.floor(np.clip(lod, 0, len(chains[a]) - 1) + 0.5).astype(int)
            per_level = np.stack([ref.bilinear(c, uvs[a], address) for c in chains[a]])
            out.append(per_level[level, np.arange(len(level))])
        else:
            raise ValueError(filter)
    return np.stack(out)


def _inputs(gbuffer: dict, object_to_world):
    covered = gbuffer["mask"].reshape(-1) != 0
    flat = {k: gbuffer[k].reshape(-1, 3)[covered] for k in ("position", "normal", "position_dx", "position_dy")}
    p, n, dx, dy = to_object(flat["position"], flat["normal"], flat["position_dx"], flat["position_dy"], object_to_world)
    return covered, p, n, dx, dy


def _chains(images, layer):
    """Per projection: the mip chain of ``images[a]`` (an ``[L, H, W, C]`` or ``[H, W, C]`` array)."""
    chains, cache = [], {}
    for img in images:
        key = id(img)
        if key not in cache:
            arr = _f64(img)
            cache[key] = ref.mip_chain(arr[layer] if arr.ndim == 4 else arr)
        chains.append(cache[key])
    return chains


def _samples(images, layer, n, uvs, dx, dy, tiling, sampler) -> np.ndarray:
    """``[3, N, C]``: what each projection reads. ``images``: three (X, Y, Z projections) or six
    (faces ``+X, -X, +Y, -Y, +Z, -Z``); with six, every face's texture is sampled everywhere and
    projection ``a`` keeps the ``-a`` face's sample where ``n[a] < 0``, the ``+a`` face's elsewhere."""
    if len(images) == 3:
        chains = _chains(images, layer)
        lods = projection_lods(dx, dy, tiling, [c[0].shape[:2] for c in chains])
        return sample_projections(chains, uvs, lods, **sampler)
    assert len(images) == 6, "three projections or six faces"
    per_sign = []
    for first in (0, 1):  # the + faces, then the - faces
        chains = _chains(images[first::2], layer)
        lods = projection_lods(dx, dy, tiling, [c[0].shape[:2] for c in chains])
        per_sign.append(sample_projections(chains, uvs, lods, **sampler))
    negative = (n < 0).T[..., None]  # [3, N, 1]; NaN compares False: the + face
    return np.where(negative, per_sign[1], per_sign[0])


def triplanar(gbuffer: dict, images, *, tiling=1.0, sharpness=4.0, offsets=None, mirror_fix=True, biplanar=False, layer=0, object_to_world=None, **sampler) -> np.ndarray:
    """Reference of ``warptex.triplanar`` (``biplanar=True``: ``warptex.biplanar``).

    Args:
        gbuffer: ``GBuffer.numpy()``.
        images: three level-0 images (X, Y, Z projections) or six (faces ``+X, -X, +Y, -Y, +Z,
            -Z``, chosen by the sign of the projected-space normal), ``[H, W, C]`` or ``[L, H, W, C]``.
        sampler: ``filter``, ``address``, ``lod_bias``, ``min_lod``, ``max_lod``.

    Returns:
        ``[H, W, C]`` float64.
    """
    covered, p, n, dx, dy = _inputs(gbuffer, object_to_world)
    w = (biplanar_weights if biplanar else triplanar_weights)(n, sharpness)
    uvs = projection_uvs(p, n, tiling, offsets, mirror_fix)
    samples = _samples(images, layer, n, uvs, dx, dy, tiling, sampler)
    colour = np.where(w.T[..., None] > 0, w.T[..., None] * samples, 0.0).sum(axis=0)
    out = np.zeros(gbuffer["mask"].shape + (colour.shape[-1],))
    out.reshape(-1, colour.shape[-1])[covered] = colour
    return out


def decode_normals(texels, *, strength=1.0, flip_green=False) -> np.ndarray:
    """Tangent-space normals from ``[..., C]`` texels (C >= 2), strength applied, unit length."""
    texels = _f64(texels)
    x = 2 * texels[..., 0] - 1
    y = (2 * texels[..., 1] - 1) * (-1.0 if flip_green else 1.0)
    if texels.shape[-1] >= 3:
        z = 2 * texels[..., 2] - 1
    else:
        z = np.sqrt(np.maximum(0.0, 1 - x * x - y * y))
    t = np.stack([x * strength, y * strength, z], axis=-1)
    length = np.linalg.norm(t, axis=-1, keepdims=True)
    return np.where(length > 0, t / np.where(length > 0, length, 1.0), 0.0)


def blend(t, b, kind: str) -> np.ndarray:
    """Whiteout / UDN / RNM of tangent normals ``t`` onto base normals ``b`` (same frame), ``[..., 3]``."""
    xy = t[..., :2] + b[..., :2]
    if kind == "whiteout":
        return np.concatenate([xy, (t[..., 2] * b[..., 2])[..., None]], axis=-1)
    if kind == "udn":
        return np.concatenate([xy, b[..., 2:3]], axis=-1)
    if kind == "rnm":
        n1 = np.concatenate([b[..., :2], np.abs(b[..., 2:3]) + 1], axis=-1)
        n2 = t * np.array([-1.0, -1.0, 1.0])
        r = n1 * (np.sum(n1 * n2, axis=-1, keepdims=True) / n1[..., 2:3]) - n2
        return r * np.concatenate([np.ones_like(b[..., :2]), sign_or_one(b[..., 2:3])], axis=-1)
    raise ValueError(kind)


def triplanar_normal(
    gbuffer: dict,
    images,
    *,
    tiling=1.0,
    sharpness=4.0,
    offsets=None,
    mirror_fix=True,
    biplanar=False,
    layer=0,
    blend_kind="whiteout",
    strength=1.0,
    flip_green=False,
    object_to_world=None,
    **sampler,
) -> np.ndarray:
    """Reference of ``warptex.triplanar_normal``: unit world normals ``[H, W, 3]``, 0 off the mask.
    ``images``: as for :func:`triplanar` (three projections or six faces).

    The surface normal is used at unit length in the blends (in object space it is renormalised
    after the inverse-transpose transform, which does not keep lengths).
    """
    covered, p, n, dx, dy = _inputs(gbuffer, object_to_world)
    w = (biplanar_weights if biplanar else triplanar_weights)(n, sharpness)
    uvs = projection_uvs(p, n, tiling, offsets, mirror_fix)
    texels = _samples(images, layer, n, uvs, dx, dy, tiling, sampler)  # [3, N, C]
    t = decode_normals(texels, strength=strength, flip_green=flip_green)
    if mirror_fix:
        t[..., 0] *= MIRROR[:, None] * sign_or_one(n).T
    length = np.linalg.norm(np.nan_to_num(n), axis=1, keepdims=True)
    unit = np.nan_to_num(n) / np.where(length > 0, length, 1.0)
    base = unit[:, FRAMES].transpose(1, 0, 2)  # [3, N, 3]: (plane u, plane v, axis) components
    r = blend(t, base, blend_kind)
    world = np.zeros_like(r)
    np.put_along_axis(world, np.broadcast_to(FRAMES[:, None, :], r.shape), r, axis=-1)  # world[FRAMES[a]] = r
    total = np.where(w.T[..., None] > 0, w.T[..., None] * world, 0.0).sum(axis=0)
    if object_to_world is not None:
        lin = _f64(np.asarray(object_to_world, np.float32))[:3, :3]
        total = total @ np.linalg.inv(lin)  # inv(L)ᵀ applied to row vectors
        unit = unit @ np.linalg.inv(lin)
    length = np.linalg.norm(total, axis=1, keepdims=True)
    ulen = np.linalg.norm(unit, axis=1, keepdims=True)
    result = np.where(length > 1e-12, total / np.where(length > 0, length, 1.0), np.where(ulen > 0, unit / np.where(ulen > 0, ulen, 1.0), 0.0))
    result = np.where(w.sum(axis=1, keepdims=True) > 0, result, 0.0)
    out = np.zeros(gbuffer["mask"].shape + (3,))
    out.reshape(-1, 3)[covered] = result
    return out
