"""Texture-array layers blended by splat maps (terrain texturing), with height-based blending.

Per pixel, the splat maps are read in UV0 (bilinear on level 0, clamped at the edges, so texel
centres return their texel exactly): channel ``c`` of map ``m`` is the weight of layer
``m · C + c``. Negative weights are clamped to 0. With ``normalize`` the weights are divided by
their sum (all-zero weights give weight 0 everywhere, so the output is 0). Each layer with a
non-zero weight is sampled with its own tiling, in UV0, on world XZ, or triplanar, and the
samples are blended.

Height-based blending (Unity TerrainLit; DESIGN.md §3), with transition ``t > 0``::

    h_j = height_j · w_j;   m = max_j h_j;   wh_j = max(0, h_j + t - m);   w'_j = wh_j · w_j / Σ_k wh_k · w_k

where ``height_j`` is read at layer ``j``'s UV from a channel of the layer itself or from a
separate height array. Small ``t`` gives sharp, height-driven borders; large ``t`` tends to the
plain blend.

The kernels are made per layer count and splat channel count (:func:`splat_kernel`), so every
per-layer loop is unrolled at compile time and the local weight, height and colour storage has
exactly the size it needs.
"""

import functools

import warp as wp

from .sampling import Sampler, TextureView, lod_from_derivatives, sample_lod, write_channels
from .stochastic import StochasticParams, sample_stochastic
from .triplanar import Projection, plane_lod, plane_uv, triplanar_sample, triplanar_weights

PROJECT_UV = wp.constant(0)  # UV0 × tiling
PROJECT_WORLD_XZ = wp.constant(1)  # the triplanar top projection, (-x, z) × tiling
PROJECT_TRIPLANAR = wp.constant(2)

HEIGHT_NONE = wp.constant(0)
HEIGHT_CHANNEL = wp.constant(1)  # a channel of each layer
HEIGHT_ARRAY = wp.constant(2)  # a separate one-channel array of L layers

SPLAT_EPS = wp.constant(1.0e-20)


@wp.struct
class SplatParams:
    """Options of a splat blend. ``tiling`` holds 1 or L values and ``transition`` 1, as arrays
    so that a ``wp.Tape`` carries gradients into them."""

    tiling: wp.array(dtype=float)
    transition: wp.array(dtype=float)
    projection: wp.int32
    height_mode: wp.int32
    height_channel: wp.int32
    normalize: wp.int32


@wp.func
def layer_tiling(params: SplatParams, layer: wp.int32) -> float:
    return params.tiling[wp.min(layer, params.tiling.shape[0] - 1)]


@wp.func
def sample_layer(
    tex: TextureView,
    layer: wp.int32,
    params: SplatParams,
    proj: Projection,
    uv0: wp.vec2,
    uv0_dx: wp.vec2,
    uv0_dy: wp.vec2,
    p: wp.vec3,
    n: wp.vec3,
    tri_w: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    smp: Sampler,
    stoch: StochasticParams,
) -> wp.vec4:
    """Layer ``layer`` of ``tex`` with that layer's tiling, in the splat's projection, sampled as
    ``stoch`` says (plain for ``METHOD_NONE``)."""
    t = layer_tiling(params, layer)
    value = wp.vec4(0.0)
    if params.projection == PROJECT_UV:
        value = sample_stochastic(tex, layer, uv0 * t, lod_from_derivatives(tex, uv0_dx * t, uv0_dy * t), smp, stoch)
    elif params.projection == PROJECT_WORLD_XZ:
        up = wp.vec3(0.0, 1.0, 0.0)
        value = sample_stochastic(tex, layer, plane_uv(proj, 1, p, up, t), plane_lod(tex, 1, dpdx, dpdy, t), smp, stoch)
    else:
        value = triplanar_sample(tex, layer, proj, tri_w, p, n, dpdx, dpdy, t, smp, stoch)
    return value


@functools.cache
def splat_kernel(num_layers: int, map_channels: int):
    """The splat kernel for ``num_layers`` layers whose weights come ``map_channels`` per map."""
    weights_t = wp.types.vector(length=num_layers, dtype=float)
    colours_t = wp.types.matrix(shape=(num_layers, 4), dtype=float)

    # Per-layer loops unroll. Components are only ever written once into fresh vectors (Warp's
    # in-place component writes have exact adjoints then, but not when they overwrite a value).
    @wp.kernel(module="unique", module_options={"max_unroll": max(16, num_layers)})
    def kernel(
        layers: TextureView,
        heights: TextureView,
        maps: TextureView,
        uv0: wp.array(dtype=wp.vec2),
        uv0_dx: wp.array(dtype=wp.vec2),
        uv0_dy: wp.array(dtype=wp.vec2),
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        params: SplatParams,
        proj: Projection,
        smp: Sampler,
        map_smp: Sampler,
        stoch: StochasticParams,
        height_stoch: StochasticParams,
        out: wp.array2d(dtype=float),
    ):
        i = wp.tid()
        colour = wp.vec4(0.0)
        if mask[i] != 0.0:
            uv = uv0[i]
            p = position[i]
            n = normal[i]
            tri_w = wp.vec3(0.0)
            if params.projection == PROJECT_TRIPLANAR:
                tri_w = triplanar_weights(n, proj.sharpness[0])

            # Weights from the splat maps, one bilinear read per map.
            w = weights_t()
            texel = wp.vec4(0.0)
            for j in range(wp.static(num_layers)):
                if j % wp.static(map_channels) == 0:
                    texel = sample_lod(maps, j // wp.static(map_channels), uv, 0.0, map_smp)
                w[j] = wp.max(texel[j % wp.static(map_channels)], 0.0)
            if params.normalize != 0:
                w = w / wp.max(wp.dot(w, weights_t(1.0)), SPLAT_EPS)

            # Every layer with weight, and its height when blending by height.
            c = colours_t()
            h = weights_t()
            for j in range(wp.static(num_layers)):
                if w[j] > 0.0:
                    value = sample_layer(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, stoch)
                    c[j] = value
                    if params.height_mode == HEIGHT_CHANNEL:
                        h[j] = value[params.height_channel] * w[j]
                    elif params.height_mode == HEIGHT_ARRAY:
                        height = sample_layer(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, height_stoch)
                        h[j] = height[0] * w[j]

            if params.height_mode != HEIGHT_NONE:
                top = -1.0e30
                for j in range(wp.static(num_layers)):
                    if w[j] > 0.0:
                        top = wp.max(top, h[j])
                t = params.transition[0]
                wh = weights_t()
                for j in range(wp.static(num_layers)):
                    wh[j] = wp.max(h[j] + t - top, 0.0)
                w = wp.cw_mul(wh, w)
                w = w / wp.max(wp.dot(w, weights_t(1.0)), SPLAT_EPS)

            for j in range(wp.static(num_layers)):
                colour += w[j] * c[j]
        write_channels(out, i, colour)

    return kernel
