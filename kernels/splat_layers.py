"""Splat-map terrain texturing: the options and reading one layer (the kernels: :mod:`.splat`).

Texture-array layers blended by splat maps, with height-based blending.

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

from typing import Any

import warp as wp

from . import inlined, out_of_line, specialised
from .filters import sample_footprint_derivatives, sample_lod
from .footprint import lod_scale_slope, texture_footprint
from .projection import ProjectionArgs, plane_coords, plane_footprint, plane_uv, slope_coords, triplanar_weights, u_sign
from .stochastic import StochasticArgs, sample_plain, sample_stochastic, sample_stochastic_outlined, scatter_plain, scatter_stochastic
from .texels import SamplerArgs, TexelGrad, TextureView

PROJECT_UV = wp.constant(0)  # UV0 × tiling
PROJECT_WORLD_XZ = wp.constant(1)  # the triplanar top projection, (-x, z) × tiling
PROJECT_TRIPLANAR = wp.constant(2)

HEIGHT_NONE = wp.constant(0)
HEIGHT_CHANNEL = wp.constant(1)  # a channel of each layer
HEIGHT_ARRAY = wp.constant(2)  # a separate one-channel array of L layers

SPLAT_EPS = wp.constant(1.0e-20)


@wp.struct
class SplatParams:
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


@wp.struct
class LayerReads:
    """How every layer is read: the splat's options, its triplanar projection, the layers' sampler
    (what the layer reads below take, rather than the whole :class:`SplatArgs`: an out-of-line read
    with Warp's generated adjoint compiles an adjoint of every struct it is given)."""

    params: SplatParams
    proj: ProjectionArgs
    smp: SamplerArgs


@wp.struct
class SplatArgs:
    """What every pixel of a splat launch reads: the colour layers, the height layers (the colour
    layers themselves when heights come from a channel), the splat maps, how layers are read, the
    maps' sampler, and the stochastic options of the layers and of the heights."""

    layers: TextureView
    heights: TextureView
    maps: TextureView
    reads: LayerReads
    map_smp: SamplerArgs
    stoch: StochasticArgs
    height_stoch: StochasticArgs


@wp.struct
class LayerPoint:
    """Where a pixel reads its layers: UV0 and its derivatives, the (projected-space) position, normal
    and position derivatives, and the triplanar weights of the layers' projections."""

    uv0: wp.vec2
    uv0_dx: wp.vec2
    uv0_dy: wp.vec2
    p: wp.vec3
    n: wp.vec3
    dpdx: wp.vec3
    dpdy: wp.vec3
    tri_w: wp.vec3


@wp.func
def layer_tiling(params: SplatParams, layer: wp.int32) -> float:
    return params.tiling[wp.min(layer, params.tiling.shape[0] - 1)]


@wp.func
def layer_reads(params: SplatParams) -> wp.int32:
    """Reads per layer: the three projections when mapped triplanar, else one."""
    return wp.where(params.projection == PROJECT_TRIPLANAR, 3, 1)


@wp.func
def face_layer(params: SplatParams, layer: wp.int32, k: wp.int32, n: wp.vec3) -> wp.int32:
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
def layer_read(tex: TextureView, layer: wp.int32, k: wp.int32, reads: LayerReads, pt: LayerPoint):
    """``(uv, footprint, weight)`` of read ``k`` of ``layer`` at the layer's tiling: UV0, the world XZ
    plane (the triplanar top projection seen from above), or projection ``k`` weighted ``tri_w[k]``."""
    t = layer_tiling(reads.params, layer)
    uv = pt.uv0 * t
    fp = wp.vec4()
    weight = 1.0
    if reads.params.projection == PROJECT_UV:
        fp = texture_footprint(tex, pt.uv0_dx * t, pt.uv0_dy * t, reads.smp)
    elif reads.params.projection == PROJECT_WORLD_XZ:
        up = wp.vec3(0.0, 1.0, 0.0)
        uv = plane_uv(reads.proj, 1, pt.p, up, t)
        fp = plane_footprint(tex, reads.proj, 1, up, pt.dpdx, pt.dpdy, t, reads.smp)
    else:
        uv = plane_uv(reads.proj, k, pt.p, pt.n, t)
        fp = plane_footprint(tex, reads.proj, k, pt.n, pt.dpdx, pt.dpdy, t, reads.smp)
        weight = pt.tri_w[k]
    return uv, fp, weight


@wp.func
def layer_read_slopes(tex: TextureView, layer: wp.int32, k: wp.int32, reads: LayerReads, pt: LayerPoint):
    """``(d uv / d t, d lod / d t)`` of :func:`layer_read` along the layer's tiling ``t``: the UV moves
    by the (mirror-fixed) plane coordinates, the LOD by ``1 / (t ln 2)``."""
    t = layer_tiling(reads.params, layer)
    axis = k
    n = pt.n
    if reads.params.projection == PROJECT_WORLD_XZ:
        axis = 1
        n = wp.vec3(0.0, 1.0, 0.0)
    uv_slope = pt.uv0
    lod_slope = 0.0
    if reads.params.projection == PROJECT_UV:
        lod_slope = lod_scale_slope(tex, pt.uv0_dx, pt.uv0_dy, t)
    else:
        c = slope_coords(reads.proj, pt.p, axis)
        uv_slope = wp.vec2(c[0] * u_sign(n, axis, reads.proj.mirror_fix), c[1])
        lod_slope = lod_scale_slope(tex, plane_coords(pt.dpdx, axis), plane_coords(pt.dpdy, axis), t)
    return uv_slope, lod_slope


@wp.func
def surface_weights(params: SplatParams, proj: ProjectionArgs, n: wp.vec3) -> wp.vec3:
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
def map_layer(params: SplatParams, m: wp.int32, c: wp.int32) -> wp.int32:
    """The layer whose splat value channel ``c`` of map ``m`` holds (``m C + c``), or -1: a channel
    the maps do not have, or one past the last layer."""
    j = m * params.map_channels + c
    if c >= params.map_channels or j >= params.num_layers:
        j = -1
    return j


@wp.func
def map_count(params: SplatParams) -> wp.int32:
    """Splat maps holding the layers' weights, ``ceil(L / C)``."""
    return (params.num_layers + params.map_channels - 1) // params.map_channels


@wp.func
def layer_textures(params: SplatParams) -> wp.int32:
    """Textures read per layer: the layer, and its separate height (``HEIGHT_ARRAY``)."""
    return wp.where(params.height_mode == HEIGHT_ARRAY, 2, 1)


@wp.func
def pick(layers_value: Any, heights_value: Any, t: wp.int32):
    """What texture ``t`` of :func:`layer_textures` reads with: ``layers_value`` for the layer,
    ``heights_value`` for its separate height (a texture, its stochastic options or its texel
    gradient: chosen, then read by one call, so the code that reads a layer is compiled once, not
    once for colours and once for heights)."""
    value = layers_value
    if t == 1:
        value = heights_value
    return value


@wp.func
def layer_weighted(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, layer: wp.int32, map_channels: wp.int32) -> bool:
    """Whether layer ``layer``'s raw splat-map value at ``uv`` is positive (the layers the splat
    kernels read)."""
    return splat_value(maps, uv, map_smp, layer, map_channels) > 0.0


@wp.func_grad(layer_weighted)
def adj_layer_weighted(maps: TextureView, uv: wp.vec2, map_smp: SamplerArgs, layer: wp.int32, map_channels: wp.int32, adj_ret: bool):
    """A branch condition: no gradient (and no adjoint code to compile)."""
    pass


def _layer_reads(sample, scatter, suffix: str, one_call: bool, decorate=wp.func):
    """``(read_layer, scatter_layer)``: layer ``layer`` of ``tex`` read in the splat's projection
    with ``sample`` (zero-weight projections not read), and the gradient ``g`` of that read added
    into ``grad``, the texels' gradient (nothing when it is empty: not needed; linear blends only).

    With ``one_call``, every projection goes through one call of ``sample`` in a loop (stochastic
    sampling is then compiled once); without, the loop is taken for triplanar projection only and
    UV and world-XZ layers are read by one call outside it (faster)."""

    def read_projections(tex: TextureView, layer: wp.int32, reads: LayerReads, pt: LayerPoint, stoch: StochasticArgs) -> wp.vec4:
        value = wp.vec4(0.0)
        for k in range(layer_reads(reads.params)):
            uv, fp, weight = layer_read(tex, layer, k, reads, pt)
            if weight > 0.0:
                value += weight * sample(tex, face_layer(reads.params, layer, k, pt.n), uv, fp, reads.smp, stoch)
        return value

    def read_layer(tex: TextureView, layer: wp.int32, reads: LayerReads, pt: LayerPoint, stoch: StochasticArgs) -> wp.vec4:
        value = wp.vec4(0.0)
        if wp.static(one_call):
            value = loop(tex, layer, reads, pt, stoch)
        elif reads.params.projection == PROJECT_TRIPLANAR:
            value = loop(tex, layer, reads, pt, stoch)
        else:
            uv, fp, weight = layer_read(tex, layer, 0, reads, pt)
            value = sample(tex, layer, uv, fp, reads.smp, stoch)
        return value

    def scatter_projections(tex: TextureView, grad: TexelGrad, layer: wp.int32, reads: LayerReads, pt: LayerPoint, stoch: StochasticArgs, g: wp.vec4):
        for k in range(layer_reads(reads.params)):
            uv, fp, weight = layer_read(tex, layer, k, reads, pt)
            if weight > 0.0:
                scatter(tex, grad, face_layer(reads.params, layer, k, pt.n), uv, fp, reads.smp, stoch, weight * g)

    def scatter_layer(tex: TextureView, grad: TexelGrad, layer: wp.int32, reads: LayerReads, pt: LayerPoint, stoch: StochasticArgs, g: wp.vec4):
        if grad.texels.shape[0] > 0:
            if wp.static(one_call):
                add_loop(tex, grad, layer, reads, pt, stoch, g)
            elif reads.params.projection == PROJECT_TRIPLANAR:
                add_loop(tex, grad, layer, reads, pt, stoch, g)
            else:
                uv, fp, weight = layer_read(tex, layer, 0, reads, pt)
                scatter(tex, grad, layer, uv, fp, reads.smp, stoch, g)

    loop = wp.func(specialised(read_projections, "read_projections" + suffix))
    add_loop = wp.func(specialised(scatter_projections, "scatter_projections" + suffix))
    return decorate(specialised(read_layer, "read_layer" + suffix)), inlined(specialised(scatter_layer, "scatter_layer" + suffix))


# Inlined where they are read: they take the launch's SplatArgs, which a call would copy whole, per layer.
read_layer_plain, _ = _layer_reads(sample_plain, scatter_plain, "_plain", one_call=False, decorate=inlined)  # the texel gradient scatters with the _once pair
# For the plain texel gradient, which replays the forward beside the scatters: each compiled once.
read_layer_plain_once, scatter_layer_plain_once = _layer_reads(sample_plain, scatter_plain, "_plain_once", one_call=True, decorate=inlined)
read_layer_stochastic, scatter_layer_stochastic = _layer_reads(sample_stochastic, scatter_stochastic, "_stochastic", one_call=True, decorate=inlined)
# For the generated adjoint: out of line, on the out-of-line stochastic sampler.
read_layer_outlined, _ = _layer_reads(sample_stochastic_outlined, scatter_stochastic, "_outlined", one_call=True, decorate=out_of_line)


@inlined
def read_layer_slope(tex: TextureView, layer: wp.int32, reads: LayerReads, pt: LayerPoint):
    """``(value, d value / d tiling)`` of ``read_layer`` with plain sampling, as Warp's adjoint takes
    the derivative (an anisotropic footprint's steps move in proportion to the tiling)."""
    value = wp.vec4(0.0)
    slope = wp.vec4(0.0)
    for k in range(layer_reads(reads.params)):
        uv, fp, weight = layer_read(tex, layer, k, reads, pt)
        if weight > 0.0:
            uv_slope, lod_slope = layer_read_slopes(tex, layer, k, reads, pt)
            v, d_u, d_v, d_lod, d_spread = sample_footprint_derivatives(tex, face_layer(reads.params, layer, k, pt.n), uv, fp, reads.smp)
            value += weight * v
            slope += weight * (d_u * uv_slope[0] + d_v * uv_slope[1] + d_lod * lod_slope + d_spread / layer_tiling(reads.params, layer))
    return value, slope
