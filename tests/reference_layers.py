"""A NumPy reference of splat-map layer blending (as Unity's TerrainLit blends), in float64.

Written as whole-image array operations (every layer sampled everywhere, weights as ``[N, L]``
matrices), unlike the per-pixel kernel that skips zero-weight layers.
"""

import numpy as np

from reference import bilinear, lod_from_derivatives, mip_chain, trilinear


def _sign(x):
    return np.where(x < 0, -1.0, 1.0)


def _trilinear_at(chain, uv, uv_dx, uv_dy):
    h, w = chain[0].shape[:2]
    return trilinear(chain, uv, lod_from_derivatives(uv_dx, uv_dy, h, w), "wrap")


def _layer_samples(chain, g, t, projection, sharpness, face_chains=None):
    """``[N, C]`` samples of one layer's mip ``chain`` at tiling ``t`` for every pixel.

    ``face_chains`` (triplanar only): six mip chains, faces ``+x, -x, +y, -y, +z, -z``; projection
    ``a`` then reads chain ``2a + 1`` where ``n[a] < 0``, chain ``2a`` elsewhere, instead of ``chain``."""
    if projection == "uv":
        return _trilinear_at(chain, g["uv"] * t, g["uv_dx"] * t, g["uv_dy"] * t)
    p, n, dx, dy = g["position"], g["normal"], g["position_dx"], g["position_dy"]
    planes = {0: [2, 1], 1: [0, 2], 2: [0, 1]}
    if projection == "world_xz":
        # The triplanar top projection of an upward-facing surface: u = -x.
        uv = p[:, planes[1]] * t * [-1.0, 1.0]
        return _trilinear_at(chain, uv, dx[:, planes[1]] * t, dy[:, planes[1]] * t)
    a = np.abs(n)
    w = np.where(a > 0, a ** sharpness, 0.0)
    w = w / np.maximum(w.sum(-1, keepdims=True), 1e-300)
    flips = {0: -_sign(n[:, 0]), 1: -_sign(n[:, 1]), 2: _sign(n[:, 2])}
    total = 0.0
    for axis in range(3):
        uv = p[:, planes[axis]] * t
        uv[:, 0] *= flips[axis]
        derivatives = (dx[:, planes[axis]] * t, dy[:, planes[axis]] * t)
        if face_chains is None:
            sample = _trilinear_at(chain, uv, *derivatives)
        else:
            plus, minus = (_trilinear_at(face_chains[2 * axis + k], uv, *derivatives) for k in (0, 1))
            sample = np.where(n[:, axis : axis + 1] < 0, minus, plus)
        total = total + w[:, axis : axis + 1] * sample
    return total


def splat_reference(g, layers, maps, *, tiling, projection="uv", normalize=True, transition=None, heights=None, height_channel=3, sharpness=4.0, layers_per_face=None):
    """Expected ``splat()`` output ``[N, C]`` for flattened G-buffer arrays ``g`` (covered pixels only).

    ``layers``: ``[L, h, w, C]``; ``maps``: ``[M, hm, wm, Cm]``; ``heights``: ``[L, hh, wh, 1]`` or None;
    ``layers_per_face``: ``[L, 6]`` array layers read per face (``+x, -x, +y, -y, +z, -z``) or None.
    """
    num_layers = len(layers)
    tiling = np.broadcast_to(np.asarray(tiling, np.float64), (num_layers,))
    per_map = [bilinear(m, g["uv"], "clamp") for m in maps]
    w = np.clip(np.concatenate(per_map, axis=-1)[:, :num_layers], 0.0, None)
    if normalize:
        w = w / np.maximum(w.sum(-1, keepdims=True), 1e-20)
    chains = [mip_chain(layer) for layer in layers]
    height_chains = None if heights is None else [mip_chain(h) for h in heights]

    def faces(source, j):
        return None if layers_per_face is None else [source[int(k)] for k in layers_per_face[j]]

    samples = np.stack([_layer_samples(chains[j], g, tiling[j], projection, sharpness, faces(chains, j)) for j in range(num_layers)], axis=1)
    if transition is not None:
        if heights is None:
            height = samples[..., height_channel]
        else:
            height = np.stack([_layer_samples(height_chains[j], g, tiling[j], projection, sharpness, faces(height_chains, j))[:, 0] for j in range(num_layers)], axis=1)
        h = height * w
        top = np.where(w > 0, h, -np.inf).max(axis=-1, keepdims=True)
        top = np.where(np.isfinite(top), top, 0.0)  # no layer has weight: the output is 0 anyway
        w = np.maximum(h + transition - top, 0.0) * w
        w = w / np.maximum(w.sum(-1, keepdims=True), 1e-20)
    return np.einsum("nl,nlc->nc", w, samples)
