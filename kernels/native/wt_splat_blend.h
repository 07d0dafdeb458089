// The splat maps' raw values, the splat weights, the blend and the blend's gradient for a lane of
// pixels, for the kernels of up to 8 layers. Each restates a block of warptex.kernels.splat_blend
// pixel by pixel, in its order and with Warp's own functions where the block calls them (wp::dot,
// wp::div...), so that the splat lanes give the one-pixel kernels' bits; the scalar blocks copy each
// pixel's weights, colours and heights in and out of Warp's local matrices, which cost more than the
// arithmetic.
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_scatter.h"

typedef wp::mat_t<WT_L, 8, float> wt_lane_weights8;  // a row of 8 layers' values per lane pixel
typedef wp::vec_t<8, float> wt_v8;
// What the blend's gradient gives: rows 8 l + j, the gradient of layer j's colour at lane pixel l;
// entry l % 4 of row 8 WT_L + l / 4, its transition's; entry (8 l + j) % 4 of row
// 8 WT_L + WT_L / 4 + (8 l + j) / 4, its height's (lanes.splat_blend.lane_grads).
#define WT_GRAD_TRANSITION (WT_L * 8)
#define WT_GRAD_HEIGHT (WT_L * 8 + WT_L / 4)
typedef wp::mat_t<WT_L * 8 + WT_L / 4 + WT_L * 2, 4, float> wt_lane_grads8;

// splat_blend.map_values for a lane: map m's texels (row l: covered pixel l's read) as the raw splat
// values of the layers whose weights its channels hold.
// twin: splat_blend.blend_functions:map_values
template <class Params, class Floats>
WT_INLINE wt_lane_weights8 wt_map_values_lane8(const Params& params, int m, const wt_lane_colours& texels,
                                               const Floats& covered, const wt_lane_weights8& rs) {
    wt_lane_weights8 out = rs;
    for (int l = 0; l < WT_L; ++l) {
        if (!(covered.c[l] > 0.0f)) continue;
        for (int c = 0; c < 4; ++c) {
            const int j = m * params.map_channels + c;  // splat_layers.map_layer
            if (c < params.map_channels && j < params.num_layers) out.data[l][j] = texels.data[l][c];
        }
    }
    return out;
}

// splat_blend.weights_of for a lane: each covered pixel's weights from its raw splat values (row l),
// clamped at 0, summed over all 8 entries from 0, normalised by the sum (SPLAT_EPS at least).
// twin: splat_blend.blend_functions:weights_of
template <class Params, class Floats>
WT_INLINE wt_lane_weights8 wt_weights_lane8(const Params& params, const wt_lane_weights8& rs, const Floats& covered) {
    const int n = params.num_layers;
    wt_lane_weights8 out;
    for (int l = 0; l < WT_L; ++l) {
        if (!(covered.c[l] > 0.0f)) continue;
        float w0[8], sum = 0.0f;
        for (int j = 0; j < 8; ++j) w0[j] = j < n ? wp::max(rs.data[l][j], 0.0f) : 0.0f;
        for (int j = 0; j < 8; ++j) sum += w0[j] * 1.0f;
        const float total = wp::max(sum, (float)WT_SPLAT_EPS);
        wt_f8 row;  // all 8 entries in one divide (a scalar divide per layer was 2% of a splat); past n, 0 / total = 0
        __builtin_memcpy(&row, w0, sizeof(row));
        if (params.normalize != 0) row = row / total;
        __builtin_memcpy(out.data[l], &row, sizeof(row));
    }
    return out;
}

