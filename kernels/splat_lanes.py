"""Splat-map terrain texturing, part 4: the plain splat forward for a lane of pixels on the CPU.

The lane body (:func:`lane_body`) computes what :mod:`.splat`'s forward body computes for
:data:`~.lanes.LANES` pixels, in three passes: the splat maps read for the whole lane, then each
pixel's splat weights and reading point by the scalar blocks; then layer by layer, each pixel's reads (UV, footprint, weight and array layer, by
``layer_read`` and ``face_layer``) and the lane's texture reads by
:func:`~.lanes.accumulate_footprint_lane`, projection by projection in the order ``read_layer``
adds them; then each pixel's blend.
"""

import functools

import warp as wp

from . import inlined, specialised
from .lane_scatter import scatter_lod_lanes
from .lanes import LANES, accumulate_footprint_lane, cpu_snippet, lane_colours, lane_floats, lane_ints, lane_reads
from .projection import SurfacePixels
from .projection_lanes import PLANE_CPP
from .splat_blend import blend_functions
from .splat_layers import HEIGHT_ARRAY, HEIGHT_CHANNEL, HEIGHT_NONE, PROJECT_TRIPLANAR, LayerPoint, LayerReads, SplatArgs, SplatParams, face_layer, layer_read, layer_reads, map_count, surface_weights
from .texels import FILTER_ANISOTROPIC, TexelGrad, TextureView, read_channels, write_channels

# Per lane pixel (row): a reading point's vectors, and (per read, row; per pixel, column) what a read
# of a layer samples.
_lane_vec2 = wp.types.matrix(shape=(LANES, 2), dtype=float)
_lane_vec3 = wp.types.matrix(shape=(LANES, 3), dtype=float)
_reads_f = wp.types.matrix(shape=(3, LANES), dtype=float)
_reads_i = wp.types.matrix(shape=(3, LANES), dtype=wp.int32)


@wp.func
def _vec2(m: _lane_vec2, l: wp.int32) -> wp.vec2:
    return wp.vec2(m[l, 0], m[l, 1])


@wp.func
def _vec3(m: _lane_vec3, l: wp.int32) -> wp.vec3:
    return wp.vec3(m[l, 0], m[l, 1], m[l, 2])


_LAYER_READS = PLANE_CPP + r"""
// The lane's reading points (layer_point), pixel by pixel into rows, then as vectors (the tail repeats
// pixel base, not read).
auto rows_of = [&](const auto& a, int dims, wt_vf* out) __attribute__((always_inline)) {
    float rows[3][WT_L];
    for (int l = 0; l < WT_L; ++l) {
        const float* e = (const float*)((const char*)a.data + (long long)(base + (l < count ? l : 0)) * a.strides[0]);
        for (int d = 0; d < dims; ++d) rows[d][l] = e[d];
    }
    for (int d = 0; d < dims; ++d) __builtin_memcpy(&out[d], rows[d], sizeof(wt_vf));
};
const auto& params = reads.params;
const float t = *(const float*)((const char*)params.tiling.data + (long long)wp::min(j, params.tiling.shape[0] - 1) * params.tiling.strides[0]);  // layer_tiling
wt_vf w;
__builtin_memcpy(&w, weighted.c, sizeof(w));
const wt_vi read = w > 0.0f;
const wt_vf zero = 0.0f, one = 1.0f;
wp::mat_t<12, WT_L, float> out;
auto put = [&](int k, wt_vf u, wt_vf v, wt_vf lod, wt_vf weight) __attribute__((always_inline)) {
    const wt_vf rows[4] = {wt_sel(read, u, zero), wt_sel(read, v, zero), wt_sel(read, lod, zero), wt_sel(read, weight, zero)};
    for (int q = 0; q < 4; ++q) __builtin_memcpy(out.data[3 * q + k], &rows[q], sizeof(wt_vf));
};
if (params.projection == 0) {  // PROJECT_UV: UV0 × tiling, its footprint from UV0's derivatives × tiling
    wt_vf uv[2], dx[2], dy[2];
    rows_of(uv0, 2, uv);
    rows_of(uv0_dx, 2, dx);
    rows_of(uv0_dy, 2, dy);
    const float width = (float)wt_int(tex.level_width, 0), height = (float)wt_int(tex.level_height, 0);
    put(0, uv[0] * t, uv[1] * t, wt_lod_of((dx[0] * t) * width, (dx[1] * t) * height, (dy[0] * t) * width, (dy[1] * t) * height), one);
} else {
    wt_vf P[3], DX[3], DY[3], u, v, lod;
    rows_of(surface.position, 3, P);
    rows_of(surface.position_dx, 3, DX);
    rows_of(surface.position_dy, 3, DY);
    if (params.projection == 1) {  // PROJECT_WORLD_XZ: the Y projection seen from above
        const wt_vf up[3] = {zero, one, zero};
        wt_plane_reads(reads.proj, 1, t, tex, P, up, DX, DY, u, v, lod);
        put(0, u, v, lod, one);
    } else {  // PROJECT_TRIPLANAR: the three projections, weighted by tri_w
        wt_vf N[3];
        rows_of(surface.normal, 3, N);
        for (int k = 0; k < 3; ++k) {
            float weight[WT_L];
            for (int l = 0; l < WT_L; ++l) weight[l] = tri_w.data[l][k];
            wt_vf wk;
            __builtin_memcpy(&wk, weight, sizeof(wk));
            wt_plane_reads(reads.proj, k, t, tex, P, N, DX, DY, u, v, lod);
            put(k, u, v, lod, wk);
        }
    }
}
return out;
"""


