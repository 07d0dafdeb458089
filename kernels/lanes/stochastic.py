"""``stochastic``'s CPU lanes (:mod:`.`): a lane's stochastic taps, worked out natively
(``native/wt_taps.h``: the hash 4-tap, cheap 2-tap and hex rules of :mod:`warptex.kernels.stochastic`,
operation for operation), for ``stochastic`` (:func:`stochastic_taps_lane`) and for a triplanar
lane's projections (:func:`projection_taps_lane`); a lookup over each pixel's footprint, every
footprint tap's stochastic taps read one by one (:func:`stochastic_footprint_lane`,
:func:`stochastic_read_lane`: the anisotropic filter's footprints too); and the lane bodies of
``stochastic``, forward and texel gradient (:func:`lane_bodies`), whose gradient adds the taps'
shares with :func:`.scatter.scatter_taps_lane` (one-tap footprints), or with the anisotropic
filter, every footprint tap's with :func:`scatter_stochastic_footprint_lane`.
"""

import functools

import warp as wp

from .. import inlined
from ..native import cpu_snippet
from ..sampling import SampleGrads, SamplePixels, sample_layer
from ..stochastic import METHOD_NONE, StochasticArgs
from ..texels import FILTER_ANISOTROPIC, SamplerArgs, TexelGrad, TextureView, read_channels
from . import LANES, lane_colours, lane_ints, lane_reads, lane_taps
from .sample import write_lane
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


@wp.func_native(cpu_snippet("return wt_stochastic_footprint_lane(tex, smp, params, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);\n", "return {};\n"))
def stochastic_footprint_lane(tex: TextureView, smp: SamplerArgs, params: StochasticArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2),
                              lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float, base: wp.int32) -> lane_colours:  # fmt: skip
    """Row ``l``: ``stochastic.sample_stochastic`` (a linear blend: :func:`lane_blend_linear`) of
    pixel ``base + l`` over its footprint (``sampling.sample_footprint_of``; the anisotropic
    filter's taps each with their stochastic taps), NaN where its UV or LOD is not finite."""
    ...


