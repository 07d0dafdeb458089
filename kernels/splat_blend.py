"""Splat-map terrain texturing: the blend of a pixel's layers and its hand-written gradient,
for a fixed capacity of layers (:func:`blend_functions`; formulas in :mod:`.splat_layers`).

Per pixel the kernels keep each layer's colour and height in local storage of a fixed capacity (8,
16, 32... layers; :func:`capacity`), so these functions are built once per capacity, in the Warp
module of that capacity's kernels.
"""

import functools
import types

import warp as wp

from .filters import sample_lod, sample_lod_derivatives
from .scatter import scatter_lod
from .splat_layers import HEIGHT_CHANNEL, HEIGHT_NONE, SPLAT_EPS, SplatParams, map_count, map_layer
from .texels import SamplerArgs, TexelGrad, TextureView


def capacity(num_layers: int) -> int:
    """The local storage (layers) of the kernels that blend ``num_layers`` layers: 8, 16, 32...
    (4 measured no faster than 8 on the default 4-layer terrain, and would be one more module to
    compile)."""
    cap = 8
    while cap < num_layers:
        cap *= 2
    return cap


@functools.cache
def blend_functions(cap: int) -> types.SimpleNamespace:
    """The blend's ``@wp.func``\\ s for up to ``cap`` layers, in the Warp module ``warptex.splat{cap}``:
    ``splat_weights`` (``map_values`` and ``weights_of`` its two steps), ``blend``, ``blend_backward``, ``weights_backward``, ``map_gradient``,
    ``scatter_maps``, ``maps_uv_gradient``, and the types ``weights_t`` (``cap`` floats) and
    ``colours_t`` (``cap × 4``)."""
    weights_t = wp.types.vector(length=cap, dtype=float)
    colours_t = wp.types.matrix(shape=(cap, 4), dtype=float)
    module = f"warptex.splat{cap}"

    @wp.func(module=module)
    def map_values(r: weights_t, m: wp.int32, texel: wp.vec4, params: SplatParams) -> weights_t:
        """``r`` with map ``m``'s ``texel`` (its read at a pixel) in the raw splat values of its layers."""
        values = r
        for c in range(4):
            j = map_layer(params, m, c)
            if j >= 0:
                values[j] = texel[c]
        return values

    @wp.func(module=module)
    def weights_of(r: weights_t, params: SplatParams):
        """``(r, w0, total, w1)`` of :func:`splat_weights` from the raw splat values ``r``."""
        w0 = weights_t()
        for j in range(params.num_layers):
            w0[j] = wp.max(r[j], 0.0)
        total = wp.dot(w0, weights_t(1.0))
        w1 = w0
        if params.normalize != 0:
            w1 = w0 / wp.max(total, SPLAT_EPS)
        return r, w0, total, w1

    @wp.func(module=module)
    def splat_weights(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, params: SplatParams):
        """``(r, w0, total, w1)``: the raw splat values, clamped at 0, their sum, and the weights
        (normalised when ``params.normalize``); one bilinear read per map."""
        r = weights_t()
        for m in range(map_count(params)):
            r = map_values(r, m, sample_lod(maps, m, uv, 0.0, map_smp), params)
        return weights_of(r, params)

    @wp.func(module=module)
    def blend(w1: weights_t, c: colours_t, hv: weights_t, params: SplatParams) -> wp.vec4:
        """The blended colour of the layers' colours ``c`` with weights ``w1`` and, when height
        blending, heights ``hv`` (module docstring)."""
        w = w1
        if params.height_mode != HEIGHT_NONE:
            h = wp.cw_mul(hv, w1)
            top = float(-1.0e30)
            for j in range(params.num_layers):
                if w1[j] > 0.0:
                    top = wp.max(top, h[j])
            t = params.transition[0]
            wh = weights_t()
            for j in range(params.num_layers):
                wh[j] = wp.max(h[j] + t - top, 0.0)
            w = wp.cw_mul(wh, w1)
            w = w / wp.max(wp.dot(w, weights_t(1.0)), SPLAT_EPS)
        colour = wp.vec4(0.0)
        for j in range(params.num_layers):
            colour += w[j] * c[j]
        return colour

    @wp.func(module=module)
    def blend_backward(w1: weights_t, c: colours_t, hv: weights_t, params: SplatParams, g: wp.vec4):
        """``(gw1, gc, ghv, g_t)``: the gradients of :func:`blend`'s colour (gradient ``g``) with
        respect to the weights, the colours, the heights and the transition. With heights from a
        channel of the layers, the heights' gradient is already added into that channel of ``gc``."""
        gw1 = weights_t()
        gc = colours_t()
        ghv = weights_t()
        g_t = float(0.0)
        if params.height_mode == HEIGHT_NONE:
            for j in range(params.num_layers):
                gc[j] = w1[j] * g
                gw1[j] = wp.dot(g, c[j])
        else:
            h = wp.cw_mul(hv, w1)
            top = float(-1.0e30)
            arg = int(-1)
            for j in range(params.num_layers):
                if w1[j] > 0.0 and h[j] >= top:  # ties: the later layer, as Warp's max adjoint
                    top = h[j]
                    arg = j
            t = params.transition[0]
            wh = weights_t()
            for j in range(params.num_layers):
                wh[j] = wp.max(h[j] + t - top, 0.0)
            v = wp.cw_mul(wh, w1)
            v_total = wp.dot(v, weights_t(1.0))
            d = wp.max(v_total, SPLAT_EPS)
            gv = weights_t()
            for j in range(params.num_layers):
                gc[j] = (v[j] / d) * g
                gv[j] = wp.dot(g, c[j]) / d
            if v_total > SPLAT_EPS:
                gv -= weights_t(wp.dot(gv, v) / d)
            g_top = float(0.0)
            gh = weights_t()
            for j in range(params.num_layers):
                gw1[j] = gv[j] * wh[j]
                if h[j] + t - top > 0.0:
                    ge = gv[j] * w1[j]
                    gh[j] = ge
                    g_t += ge
                    g_top -= ge
            if arg >= 0:
                gh[arg] = gh[arg] + g_top
            for j in range(params.num_layers):
                gw1[j] = gw1[j] + gh[j] * hv[j]
                ghv[j] = gh[j] * w1[j]
            if params.height_mode == HEIGHT_CHANNEL:
                for j in range(params.num_layers):
                    gc[j, params.height_channel] = gc[j, params.height_channel] + ghv[j]
        return gw1, gc, ghv, g_t

    @wp.func(module=module)
    def weights_backward(r: weights_t, w0: weights_t, total: float, gw1: weights_t, params: SplatParams) -> weights_t:
        """The gradient of the raw splat values, given ``gw1``, that of :func:`splat_weights`' ``w1``:
        back through the normalisation and the clamp at 0."""
        gw0 = gw1
        if params.normalize != 0:
            s = wp.max(total, SPLAT_EPS)
            gw0 = gw1 / s
            if total > SPLAT_EPS:
                gw0 -= weights_t(wp.dot(gw1, w0) / (s * s))
        gr = weights_t()
        for j in range(params.num_layers):
            if r[j] > 0.0:
                gr[j] = gw0[j]
        return gr

    @wp.func(module=module)
    def map_gradient(gr: weights_t, m: wp.int32, params: SplatParams) -> wp.vec4:
        """Map ``m``'s share of ``gr``, the gradient of the raw splat values: one channel per layer."""
        gm = wp.vec4(0.0)
        for c in range(4):
            j = map_layer(params, m, c)
            if j >= 0:
                gm[c] = gr[j]
        return gm

    @wp.func(module=module)
    def scatter_maps(maps: TextureView, grad_maps: TexelGrad, uv: wp.vec2, map_smp: SamplerArgs, gr: weights_t, params: SplatParams):
        """Add ``gr``, the gradient of the raw splat values, into the splat-map texels (``grad_maps``;
        nothing when it is empty)."""
        if grad_maps.texels.shape[0] > 0:
            for m in range(map_count(params)):
                scatter_lod(maps, grad_maps, m, uv, 0.0, map_smp, map_gradient(gr, m, params))

    @wp.func(module=module)
    def maps_uv_gradient(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, gr: weights_t, params: SplatParams) -> wp.vec2:
        """The gradient with respect to ``uv`` of the maps' reads, given ``gr``, that of the raw splat values."""
        g_uv = wp.vec2(0.0)
        for m in range(map_count(params)):
            gm = map_gradient(gr, m, params)
            value, d_u, d_v, d_lod = sample_lod_derivatives(maps, m, uv, 0.0, map_smp)
            g_uv += wp.vec2(wp.dot(gm, d_u), wp.dot(gm, d_v))
        return g_uv

    return types.SimpleNamespace(weights_t=weights_t, colours_t=colours_t, splat_weights=splat_weights, map_values=map_values, weights_of=weights_of, blend=blend, blend_backward=blend_backward,
                                 weights_backward=weights_backward, map_gradient=map_gradient, scatter_maps=scatter_maps, maps_uv_gradient=maps_uv_gradient)  # fmt: skip
