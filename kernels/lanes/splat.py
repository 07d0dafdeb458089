"""The splat for a lane of pixels on the CPU, plain or stochastic, forward and texel gradient (:mod:`.`).

The forward lane body computes what :mod:`warptex.kernels.splat`'s forward body computes for
:data:`~.LANES` pixels: the splat maps read for the whole lane and the pixels' splat weights;
then layer by layer, in one native call (:func:`.splat_layers.layer_values_lane`), the lane's
reads of the layer (UV, footprint, weight: ``layer_read`` restated, ``wt_layer_reads_into``) and its
texels' reads over their footprints (``wt_accumulate_footprint``), projection by projection in
the order ``read_layer`` adds them; then the blend. Without height blending the blend is a
weighted sum in the layers' order, added a layer at a time inside that call
(:func:`.splat_layers.layer_blend_lane`). Where the forward ran on a tape, its lane keeps each
pixel's layer colours (``SplatPixels.saved``, ``Kernels.lane_saved``), and where the tiling needs
its gradient, their slopes along it, from the same taps; the gradient's lane body, which runs only
after such a forward, reads them. It takes each pixel's blend and weights backwards and adds into
its splat maps and the tiling in pixel order, then adds each layer's gradient into its texels by
:func:`.splat_layers.scatter_layer_lane`, layer by layer: a layer's reads touch texels of its own
array layer only, so every texel gets the one-pixel body's sums in its order, and the outputs and
gradients are the one-pixel kernels' bits. Face layers change only the array layer each read
samples (``wt_read_layers``), so that layers share array layers; their gradients add every layer's
reads at once, pixel by pixel, layer by layer (``scatter_face_layers_lane``), the one-pixel order
again. The cases :func:`grad_lanes_take` names run the one-pixel kernel. In the kernels of up to 8
layers the weights, the blend and the blend and weights backwards are native code for the whole
lane (:mod:`.splat_blend`); beyond, the scalar blocks run pixel by pixel.

The stochastic splat's lanes are the same bodies with each layer read by
:func:`.splat_layers.layer_values_stochastic_lane`: per read, each footprint tap's stochastic taps
worked out natively and read tap by tap (``wt_stochastic_footprint``, as ``stochastic`` and
stochastic triplanar read theirs), and added back by
:func:`.splat_layers.scatter_layer_stochastic_lane` (with the anisotropic filter, every footprint
tap's stochastic taps in order; with face layers, every layer's at once,
``scatter_face_layers_stochastic_lane``). Its forward lane keeps the layers' colours for the
gradient lane itself (it never takes the tiling's gradient by hand). A histogram's blend runs the
one-pixel kernels (:func:`stochastic_lanes_take`).
"""

import functools

import warp as wp

from .. import inlined, specialised
from ..splat_blend import blend_functions
from ..splat_layers import HEIGHT_ARRAY, HEIGHT_CHANNEL, HEIGHT_NONE, PROJECT_TRIPLANAR, SplatArgs, SplatParams, layer_textures, map_count, pick, surface_weights
from ..texels import read_channels, write_channels
from . import LANES, lane_colours, lane_floats, lane_ints
from .sample import accumulate_footprint_lane, write_covered_lane, write_lane
from .splat_blend import GRAD_HEIGHT, GRAD_TRANSITION, blend_backward_lane8, blend_lane8, lane_grads, map_values_lane8, weights_lane8
from .splat_layers import (lane_vec3, layer_blend_kept_lane, layer_blend_lane, layer_values_kept_lane, layer_values_lane, layer_values_stochastic_lane, scatter_face_layers_of,
                           scatter_layer_lane, scatter_layer_stochastic_lane, scatter_layers_lane8)  # fmt: skip
from .stochastic import linear_blend


def grad_lanes_take(args: SplatArgs) -> bool:
    """Whether the texel-gradient lane body takes a launch with ``args`` (``Kernels.grad_lanes_take``):
    height layers, where there are, whose gradient is not (in part) the colour layers' (``heights=``
    the layers themselves). Its layers, and its height layers, then add into texels of their own,
    so it adds layer by layer and every texel still gets the one-pixel body's sums in its order;
    with face layers, by which layers share array layers, it adds every layer's reads pixel by
    pixel (``splat_layers.scatter_face_layers_of``). (The forward lanes take every launch: face
    layers only change the array layer each read samples, ``wt_read_layers``.)"""
    params = args.reads.params
    return not (params.height_mode == HEIGHT_ARRAY and _overlap(args.layers.texels.grad, args.heights.texels.grad))


