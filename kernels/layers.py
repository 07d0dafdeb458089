"""Texture-array layers blended by splat maps (terrain texturing), with height-based blending.

Per pixel, the splat maps are read in UV0 (bilinear on level 0, clamped at the edges, so texel
centres return their texel exactly): channel ``c`` of map ``m`` is the weight of layer
``m · C + c``. Negative weights are clamped to 0. With ``normalize`` the weights are divided by
their sum (all-zero weights give weight 0 everywhere, so the output is 0). Each layer with a
non-zero weight is sampled with its own tiling, in UV0, on world XZ, or triplanar, and the
samples are blended.

Height-based blending (as Unity's TerrainLit shader does), with transition ``t > 0``::

    h_j = height_j · w_j;   m = max_j h_j;   wh_j = max(0, h_j + t - m);   w'_j = wh_j · w_j / Σ_k wh_k · w_k

where ``height_j`` is read at layer ``j``'s UV from a channel of the layer itself or from a
separate height array. Small ``t`` gives sharp, height-driven borders; large ``t`` tends to the
plain blend.

**Layers per face.** Mapped triplanar, a layer may read other array layers on some faces
(``SplatArgs.face_layers``, :func:`face_layer`): projection ``a`` of layer ``j`` then samples (colour,
and height from either source) the array layer given for the ``+a`` face where ``n[a] >= 0``, for
the ``-a`` face elsewhere, with layer ``j``'s tiling; ``j``'s splat weight and its place in the
height blend are unchanged.

**Kernels.** The layer count is a run-time value (``SplatArgs.num_layers``): every per-layer loop
is a loop, so a kernel's code does not grow with the layers. Per pixel, the kernels keep each
layer's colour and height in local storage of a fixed *capacity* (:func:`splat_kernels`: 8, 16,
32... layers), one Warp module per capacity, with plain and stochastic variants as for triplanar.

**Hand-written gradient.** Warp's generated adjoint replays each sampling function's forward pass
inside its reverse pass (about 5× the forward here). Where only texels, the transition and, with
plain sampling, the tiling need gradients (no sharpness, offsets or G-buffer gradients) and every
blend of taps is linear (no histogram), the texel-gradient kernel computes them directly: per
pixel it replays the forward once, takes the blend's derivatives by hand (:func:`blend_backward`),
and adds each layer's colour gradient into the texels the layer read, each weight's into the
splat-map texels, and each layer's colour gradient times the sample's derivative along its tiling
into the tiling::

    colour = Σ w''_j c_j                          ∂/∂c_j = w''_j · g,   ∂/∂w''_j = g · c_j
    w''_j = v_j / max(Σ v, ε),  v_j = wh_j w'_j     (height blending, from h_j = height_j · w'_j)
    w'_j = w_j / max(Σ w, ε)                        (normalize),  w_j = max(splat_j, 0)

Where Warp's ``max`` has ties its adjoint takes the second operand; the hand-written one does the
same (the running height maximum credits the last layer at the maximum).

**Other gradients** (sharpness, offsets, the G-buffer, a stochastic method's tiling, a histogram)
take two steps: :data:`splat_samples_adjoint_kernel` stores every weighted layer's sample per pixel
with Warp's generated adjoint (a loop over layers that only writes, which that adjoint
differentiates exactly), and the blend kernel reads them, its gradient by hand as above.
"""

import functools

import warp as wp

from . import ADJOINT_MODULE, out_of_line, specialised
from .projection import ProjectionArgs, plane_coords, plane_footprint, plane_uv, slope_coords, surface_frame, triplanar_weights, u_sign
from .sampling import SamplerArgs, TexelGrad, TextureView, lod_scale_slope, read_channels, sample_footprint_derivatives, sample_lod, sample_lod_derivatives, scatter_lod, texture_footprint, write_channels
from .stochastic import StochasticArgs, sample_plain, sample_stochastic, sample_stochastic_call, scatter_plain, scatter_stochastic

