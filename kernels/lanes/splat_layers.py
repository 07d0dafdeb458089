"""The splat's layer reads and their texel gradients for a lane of pixels, as native calls (the twins
of :mod:`warptex.kernels.splat_layers`, ``native/wt_splat_layers.h``): a layer's reads of a lane
(UV, footprint, weight per projection: ``layer_read`` restated, ``wt_layer_reads_into``) and their
texels' reads over their footprints, plain or stochastic, kept for the gradient lane where it
reads them; and the adds of a layer's gradient into its texels, layer by layer, or, with face
layers (by which layers share array layers), every layer's at once, pixel by pixel. The splat's
lane bodies (:mod:`.splat`) call them.
"""

import functools

import warp as wp

from .. import specialised
from ..native import cpu_snippet
from ..projection import SurfacePixels
from ..splat_layers import LayerReads
from ..stochastic import StochasticArgs
from ..texels import TexelGrad, TextureView
from . import LANES, lane_colours, lane_floats
from .splat_blend import lane_grads


# Per lane pixel (row): its projections' triplanar weights.
lane_vec3 = wp.types.matrix(shape=(LANES, 3), dtype=float)


_VALUES = "return wt_layer_values_lane<{}>(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, keep, saved);\n"
_BLEND = "return wt_layer_blend_lane<{}>(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, keep, saved, colour);\n"


@wp.func_native(cpu_snippet(_VALUES.format("false"), "return {};\n"))
def layer_values_lane(tex: TextureView, reads: LayerReads, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2), uv0_dx: wp.array(dtype=wp.vec2),
                      uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32, tri_w: lane_vec3, keep: wp.int32,
                      saved: wp.array2d(dtype=float)) -> lane_colours:  # fmt: skip
    """Row ``l``: layer ``j`` of ``tex`` read at lane pixel ``l`` over the footprints of
    ``wt_layer_reads_into``' reads as ``read_layer`` reads it (0 where ``weighted[l]`` is not positive);
    one native call rather than a read per projection. Where ``keep`` and ``saved`` is not empty,
    also stored in ``saved``'s row ``base + l``, columns ``4 j .. 4 j + 3`` (``SplatPixels.saved``)."""
    ...


@wp.func_native(cpu_snippet(_VALUES.format("true"), "return {};\n"))
def layer_values_kept_lane(tex: TextureView, reads: LayerReads, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2), uv0_dx: wp.array(dtype=wp.vec2),
                           uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32, tri_w: lane_vec3, keep: wp.int32,
                           saved: wp.array2d(dtype=float)) -> lane_colours:  # fmt: skip
    """:func:`layer_values_lane` for the forward lane that keeps what the gradient lane reads
    (``Kernels.kept_lanes``): where ``saved`` has 8 columns a layer (the tiling needs its gradient:
    :func:`lane_saved`), the same taps also give ``read_layer_slope``'s value and slope along the
    layer's tiling, kept in columns ``4 j ..`` and ``4 (L + j) ..`` (``L`` layers). That value may
    differ from the forward's in the last bit (a footprint of several taps is divided by its taps,
    where the forward multiplies by their reciprocal) or the sign of a zero, and the one-pixel
    gradient blends the values it reads with the slopes. Only this one compiles the slopes' code
    (``wt_layer_values_slopes``: 4 s more of a render's cold compile, which never needs it)."""
    ...


@wp.func_native(cpu_snippet(_BLEND.format("false"), "return {};\n"))
def layer_blend_lane(tex: TextureView, reads: LayerReads, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2), uv0_dx: wp.array(dtype=wp.vec2),
                     uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32, tri_w: lane_vec3, keep: wp.int32,
                     saved: wp.array2d(dtype=float), colour: lane_colours) -> lane_colours:  # fmt: skip
    """``colour`` plus layer ``j`` (:func:`layer_values_lane`, the same arguments) weighted by
    ``weighted``, row by row: ``splat_blend.blend``'s sum without height blending, a layer at a
    time, so that the lane's colours are never held for all layers at once."""
    ...


@wp.func_native(cpu_snippet(_BLEND.format("true"), "return {};\n"))
def layer_blend_kept_lane(tex: TextureView, reads: LayerReads, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2), uv0_dx: wp.array(dtype=wp.vec2),
                          uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32, tri_w: lane_vec3, keep: wp.int32,
                          saved: wp.array2d(dtype=float), colour: lane_colours) -> lane_colours:  # fmt: skip
    """:func:`layer_blend_lane` of :func:`layer_values_kept_lane`."""
    ...


_STOCHASTIC = "return wt_layer_values_stochastic_lane(tex, reads, stoch, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, keep, saved);\n"


@wp.func_native(cpu_snippet(_STOCHASTIC, "return {};\n"))
def layer_values_stochastic_lane(tex: TextureView, reads: LayerReads, stoch: StochasticArgs, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2),
                                 uv0_dx: wp.array(dtype=wp.vec2), uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32,
                                 tri_w: lane_vec3, keep: wp.int32, saved: wp.array2d(dtype=float)) -> lane_colours:  # fmt: skip
    """:func:`layer_values_lane` with stochastic sampling (``stoch``; :func:`.splat.stochastic_lanes_take`):
    ``read_layer_stochastic``, each read's stochastic taps (of each tap of its footprint) worked out
    natively and read tap by tap (``wt_layer_values_stochastic_lane``)."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_layer_stochastic_lane(tex, grad, reads, stoch, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, g);\n"))
def scatter_layer_stochastic_lane(tex: TextureView, grad: TexelGrad, reads: LayerReads, stoch: StochasticArgs, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2),
                                  uv0_dx: wp.array(dtype=wp.vec2), uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32,
                                  tri_w: lane_vec3, g: lane_colours):  # fmt: skip
    """:func:`scatter_layer_lane` of :func:`layer_values_stochastic_lane`'s reads: each read's share
    ``w · g`` added through its stochastic taps, pixel by pixel in read and tap order
    (``scatter_layer_stochastic``)."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_layer_lane(tex, grad, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, g);\n"))
