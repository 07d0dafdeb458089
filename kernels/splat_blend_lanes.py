"""Splat-map terrain texturing, part 5: the splat maps' raw values, the splat weights, the blend and
the blend's gradient for a lane of pixels on the CPU, in native code (:mod:`.lanes`), for the kernels
of up to 8 layers.

Each restates a block of :mod:`.splat_blend` pixel by pixel, in its order and with Warp's own
functions where the block calls them (``wp::dot``, ``wp::div``...), so that the lane bodies of
:mod:`.splat_lanes` give the one-pixel kernels' bits (``tests/test_lanes.py``); the scalar blocks
copy each pixel's weights, colours and heights in and out of Warp's local matrices, which cost more
than the arithmetic. Kernels of 16 layers or more run the scalar blocks pixel by pixel.
"""

import warp as wp

from .lane_scatter import _SCATTER_CORE
from .lanes import LANES, cpu_snippet, lane_colours, lane_floats
from .projection import SurfacePixels
from .splat_layers import SplatParams
from .texels import SamplerArgs, TexelGrad, TextureView

# splat_blend.blend for a lane: each covered pixel's weights (row l of w1s), colours (rows l cap + j)
# and heights (row l), 0 where a layer is not weighted, blended as the scalar block does, in its
# order: the heights' top and weights over the layers, their sum over all `cap` entries from 0.
_BLEND = r"""
constexpr int cap = sizeof(w1s.data[0]) / sizeof(float);
const int n = params.num_layers;
const float transition = params.height_mode != 0 ? *(const float*)params.transition.data : 0.0f;
wp::mat_t<WT_L, 4, float> out;
for (int l = 0; l < count; ++l) {
    float colour[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    if (*(const float*)((const char*)surface.mask.data + (long long)(base + l) * surface.mask.strides[0]) != 0.0f) {
        float w[cap];
        for (int j = 0; j < cap; ++j) w[j] = w1s.data[l][j];
        if (params.height_mode != 0) {  // height blending (HEIGHT_CHANNEL, HEIGHT_ARRAY)
            float h[cap], top = -1.0e30f, sum = 0.0f;
            for (int j = 0; j < cap; ++j) h[j] = heights.data[l][j] * w[j];
            for (int j = 0; j < n; ++j) if (w[j] > 0.0f) top = wp::max(top, h[j]);
            for (int j = 0; j < cap; ++j) {
                const float wh = j < n ? wp::max(h[j] + transition - top, 0.0f) : 0.0f;
                w[j] = wh * w[j];
                sum += w[j] * 1.0f;
            }
            const float total = wp::max(sum, 1.0e-20f);  // SPLAT_EPS
            for (int j = 0; j < cap; ++j) w[j] = w[j] / total;
        }
        for (int j = 0; j < n; ++j)
            for (int c = 0; c < 4; ++c) colour[c] = colour[c] + w[j] * colours.data[l * cap + j][c];
    }
    for (int c = 0; c < 4; ++c) out.data[l][c] = colour[c];
}
return out;
"""


# splat_blend.map_values for a lane: map m's texels (row l: covered pixel l's read) as the raw splat
# values of the layers whose weights its channels hold.
_MAP_VALUES = r"""
wp::mat_t<WT_L, 8, float> out = rs;
for (int l = 0; l < WT_L; ++l) {
    if (!(covered.c[l] > 0.0f)) continue;
    for (int c = 0; c < 4; ++c) {
        const int j = m * params.map_channels + c;  // splat_layers.map_layer
        if (c < params.map_channels && j < params.num_layers) out.data[l][j] = texels.data[l][c];
    }
}
return out;
"""


@wp.func_native(cpu_snippet(_MAP_VALUES, "return {};\n"))
def map_values_lane8(params: SplatParams, m: wp.int32, texels: lane_colours, covered: lane_floats, rs: wp.types.matrix(shape=(LANES, 8), dtype=float)) -> wp.types.matrix(shape=(LANES, 8), dtype=float):  # fmt: skip
    """``rs`` with, in the rows of the lane pixels ``l`` where ``covered[l] > 0``,
    ``splat_blend.map_values`` of map ``m``'s ``texels[l]``, for the kernels of up to 8 layers."""
    ...