def _overlap(a: wp.array | None, b: wp.array | None) -> bool:
    """Whether gradient arrays ``a`` and ``b`` (``None``: none) share memory."""
    return a is not None and b is not None and a.ptr < b.ptr + b.capacity and b.ptr < a.ptr + a.capacity


def stochastic_lanes_take(args: SplatArgs) -> bool:
    """Whether the stochastic kernels' forward lanes take a launch with ``args``: a linear blend
    (:func:`~.stochastic.linear_blend`), which they read tap by tap; a histogram's runs the one-pixel kernels."""
    return linear_blend(args.stoch)


def stochastic_grad_lanes_take(args: SplatArgs) -> bool:
    """:func:`grad_lanes_take` for the stochastic kernels (:func:`stochastic_lanes_take`)."""
    return stochastic_lanes_take(args) and grad_lanes_take(args)


def stochastic_lane_saved(args: SplatArgs) -> int:
    """:func:`lane_saved` for the stochastic kernels: values only (no tiling's gradient by hand)."""
    return _kept_width(args.reads.params)


def _kept_width(params: SplatParams) -> int:
    """Floats a pixel keeps of its layers' values for the gradient lane: 4 a layer's colour, and 1
    its height where height layers give it (``wt_kept_width``, ``wt_kept_column``)."""
    return (5 if params.height_mode == HEIGHT_ARRAY else 4) * params.num_layers


def lane_saved(args: SplatArgs) -> int:
    """Floats a pixel keeps for the texel-gradient lane (``Kernels.lane_saved``): its layers'
    colours, 4 a layer, and their heights where height layers give them, 1 a layer
    (:func:`_kept_width`); where the tiling needs its gradient, the slopes of each along it, as many
    again (:func:`.splat_layers.layer_values_kept_lane`). Sampling the layers again was a fifth of
    a splat's forward and backward; with the slopes, which the forward takes from its own taps, it
    was 60% of it (the fit's view: anisotropic, triplanar layers)."""
    params = args.reads.params
    return (2 if params.tiling.requires_grad else 1) * _kept_width(params)