// splat_blend.blend for a lane: each covered pixel's weights (row l of w1s), colours (rows l cap +
// j) and heights (row l), 0 where a layer is not weighted, blended as the scalar block does, in its
// order: the heights' top and weights over the layers, their sum over all `cap` entries from 0.
// twin: splat_blend.blend_functions:blend
template <class Params, class Surface, class Colours>
WT_INLINE wt_lane_colours wt_blend_lane8(const Params& params, const Surface& surface, int base, int count,
                                         const wt_lane_weights8& w1s, const Colours& colours,
                                         const wt_lane_weights8& heights) {
    constexpr int cap = 8;
    const int n = params.num_layers;
    const float transition = params.height_mode != WT_HEIGHT_NONE ? *(const float*)params.transition.data : 0.0f;
    wt_lane_colours out;
    for (int l = 0; l < count; ++l) {
        float colour[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        if (wt_float(surface.mask, base + l) != 0.0f) {
            float w[cap];
            for (int j = 0; j < cap; ++j) w[j] = w1s.data[l][j];
            if (params.height_mode != WT_HEIGHT_NONE) {  // height blending (HEIGHT_CHANNEL, HEIGHT_ARRAY)
                float h[cap], top = -1.0e30f, sum = 0.0f;
                for (int j = 0; j < cap; ++j) h[j] = heights.data[l][j] * w[j];
                for (int j = 0; j < n; ++j)
                    if (w[j] > 0.0f) top = wp::max(top, h[j]);
                for (int j = 0; j < cap; ++j) {
                    const float wh = j < n ? wp::max(h[j] + transition - top, 0.0f) : 0.0f;
                    w[j] = wh * w[j];
                    sum += w[j] * 1.0f;
                }
                const float total = wp::max(sum, (float)WT_SPLAT_EPS);
                for (int j = 0; j < cap; ++j) w[j] = w[j] / total;
            }
            for (int j = 0; j < n; ++j)
                for (int c = 0; c < 4; ++c) colour[c] = colour[c] + w[j] * colours.data[l * cap + j][c];
        }
        for (int c = 0; c < 4; ++c) out.data[l][c] = colour[c];
    }
    return out;
}

// lanes.splat_blend.blend_backward_lane8: for each covered lane pixel l (pixel base + l), with its
// weights and raw splat values, the colours its forward lane kept (row base + l of saved; heights
// from their height channel, or the height layers' kept) and its output gradient adj[base + l]:
// splat_blend.blend_backward's colours' and transition's gradients (the heights' added into the
// colours' height channel) and weights_backward's raw values' gradient; the colours', transition's
// and heights' as wt_lane_grads8 lays them out, the raw values' added into the splat maps' texels
// (grad_maps; nothing when it is empty) at the pixel's UV0 where it is finite, in pixel order
// (splat_blend.scatter_maps), three maps at a time: each map is its own array layer, so every texel
// still gets its adds in pixel order.
// twin: splat_blend.blend_functions:blend_backward
template <class Params, class Surface, class Adj, class Saved, class Tex, class Grad, class Smp, class UV>
WT_INLINE wt_lane_grads8 wt_blend_backward_lane8(const Params& params, const Surface& surface, int base, int count,
                                                 const wt_lane_weights8& w1s, const wt_lane_weights8& rs,
                                                 const Adj& adj, const Saved& saved, const Tex& maps,
                                                 const Grad& grad_maps, const Smp& map_smp, const UV& uv0) {
    const int n = params.num_layers;
    const float eps = (float)WT_SPLAT_EPS;
    const float t = params.height_mode != WT_HEIGHT_NONE ? *(const float*)params.transition.data : 0.0f;
    wt_lane_grads8 out;
    float raw[WT_L][8] = {};  // each pixel's raw splat values' gradient, for the splat maps' adds below
    for (int l = 0; l < count; ++l) {
        const int i = base + l;
        if (wt_float(surface.mask, i) == 0.0f) continue;
        wt_v4 g(0.0f);  // texels.read_channels
        const char* row = (const char*)adj.data + (long long)i * adj.strides[0];
        for (int c = 0; c < adj.shape[1] && c < 4; ++c) g.c[c] = *(const float*)(row + (long long)c * adj.strides[1]);
        wt_v8 w1(0.0f), hv(0.0f);  // pixel_layers: colours and heights where weighted
        wt_v4 c[8];
        const char* kept = (const char*)saved.data + (long long)i * saved.strides[0];
        for (int j = 0; j < 8; ++j) {
            w1.c[j] = w1s.data[l][j];
            c[j] = wt_v4(0.0f);
            if (j < n && w1.c[j] > 0.0f) {  // the colours the forward lane kept; heights from a channel of them, or
                                            // the height layers' it kept (wt_kept_column)
                for (int k = 0; k < 4; ++k)
                    c[j].c[k] = *(const float*)(kept + (long long)(4 * j + k) * saved.strides[1]);
                if (params.height_mode == WT_HEIGHT_CHANNEL) hv.c[j] = c[j].c[params.height_channel];
                if (params.height_mode == WT_HEIGHT_ARRAY)
                    hv.c[j] = *(const float*)(kept + (long long)wt_kept_column(params, 1, false, j) * saved.strides[1]);
            }
        }
        wt_v8 gw1(0.0f);  // blend_backward
        wt_v4 gc[8];
        for (int j = 0; j < 8; ++j) gc[j] = wt_v4(0.0f);
        float g_t = 0.0f;
        if (params.height_mode == WT_HEIGHT_NONE) {
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
                out.data[WT_GRAD_HEIGHT + (l * 8 + j) / 4][(l * 8 + j) % 4] = ghv;
                if (params.height_mode == WT_HEIGHT_CHANNEL)
                    gc[j].c[params.height_channel] = gc[j].c[params.height_channel] + ghv;
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
        out.data[WT_GRAD_TRANSITION + l / 4][l % 4] = g_t;
    }
    // splat_blend.scatter_maps for the lane: each covered pixel's raw values' gradient added into the
    // splat maps at its UV0 (level 0, every map m of the pixel before the next pixel's).
    if (grad_maps.texels.shape[0] > 0) {
        const int channels = params.map_channels;
        const int maps_n = (n + channels - 1) / channels;  // map_count
        float p[2][WT_L];
        wt_rows(uv0, base, count, 2, p);
        bool covered[WT_L];
        for (int l = 0; l < WT_L; ++l) {
            const bool finite = __builtin_fabsf(p[0][l]) <= wt_float_max && __builtin_fabsf(p[1][l]) <= wt_float_max;
            covered[l] = l < count && finite && wt_float(surface.mask, base + l) != 0.0f;
        }
        int level;  // scatter_lod at LOD 0: the same level and fraction for every read
        float fraction;
        wt_mip_levels(maps, map_smp, 0.0f, level, fraction);
        const Tex* texs[3] = {&maps, &maps, &maps};
        const Grad* grads[3] = {&grad_maps, &grad_maps, &grad_maps};
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
    return out;
}