# splat_blend.weights_of for a lane: each covered pixel's weights from its raw splat values (row l),
# clamped at 0, summed over all 8 entries from 0, normalised by the sum (SPLAT_EPS at least).
_WEIGHTS = r"""
const int n = params.num_layers;
wp::mat_t<WT_L, 8, float> out;
for (int l = 0; l < WT_L; ++l) {
    if (!(covered.c[l] > 0.0f)) continue;
    float w0[8], sum = 0.0f;
    for (int j = 0; j < 8; ++j) w0[j] = j < n ? wp::max(rs.data[l][j], 0.0f) : 0.0f;
    for (int j = 0; j < 8; ++j) sum += w0[j] * 1.0f;
    const float total = wp::max(sum, 1.0e-20f);  // SPLAT_EPS
    for (int j = 0; j < n; ++j) out.data[l][j] = params.normalize != 0 ? w0[j] / total : w0[j];
}
return out;
"""


@wp.func_native(cpu_snippet(_WEIGHTS, "return {};\n"))
def weights_lane8(params: SplatParams, rs: wp.types.matrix(shape=(LANES, 8), dtype=float), covered: lane_floats) -> wp.types.matrix(shape=(LANES, 8), dtype=float):
    """Row ``l``: ``splat_blend.weights_of``'s ``w1`` of lane pixel ``l``'s raw splat values (row ``l``
    of ``rs``), for the kernels of up to 8 layers; 0 where ``covered[l]`` is not positive."""
    ...


@wp.func_native(cpu_snippet(_BLEND, "return {};\n"))
def blend_lane8(params: SplatParams, surface: SurfacePixels, base: wp.int32, count: wp.int32, w1s: wp.types.matrix(shape=(LANES, 8), dtype=float),
                colours: wp.types.matrix(shape=(LANES * 8, 4), dtype=float), heights: wp.types.matrix(shape=(LANES, 8), dtype=float)) -> lane_colours:  # fmt: skip
    """Row ``l``: ``splat_blend.blend`` of lane pixel ``l``'s weights (row ``l`` of ``w1s``), colours
    (rows ``8 l + j``) and heights (row ``l``), for the kernels of up to 8 layers; 0 where the pixel is
    not covered."""
    ...