def scatter_layer_lane(tex: TextureView, grad: TexelGrad, reads: LayerReads, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2),
                       uv0_dx: wp.array(dtype=wp.vec2), uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32,
                       tri_w: lane_vec3, g: lane_colours):  # fmt: skip
    """``scatter_layer`` of the gradients ``g[l]`` of layer ``j``'s reads of ``tex`` (``wt_layer_reads_into``,
    as :func:`layer_values_lane` reads them) into ``grad``, pixel by pixel and read by read:
    ``w · g`` per projection where triplanar (``scatter_projections``), ``g`` itself for the one
    read of the other projections (``wt_scatter_lod``); where a read has several taps
    (the anisotropic filter's), the lane's taps pixel by pixel, read by read, each read's in order
    (``wt_scatter_footprint_rows``)."""
    ...


@wp.func_native(cpu_snippet("wt_scatter_layers_lane8(tex, grad, reads, w1s, back, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w);\n"))
def scatter_layers_lane8(tex: wp.ref[TextureView], grad: wp.ref[TexelGrad], reads: wp.ref[LayerReads], w1s: wp.ref[wp.types.matrix(shape=(LANES, 8), dtype=float)], back: wp.ref[lane_grads], uv0: wp.array(dtype=wp.vec2),
                         uv0_dx: wp.array(dtype=wp.vec2), uv0_dy: wp.array(dtype=wp.vec2), surface: wp.ref[SurfacePixels], base: wp.int32, count: wp.int32, tri_w: wp.ref[lane_vec3]):  # fmt: skip
    """:func:`scatter_layer_lane` of every colour layer ``j`` of a splat kernel of up to 8 layers in
    turn (weights ``w1s[l, j]``, the gradient of its colour at lane pixel ``l`` row ``8 l + j`` of
    ``back``, :func:`.splat_blend.blend_backward_lane8`'s), in one call: through Warp, each layer's
    gradient rows were built, then copied into its call with the weights (a tenth of the texel
    adds' lane body). ``back`` and the structs are passed by reference (``wp.ref``): by value, each
    lane copied ``back``'s 2.6 KB into the call."""
    ...


#: The stubs :func:`scatter_face_layers_of` has made, by their Warp name (for ``tests/test_native.py``,
#: which reads the stubs of module attributes).
FACE_LAYER_STUBS: dict = {}


@functools.cache
def scatter_face_layers_of(cap: int, lane_weights_t, lane_layers_t, stochastic: bool = False):
    """The native call that adds the texel gradients of every layer of a splat of ``cap`` layers
    where face layers let layers share array layers (``wt_scatter_face_layers_lane``; with
    ``stochastic``, ``wt_scatter_face_layers_stochastic_lane``, whose stub also takes the
    :class:`~warptex.kernels.stochastic.StochasticArgs` ``stoch`` after ``reads``)."""
    stub = _face_layers_stub(cap, lane_weights_t, lane_layers_t, stochastic)
    FACE_LAYER_STUBS[stub.key] = stub
    return stub


def _face_layers_stub(cap: int, lane_weights_t, lane_layers_t, stochastic: bool):
    """:func:`scatter_face_layers_of`'s stub, made."""
    if stochastic:

        def scatter_face_layers_stochastic_lane(tex: TextureView, grad: TexelGrad, reads: LayerReads, stoch: StochasticArgs, w1s: lane_weights_t, uv0: wp.array(dtype=wp.vec2),
                                                uv0_dx: wp.array(dtype=wp.vec2), uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32,
                                                tri_w: lane_vec3, g: lane_layers_t):  # fmt: skip
            """``scatter_face_layers_lane`` with stochastic sampling (``stoch``): each read's share
            ``w · g`` through its stochastic taps over its footprint, pixel by pixel, layer by
            layer, read by read (``wt_scatter_stochastic_rows``)."""
            ...

        call = f"wt_scatter_face_layers_stochastic_lane<{cap}>(tex, grad, reads, stoch, w1s, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, g);\n"
        return wp.func_native(cpu_snippet(call))(specialised(scatter_face_layers_stochastic_lane, f"scatter_face_layers_stochastic_lane{cap}"))

    def scatter_face_layers_lane(tex: TextureView, grad: TexelGrad, reads: LayerReads, w1s: lane_weights_t, uv0: wp.array(dtype=wp.vec2), uv0_dx: wp.array(dtype=wp.vec2),
                                 uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32, tri_w: lane_vec3, g: lane_layers_t):  # fmt: skip
        """:func:`scatter_layer_lane` of every layer ``j`` (weights ``w1s[l, j]``, gradients
        ``g[l * cap + j]``), pixel by pixel, layer by layer, read by read: the one-pixel body's
        order, in which two layers' reads of one array layer add at two pixels. One native call:
        every layer's reads in one ``wt_scatter_footprint_rows``."""
        ...

    snippet = cpu_snippet(f"wt_scatter_face_layers_lane<{cap}>(tex, grad, reads, w1s, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, g);\n")
    return wp.func_native(snippet)(specialised(scatter_face_layers_lane, f"scatter_face_layers_lane{cap}"))