@functools.cache
def lane_bodies(cap: int, pixels_t, grads_t, stochastic: bool = False):
    """``(lane, kept_lane, grad_lane)``: the lane bodies of the splat of ``cap`` layers, plain or
    ``stochastic``: the forward, the forward that keeps what the gradient lane reads
    (``Kernels.kept_lanes``; ``None`` for the stochastic splat, whose forward lane keeps its
    colours itself), and the texel gradient (``pixels_t``, ``grads_t``: :class:`~.splat.SplatPixels`,
    :class:`~.splat.SplatGrads`)."""
    f = blend_functions(cap)
    weights_t, colours_t = f.weights_t, f.colours_t
    lane_weights_t = wp.types.matrix(shape=(LANES, cap), dtype=float)
    lane_layers_t = wp.types.matrix(shape=(LANES * cap, 4), dtype=float)  # row l * cap + j
    module = f"warptex.splat{cap}"
    kind = "_stochastic" if stochastic else ""
    scatter_face_layers_lane = scatter_face_layers_of(cap, lane_weights_t, lane_layers_t, stochastic)

    def lane_weights(args: SplatArgs, pixels: pixels_t, base: wp.int32, count: wp.int32):
        """``(rs, w1s, tri_w)``: each covered lane pixel's raw splat values and weights (splat_weights,
        the maps read for the whole lane) and its projections' triplanar weights (surface_weights)."""
        params = args.reads.params
        covered = lane_floats()
        map_u = lane_floats()
        map_v = lane_floats()
        for l in range(count):
            if pixels.surface.mask[base + l] != 0.0:
                covered[l] = 1.0
                map_u[l] = pixels.uv0[base + l][0]
                map_v[l] = pixels.uv0[base + l][1]
        rs = lane_weights_t()
        zero = lane_floats()
        for m in range(map_count(params)):
            texels = accumulate_footprint_lane(args.maps, args.map_smp, lane_ints(m), map_u, map_v, zero, zero, zero, lane_floats(1.0), covered, 0, lane_colours())
            if wp.static(cap == 8):
                rs = map_values_lane8(params, m, texels, covered, rs)
            else:
                for l in range(count):
                    if covered[l] > 0.0:
                        rs[l] = f.map_values(rs[l], m, texels[l], params)
        w1s = lane_weights_t()
        if wp.static(cap == 8):
            w1s = weights_lane8(params, rs, covered)
        else:
            for l in range(count):
                if covered[l] > 0.0:
                    r, w0, total, w1 = f.weights_of(rs[l], params)
                    for j in range(params.num_layers):
                        w1s[l, j] = w1[j]
        tri_w = lane_vec3()
        if params.projection == PROJECT_TRIPLANAR:
            for l in range(count):
                if covered[l] > 0.0:
                    tw = surface_weights(params, args.reads.proj, pixels.surface.normal[base + l])
                    for e in range(3):
                        tri_w[l, e] = tw[e]
        return rs, w1s, tri_w

    def pixel_layers(w1s: lane_weights_t, colours: lane_layers_t, heights: lane_weights_t, l: wp.int32, params: SplatParams):
        """``(w1, c, hv)``: lane pixel ``l``'s weights, colours and heights, as the one-pixel body holds them."""
        w1 = weights_t()
        c = colours_t()
        hv = weights_t()
        for j in range(params.num_layers):
            w1[j] = w1s[l, j]
            if w1[j] > 0.0:
                c[j] = colours[l * cap + j]
                hv[j] = heights[l, j]
        return w1, c, hv

    lane_weights = inlined(specialised(lane_weights, f"splat{cap}{kind}_lane_weights"), module=module)
    pixel_layers = inlined(specialised(pixel_layers, f"splat{cap}{kind}_pixel_layers"), module=module)

    def forward_lane(kept: bool):
        """The forward lane body, plain or (``kept``) the one that keeps, where asked, the tiling's
        slopes for the gradient lane (:func:`.splat_layers.layer_values_kept_lane`)."""
        values_lane, blend_lane = (layer_values_kept_lane, layer_blend_kept_lane) if kept else (layer_values_lane, layer_blend_lane)
        suffix = kind + ("_kept" if kept else "")

        def lane_layers(args: SplatArgs, pixels: pixels_t, base: wp.int32, count: wp.int32, w1s: lane_weights_t, tri_w: lane_vec3):
            """``(colours, heights)``: read_layers for each lane pixel, layer by layer, each layer's reads
            and its texels' for the whole lane (``layer_values_lane``); for each texture a layer reads
            (its colour, and its separate height: ``pick``) one call, compiled once."""
            params = args.reads.params
            colours = lane_layers_t()
            heights = lane_weights_t()
            for j in range(params.num_layers):  # read_layers: every weighted layer, lane by lane
                weighted = lane_floats()
                for l in range(count):
                    weighted[l] = w1s[l, j]
                for t in range(layer_textures(params)):
                    tex = pick(args.layers, args.heights, t)
                    keep = t + 1  # where pixels.saved keeps it (wt_kept_column)
                    if wp.static(stochastic):
                        stoch = pick(args.stoch, args.height_stoch, t)
                        value = layer_values_stochastic_lane(tex, args.reads, stoch, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w, keep, pixels.saved)
                    else:
                        value = values_lane(tex, args.reads, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w, keep, pixels.saved)
                    for l in range(count):
                        if w1s[l, j] > 0.0:
                            if t == 0:
                                colours[l * cap + j] = value[l]
                                if params.height_mode == HEIGHT_CHANNEL:
                                    heights[l, j] = value[l, params.height_channel]
                            else:
                                heights[l, j] = value[l, 0]
            return colours, heights

        lane_layers = inlined(specialised(lane_layers, f"splat{cap}_lane_layers{suffix}"), module=module)

        def lane(args: SplatArgs, pixels: pixels_t, base: wp.int32, out: wp.array2d(dtype=float)):
            count = wp.min(out.shape[0] - base, LANES)
            params = args.reads.params
            rs, w1s, tri_w = lane_weights(args, pixels, base, count)
            if params.height_mode == HEIGHT_NONE:  # the blend a layer at a time
                blended = lane_colours()
                for j in range(params.num_layers):
                    weighted = lane_floats()
                    for l in range(LANES):  # unrolled (w1s is 0 past count)
                        weighted[l] = w1s[l, j]
                    if wp.static(stochastic):  # blend_lane's sum, row by row
                        value = layer_values_stochastic_lane(args.layers, args.reads, args.stoch, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w, 1, pixels.saved)
                        for l in range(LANES):
                            blended[l] = blended[l] + weighted[l] * value[l]
                    else:
                        blended = blend_lane(args.layers, args.reads, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w, 1, pixels.saved, blended)
                write_covered_lane(out, base, count, blended, pixels.surface.mask)
                return
            colours, heights = lane_layers(args, pixels, base, count, w1s, tri_w)
            if wp.static(cap == 8):  # the blend for the whole lane
                write_lane(out, base, count, blend_lane8(params, pixels.surface, base, count, w1s, colours, heights))
            else:
                for l in range(count):  # each pixel's blend
                    colour = wp.vec4(0.0)
                    if pixels.surface.mask[base + l] != 0.0:
                        w1, c, hv = pixel_layers(w1s, colours, heights, l, params)
                        colour = f.blend(w1, c, hv, params)
                    write_channels(out, base + l, colour)

        return inlined(specialised(lane, f"splat{cap}_lane{suffix}"), module=module)

    def grad_lane(args: SplatArgs, pixels: pixels_t, base: wp.int32, grads: grads_t, adj: wp.array2d(dtype=float)):
        """Launched only where :func:`grad_lanes_take` holds (the one-pixel kernel runs the rest), after
        a forward lane that kept each pixel's layer colours (and heights of height layers) in
        ``pixels.saved`` (``_op`` sees to both). With the tiling's gradient, each pixel's layers add
        ``dot(gc, dc) + ghv · dhv`` into the tiling, in pixel and layer order, of the slopes ``dc``
        and ``dhv`` the forward kept (:func:`lane_saved`; ``dhv`` is 0 without height layers)."""
        count = wp.min(adj.shape[0] - base, LANES)
        params = args.reads.params
        rs, w1s, tri_w = lane_weights(args, pixels, base, count)
        tiling_grads = grads.tiling.shape[0] > 0
        height_layers = params.height_mode == HEIGHT_ARRAY
        num_layers = params.num_layers
        ghvs = lane_weights_t()  # each pixel's layers' heights' gradients, for the tiling's and the height layers' texels
        if wp.static(cap == 8):  # the blend and weights backwards for the whole lane, and each pixel's splat maps' adds
            back = lane_grads()
            blend_backward_lane8(params, pixels.surface, base, count, w1s, rs, adj, pixels.saved, args.maps, grads.maps, args.map_smp, pixels.uv0, back)
            if grads.transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                for l in range(count):
                    if pixels.surface.mask[base + l] != 0.0:
                        wp.atomic_add(grads.transition, 0, back[GRAD_TRANSITION + l // 4, l % 4])
            if tiling_grads or height_layers:
                for l in range(count):
                    for j in range(params.num_layers):
                        ghvs[l, j] = back[GRAD_HEIGHT + (l * 8 + j) // 4, (l * 8 + j) % 4]
        else:
            back = lane_layers_t()  # rows l * cap + j: the gradient of layer j's colour at pixel l
            for l in range(count):  # each pixel's blend and weights backwards, and its splat maps' adds, in pixel order
                i = base + l
                if pixels.surface.mask[i] != 0.0:
                    w1 = weights_t()  # pixel_layers, from the kept colours (zero where a layer has no weight, as read_layers leaves them)
                    c = colours_t()
                    hv = weights_t()
                    for j in range(params.num_layers):
                        w1[j] = w1s[l, j]
                        if w1[j] > 0.0:
                            c[j] = wp.vec4(pixels.saved[i, 4 * j], pixels.saved[i, 4 * j + 1], pixels.saved[i, 4 * j + 2], pixels.saved[i, 4 * j + 3])
                            if params.height_mode == HEIGHT_CHANNEL:
                                hv[j] = c[j][params.height_channel]
                            elif height_layers:
                                hv[j] = pixels.saved[i, 4 * num_layers + j]
                    gw1, gc, ghv, g_t = f.blend_backward(w1, c, hv, params, read_channels(adj, i))
                    if grads.transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                        wp.atomic_add(grads.transition, 0, g_t)
                    r, w0, total, w1_ = f.weights_of(rs[l], params)
                    f.scatter_maps(args.maps, grads.maps, pixels.uv0[i], args.map_smp, f.weights_backward(r, w0, total, gw1, params), params)
                    for j in range(params.num_layers):
                        back[l * cap + j] = gc[j]
                        ghvs[l, j] = ghv[j]
        if tiling_grads:  # each pixel's layers' adds into the tiling, in pixel order (scatter's), of the slopes the forward kept
            width = wp.where(height_layers, 5, 4) * num_layers  # the slopes follow the values (wt_kept_column)
            for l in range(count):
                i = base + l
                if pixels.surface.mask[i] != 0.0:
                    for j in range(num_layers):
                        if w1s[l, j] > 0.0:
                            k = width + 4 * j
                            dc = wp.vec4(pixels.saved[i, k], pixels.saved[i, k + 1], pixels.saved[i, k + 2], pixels.saved[i, k + 3])
                            dhv = float(0.0)
                            if height_layers:
                                dhv = pixels.saved[i, width + 4 * num_layers + j]
                            wp.atomic_add(grads.tiling, wp.min(j, grads.tiling.shape[0] - 1), wp.dot(back[l * cap + j], dc) + ghvs[l, j] * dhv)
        face_layers = params.face_layers.shape[0] > 0 and params.projection == PROJECT_TRIPLANAR
        for t in range(layer_textures(params)):  # the colour layers' adds, then the height layers'
            if face_layers and pick(grads.layers, grads.heights, t).texels.shape[0] > 0:  # layers share array layers
                gs = lane_layers_t()  # row l * cap + j: the gradient of layer j's value at lane pixel l
                for i in range(LANES * cap):  # a loop, not unrolled
                    gs[i] = wp.where(t == 0, back[i], wp.vec4(ghvs[i // cap, i % cap], 0.0, 0.0, 0.0))
                if wp.static(stochastic):
                    scatter_face_layers_lane(pick(args.layers, args.heights, t), pick(grads.layers, grads.heights, t), args.reads, pick(args.stoch, args.height_stoch, t), w1s,
                                             pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w, gs)  # fmt: skip
                else:
                    scatter_face_layers_lane(pick(args.layers, args.heights, t), pick(grads.layers, grads.heights, t), args.reads, w1s, pixels.uv0, pixels.uv0_dx,
                                             pixels.uv0_dy, pixels.surface, base, count, tri_w, gs)  # fmt: skip
            elif pick(grads.layers, grads.heights, t).texels.shape[0] > 0:
                one_call = False
                if wp.static(cap == 8 and not stochastic):
                    if t == 0:  # the colour layers' adds in one call
                        scatter_layers_lane8(args.layers, grads.layers, args.reads, w1s, back, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w)
                        one_call = True
                if not one_call:
                    for j in range(num_layers):  # each layer's adds: without face layers, layers add into texels of their own
                        weighted = lane_floats()
                        g = lane_colours()
                        for l in range(LANES):  # unrolled (w1s, back and ghvs are 0 past count)
                            weighted[l] = w1s[l, j]
                            g[l] = wp.where(t == 0, back[l * cap + j], wp.vec4(ghvs[l, j], 0.0, 0.0, 0.0))
                        if wp.static(stochastic):
                            scatter_layer_stochastic_lane(pick(args.layers, args.heights, t), pick(grads.layers, grads.heights, t), args.reads, pick(args.stoch, args.height_stoch, t), j, weighted,
                                                          pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w, g)  # fmt: skip
                        else:
                            scatter_layer_lane(pick(args.layers, args.heights, t), pick(grads.layers, grads.heights, t), args.reads, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy,
                                               pixels.surface, base, count, tri_w, g)  # fmt: skip

    return forward_lane(False), None if stochastic else forward_lane(True), inlined(specialised(grad_lane, f"splat{cap}{kind}_grad_lane"), module=module)
