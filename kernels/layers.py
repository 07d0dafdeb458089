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

The kernels are made per layer count and splat channel count (:func:`splat_kernels`), so every
per-layer loop is unrolled at compile time and the local weight, height and colour storage has
exactly the size it needs.

**Hand-written gradient.** Warp's generated adjoint replays each sampling function's forward pass
inside its reverse pass (about 5× the forward here). Where only texels, the transition and, with
plain sampling, the tiling need gradients (no sharpness, offsets or G-buffer gradients) and every
blend of taps is linear (no histogram), :func:`splat_kernels`' second kernel computes them
directly: per pixel it replays the forward once, takes the blend's derivatives by hand, and adds
each layer's colour gradient into the texels the layer read (:func:`add_layer_gradient`), each
weight's into the splat-map texels, and each layer's colour gradient times the sample's derivative
along its tiling (:func:`sample_layer_slope`) into the tiling::

    colour = Σ w''_j c_j                          ∂/∂c_j = w''_j · g,   ∂/∂w''_j = g · c_j
    w''_j = v_j / max(Σ v, ε),  v_j = wh_j w'_j     (height blending, from h_j = height_j · w'_j)
    w'_j = w_j / max(Σ w, ε)                        (normalize),  w_j = max(splat_j, 0)

Where Warp's ``max`` has ties its adjoint takes the second operand; the hand-written one does the
same (the running height maximum credits the last layer at the maximum).
"""

import functools

import warp as wp

from .sampling import Sampler, TextureView, lod_from_derivatives, lod_scale_slope, read_channels, sample_lod, sample_lod_derivatives, splat_lod, write_channels
from .stochastic import StochasticParams, sample_stochastic, splat_stochastic
from .triplanar import Projection, plane_lod, plane_sample_slope, plane_uv, triplanar_sample, triplanar_weights

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


@wp.func
def sample_layer_slope(
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
):
    """``(value, d value / d tiling)`` of :func:`sample_layer` with plain sampling (no stochastic
    method), as Warp's adjoint takes the derivative."""
    t = layer_tiling(params, layer)
    value = wp.vec4(0.0)
    slope = wp.vec4(0.0)
    if params.projection == PROJECT_UV:
        value, d_u, d_v, d_lod = sample_lod_derivatives(tex, layer, uv0 * t, lod_from_derivatives(tex, uv0_dx * t, uv0_dy * t), smp)
        slope = d_u * uv0[0] + d_v * uv0[1] + d_lod * lod_scale_slope(tex, uv0_dx, uv0_dy, t)
    elif params.projection == PROJECT_WORLD_XZ:
        value, slope = plane_sample_slope(tex, layer, proj, 1, p, wp.vec3(0.0, 1.0, 0.0), dpdx, dpdy, t, smp)
    else:
        for axis in range(3):
            if tri_w[axis] > 0.0:
                v, s = plane_sample_slope(tex, layer, proj, axis, p, n, dpdx, dpdy, t, smp)
                value += tri_w[axis] * v
                slope += tri_w[axis] * s
    return value, slope


@wp.func
def add_layer_gradient(
    tex: TextureView,
    grad: wp.array(dtype=wp.vec4),
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
    g: wp.vec4,
):
    """Add the gradient ``g`` of :func:`sample_layer` (same arguments; linear blends only) into
    ``grad``, the texels' gradient; nothing when ``grad`` is empty (not needed)."""
    if grad.shape[0] > 0:
        t = layer_tiling(params, layer)
        if params.projection == PROJECT_UV:
            splat_stochastic(tex, grad, layer, uv0 * t, lod_from_derivatives(tex, uv0_dx * t, uv0_dy * t), smp, stoch, g)
        elif params.projection == PROJECT_WORLD_XZ:
            up = wp.vec3(0.0, 1.0, 0.0)
            splat_stochastic(tex, grad, layer, plane_uv(proj, 1, p, up, t), plane_lod(tex, 1, dpdx, dpdy, t), smp, stoch, g)
        else:
            for axis in range(3):
                if tri_w[axis] > 0.0:
                    splat_stochastic(tex, grad, layer, plane_uv(proj, axis, p, n, t), plane_lod(tex, axis, dpdx, dpdy, t), smp, stoch, tri_w[axis] * g)


