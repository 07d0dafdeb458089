"""The splat maps' raw values, the splat weights, the blend and the blend's gradient for a lane of
pixels on the CPU, in native code (:mod:`.`, ``native/wt_splat_blend.h``), for the splat kernels of
up to 8 layers.

Each restates a block of :mod:`warptex.kernels.splat_blend` pixel by pixel, in its order and with Warp's own
functions where the block calls them (``wp::dot``, ``wp::div``...), so that the lane bodies of
:mod:`.splat` give the one-pixel kernels' bits (``tests/test_lanes.py``); the scalar blocks
copy each pixel's weights, colours and heights in and out of Warp's local matrices, which cost more
than the arithmetic. Kernels of 16 layers or more run the scalar blocks pixel by pixel.
"""

import warp as wp

from ..native import cpu_snippet
from ..projection import SurfacePixels
from ..splat_layers import SplatParams
from ..texels import SamplerArgs, TexelGrad, TextureView
from . import LANES, lane_colours, lane_floats

#: What :func:`blend_backward_lane8` gives: rows ``8 l + j``, the gradient of layer ``j``'s colour at
#: lane pixel ``l``; entry ``l % 4`` of row ``GRAD_TRANSITION + l // 4``, its transition's; entry
#: ``(8 l + j) % 4`` of row ``GRAD_HEIGHT + (8 l + j) // 4``, its height's (``blend_backward``'s
#: ``ghv``, which the tiling's gradient reads).
lane_grads = wp.types.matrix(shape=(LANES * 8 + LANES // 4 + LANES * 2, 4), dtype=float)
GRAD_TRANSITION = wp.constant(LANES * 8)
GRAD_HEIGHT = wp.constant(LANES * 8 + LANES // 4)


@wp.func_native(cpu_snippet("return wt_map_values_lane8(params, m, texels, covered, rs);\n", "return {};\n"))
def map_values_lane8(params: SplatParams, m: wp.int32, texels: lane_colours, covered: lane_floats, rs: wp.types.matrix(shape=(LANES, 8), dtype=float)) -> wp.types.matrix(shape=(LANES, 8), dtype=float):  # fmt: skip
    """``rs`` with, in the rows of the lane pixels ``l`` where ``covered[l] > 0``,
    ``splat_blend.map_values`` of map ``m``'s ``texels[l]``, for the kernels of up to 8 layers."""
    ...


@wp.func_native(cpu_snippet("return wt_weights_lane8(params, rs, covered);\n", "return {};\n"))
def weights_lane8(params: SplatParams, rs: wp.types.matrix(shape=(LANES, 8), dtype=float), covered: lane_floats) -> wp.types.matrix(shape=(LANES, 8), dtype=float):
    """Row ``l``: ``splat_blend.weights_of``'s ``w1`` of lane pixel ``l``'s raw splat values (row ``l``
    of ``rs``), for the kernels of up to 8 layers; 0 where ``covered[l]`` is not positive."""
    ...


@wp.func_native(cpu_snippet("return wt_blend_lane8(params, surface, base, count, w1s, colours, heights);\n", "return {};\n"))
def blend_lane8(params: SplatParams, surface: SurfacePixels, base: wp.int32, count: wp.int32, w1s: wp.types.matrix(shape=(LANES, 8), dtype=float),
                colours: wp.types.matrix(shape=(LANES * 8, 4), dtype=float), heights: wp.types.matrix(shape=(LANES, 8), dtype=float)) -> lane_colours:  # fmt: skip
    """Row ``l``: ``splat_blend.blend`` of lane pixel ``l``'s weights (row ``l`` of ``w1s``), colours
    (rows ``8 l + j``) and heights (row ``l``), for the kernels of up to 8 layers; 0 where the pixel is
    not covered."""
    ...


@wp.func_native(cpu_snippet("wt_blend_backward_lane8(params, surface, base, count, w1s, rs, adj, saved, maps, grad_maps, map_smp, uv0, out);\n"))
def blend_backward_lane8(params: wp.ref[SplatParams], surface: wp.ref[SurfacePixels], base: wp.int32, count: wp.int32, w1s: wp.ref[wp.types.matrix(shape=(LANES, 8), dtype=float)],
                         rs: wp.ref[wp.types.matrix(shape=(LANES, 8), dtype=float)], adj: wp.array2d(dtype=float), saved: wp.array2d(dtype=float), maps: wp.ref[TextureView],
                         grad_maps: wp.ref[TexelGrad], map_smp: wp.ref[SamplerArgs], uv0: wp.array(dtype=wp.vec2), out: wp.ref[lane_grads]):  # fmt: skip
    """For each covered lane pixel ``l`` (pixel ``base + l``), with its weights and raw splat values
    as :func:`blend_lane8` and ``weights_lane8`` take them, the colours its forward lane kept (row
    ``base + l`` of ``saved``, ``SplatPixels.saved``; heights from their height channel, or the
    height layers' it kept: ``wt_kept_column``) and its output gradient ``adj[base + l]``:
    ``splat_blend.blend_backward``'s colours', transition's and heights' gradients (the heights'
    also added into the colours' height channel, where that is where they are) and
    ``weights_backward``'s raw values' gradient; the colours', transition's and heights' written
    into ``out``, every row of it, laid out as :data:`lane_grads` says (0 for the other pixels),
    the raw values' added into the splat maps' texels (``grad_maps``; nothing when it is empty) at
    the pixel's UV0 where it is finite, in pixel order (``splat_blend.scatter_maps``), in the same
    call, so that they never leave it.

    Its matrices and structs are passed by reference (``wp.ref``), and ``out`` is the caller's:
    by value, every lane copied them into the call, and the 2.6 KB result out of it."""
    ...
