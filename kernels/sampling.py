"""The ``sample`` technique's kernels (plain sampling at given UVs), and mip-chain downsampling.

The building blocks every technique samples with live beside this module: texture storage,
addressing and channel I/O in :mod:`.texels`, levels of detail and footprints in
:mod:`.footprint`, filtering in :mod:`.filters`, texel gradients in :mod:`.scatter`.
"""

import warp as wp

from . import inlined, specialised
from .family import Kernels, family, lane_kernel, pixel_kernels
from .filters import sample_footprint, sample_footprint_derivatives, sample_footprint_outlined, sample_levels, sample_levels_derivatives
from .footprint import point_footprint, texture_footprint
from .lanes.sample import sample_footprint_lane, sample_levels_lane
from .lanes.scatter import scatter_footprint_lane, scatter_levels_lane
from .native import use
from .scatter import scatter_footprint, scatter_levels
from .texels import LOD_CONSTANT, LOD_DERIVATIVES, LOD_PER_SAMPLE, SamplerArgs, TexelGrad, TextureView, finite_uv_lod, read_channels, resolve_layer, write_channels

MODULE = use("warptex.sample")
LOD_MODULE = use(MODULE + ".lod")  # the lanes of a LOD per sample: apart from the one-LOD lanes, which every plain lookup compiles
MIPS_MODULE = use("warptex.mips")


@wp.struct
class SampleArgs:
    """What every sample of a ``sample`` (or ``stochastic``) launch reads: the texture, the
    sampler, where the LOD comes from (``lod_source``, one of ``LOD_*``; ``constant_lod`` for
    ``LOD_CONSTANT``), the layer when there are no per-sample layers, and, for the kernels of one
    LOD shared by every sample, that LOD's ``level`` and ``fraction`` resolved on the host (as
    :func:`~warptex.kernels.footprint.mip_levels` does): the level's size and offset are then the
    same for every sample, which measured a third faster than deriving them per sample."""

    tex: TextureView
    smp: SamplerArgs
    lod_source: wp.int32
    constant_lod: float
    constant_layer: wp.int32
    level: wp.int32
    fraction: float


@wp.struct
class SamplePixels:
    """The per-sample inputs (empty arrays where unused): UVs, their screen-space derivatives, LODs
    and layer indices."""

    uv: wp.array(dtype=wp.vec2)
    uv_dx: wp.array(dtype=wp.vec2)
    uv_dy: wp.array(dtype=wp.vec2)
    lods: wp.array(dtype=float)
    layers: wp.array(dtype=wp.int32)


@wp.struct
class SampleGrads:
    """The hand-written gradient's targets (empty: not needed): the texels of ``args.tex``, and each
    sample's UV and LOD (``pixels.uv``, ``pixels.lods``)."""

    tex: TexelGrad
    uv: wp.array(dtype=wp.vec2)
    lods: wp.array(dtype=float)


@wp.func
def sample_layer(args: SampleArgs, pixels: SamplePixels, i: wp.int32) -> wp.int32:
    """Sample ``i``'s layer: its per-sample index, clamped to the array, or the constant layer."""
    return resolve_layer(args.tex, i, pixels.layers, args.constant_layer)


@wp.func
def sample_footprint_of(args: SampleArgs, pixels: SamplePixels, i: wp.int32) -> wp.vec4:
    """Sample ``i``'s footprint by ``args.lod_source`` (a given LOD is one tap)."""
    fp = point_footprint(0.0)
    if args.lod_source == LOD_CONSTANT:
        fp = point_footprint(args.constant_lod)
    elif args.lod_source == LOD_PER_SAMPLE:
        fp = point_footprint(pixels.lods[i])
    elif args.lod_source == LOD_DERIVATIVES:
        fp = texture_footprint(args.tex, pixels.uv_dx[i], pixels.uv_dy[i], args.smp)
    return fp


# -- kernels (see .family: forward, texel_grad and adjoint of each configuration) ----------------------


def _footprint_bodies(sample, name: str):
    """``body`` and ``scatter`` of the per-sample kernels: each sample's own LOD (or derivatives)."""

    def body(args: SampleArgs, pixels: SamplePixels, i: wp.int32, out: wp.array2d(dtype=float)):
        """``out[i, c]`` = channel ``c`` of the texture sampled at ``pixels.uv[i]``."""
        write_channels(out, i, sample(args.tex, sample_layer(args, pixels, i), pixels.uv[i], sample_footprint_of(args, pixels, i), args.smp))

    return inlined(specialised(body, name))