PROJECT_UV = wp.constant(0)  # UV0 × tiling
PROJECT_WORLD_XZ = wp.constant(1)  # the triplanar top projection, (-x, z) × tiling
PROJECT_TRIPLANAR = wp.constant(2)

HEIGHT_NONE = wp.constant(0)
HEIGHT_CHANNEL = wp.constant(1)  # a channel of each layer
HEIGHT_ARRAY = wp.constant(2)  # a separate one-channel array of L layers

SPLAT_EPS = wp.constant(1.0e-20)


@wp.struct
class SplatArgs:
    """Options of a splat blend, as kernels see them. ``tiling`` holds 1 or L values and
    ``transition`` 1, as arrays so that a ``wp.Tape`` carries gradients into them.
    ``face_layers`` is empty, or (projection triplanar) holds ``6 L`` array-layer indices: entry
    ``6 l + f`` is the layer that layer ``l`` reads on face ``f`` (``+x, -x, +y, -y, +z, -z``),
    see :func:`face_layer`."""

    tiling: wp.array(dtype=float)
    transition: wp.array(dtype=float)
    face_layers: wp.array(dtype=wp.int32)
    projection: wp.int32
    height_mode: wp.int32
    height_channel: wp.int32
    normalize: wp.int32
    num_layers: wp.int32
    map_channels: wp.int32


@wp.func
def layer_tiling(params: SplatArgs, layer: wp.int32) -> float:
    return params.tiling[wp.min(layer, params.tiling.shape[0] - 1)]


@wp.func
def layer_reads(params: SplatArgs) -> wp.int32:
    """Reads per layer: the three projections when mapped triplanar, else one."""
    reads = 1
    if params.projection == PROJECT_TRIPLANAR:
        reads = 3
    return reads


@wp.func
def face_layer(params: SplatArgs, layer: wp.int32, k: wp.int32, n: wp.vec3) -> wp.int32:
    """The array layer that read ``k`` of ``layer`` samples: ``layer`` itself, or, with
    ``face_layers`` (projection triplanar), that of the face projection ``k`` sees: ``+k`` where
    ``n[k] >= 0`` (``sign(0) = +1``, as the mirror fix), else ``-k``. The choice flips where the
    projection's weight is 0, so the seam blends as the others do. The layer's splat weight, tiling
    and place in the height blend stay those of ``layer``."""
    read = layer
    if params.face_layers.shape[0] > 0 and params.projection == PROJECT_TRIPLANAR:
        f = 2 * k
        if n[k] < 0.0:
            f = f + 1
        read = params.face_layers[layer * 6 + f]
    return read


@wp.func
def layer_read(
    tex: TextureView, layer: wp.int32, k: wp.int32, params: SplatArgs, proj: ProjectionArgs, uv0: wp.vec2, uv0_dx: wp.vec2, uv0_dy: wp.vec2,
    p: wp.vec3, n: wp.vec3, tri_w: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs,
):  # fmt: skip
    """``(uv, footprint, weight)`` of read ``k`` of ``layer`` at the layer's tiling: UV0, the world XZ
    plane (the triplanar top projection seen from above), or projection ``k`` weighted ``tri_w[k]``."""
    t = layer_tiling(params, layer)
    uv = uv0 * t
    fp = wp.vec4()
    weight = 1.0
    if params.projection == PROJECT_UV:
        fp = texture_footprint(tex, uv0_dx * t, uv0_dy * t, smp)
    elif params.projection == PROJECT_WORLD_XZ:
        up = wp.vec3(0.0, 1.0, 0.0)
        uv = plane_uv(proj, 1, p, up, t)
        fp = plane_footprint(tex, proj, 1, up, dpdx, dpdy, t, smp)
    else:
        uv = plane_uv(proj, k, p, n, t)
        fp = plane_footprint(tex, proj, k, n, dpdx, dpdy, t, smp)
        weight = tri_w[k]
    return uv, fp, weight


