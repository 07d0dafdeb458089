"""Texel gradients for a lane of pixels: the ``scatter_*`` twins of :mod:`.sample` (as
:mod:`warptex.kernels.scatter` is of :mod:`warptex.kernels.filters`), in ``native/wt_scatter.h``.

A lane's taps and weights are computed for every pixel first, then added pixel by pixel and read by
read, in the order the scalar kernels add them: the same texels get the same sums in the same order,
so the gradients are the same bits, and the same tile marks (``scatter.mark_rows``) are made.
"""

import warp as wp

from ..native import cpu_snippet
from ..texels import SamplerArgs, TexelGrad, TextureView
from . import lane_colours, lane_ints, lane_reads, lane_taps


@wp.func_native(cpu_snippet("wt_scatter_levels_lane(tex, grad, uv_grad, smp, uv, layers, constant_layer, level, fraction, adj, base);\n"))
def scatter_levels_lane(tex: TextureView, grad: TexelGrad, uv_grad: wp.array(dtype=wp.vec2), smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), layers: wp.array(dtype=wp.int32),
                        constant_layer: wp.int32, level: wp.int32, fraction: float, adj: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """:func:`~warptex.kernels.scatter.scatter_levels` of the gradient ``adj[i]`` for the lane's
    pixels ``i = base ..`` whose ``uv[i]`` is finite (:func:`~.sample.sample_levels_lane`'s reads),
    where ``grad`` is needed, and where ``uv_grad`` is, ``sampling.scatter_sample_level``'s adds
    into it (not empty)."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_footprint_lane(tex, grad, uv_grad, lod_grad, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, adj, base);\n"))
def scatter_footprint_lane(tex: TextureView, grad: TexelGrad, uv_grad: wp.array(dtype=wp.vec2), lod_grad: wp.array(dtype=float), smp: SamplerArgs, uv: wp.array(dtype=wp.vec2),
                           uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2), lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32,
                           lod_source: wp.int32, constant_lod: float, adj: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """:func:`~warptex.kernels.scatter.scatter_footprint` of the gradient ``adj[i]`` for the lane's
    pixels ``i = base ..`` (:func:`~.sample.sample_footprint_lane`'s reads), where ``grad`` is
    needed; where the anisotropic filter's footprints take several taps, pixel by pixel, each
    footprint's taps in order. Where ``uv_grad`` and ``lod_grad`` are needed (not empty),
    ``sampling.scatter_sample``'s adds into them."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_face_reads_lanes(tex_px, tex_nx, tex_py, tex_ny, tex_pz, tex_nz, grad_px, grad_nx, grad_py, grad_ny, grad_pz, grad_nz, smp, layers, plus, minus, weigh, g0, g1, g2);\n"))
def scatter_face_reads_lanes(tex_px: TextureView, tex_nx: TextureView, tex_py: TextureView, tex_ny: TextureView, tex_pz: TextureView, tex_nz: TextureView,
                             grad_px: TexelGrad, grad_nx: TexelGrad, grad_py: TexelGrad, grad_ny: TexelGrad, grad_pz: TexelGrad, grad_nz: TexelGrad,
                             smp: SamplerArgs, layers: lane_ints, plus: lane_reads, minus: lane_reads, weigh: wp.int32, g0: lane_colours, g1: lane_colours, g2: lane_colours):  # fmt: skip
    """:func:`~warptex.kernels.scatter.scatter_lod` of the lane's reads with a texture per face:
    every lane pixel ``l`` adds each projection ``a``'s gradient ``g_a[l]`` (its share
    ``w · g_a[l]`` where ``weigh``: colour's; the sample's own where not: the two-step normal's)
    into the gradient of the face it reads
    (``plus``, ``minus``: ``projection.triplanar_reads_lane``'s reads of the two sides), where
    ``w`` is positive, pixel by pixel and projection by projection as the scalar kernels add them."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_projection_taps_lanes(tex0, tex1, tex2, grad0, grad1, grad2, smp, layers, taps0, taps1, taps2, g0, g1, g2);\n"))
def scatter_projection_taps_lanes(tex0: TextureView, tex1: TextureView, tex2: TextureView, grad0: TexelGrad, grad1: TexelGrad, grad2: TexelGrad, smp: SamplerArgs, layers: lane_ints,
                                  taps0: lane_taps, taps1: lane_taps, taps2: lane_taps, g0: lane_colours, g1: lane_colours, g2: lane_colours):  # fmt: skip
    """:func:`~warptex.kernels.stochastic.scatter_stochastic` of a stochastic triplanar lane's three
    projections: every tap in ``taps_a`` (:func:`~.stochastic.projection_taps_lane`) of lane
    pixel ``l`` adds its weight times ``g_a[l]`` (the projection's share of the pixel's gradient)
    into ``grad_a``, where the weight is positive, pixel by pixel in projection and tap order."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_taps_lane(tex, grad, smp, layers, taps, g);\n"))
def scatter_taps_lane(tex: TextureView, grad: TexelGrad, smp: SamplerArgs, layers: lane_ints, taps: lane_taps, g: lane_colours):
    """:func:`~warptex.kernels.stochastic.scatter_stochastic` of one-tap footprints for the lane:
    every stochastic tap in ``taps`` (:data:`~.lane_taps`) of lane pixel ``l`` adds its weight
    times ``g[l]`` into ``grad`` (layer ``layers[l]``, clamped), where the weight is positive."""
    ...