@wp.func_native(cpu_snippet(_LAYER_READS, "return {};\n"))
def layer_reads_lane(tex: TextureView, reads: LayerReads, j: wp.int32, weighted: lane_floats, uv0: wp.array(dtype=wp.vec2), uv0_dx: wp.array(dtype=wp.vec2),
                     uv0_dy: wp.array(dtype=wp.vec2), surface: SurfacePixels, base: wp.int32, count: wp.int32, tri_w: _lane_vec3) -> lane_reads:  # fmt: skip
    """What each lane pixel ``l`` (pixel ``base + l`` of the launch) with ``weighted[l] > 0`` reads of
    layer ``j`` of ``tex`` with a one-tap filter and no face layers: ``splat_layers.layer_read``'s UV,
    LOD and weight of each read ``k`` at the pixel's point (its UV0 and their derivatives, or its
    surface; ``tri_w``: its triplanar weights), as :data:`~.lanes.lane_reads` (all 0 for the other
    pixels), 16 pixels at a time."""
    ...


def grad_lanes_apply(args: SplatArgs) -> bool:
    """Whether the texel-gradient lane body takes a launch with ``args``: a one-tap filter, no face
    layers, no height layers (which may be the colour layers themselves) and no tiling gradient (which
    takes each read's slope). Its layers then add into texels of their own, so it adds layer by layer
    and every texel still gets the one-pixel body's sums in its order."""
    params = args.reads.params
    face_layers = params.face_layers.shape[0] > 0 and params.projection == PROJECT_TRIPLANAR
    return args.reads.smp.filter != FILTER_ANISOTROPIC and not face_layers and params.height_mode != HEIGHT_ARRAY and not params.tiling.requires_grad


@inlined
def whole_lane_reads(reads: LayerReads) -> bool:
    """Whether :func:`layer_reads_lane` computes a layer's reads: a one-tap filter, no face layers."""
    return reads.smp.filter != FILTER_ANISOTROPIC and (reads.params.face_layers.shape[0] == 0 or reads.params.projection != PROJECT_TRIPLANAR)


@inlined
def sample_lane_reads(tex: TextureView, j: wp.int32, reads: LayerReads, at: lane_reads) -> lane_colours:
    """Row ``l``: layer ``j`` of ``tex`` read one tap at a time as ``at`` says (``read_layer``)."""
    layer = lane_ints(j)
    zero = lane_floats()
    one = lane_floats(1.0)
    value = lane_colours()
    if reads.params.projection == PROJECT_TRIPLANAR:  # read_projections: value += w · sample, w > 0
        value = accumulate_footprint_lane(tex, reads.smp, layer, at[0], at[3], at[6], zero, zero, one, at[9], 1, value)
        value = accumulate_footprint_lane(tex, reads.smp, layer, at[1], at[4], at[7], zero, zero, one, at[10], 1, value)
        value = accumulate_footprint_lane(tex, reads.smp, layer, at[2], at[5], at[8], zero, zero, one, at[11], 1, value)
    else:  # one read of weight 1: value = sample
        value = accumulate_footprint_lane(tex, reads.smp, layer, at[0], at[3], at[6], zero, zero, one, at[9], 0, value)
    return value


@inlined
def scatter_lane_reads(tex: TextureView, grad: TexelGrad, j: wp.int32, reads: LayerReads, count: wp.int32, at: lane_reads, g: lane_colours):
    """``scatter_layer`` of the gradients ``g[l]`` of layer ``j``'s reads ``at`` of ``tex`` into
    ``grad``, pixel by pixel and read by read: ``w · g`` per projection where triplanar, ``g``
    itself for the one read of the other projections."""
    g0 = g
    g1 = lane_colours()
    g2 = lane_colours()
    count_reads = 1
    if reads.params.projection == PROJECT_TRIPLANAR:  # scatter_projections
        count_reads = 3
        for l in range(count):
            g0[l] = at[9, l] * g[l]
            g1[l] = at[10, l] * g[l]
            g2[l] = at[11, l] * g[l]
    scatter_lod_lanes(tex, tex, tex, grad, grad, grad, reads.smp, count_reads, lane_ints(j), at, g0, g1, g2)