@wp.func_native(cpu_snippet("return wt_stochastic_read_lane(tex, smp, params, layers, reads, axis, count);\n", "return {};\n"))
def stochastic_read_lane(tex: TextureView, smp: SamplerArgs, params: StochasticArgs, layers: lane_ints, reads: lane_reads, axis: wp.int32, count: wp.int32) -> lane_colours:
    """Row ``l``: ``stochastic.sample_stochastic`` (a linear blend) of read ``axis`` of a triplanar
    lane's ``reads`` over its footprint, where its weight is positive (NaN where its UV or LOD is
    not finite), else 0."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_stochastic_footprint_lane(tex, grad, smp, params, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, adj, base);\n"))
def scatter_stochastic_footprint_lane(tex: TextureView, grad: TexelGrad, smp: SamplerArgs, params: StochasticArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2),
                                      uv_dy: wp.array(dtype=wp.vec2), lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32,
                                      constant_lod: float, adj: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """``stochastic.scatter_stochastic`` (a linear blend) of the gradient ``adj[i]`` for the lane's
    pixels ``i = base ..`` over their footprints (:func:`stochastic_footprint_lane`'s reads: the
    anisotropic filter's too), pixel by pixel, each footprint tap's stochastic taps in order; the
    footprint taps' stochastic taps worked out natively 8 at a time."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_stochastic_reads_lanes(tex0, tex1, tex2, grad0, grad1, grad2, smp, params, layers, reads, weigh, g0, g1, g2);\n"))
def scatter_stochastic_reads_lanes(tex0: TextureView, tex1: TextureView, tex2: TextureView, grad0: TexelGrad, grad1: TexelGrad, grad2: TexelGrad, smp: SamplerArgs, params: StochasticArgs,
                                   layers: lane_ints, reads: lane_reads, weigh: wp.int32, g0: lane_colours, g1: lane_colours, g2: lane_colours):  # fmt: skip
    """``stochastic.scatter_stochastic`` (a linear blend) of a stochastic triplanar lane's three
    projections over their footprints (the anisotropic filter's too): every lane pixel ``l`` adds
    projection ``a``'s share (``w · g_a[l]`` where ``weigh``, else ``g_a[l]``) into ``grad_a``,
    where ``w`` is positive, pixel by pixel in projection, footprint tap and stochastic tap order."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_stochastic_face_reads_lanes(tex_px, tex_nx, tex_py, tex_ny, tex_pz, tex_nz, grad_px, grad_nx, grad_py, grad_ny, grad_pz, grad_nz, smp, params, layers, plus, minus, weigh, g0, g1, g2);\n"))
def scatter_stochastic_face_reads_lanes(tex_px: TextureView, tex_nx: TextureView, tex_py: TextureView, tex_ny: TextureView, tex_pz: TextureView, tex_nz: TextureView,
                                        grad_px: TexelGrad, grad_nx: TexelGrad, grad_py: TexelGrad, grad_ny: TexelGrad, grad_pz: TexelGrad, grad_nz: TexelGrad,
                                        smp: SamplerArgs, params: StochasticArgs, layers: lane_ints, plus: lane_reads, minus: lane_reads, weigh: wp.int32,
                                        g0: lane_colours, g1: lane_colours, g2: lane_colours):  # fmt: skip
    """``stochastic.scatter_stochastic`` (a linear blend) with a texture per face, every filter's:
    every lane pixel ``l`` adds each projection ``a``'s gradient ``g_a[l]`` (its share ``w · g_a[l]``
    where ``weigh``) through its stochastic taps into the gradient of the face it reads (``plus``,
    ``minus``: ``projection.triplanar_reads_lane``'s reads of the two sides), pixel by pixel in
    projection, footprint tap and stochastic tap order."""
    ...


def linear_blend(params: StochasticArgs) -> bool:
    """Whether the lanes take a lookup with ``params`` (``Kernels.lanes_take`` of each stochastic
    lane kernel): a linear blend (no histogram) of a stochastic method, over footprints of any
    filter (:func:`stochastic_footprint_lane`, :func:`stochastic_read_lane`). A histogram's blend
    is not linear: the one-pixel kernels run it, so that no lane kernel compiles the pixel bodies
    as its fallback (they made the stochastic lane modules' CUDA compile about 13 s each)."""
    return params.histogram == 0 and params.method != METHOD_NONE


def linear_blend_take(args) -> bool:
    """:func:`linear_blend` of a launch's ``args`` (a struct whose ``params`` are its stochastic
    options: ``stochastic_sample.StochasticSampleArgs``)."""
    return linear_blend(args.params)


@functools.cache
def lane_bodies(args_t):
    """``(stochastic_lane, scatter_stochastic_lane)``: the lane bodies of ``stochastic`` over
    arguments ``args_t`` (``stochastic_sample.StochasticSampleArgs``: ``sample`` and ``params``),
    launched where :func:`linear_blend_take` holds."""

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
        """``stochastic_sample.stochastic_pixel`` for the lane of pixels from ``base``: each
        pixel's footprint, each footprint tap's stochastic taps, read natively tap by tap
        (:func:`stochastic_footprint_lane`)."""
        count = wp.min(out.shape[0] - base, LANES)
        a = args.sample
        write_lane(out, base, count, stochastic_footprint_lane(a.tex, a.smp, args.params, pixels.uv, pixels.uv_dx, pixels.uv_dy, pixels.lods, pixels.layers, a.constant_layer, a.lod_source,
                                                            a.constant_lod, base))  # fmt: skip

    @inlined
    def scatter_stochastic_lane(args: args_t, pixels: SamplePixels, base: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
        """``stochastic_sample.scatter_stochastic_pixel`` for the lane of pixels from ``base``: the
        lane's taps, then their adds natively (``scatter_taps_lane``), pixel by pixel and tap by tap
        as the body adds them; with the anisotropic filter, every footprint tap's taps in order
        (:func:`scatter_stochastic_footprint_lane`)."""
        count = wp.min(adj.shape[0] - base, LANES)
        a = args.sample
        if a.smp.filter == FILTER_ANISOTROPIC:
            scatter_stochastic_footprint_lane(a.tex, grads.tex, a.smp, args.params, pixels.uv, pixels.uv_dx, pixels.uv_dy, pixels.lods, pixels.layers, a.constant_layer, a.lod_source, a.constant_lod, adj, base)
        else:
            taps, layers = stochastic_lane_taps(args, pixels, base, count)
            g = lane_colours()
            for l in range(count):
                g[l] = read_channels(adj, base + l)
            scatter_taps_lane(args.sample.tex, grads.tex, args.sample.smp, layers, taps, g)

    return stochastic_lane, scatter_stochastic_lane