@wp.func
def layer_read_slopes(
    tex: TextureView, layer: wp.int32, k: wp.int32, params: SplatArgs, proj: ProjectionArgs, uv0: wp.vec2, uv0_dx: wp.vec2, uv0_dy: wp.vec2,
    p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3,
):  # fmt: skip
    """``(d uv / d t, d lod / d t)`` of :func:`layer_read` along the layer's tiling ``t``: the UV moves
    by the (mirror-fixed) plane coordinates, the LOD by ``1 / (t ln 2)``."""
    t = layer_tiling(params, layer)
    axis = k
    if params.projection == PROJECT_WORLD_XZ:
        axis = 1
        n = wp.vec3(0.0, 1.0, 0.0)
    uv_slope = uv0
    lod_slope = 0.0
    if params.projection == PROJECT_UV:
        lod_slope = lod_scale_slope(tex, uv0_dx, uv0_dy, t)
    else:
        c = slope_coords(proj, p, axis)
        uv_slope = wp.vec2(c[0] * u_sign(n, axis, proj.mirror_fix), c[1])
        lod_slope = lod_scale_slope(tex, plane_coords(dpdx, axis), plane_coords(dpdy, axis), t)
    return uv_slope, lod_slope


@wp.func
def surface_weights(params: SplatArgs, proj: ProjectionArgs, n: wp.vec3) -> wp.vec3:
    """The triplanar weights of the layers' projections (zero unless they are mapped triplanar)."""
    tri_w = wp.vec3(0.0)
    if params.projection == PROJECT_TRIPLANAR:
        tri_w = triplanar_weights(n, proj.sharpness[0])
    return tri_w