@functools.cache
def splat_kernels(num_layers: int, map_channels: int):
    """``(forward, texel_grad)``: the splat kernel for ``num_layers`` layers whose weights come
    ``map_channels`` per map, and its hand-written gradient (module docstring), compiled together
    as one Warp module."""
    weights_t = wp.types.vector(length=num_layers, dtype=float)
    colours_t = wp.types.matrix(shape=(num_layers, 4), dtype=float)
    module = f"warptex_splat_{num_layers}x{map_channels}"
    wp.set_module_options({"max_unroll": max(16, num_layers)}, module=module)

    @wp.func(module=module)
    def splat_values(maps: TextureView, uv: wp.vec2, map_smp: Sampler):
        """Each layer's raw splat-map value at ``uv``: one bilinear read per map, channel ``j % C``
        of map ``j // C`` for layer ``j``."""
        r = weights_t()
        texel = wp.vec4(0.0)
        for j in range(wp.static(num_layers)):
            if j % wp.static(map_channels) == 0:
                texel = sample_lod(maps, j // wp.static(map_channels), uv, 0.0, map_smp)
            r[j] = texel[j % wp.static(map_channels)]
        return r

    # Per-layer loops unroll. Components are only ever written once into fresh vectors (Warp's
    # in-place component writes have exact adjoints then, but not when they overwrite a value).
    @wp.kernel(module=module)
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

            # Weights from the splat maps, clamped at 0.
            r = splat_values(maps, uv, map_smp)
            w = weights_t()
            for j in range(wp.static(num_layers)):
                w[j] = wp.max(r[j], 0.0)
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

    @wp.kernel(enable_backward=False, module=module)
    def texel_grad(
        layers: TextureView,
        heights: TextureView,
        maps: TextureView,
        grad_layers: wp.array(dtype=wp.vec4),
        grad_heights: wp.array(dtype=wp.vec4),
        grad_maps: wp.array(dtype=wp.vec4),
        grad_transition: wp.array(dtype=float),
        grad_tiling: wp.array(dtype=float),
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
        adj_out: wp.array2d(dtype=float),
    ):
        """Add the gradient of ``kernel`` (linear blends of taps) with respect to the layers',
        heights' and splat maps' texels, the transition and (plain sampling only) the tiling into
        ``grad_*`` (empty: not needed), given the output's gradient ``adj_out``: the forward
        replayed, then its blend reversed."""
        i = wp.tid()
        if mask[i] != 0.0:
            uv = uv0[i]
            p = position[i]
            n = normal[i]
            tri_w = wp.vec3(0.0)
            if params.projection == PROJECT_TRIPLANAR:
                tri_w = triplanar_weights(n, proj.sharpness[0])

            # Forward: raw splat values r, clamped w0, normalised w1, colours c, raw heights hv
            # (and, for the tiling, their derivatives dc, dhv).
            r = splat_values(maps, uv, map_smp)
            w0 = weights_t()
            for j in range(wp.static(num_layers)):
                w0[j] = wp.max(r[j], 0.0)
            total = wp.dot(w0, weights_t(1.0))
            w1 = w0
            if params.normalize != 0:
                w1 = w0 / wp.max(total, SPLAT_EPS)
            c = colours_t()
            hv = weights_t()
            dc = colours_t()
            dhv = weights_t()
            tiling_grads = grad_tiling.shape[0] > 0
            for j in range(wp.static(num_layers)):
                if w1[j] > 0.0:
                    if tiling_grads:
                        value, slope = sample_layer_slope(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp)
                        c[j] = value
                        dc[j] = slope
                    else:
                        c[j] = sample_layer(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, stoch)
                    if params.height_mode == HEIGHT_CHANNEL:
                        hv[j] = c[j, params.height_channel]
                    elif params.height_mode == HEIGHT_ARRAY:
                        if tiling_grads:
                            height, height_slope = sample_layer_slope(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp)
                            hv[j] = height[0]
                            dhv[j] = height_slope[0]
                        else:
                            hv[j] = sample_layer(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, height_stoch)[0]
            g = read_channels(adj_out, i)

            # Backward through the blend: gw1 is the gradient of w1, gc of the colours, ghv of the heights.
            gw1 = weights_t()
            gc = colours_t()
            ghv = weights_t()
            if params.height_mode == HEIGHT_NONE:
                for j in range(wp.static(num_layers)):
                    gc[j] = w1[j] * g
                    gw1[j] = wp.dot(g, c[j])
            else:
                h = wp.cw_mul(hv, w1)
                top = -1.0e30
                arg = -1
                for j in range(wp.static(num_layers)):
                    if w1[j] > 0.0 and h[j] >= top:  # ties: the later layer, as Warp's max adjoint
                        top = h[j]
                        arg = j
                t = params.transition[0]
                wh = weights_t()
                for j in range(wp.static(num_layers)):
                    wh[j] = wp.max(h[j] + t - top, 0.0)
                v = wp.cw_mul(wh, w1)
                v_total = wp.dot(v, weights_t(1.0))
                d = wp.max(v_total, SPLAT_EPS)
                gv = weights_t()
                for j in range(wp.static(num_layers)):
                    gc[j] = (v[j] / d) * g
                    gv[j] = wp.dot(g, c[j]) / d
                if v_total > SPLAT_EPS:
                    gv -= weights_t(wp.dot(gv, v) / d)
                g_top = 0.0
                g_t = 0.0
                gh = weights_t()
                for j in range(wp.static(num_layers)):
                    gw1[j] = gv[j] * wh[j]
                    if h[j] + t - top > 0.0:
                        ge = gv[j] * w1[j]
                        gh[j] = ge
                        g_t += ge
                        g_top -= ge
                if arg >= 0:
                    gh[arg] = gh[arg] + g_top
                for j in range(wp.static(num_layers)):
                    gw1[j] = gw1[j] + gh[j] * hv[j]
                    ghv[j] = gh[j] * w1[j]
                if params.height_mode == HEIGHT_CHANNEL:
                    for j in range(wp.static(num_layers)):
                        gc[j, params.height_channel] = gc[j, params.height_channel] + ghv[j]
                if grad_transition.shape[0] > 0:
                    wp.atomic_add(grad_transition, 0, g_t)

            # Through the normalisation and the clamp: gr, the gradient of the raw splat values.
            gw0 = gw1
            if params.normalize != 0:
                s = wp.max(total, SPLAT_EPS)
                gw0 = gw1 / s
                if total > SPLAT_EPS:
                    gw0 -= weights_t(wp.dot(gw1, w0) / (s * s))
            gr = weights_t()
            for j in range(wp.static(num_layers)):
                if r[j] > 0.0:
                    gr[j] = gw0[j]

            # Into the tiling (each layer's entry), then the texels: each map's channels, each
            # layer's colour, each separate height.
            if tiling_grads:
                for j in range(wp.static(num_layers)):
                    if w1[j] > 0.0:
                        wp.atomic_add(grad_tiling, wp.min(j, grad_tiling.shape[0] - 1), wp.dot(gc[j], dc[j]) + ghv[j] * dhv[j])
            if grad_maps.shape[0] > 0:
                gm = wp.vec4(0.0)
                for j in range(wp.static(num_layers)):
                    gm[j % wp.static(map_channels)] = gr[j]
                    if j % wp.static(map_channels) == wp.static(map_channels - 1) or j == wp.static(num_layers - 1):
                        splat_lod(maps, grad_maps, j // wp.static(map_channels), uv, 0.0, map_smp, gm)
                        gm = wp.vec4(0.0)
            for j in range(wp.static(num_layers)):
                if w1[j] > 0.0:
                    add_layer_gradient(layers, grad_layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, stoch, gc[j])
                    if params.height_mode == HEIGHT_ARRAY:
                        gh4 = wp.vec4(ghv[j], 0.0, 0.0, 0.0)
                        add_layer_gradient(heights, grad_heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, height_stoch, gh4)

    return kernel, texel_grad