# splat_blend.blend_backward (colours' gradients, weights' gradient, transition's) then weights_of and
# weights_backward (the raw splat values' gradient, in `raw`) of each covered pixel, the colours' and
# the transition's as lane_grads holds them.
_BLEND_BACKWARD = r"""
typedef wp::vec_t<8, float> wt_v8;
typedef wp::vec_t<4, float> wt_v4;
const int n = params.num_layers;
const float eps = 1.0e-20f;  // SPLAT_EPS
const float t = params.height_mode != 0 ? *(const float*)params.transition.data : 0.0f;
wp::mat_t<WT_L * 8 + WT_L / 4, 4, float> out;
float raw[WT_L][8] = {};  // each pixel's raw splat values' gradient, for _SCATTER_MAPS
for (int l = 0; l < count; ++l) {
    const int i = base + l;
    if (*(const float*)((const char*)surface.mask.data + (long long)i * surface.mask.strides[0]) == 0.0f) continue;
    wt_v4 g(0.0f);  // texels.read_channels
    const char* row = (const char*)adj.data + (long long)i * adj.strides[0];
    for (int c = 0; c < adj.shape[1] && c < 4; ++c) g.c[c] = *(const float*)(row + (long long)c * adj.strides[1]);
    wt_v8 w1(0.0f), hv(0.0f);  // pixel_layers: colours and heights where weighted
    wt_v4 c[8];
    const char* kept = (const char*)saved.data + (long long)i * saved.strides[0];
    for (int j = 0; j < 8; ++j) {
        w1.c[j] = w1s.data[l][j];
        c[j] = wt_v4(0.0f);
        if (j < n && w1.c[j] > 0.0f) {  // the colours the forward lane kept; heights from a channel of them (the lanes take no height layers)
            for (int k = 0; k < 4; ++k) c[j].c[k] = *(const float*)(kept + (long long)(4 * j + k) * saved.strides[1]);
            hv.c[j] = params.height_mode == 1 ? c[j].c[params.height_channel] : 0.0f;  // HEIGHT_CHANNEL
        }
    }
    wt_v8 gw1(0.0f);  // blend_backward
    wt_v4 gc[8];
    for (int j = 0; j < 8; ++j) gc[j] = wt_v4(0.0f);
    float g_t = 0.0f;
    if (params.height_mode == 0) {
        for (int j = 0; j < n; ++j) {
            gc[j] = wp::mul(w1.c[j], g);
            gw1.c[j] = wp::dot(g, c[j]);
        }
    } else {
        const wt_v8 h = wp::cw_mul(hv, w1);
        float top = -1.0e30f;
        int arg = -1;
        for (int j = 0; j < n; ++j) {
            if (w1.c[j] > 0.0f && h.c[j] >= top) top = h.c[j], arg = j;
        }
        wt_v8 wh(0.0f), gv(0.0f), gh(0.0f);
        for (int j = 0; j < n; ++j) wh.c[j] = wp::max(h.c[j] + t - top, 0.0f);
        const wt_v8 v = wp::cw_mul(wh, w1);
        const float v_total = wp::dot(v, wt_v8(1.0f));
        const float d = wp::max(v_total, eps);
        for (int j = 0; j < n; ++j) {
            gc[j] = wp::mul(v.c[j] / d, g);
            gv.c[j] = wp::dot(g, c[j]) / d;
        }
        if (v_total > eps) gv = wp::sub(gv, wt_v8(wp::dot(gv, v) / d));
        float g_top = 0.0f;
        for (int j = 0; j < n; ++j) {
            gw1.c[j] = gv.c[j] * wh.c[j];
            if (h.c[j] + t - top > 0.0f) {
                const float ge = gv.c[j] * w1.c[j];
                gh.c[j] = ge;
                g_t = g_t + ge;
                g_top = g_top - ge;
            }
        }
        if (arg >= 0) gh.c[arg] = gh.c[arg] + g_top;
        for (int j = 0; j < n; ++j) {
            gw1.c[j] = gw1.c[j] + gh.c[j] * hv.c[j];
            const float ghv = gh.c[j] * w1.c[j];
            if (params.height_mode == 1) gc[j].c[params.height_channel] = gc[j].c[params.height_channel] + ghv;  // HEIGHT_CHANNEL
        }
    }
    wt_v8 r, w0(0.0f);  // weights_of's r, w0 and total
    for (int j = 0; j < 8; ++j) r.c[j] = rs.data[l][j];
    for (int j = 0; j < n; ++j) w0.c[j] = wp::max(r.c[j], 0.0f);
    const float total = wp::dot(w0, wt_v8(1.0f));
    wt_v8 gw0 = gw1;  // weights_backward
    if (params.normalize != 0) {
        const float s = wp::max(total, eps);
        gw0 = wp::div(gw1, s);
        if (total > eps) gw0 = wp::sub(gw0, wt_v8(wp::dot(gw1, w0) / (s * s)));
    }
    for (int j = 0; j < 8; ++j) {
        for (int k = 0; k < 4; ++k) out.data[l * 8 + j][k] = gc[j].c[k];
        raw[l][j] = j < n && r.c[j] > 0.0f ? gw0.c[j] : 0.0f;
    }
    out.data[WT_L * 8 + l / 4][l % 4] = g_t;
}
"""