@inlined
def read_lane_layer(tex: TextureView, j: wp.int32, reads: LayerReads, count: wp.int32, weighted: lane_floats,
                    uv0: _lane_vec2, uv0_dx: _lane_vec2, uv0_dy: _lane_vec2, p: _lane_vec3, n: _lane_vec3, dpdx: _lane_vec3, dpdy: _lane_vec3, tri_w: _lane_vec3) -> lane_colours:  # fmt: skip
    """Row ``l``: layer ``j`` of ``tex`` as ``read_layer`` reads it at pixel ``l``'s point, where
    ``weighted[l] > 0`` (others: 0), pixel by pixel through the scalar blocks."""
    params = reads.params
    u = _reads_f()
    v = _reads_f()
    lod = _reads_f()  # the footprint: LOD, step and taps (footprint.py)
    du = _reads_f()
    dv = _reads_f()
    taps = _reads_f()
    weight = _reads_f()
    layer = _reads_i()
    for l in range(count):
        if weighted[l] > 0.0:
            pt = LayerPoint()
            pt.uv0 = _vec2(uv0, l)
            pt.uv0_dx = _vec2(uv0_dx, l)
            pt.uv0_dy = _vec2(uv0_dy, l)
            pt.p = _vec3(p, l)
            pt.n = _vec3(n, l)
            pt.dpdx = _vec3(dpdx, l)
            pt.dpdy = _vec3(dpdy, l)
            pt.tri_w = _vec3(tri_w, l)
            for k in range(layer_reads(params)):
                uv, fp, w = layer_read(tex, j, k, reads, pt)
                u[k, l] = uv[0]
                v[k, l] = uv[1]
                lod[k, l] = fp[0]
                du[k, l] = fp[1]
                dv[k, l] = fp[2]
                taps[k, l] = fp[3]
                weight[k, l] = w
                layer[k, l] = face_layer(params, j, k, pt.n)
    value = lane_colours()
    if params.projection == PROJECT_TRIPLANAR:  # read_projections: value += w · sample, w > 0
        for k in range(3):
            value = accumulate_footprint_lane(tex, reads.smp, layer[k], u[k], v[k], lod[k], du[k], dv[k], taps[k], weight[k], 1, value)
    else:  # one read of weight 1: value = sample
        value = accumulate_footprint_lane(tex, reads.smp, layer[0], u[0], v[0], lod[0], du[0], dv[0], taps[0], weight[0], 0, value)
    return value