@inlined
def scatter_sample(args: SampleArgs, pixels: SamplePixels, i: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """Add the gradient ``g = adj[i]`` of the per-sample body into the texels it read, and where they
    are needed, ``(g · d/du, g · d/dv)`` into its UV's gradient and ``g · d/dlod`` into its LOD's
    (:func:`~.filters.sample_footprint_derivatives`; ``pixels.lods`` is read only for a LOD per
    sample, the one LOD source whose gradient this body takes)."""
    layer = sample_layer(args, pixels, i)
    fp = sample_footprint_of(args, pixels, i)
    g = read_channels(adj, i)
    if grads.tex.texels.shape[0] > 0:
        scatter_footprint(args.tex, grads.tex, layer, pixels.uv[i], fp, args.smp, g)
    if grads.uv.shape[0] > 0 or grads.lods.shape[0] > 0:
        value, d_u, d_v, d_lod, d_spread = sample_footprint_derivatives(args.tex, layer, pixels.uv[i], fp, args.smp)
        if grads.uv.shape[0] > 0:
            wp.atomic_add(grads.uv, i, wp.vec2(wp.dot(g, d_u), wp.dot(g, d_v)))
        if grads.lods.shape[0] > 0:
            wp.atomic_add(grads.lods, i, wp.dot(g, d_lod))


@inlined
def sample_level_pixel(args: SampleArgs, pixels: SamplePixels, i: wp.int32, out: wp.array2d(dtype=float)):
    """The per-sample body for one LOD shared by every sample (``args.level``, ``args.fraction``)."""
    layer = sample_layer(args, pixels, i)
    result = wp.vec4(wp.nan)
    if finite_uv_lod(pixels.uv[i], 0.0):
        result = sample_levels(args.tex, layer, pixels.uv[i], args.level, args.fraction, args.smp)
    write_channels(out, i, result)


@inlined
def scatter_sample_level(args: SampleArgs, pixels: SamplePixels, i: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """Add the gradient ``g = adj[i]`` of :func:`sample_level_pixel` into the texels it read, and
    where it is needed, ``(g · d/du, g · d/dv)`` into its UV's gradient
    (:func:`~.filters.sample_levels_derivatives`); a non-finite UV adds nothing."""
    if finite_uv_lod(pixels.uv[i], 0.0):
        layer = sample_layer(args, pixels, i)
        g = read_channels(adj, i)
        if grads.tex.texels.shape[0] > 0:
            scatter_levels(args.tex, grads.tex, layer, pixels.uv[i], args.level, args.fraction, args.smp, g)
        if grads.uv.shape[0] > 0:
            d_u, d_v = sample_levels_derivatives(args.tex, layer, pixels.uv[i], args.level, args.fraction, args.smp)
            wp.atomic_add(grads.uv, i, wp.vec2(wp.dot(g, d_u), wp.dot(g, d_v)))


@inlined
def sample_level_lane(args: SampleArgs, pixels: SamplePixels, base: wp.int32, out: wp.array2d(dtype=float)):
    """:func:`sample_level_pixel` for the lane of pixels from ``base`` (:mod:`.lanes`), on the CPU."""
    sample_levels_lane(args.tex, args.smp, pixels.uv, pixels.layers, args.constant_layer, args.level, args.fraction, out, base)


@inlined
def scatter_sample_level_lane(args: SampleArgs, pixels: SamplePixels, base: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """:func:`scatter_sample_level` for the lane of pixels from ``base`` (:mod:`.lanes`), on the CPU."""
    scatter_levels_lane(args.tex, grads.tex, grads.uv, args.smp, pixels.uv, pixels.layers, args.constant_layer, args.level, args.fraction, adj, base)


@inlined
def sample_lane(args: SampleArgs, pixels: SamplePixels, base: wp.int32, out: wp.array2d(dtype=float)):
    """:func:`sample_pixel` for the lane of pixels from ``base`` (:mod:`.lanes`), on the CPU."""
    sample_footprint_lane(args.tex, args.smp, pixels.uv, pixels.uv_dx, pixels.uv_dy, pixels.lods, pixels.layers, args.constant_layer, args.lod_source, args.constant_lod, out, base)


@inlined
def scatter_sample_lane(args: SampleArgs, pixels: SamplePixels, base: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """:func:`scatter_sample` for the lane of pixels from ``base`` (:mod:`.lanes`), on the CPU (the
    anisotropic filter's footprints of several taps pixel by pixel, inside the native call)."""
    scatter_footprint_lane(args.tex, grads.tex, grads.uv, grads.lods, args.smp, pixels.uv, pixels.uv_dx, pixels.uv_dy, pixels.lods, pixels.layers, args.constant_layer, args.lod_source, args.constant_lod, adj, base)


sample_pixel = _footprint_bodies(sample_footprint, "sample_pixel")
sample_pixel_outlined = _footprint_bodies(sample_footprint_outlined, "sample_pixel_outlined")


#: What the hand-written gradient serves, in :class:`SampleGrads`' order (``Kernels.grads``).
GRADS = ("args.tex", "pixels.uv", "pixels.lods")


@family(configurations=[{"level": False}, {"level": True}])
def sample_kernels(*, level: bool) -> Kernels:
    """The ``sample`` kernels: with ``level``, for one LOD shared by every sample, its levels
    resolved on the host; else each sample's LOD from ``args.lod_source``. Each has lane kernels
    for the CPU, forward and hand-written gradient. The hand-written gradient reaches the texels, the
    UVs and a LOD per sample; UV derivatives (and the rest, where they need one) take the generated
    adjoint."""
    if level:
        kernels = pixel_kernels("sample_level", module=MODULE, args=SampleArgs, pixels=SamplePixels, out=wp.array2d(dtype=float),
                                body=sample_level_pixel, scatter=scatter_sample_level, grads=SampleGrads, adjoint_body=sample_level_pixel)  # fmt: skip
        lanes = lane_kernel(sample_level_lane, SampleArgs, SamplePixels, wp.array2d(dtype=float), module=MODULE, name="sample_level_lanes")
        grad_lanes = lane_kernel(scatter_sample_level_lane, SampleArgs, SamplePixels, wp.array2d(dtype=float), grads_t=SampleGrads, module=MODULE + ".grad", name="sample_level_texel_grad_lanes")
        return Kernels(*kernels, grads=GRADS, lanes=lanes, texel_grad_lanes=grad_lanes, fills=True)
    kernels = pixel_kernels("sample", module=MODULE, args=SampleArgs, pixels=SamplePixels, out=wp.array2d(dtype=float),
                            body=sample_pixel, scatter=scatter_sample, grads=SampleGrads, adjoint_body=sample_pixel_outlined)  # fmt: skip
    lanes = lane_kernel(sample_lane, SampleArgs, SamplePixels, wp.array2d(dtype=float), module=LOD_MODULE, name="sample_lanes")
    grad_lanes = lane_kernel(scatter_sample_lane, SampleArgs, SamplePixels, wp.array2d(dtype=float), grads_t=SampleGrads, module=LOD_MODULE + ".grad", name="sample_texel_grad_lanes")
    return Kernels(*kernels, grads=GRADS, lanes=lanes, texel_grad_lanes=grad_lanes, fills=True)


@wp.kernel(module=MIPS_MODULE)
def downsample_kernel(tex: TextureView, level: wp.int32, texels: wp.array(dtype=wp.vec4)):
    """Box-filter ``level`` into ``level + 1`` of every layer, for any (non-power-of-two) size.

    Launched over ``(layers, h_{k+1}, w_{k+1})``. Each coarse texel covers an axis-aligned
    rectangle of ``w_k / w_{k+1}`` by ``h_k / h_{k+1}`` fine texels and is the area-weighted mean
    of the fine texels it overlaps, so odd sizes lose nothing and a constant stays constant.
    ``texels`` is ``tex.texels``, passed separately so the tape sees the write; the two levels are
    disjoint, so the backward pass carries gradients of level ``k + 1`` down to level ``k``.
    """
    layer, row, col = wp.tid()
    w0 = tex.level_width[level]
    h0 = tex.level_height[level]
    w1 = tex.level_width[level + 1]
    h1 = tex.level_height[level + 1]
    # Cell edges as exact integer ratios, so the last cell ends exactly on the last fine texel.
    x_lo = float(col * w0) / float(w1)
    x_hi = float((col + 1) * w0) / float(w1)
    y_lo = float(row * h0) / float(h1)
    y_hi = float((row + 1) * h0) / float(h1)
    src = tex.level_offset[level] + layer * h0 * w0
    norm = float(w1 * h1) / float(w0 * h0)  # applied to each term, so that texels near FLOAT_MAX do not overflow the sum
    acc = wp.vec4(0.0)
    for y in range(int(wp.floor(y_lo)), wp.min(int(wp.ceil(y_hi)), h0)):
        wy = wp.min(y_hi, float(y + 1)) - wp.max(y_lo, float(y))
        for x in range(int(wp.floor(x_lo)), wp.min(int(wp.ceil(x_hi)), w0)):
            wx = wp.min(x_hi, float(x + 1)) - wp.max(x_lo, float(x))
            acc += texels[src + y * w0 + x] * (wx * wy * norm)
    texels[tex.level_offset[level + 1] + (layer * h1 + row) * w1 + col] = acc