#: What :func:`blend_backward_lane8` gives: rows ``8 l + j``, the gradient of layer ``j``'s colour at
#: lane pixel ``l``; entry ``l % 4`` of row ``GRAD_TRANSITION + l // 4``, its transition's.
lane_grads = wp.types.matrix(shape=(LANES * 8 + LANES // 4, 4), dtype=float)
GRAD_TRANSITION = wp.constant(LANES * 8)


# splat_blend.scatter_maps for the lane: each covered pixel's raw values' gradient (row l of
# _BLEND_BACKWARD's `raw`) added into the splat maps at its UV0 (level 0, every map m of the pixel
# before the next pixel's), three maps at a time: each map is its own array layer, so every texel
# still gets its adds in pixel order.
_SCATTER_MAPS = r"""
if (grad_maps.texels.shape[0] > 0) {
    const int n = params.num_layers, channels = params.map_channels;
    const int maps_n = (n + channels - 1) / channels;  // map_count
    float p[2][WT_L];
    wt_rows(uv0, base, count, 2, p);
    bool covered[WT_L];
    for (int l = 0; l < WT_L; ++l) {
        const bool finite = __builtin_fabsf(p[0][l]) <= wt_float_max && __builtin_fabsf(p[1][l]) <= wt_float_max;
        covered[l] = l < count && finite && *(const float*)((const char*)surface.mask.data + (long long)(base + l) * surface.mask.strides[0]) != 0.0f;
    }
    int level;  // scatter_lod at LOD 0: the same level and fraction for every read
    float fraction;
    wt_mip_levels(maps, map_smp, 0.0f, level, fraction);
    const decltype(maps)* texs[3] = {&maps, &maps, &maps};
    const decltype(grad_maps)* grads[3] = {&grad_maps, &grad_maps, &grad_maps};
    for (int m0 = 0; m0 < maps_n; m0 += 3) {
        const int reads = maps_n - m0 < 3 ? maps_n - m0 : 3;
        float us[3][WT_L], vs[3][WT_L], fractions[3][WT_L];
        int levels[3][WT_L], layer[3][WT_L];
        bool active[3][WT_L];
        wt_f4 gs[3][WT_L];
        for (int r = 0; r < reads; ++r) {
            for (int l = 0; l < WT_L; ++l) {
                active[r][l] = covered[l];
                us[r][l] = covered[l] ? p[0][l] : 0.0f;
                vs[r][l] = covered[l] ? p[1][l] : 0.0f;
                levels[r][l] = level;
                fractions[r][l] = fraction;
                layer[r][l] = m0 + r;
                wt_f4 g = {0.0f, 0.0f, 0.0f, 0.0f};  // map_gradient
                for (int c = 0; c < 4; ++c) {
                    const int j = (m0 + r) * channels + c;  // map_layer
                    if (c < channels && j < n) g[c] = raw[l][j];
                }
                gs[r][l] = g;
            }
        }
        wt_scatter_levels_any(reads, texs, grads, map_smp, us, vs, levels, fractions, layer, active, gs);
    }
}
"""


@wp.func_native(cpu_snippet(_SCATTER_CORE + _BLEND_BACKWARD + _SCATTER_MAPS + "return out;\n", "return {};\n"))
def blend_backward_lane8(params: SplatParams, surface: SurfacePixels, base: wp.int32, count: wp.int32, w1s: wp.types.matrix(shape=(LANES, 8), dtype=float),
                         rs: wp.types.matrix(shape=(LANES, 8), dtype=float), adj: wp.array2d(dtype=float), saved: wp.array2d(dtype=float), maps: TextureView,
                         grad_maps: TexelGrad, map_smp: SamplerArgs, uv0: wp.array(dtype=wp.vec2)) -> lane_grads:  # fmt: skip
    """For each covered lane pixel ``l`` (pixel ``base + l``), with its weights and raw splat values
    as :func:`blend_lane8` and ``weights_lane8`` take them, the colours its forward lane kept (row
    ``base + l`` of ``saved``, ``SplatPixels.saved``; heights from their height channel) and its
    output gradient ``adj[base + l]``: ``splat_blend.blend_backward``'s colours' and transition's
    gradients (the heights' added into the colours' height channel) and ``weights_backward``'s raw
    values' gradient; the colours' and transition's laid out as :data:`lane_grads` says (0 for the
    other pixels), the raw values' added into the splat maps' texels (``grad_maps``; nothing when it
    is empty) at the pixel's UV0 where it is finite, in pixel order (``splat_blend.scatter_maps``),
    in the same call, so that they never leave it."""
    ...