@wp.func
def splat_value(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, layer: wp.int32, map_channels: wp.int32) -> float:
    """Layer ``layer``'s raw splat-map value at ``uv``: channel ``layer % C`` of map ``layer // C``."""
    return sample_lod(maps, layer // map_channels, uv, 0.0, map_smp)[layer % map_channels]


@wp.func
def map_count(params: SplatArgs) -> wp.int32:
    """Splat maps holding the layers' weights, ``ceil(L / C)``."""
    return (params.num_layers + params.map_channels - 1) // params.map_channels


@wp.func
def layer_textures(params: SplatArgs) -> wp.int32:
    """Textures read per layer: the layer, and its separate height (``HEIGHT_ARRAY``)."""
    count = 1
    if params.height_mode == HEIGHT_ARRAY:
        count = 2
    return count


@wp.func
def pick_texture(layers: TextureView, heights: TextureView, t: wp.int32) -> TextureView:
    """Texture ``t`` of :func:`layer_textures` (chosen, then read by one call: the code that reads a
    layer is compiled once, not once for colours and once for heights)."""
    tex = layers
    if t == 1:
        tex = heights
    return tex


@wp.func
def pick_stochastic(stoch: StochasticArgs, height_stoch: StochasticArgs, t: wp.int32) -> StochasticArgs:
    """The stochastic options of texture ``t`` (see :func:`pick_texture`)."""
    st = stoch
    if t == 1:
        st = height_stoch
    return st


@wp.func
def pick_grad(grad_layers: TexelGrad, grad_heights: TexelGrad, t: wp.int32):
    """The texel gradient of texture ``t`` (see :func:`pick_texture`)."""
    grad = grad_layers
    if t == 1:
        grad = grad_heights
    return grad


@wp.func
def layer_weighted(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, layer: wp.int32, map_channels: wp.int32) -> bool:
    """Whether layer ``layer``'s raw splat-map value at ``uv`` is positive (the layers the splat
    kernels read)."""
    return splat_value(maps, uv, map_smp, layer, map_channels) > 0.0


@wp.func_grad(layer_weighted)
def adj_layer_weighted(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, layer: wp.int32, map_channels: wp.int32, adj_ret: bool):
    """A branch condition: no gradient (and no adjoint code to compile)."""
    pass


def _read_layer(sample, name: str, one_call: bool, decorate=wp.func):
    def read_layer(
        tex: TextureView, layer: wp.int32, params: SplatArgs, proj: ProjectionArgs, uv0: wp.vec2, uv0_dx: wp.vec2, uv0_dy: wp.vec2,
        p: wp.vec3, n: wp.vec3, tri_w: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs, stoch: StochasticArgs,
    ) -> wp.vec4:  # fmt: skip
        """Layer ``layer`` of ``tex`` in the splat's projection (zero-weight projections not read)."""
        value = wp.vec4(0.0)
        if wp.static(one_call):  # one call of ``sample``: stochastic sampling is compiled once
            for k in range(layer_reads(params)):
                uv, fp, weight = layer_read(tex, layer, k, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
                if weight > 0.0:
                    value += weight * sample(tex, face_layer(params, layer, k, n), uv, fp, smp, stoch)
        elif params.projection == PROJECT_TRIPLANAR:  # plain: UV and world XZ read without the loop (faster)
            for k in range(layer_reads(params)):
                uv, fp, weight = layer_read(tex, layer, k, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
                if weight > 0.0:
                    value += weight * sample(tex, face_layer(params, layer, k, n), uv, fp, smp, stoch)
        else:
            uv, fp, weight = layer_read(tex, layer, 0, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
            value = sample(tex, layer, uv, fp, smp, stoch)
        return value

    return decorate(specialised(read_layer, name))


def _scatter_layer(scatter, name: str, one_call: bool):
    def scatter_layer(
        tex: TextureView, grad: TexelGrad, layer: wp.int32, params: SplatArgs, proj: ProjectionArgs, uv0: wp.vec2, uv0_dx: wp.vec2, uv0_dy: wp.vec2,
        p: wp.vec3, n: wp.vec3, tri_w: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs, stoch: StochasticArgs, g: wp.vec4,
    ):  # fmt: skip
        """Add the gradient ``g`` of ``read_layer`` (same arguments; linear blends only) into
        ``grad``, the texels' gradient; nothing when ``grad`` is empty (not needed)."""
        if grad.texels.shape[0] > 0:
            if wp.static(one_call):  # as in read_layer
                for k in range(layer_reads(params)):
                    uv, fp, weight = layer_read(tex, layer, k, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
                    if weight > 0.0:
                        scatter(tex, grad, face_layer(params, layer, k, n), uv, fp, smp, stoch, weight * g)
            elif params.projection == PROJECT_TRIPLANAR:
                for k in range(layer_reads(params)):
                    uv, fp, weight = layer_read(tex, layer, k, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
                    if weight > 0.0:
                        scatter(tex, grad, face_layer(params, layer, k, n), uv, fp, smp, stoch, weight * g)
            else:
                uv, fp, weight = layer_read(tex, layer, 0, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
                scatter(tex, grad, layer, uv, fp, smp, stoch, g)

    return wp.func(specialised(scatter_layer, name))


read_layer_plain = _read_layer(sample_plain, "read_layer_plain", one_call=False)
read_layer_stochastic = _read_layer(sample_stochastic, "read_layer_stochastic", one_call=True)
read_layer_out_of_line = _read_layer(sample_stochastic_call, "read_layer_out_of_line", one_call=True, decorate=out_of_line)  # for the generated adjoint
scatter_layer_plain = _scatter_layer(scatter_plain, "scatter_layer_plain", one_call=False)
scatter_layer_stochastic = _scatter_layer(scatter_stochastic, "scatter_layer_stochastic", one_call=True)


@wp.func
def read_layer_slope(
    tex: TextureView, layer: wp.int32, params: SplatArgs, proj: ProjectionArgs, uv0: wp.vec2, uv0_dx: wp.vec2, uv0_dy: wp.vec2,
    p: wp.vec3, n: wp.vec3, tri_w: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs,
):  # fmt: skip
    """``(value, d value / d tiling)`` of ``read_layer`` with plain sampling, as Warp's adjoint takes
    the derivative (an anisotropic footprint's steps move in proportion to the tiling)."""
    value = wp.vec4(0.0)
    slope = wp.vec4(0.0)
    for k in range(layer_reads(params)):
        uv, fp, weight = layer_read(tex, layer, k, params, proj, uv0, uv0_dx, uv0_dy, p, n, tri_w, dpdx, dpdy, smp)
        if weight > 0.0:
            uv_slope, lod_slope = layer_read_slopes(tex, layer, k, params, proj, uv0, uv0_dx, uv0_dy, p, n, dpdx, dpdy)
            v, d_u, d_v, d_lod, d_spread = sample_footprint_derivatives(tex, face_layer(params, layer, k, n), uv, fp, smp)
            value += weight * v
            slope += weight * (d_u * uv_slope[0] + d_v * uv_slope[1] + d_lod * lod_slope + d_spread / layer_tiling(params, layer))
    return value, slope


@wp.kernel(module=ADJOINT_MODULE)
def splat_samples_adjoint_kernel(
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
    params: SplatArgs,
    proj: ProjectionArgs,
    smp: SamplerArgs,
    map_smp: SamplerArgs,
    stoch: StochasticArgs,
    height_stoch: StochasticArgs,
    samples: wp.array2d(dtype=wp.vec4),
    height_samples: wp.array2d(dtype=float),
):
    """``samples[i, j]``: layer ``j`` as the splat kernels read it, for every layer with a positive
    splat value (others stay 0); ``height_samples[i, j]``: its separate height. With Warp's
    generated adjoint, on out-of-line blocks (module docstring)."""
    i = wp.tid()
    if mask[i] != 0.0:
        uv = uv0[i]
        p, n, dpdx, dpdy, tri_w = surface_frame(proj, position[i], normal[i], position_dx[i], position_dy[i])
        if params.projection != PROJECT_TRIPLANAR:
            tri_w = wp.vec3(0.0)
        for j in range(params.num_layers):
            if layer_weighted(maps, uv, map_smp, j, params.map_channels):
                samples[i, j] = read_layer_out_of_line(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, dpdx, dpdy, smp, stoch)
                if params.height_mode == HEIGHT_ARRAY:
                    height = read_layer_out_of_line(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, dpdx, dpdy, smp, height_stoch)
                    height_samples[i, j] = height[0]


def capacity(num_layers: int) -> int:
    """The local storage (layers) of the kernels that blend ``num_layers`` layers: 8, 16, 32...
    (4 measured no faster than 8 on the default 4-layer terrain, and would be one more module to
    compile)."""
    cap = 8
    while cap < num_layers:
        cap *= 2
    return cap


@functools.cache
def splat_kernels(cap: int) -> dict:
    """The splat kernels for up to ``cap`` layers (a :func:`capacity`), by name: ``forward``,
    ``texel_grad`` (plain sampling) and ``stochastic_forward``, ``stochastic_texel_grad`` (any
    stochastic method), each pair in a Warp module of its own; ``blend`` and ``blend_grad``, the
    second step of the generated-adjoint path (module docstring), beside the plain ones."""
    weights_t = wp.types.vector(length=cap, dtype=float)
    colours_t = wp.types.matrix(shape=(cap, 4), dtype=float)
    module = f"warptex.splat{cap}"
    blend_module = module + ".blend"

    @wp.func(module=module)
    def splat_weights(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, params: SplatArgs):
        """``(r, w0, total, w1)``: the raw splat values, clamped at 0, their sum, and the weights
        (normalised when ``params.normalize``); one bilinear read per map."""
        r = weights_t()
        for m in range(map_count(params)):
            texel = sample_lod(maps, m, uv, 0.0, map_smp)
            for c in range(4):
                j = m * params.map_channels + c
                if c < params.map_channels and j < params.num_layers:
                    r[j] = texel[c]
        w0 = weights_t()
        for j in range(params.num_layers):
            w0[j] = wp.max(r[j], 0.0)
        total = wp.dot(w0, weights_t(1.0))
        w1 = w0
        if params.normalize != 0:
            w1 = w0 / wp.max(total, SPLAT_EPS)
        return r, w0, total, w1

    @wp.func(module=module)
    def blend(w1: weights_t, c: colours_t, hv: weights_t, params: SplatArgs) -> wp.vec4:
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
    def blend_backward(w1: weights_t, c: colours_t, hv: weights_t, params: SplatArgs, g: wp.vec4):
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
    def weights_backward(r: weights_t, w0: weights_t, total: float, gw1: weights_t, params: SplatArgs) -> weights_t:
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
    def map_gradient(gr: weights_t, m: wp.int32, params: SplatArgs) -> wp.vec4:
        """Map ``m``'s share of ``gr``, the gradient of the raw splat values: one channel per layer."""
        gm = wp.vec4(0.0)
        for c in range(4):
            j = m * params.map_channels + c
            if c < params.map_channels and j < params.num_layers:
                gm[c] = gr[j]
        return gm

    @wp.func(module=module)
    def scatter_maps(maps: TextureView, grad_maps: TexelGrad, uv: wp.vec2, map_smp: SamplerArgs, gr: weights_t, params: SplatArgs):
        """Add ``gr``, the gradient of the raw splat values, into the splat-map texels (``grad_maps``;
        nothing when it is empty)."""
        if grad_maps.texels.shape[0] > 0:
            for m in range(map_count(params)):
                scatter_lod(maps, grad_maps, m, uv, 0.0, map_smp, map_gradient(gr, m, params))

    @wp.func(module=module)
    def maps_uv_gradient(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, gr: weights_t, params: SplatArgs) -> wp.vec2:
        """The gradient with respect to ``uv`` of the maps' reads, given ``gr``, that of the raw splat values."""
        g_uv = wp.vec2(0.0)
        for m in range(map_count(params)):
            gm = map_gradient(gr, m, params)
            value, d_u, d_v, d_lod = sample_lod_derivatives(maps, m, uv, 0.0, map_smp)
            g_uv += wp.vec2(wp.dot(gm, d_u), wp.dot(gm, d_v))
        return g_uv

    def forward_kernel(kernel_module: str, read_layer, plain: bool):
        @wp.kernel(enable_backward=False, module=kernel_module)
        def splat_kernel(
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
            params: SplatArgs,
            proj: ProjectionArgs,
            smp: SamplerArgs,
            map_smp: SamplerArgs,
            stoch: StochasticArgs,
            height_stoch: StochasticArgs,
            out: wp.array2d(dtype=float),
        ):
            """``out[i, c]``: the layers blended by the splat maps (module docstring); 0 where ``mask`` is 0."""
            i = wp.tid()
            colour = wp.vec4(0.0)
            if mask[i] != 0.0:
                uv = uv0[i]
                p = position[i]
                n = normal[i]
                tri_w = surface_weights(params, proj, n)
                r, w0, total, w1 = splat_weights(maps, uv, map_smp, params)
                c = colours_t()
                hv = weights_t()
                for j in range(params.num_layers):
                    if w1[j] > 0.0:
                        if wp.static(plain):  # a call each for colour and height (faster)
                            value = read_layer(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, stoch)
                            c[j] = value
                            if params.height_mode == HEIGHT_CHANNEL:
                                hv[j] = value[params.height_channel]
                            elif params.height_mode == HEIGHT_ARRAY:
                                hv[j] = read_layer(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, height_stoch)[0]
                        else:  # one call for both: stochastic sampling is compiled once
                            for t in range(layer_textures(params)):
                                value = read_layer(pick_texture(layers, heights, t), j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, pick_stochastic(stoch, height_stoch, t))
                                if t == 0:
                                    c[j] = value
                                    if params.height_mode == HEIGHT_CHANNEL:
                                        hv[j] = value[params.height_channel]
                                else:
                                    hv[j] = value[0]
                colour = blend(w1, c, hv, params)
            write_channels(out, i, colour)

        return splat_kernel

    def texel_grad_kernel(kernel_module: str, read_layer, scatter_layer, plain: bool):
        @wp.kernel(enable_backward=False, module=kernel_module)
        def splat_texel_grad_kernel(
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
            params: SplatArgs,
            proj: ProjectionArgs,
            smp: SamplerArgs,
            map_smp: SamplerArgs,
            stoch: StochasticArgs,
            height_stoch: StochasticArgs,
            grad_layers: TexelGrad,
            grad_heights: TexelGrad,
            grad_maps: TexelGrad,
            grad_transition: wp.array(dtype=float),
            grad_tiling: wp.array(dtype=float),
            adj_out: wp.array2d(dtype=float),
        ):
            """Add the gradient of the forward kernel (same inputs; linear blends of taps) with
            respect to the layers', heights' and splat maps' texels, the transition and (plain
            sampling only) the tiling into ``grad_*`` (empty: not needed), given the output's
            gradient ``adj_out``: the forward replayed, then its blend reversed."""
            i = wp.tid()
            if mask[i] != 0.0:
                uv = uv0[i]
                p = position[i]
                n = normal[i]
                tri_w = surface_weights(params, proj, n)
                r, w0, total, w1 = splat_weights(maps, uv, map_smp, params)
                # The forward: colours c, raw heights hv and, for the tiling, their slopes dc, dhv.
                c = colours_t()
                hv = weights_t()
                dc = colours_t()
                dhv = weights_t()
                tiling_grads = grad_tiling.shape[0] > 0
                if wp.static(plain):  # the stochastic kernels never take the tiling's gradient by hand
                    if tiling_grads:
                        for j in range(params.num_layers):
                            if w1[j] > 0.0:
                                value, slope = read_layer_slope(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp)
                                c[j] = value
                                dc[j] = slope
                                if params.height_mode == HEIGHT_ARRAY:
                                    height, height_slope = read_layer_slope(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp)
                                    hv[j] = height[0]
                                    dhv[j] = height_slope[0]
                for j in range(params.num_layers):
                    if w1[j] > 0.0:
                        if not tiling_grads:
                            if wp.static(plain):  # as in the forward kernel
                                c[j] = read_layer(layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, stoch)
                                if params.height_mode == HEIGHT_ARRAY:
                                    hv[j] = read_layer(heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, height_stoch)[0]
                            else:
                                for t in range(layer_textures(params)):
                                    value = read_layer(pick_texture(layers, heights, t), j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, pick_stochastic(stoch, height_stoch, t))
                                    if t == 0:
                                        c[j] = value
                                    else:
                                        hv[j] = value[0]
                        if params.height_mode == HEIGHT_CHANNEL:
                            hv[j] = c[j, params.height_channel]

                # Backward: through the blend, the normalisation and the clamp, then into the
                # transition, the tiling (each layer's entry) and the texels.
                gw1, gc, ghv, g_t = blend_backward(w1, c, hv, params, read_channels(adj_out, i))
                if grad_transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                    wp.atomic_add(grad_transition, 0, g_t)
                if tiling_grads:
                    for j in range(params.num_layers):
                        if w1[j] > 0.0:
                            wp.atomic_add(grad_tiling, wp.min(j, grad_tiling.shape[0] - 1), wp.dot(gc[j], dc[j]) + ghv[j] * dhv[j])
                gr = weights_backward(r, w0, total, gw1, params)
                scatter_maps(maps, grad_maps, uv, map_smp, gr, params)
                for j in range(params.num_layers):
                    if w1[j] > 0.0:
                        if wp.static(plain):
                            scatter_layer(layers, grad_layers, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, stoch, gc[j])
                            if params.height_mode == HEIGHT_ARRAY:
                                scatter_layer(heights, grad_heights, j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, height_stoch, wp.vec4(ghv[j], 0.0, 0.0, 0.0))
                        else:
                            for t in range(layer_textures(params)):
                                g = gc[j]
                                if t == 1:
                                    g = wp.vec4(ghv[j], 0.0, 0.0, 0.0)
                                tex = pick_texture(layers, heights, t)
                                scatter_layer(tex, pick_grad(grad_layers, grad_heights, t), j, params, proj, uv, uv0_dx[i], uv0_dy[i], p, n, tri_w, position_dx[i], position_dy[i], smp, pick_stochastic(stoch, height_stoch, t), g)

        return splat_texel_grad_kernel

    @wp.func(module=module)
    def stored_layers(samples: wp.array2d(dtype=wp.vec4), height_samples: wp.array2d(dtype=float), i: wp.int32, w1: weights_t, params: SplatArgs):
        """``(c, hv)``: the colours and heights that :data:`splat_samples_adjoint_kernel` stored."""
        c = colours_t()
        hv = weights_t()
        for j in range(params.num_layers):
            if w1[j] > 0.0:
                c[j] = samples[i, j]
                if params.height_mode == HEIGHT_CHANNEL:
                    hv[j] = c[j, params.height_channel]
                elif params.height_mode == HEIGHT_ARRAY:
                    hv[j] = height_samples[i, j]
        return c, hv

    @wp.kernel(enable_backward=False, module=blend_module)
    def splat_blend_kernel(
        maps: TextureView,
        uv0: wp.array(dtype=wp.vec2),
        mask: wp.array(dtype=float),
        params: SplatArgs,
        map_smp: SamplerArgs,
        samples: wp.array2d(dtype=wp.vec4),
        height_samples: wp.array2d(dtype=float),
        out: wp.array2d(dtype=float),
    ):
        """The forward kernel's blend, of the layers :data:`splat_samples_adjoint_kernel` stored."""
        i = wp.tid()
        colour = wp.vec4(0.0)
        if mask[i] != 0.0:
            r, w0, total, w1 = splat_weights(maps, uv0[i], map_smp, params)
            c, hv = stored_layers(samples, height_samples, i, w1, params)
            colour = blend(w1, c, hv, params)
        write_channels(out, i, colour)

    @wp.kernel(enable_backward=False, module=blend_module)
    def splat_blend_grad_kernel(
        maps: TextureView,
        uv0: wp.array(dtype=wp.vec2),
        mask: wp.array(dtype=float),
        params: SplatArgs,
        map_smp: SamplerArgs,
        samples: wp.array2d(dtype=wp.vec4),
        height_samples: wp.array2d(dtype=float),
        grad_maps: TexelGrad,
        grad_transition: wp.array(dtype=float),
        grad_uv0: wp.array(dtype=wp.vec2),
        grad_samples: wp.array2d(dtype=wp.vec4),
        grad_height_samples: wp.array2d(dtype=float),
        adj_out: wp.array2d(dtype=float),
    ):
        """The gradient of :func:`splat_blend_kernel` (same inputs) with respect to the splat-map
        texels, the transition, ``uv0`` (through the maps' reads) and the stored samples, added
        into ``grad_*`` (empty: not needed), given the output's gradient ``adj_out``."""
        i = wp.tid()
        if mask[i] != 0.0:
            uv = uv0[i]
            r, w0, total, w1 = splat_weights(maps, uv, map_smp, params)
            c, hv = stored_layers(samples, height_samples, i, w1, params)
            gw1, gc, ghv, g_t = blend_backward(w1, c, hv, params, read_channels(adj_out, i))
            if grad_transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                wp.atomic_add(grad_transition, 0, g_t)
            gr = weights_backward(r, w0, total, gw1, params)
            scatter_maps(maps, grad_maps, uv, map_smp, gr, params)
            if grad_uv0.shape[0] > 0:
                grad_uv0[i] = grad_uv0[i] + maps_uv_gradient(maps, uv, map_smp, gr, params)
            for j in range(params.num_layers):
                if w1[j] > 0.0:
                    if grad_samples.shape[0] > 0:
                        grad_samples[i, j] = grad_samples[i, j] + gc[j]
                    if params.height_mode == HEIGHT_ARRAY and grad_height_samples.shape[0] > 0:
                        grad_height_samples[i, j] = grad_height_samples[i, j] + ghv[j]

    stochastic = module + ".stochastic"
    return {
        "forward": forward_kernel(module, read_layer_plain, plain=True),
        "texel_grad": texel_grad_kernel(module + ".grad", read_layer_plain, scatter_layer_plain, plain=True),
        "stochastic_forward": forward_kernel(stochastic, read_layer_stochastic, plain=False),
        "stochastic_texel_grad": texel_grad_kernel(stochastic + ".grad", read_layer_stochastic, scatter_layer_stochastic, plain=False),
        "blend": splat_blend_kernel,
        "blend_grad": splat_blend_grad_kernel,
    }