@functools.cache
def lane_bodies(cap: int, pixels_t, grads_t):
    """``(lane, grad_lane)``: the lane bodies of the plain splat of ``cap`` layers, forward and texel
    gradient (``pixels_t``, ``grads_t``: :class:`~.splat.SplatPixels`, :class:`~.splat.SplatGrads`)."""
    f = blend_functions(cap)
    weights_t, colours_t = f.weights_t, f.colours_t
    lane_weights_t = wp.types.matrix(shape=(LANES, cap), dtype=float)
    lane_layers_t = wp.types.matrix(shape=(LANES * cap, 4), dtype=float)  # row l * cap + j
    module = f"warptex.splat{cap}"

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
            for l in range(count):
                if covered[l] > 0.0:
                    rs[l] = f.map_values(rs[l], m, texels[l], params)
        w1s = lane_weights_t()
        tri_w = _lane_vec3()
        for l in range(count):
            if covered[l] > 0.0:
                r, w0, total, w1 = f.weights_of(rs[l], params)
                for j in range(params.num_layers):
                    w1s[l, j] = w1[j]
                tw = surface_weights(params, args.reads.proj, pixels.surface.normal[base + l])
                for e in range(3):
                    tri_w[l, e] = tw[e]
        return rs, w1s, tri_w

    def lane_layers(args: SplatArgs, pixels: pixels_t, base: wp.int32, count: wp.int32, w1s: lane_weights_t, tri_w: _lane_vec3):
        """``(colours, heights)``: read_layers for each lane pixel, layer by layer, each layer's reads
        for the whole lane (:func:`layer_reads_lane`) or, where it cannot, pixel by pixel."""
        params = args.reads.params
        whole = whole_lane_reads(args.reads)
        uv0 = _lane_vec2()  # the reading points (layer_point), read pixel by pixel
        uv0_dx = _lane_vec2()
        uv0_dy = _lane_vec2()
        p = _lane_vec3()
        n = _lane_vec3()
        dpdx = _lane_vec3()
        dpdy = _lane_vec3()
        if not whole:
            for l in range(count):
                i = base + l
                if pixels.surface.mask[i] != 0.0:
                    for e in range(2):
                        uv0[l, e] = pixels.uv0[i][e]
                        uv0_dx[l, e] = pixels.uv0_dx[i][e]
                        uv0_dy[l, e] = pixels.uv0_dy[i][e]
                    for e in range(3):
                        p[l, e] = pixels.surface.position[i][e]
                        n[l, e] = pixels.surface.normal[i][e]
                        dpdx[l, e] = pixels.surface.position_dx[i][e]
                        dpdy[l, e] = pixels.surface.position_dy[i][e]
        colours = lane_layers_t()
        heights = lane_weights_t()
        for j in range(params.num_layers):  # read_layers: every weighted layer, lane by lane
            weighted = lane_floats()
            for l in range(count):
                weighted[l] = w1s[l, j]
            value = lane_colours()
            height = lane_colours()
            if whole:
                value = sample_lane_reads(args.layers, j, args.reads, layer_reads_lane(args.layers, args.reads, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w))
                if params.height_mode == HEIGHT_ARRAY:
                    height = sample_lane_reads(args.heights, j, args.reads, layer_reads_lane(args.heights, args.reads, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w))
            else:
                value = read_lane_layer(args.layers, j, args.reads, count, weighted, uv0, uv0_dx, uv0_dy, p, n, dpdx, dpdy, tri_w)
                if params.height_mode == HEIGHT_ARRAY:
                    height = read_lane_layer(args.heights, j, args.reads, count, weighted, uv0, uv0_dx, uv0_dy, p, n, dpdx, dpdy, tri_w)
            for l in range(count):
                if w1s[l, j] > 0.0:
                    colours[l * cap + j] = value[l]
                    if params.height_mode == HEIGHT_CHANNEL:
                        heights[l, j] = value[l, params.height_channel]
                    elif params.height_mode == HEIGHT_ARRAY:
                        heights[l, j] = height[l, 0]
        return colours, heights

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

    lane_weights = inlined(specialised(lane_weights, f"splat{cap}_lane_weights"), module=module)
    lane_layers = inlined(specialised(lane_layers, f"splat{cap}_lane_layers"), module=module)
    pixel_layers = inlined(specialised(pixel_layers, f"splat{cap}_pixel_layers"), module=module)

    def lane(args: SplatArgs, pixels: pixels_t, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        params = args.reads.params
        rs, w1s, tri_w = lane_weights(args, pixels, base, count)
        colours, heights = lane_layers(args, pixels, base, count, w1s, tri_w)
        for l in range(count):  # each pixel's blend
            colour = wp.vec4(0.0)
            if pixels.surface.mask[base + l] != 0.0:
                w1, c, hv = pixel_layers(w1s, colours, heights, l, params)
                colour = f.blend(w1, c, hv, params)
            write_channels(out, base + l, colour)

    def grad_lane(args: SplatArgs, pixels: pixels_t, base: wp.int32, grads: grads_t, adj: wp.array2d(dtype=float)):
        """Launched only where :func:`grad_lanes_apply` holds (the one-pixel kernel runs the rest)."""
        count = wp.min(adj.shape[0] - base, LANES)
        params = args.reads.params
        rs, w1s, tri_w = lane_weights(args, pixels, base, count)
        colours, heights = lane_layers(args, pixels, base, count, w1s, tri_w)
        gcs = lane_layers_t()
        for l in range(count):  # each pixel's blend and weights backwards, and its splat maps' adds, in pixel order
            i = base + l
            if pixels.surface.mask[i] != 0.0:
                w1, c, hv = pixel_layers(w1s, colours, heights, l, params)
                gw1, gc, ghv, g_t = f.blend_backward(w1, c, hv, params, read_channels(adj, i))
                if grads.transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                    wp.atomic_add(grads.transition, 0, g_t)
                r, w0, total, w1_ = f.weights_of(rs[l], params)
                f.scatter_maps(args.maps, grads.maps, pixels.uv0[i], args.map_smp, f.weights_backward(r, w0, total, gw1, params), params)
                for j in range(params.num_layers):
                    gcs[l * cap + j] = gc[j]
        if grads.layers.texels.shape[0] > 0:
            for j in range(params.num_layers):  # each layer's adds: without face layers, layers add into texels of their own
                weighted = lane_floats()
                g = lane_colours()
                for l in range(count):
                    weighted[l] = w1s[l, j]
                    g[l] = gcs[l * cap + j]
                at = layer_reads_lane(args.layers, args.reads, j, weighted, pixels.uv0, pixels.uv0_dx, pixels.uv0_dy, pixels.surface, base, count, tri_w)
                scatter_lane_reads(args.layers, grads.layers, j, args.reads, count, at, g)

    return inlined(specialised(lane, f"splat{cap}_lane"), module=module), inlined(specialised(grad_lane, f"splat{cap}_grad_lane"), module=module)
