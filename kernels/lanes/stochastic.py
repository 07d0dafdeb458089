"""``stochastic``'s CPU lanes (:mod:`.`): a lane's stochastic taps, worked out natively
(``native/wt_taps.h``: the hash 4-tap, cheap 2-tap and hex rules of :mod:`warptex.kernels.stochastic`,
operation for operation), for ``stochastic`` (:func:`stochastic_taps_lane`) and for a triplanar
lane's projections (:func:`projection_taps_lane`); and the lane bodies of ``stochastic``, forward
and texel gradient (:func:`lane_bodies`), which read those taps one by one with
:func:`.sample.accumulate_footprint_lane` and add their gradients with
:func:`.scatter.scatter_taps_lane`.
"""

import functools

import warp as wp

from .. import inlined
from ..native import cpu_snippet
from ..sampling import SampleGrads, SamplePixels, sample_layer
from ..stochastic import METHOD_NONE, StochasticArgs
from ..texels import FILTER_ANISOTROPIC, SamplerArgs, TextureView, read_channels, write_channels
from . import LANES, lane_colours, lane_floats, lane_ints, lane_reads, lane_taps
from .sample import accumulate_footprint_lane
from .scatter import scatter_taps_lane


@wp.func_native(cpu_snippet("return wt_stochastic_taps_lane(tex, smp, params, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);\n", "return {};\n"))
def stochastic_taps_lane(tex: TextureView, smp: SamplerArgs, params: StochasticArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2),
                         lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float, base: wp.int32) -> lane_taps:  # fmt: skip
    """The lane's :data:`~.lane_taps` from ``base``: every pixel's LOD
    (``sampling.sample_footprint_of``, one tap), whether its UV and LOD are finite, and its taps and
    their weights (0 where not finite)."""
    ...


@wp.func_native(cpu_snippet("return wt_projection_taps_lane(params, reads, axis, count);\n", "return {};\n"))
def projection_taps_lane(params: StochasticArgs, reads: lane_reads, axis: wp.int32, count: wp.int32) -> lane_taps:
    """The :data:`~.lane_taps` of projection ``axis`` of a triplanar lane's ``reads``
    (:data:`~.lane_reads`): each pixel's stochastic taps of that read's UV at its LOD, their
    weights 0 where the pixel does not read the projection or its UV or LOD is not finite."""
    ...


@wp.func
def lane_taps_linear(smp: SamplerArgs, params: StochasticArgs) -> bool:
    """Whether the lanes take a lookup tap by tap: a linear blend (no histogram) of one-tap
    footprints (not the anisotropic filter) of a stochastic method (``stochastic``'s lanes, and
    those of stochastic triplanar)."""
    return smp.filter != FILTER_ANISOTROPIC and params.histogram == 0 and params.method != METHOD_NONE


@functools.cache
def lane_bodies(pixel, scatter_pixel, args_t):
    """``(stochastic_lane, scatter_stochastic_lane)``: the lane bodies of ``stochastic`` whose
    scalar bodies are ``pixel`` and ``scatter_pixel``, over arguments ``args_t``
    (``stochastic_sample.StochasticSampleArgs``: ``sample`` and ``params``)."""

    @wp.func
    def stochastic_lane_taps(args: args_t, pixels: SamplePixels, base: wp.int32, count: wp.int32):
        """``(taps, layers)``: the lane's stochastic taps (:data:`~.lane_taps`; one-tap
        footprints: each reads its UV itself), worked out natively (:func:`stochastic_taps_lane`),
        and each pixel's layer."""
        a = args.sample
        taps = stochastic_taps_lane(a.tex, a.smp, args.params, pixels.uv, pixels.uv_dx, pixels.uv_dy, pixels.lods, pixels.layers, a.constant_layer, a.lod_source, a.constant_lod, base)
        layers = lane_ints()
        for l in range(count):
            layers[l] = sample_layer(a, pixels, base + l)
        return taps, layers

    @inlined
    def stochastic_lane(args: args_t, pixels: SamplePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        """``pixel`` for the lane of pixels from ``base``: the lane's taps, then read natively,
        tap by tap, with ``accumulate_footprint_lane`` (``value += w · sample``, as
        ``sample_stochastic`` blends them, from 0). A histogram's blend (not linear), the
        anisotropic filter's footprints (several taps, each with its stochastic taps) and plain
        sampling go pixel by pixel through the body."""
        count = wp.min(out.shape[0] - base, LANES)
        if not lane_taps_linear(args.sample.smp, args.params):
            for l in range(count):
                pixel(args, pixels, base + l, out)
        else:
            a = args.sample
            taps, layers = stochastic_lane_taps(args, pixels, base, count)
            zero = lane_floats()
            one = lane_floats(1.0)
            value = lane_colours()
            for k in range(4):
                value = accumulate_footprint_lane(a.tex, a.smp, layers, taps[3 * k], taps[3 * k + 1], taps[12], zero, zero, one, taps[3 * k + 2], 1, value)
            for l in range(count):
                result = wp.vec4(wp.nan)
                if taps[13, l] != 0.0:
                    result = wp.vec4(0.0) + value[l]  # the body's `result += value`, from 0
                write_channels(out, base + l, result)

    @inlined
    def scatter_stochastic_lane(args: args_t, pixels: SamplePixels, base: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
        """``scatter_pixel`` for the lane of pixels from ``base``: the lane's taps, then their adds
        natively (``scatter_taps_lane``), pixel by pixel and tap by tap as the body adds them; what
        ``stochastic_lane`` takes pixel by pixel, likewise."""
        count = wp.min(adj.shape[0] - base, LANES)
        if not lane_taps_linear(args.sample.smp, args.params):
            for l in range(count):
                scatter_pixel(args, pixels, base + l, grads, adj)
        else:
            taps, layers = stochastic_lane_taps(args, pixels, base, count)
            g = lane_colours()
            for l in range(count):
                g[l] = read_channels(adj, base + l)
            scatter_taps_lane(args.sample.tex, grads.tex, args.sample.smp, layers, taps, g)

    return stochastic_lane, scatter_stochastic_lane
