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
// What the blend's gradient gives: rows 8 l + j, the gradient of layer j's colour at lane pixel l;
// entry l % 4 of row 8 WT_L + l / 4, its transition's; entry (8 l + j) % 4 of row
// 8 WT_L + WT_L / 4 + (8 l + j) / 4, its height's (lanes.splat_blend.lane_grads).
#define WT_GRAD_TRANSITION (WT_L * 8)
#define WT_GRAD_HEIGHT (WT_L * 8 + WT_L / 4)
typedef wp::mat_t<WT_L * 8 + WT_L / 4 + WT_L * 2, 4, float> wt_lane_grads8;
struct wt_ch4 {  // an RGBA value per lane pixel, as a vector per channel
    wt_vf c[4];
    wt_vf& operator[](int k) { return c[k]; }
    const wt_vf& operator[](int k) const { return c[k]; }
};

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
// and heights' into out (the caller's, every row written) as wt_lane_grads8 lays them out, the raw
// values' added into the splat maps' texels (grad_maps; nothing when it is empty) at the pixel's
// UV0 where it is finite, in pixel order (splat_blend.scatter_maps), three maps at a time: each
// map is its own array layer, so every texel still gets its adds in pixel order.
// twin: splat_blend.blend_functions:blend_backward
template <class Params, class Surface, class Adj, class Saved, class Tex, class Grad, class Smp, class UV>
WT_INLINE void wt_blend_backward_lane8(const Params& params, const Surface& surface, int base, int count,
                                       const wt_lane_weights8& w1s, const wt_lane_weights8& rs, const Adj& adj,
                                       const Saved& saved, const Tex& maps, const Grad& grad_maps, const Smp& map_smp,
                                       const UV& uv0, wt_lane_grads8& out) {
    // The lane's pixels at once, a vector of a value per pixel for each of the scalar block's
    // values: the same operations on each pixel's values in the same order, so the same bits. Pixel
    // by pixel (each pixel's chains of dependent adds and divides), it was 39% of the splat gradient
    // lane's samples under perf.
    const int n = params.num_layers;
    const wt_vf eps = (float)WT_SPLAT_EPS, zero = 0.0f, one = 1.0f;
    const float t = params.height_mode != WT_HEIGHT_NONE ? *(const float*)params.transition.data : 0.0f;
    wt_vi covered;
    {
        float mask[WT_L];
        for (int l = 0; l < WT_L; ++l) mask[l] = l < count ? wt_float(surface.mask, base + l) : 0.0f;
        covered = wt_covered(mask, count);
    }
    // The 4 floats of each lane pixel's row of a 2-D array from column `first`, as channels: every
    // row read (past count, row base + count - 1 again) without a branch, so that the loads go
    // straight into the transposes' registers (through a lane array of rows written per pixel, the
    // transposes' wide loads stalled on the narrow stores).
    auto channels_of = [&](const auto& a, int first) __attribute__((always_inline)) {
        const char* data = (const char*)a.data + (long long)base * a.strides[0] + (long long)first * a.strides[1];
        const long long stride = a.strides[0], column = a.strides[1];
        wt_f4 rows[WT_L];
        for (int l = 0; l < WT_L; ++l) {
            const char* row = data + (long long)(l < count ? l : count - 1) * stride;
            if (column == 4) {
                __builtin_memcpy(&rows[l], row, sizeof(wt_f4));
            } else {
                rows[l] = (wt_f4){*(const float*)row, *(const float*)(row + column), *(const float*)(row + 2 * column),
                                  *(const float*)(row + 3 * column)};
            }
        }
        wt_ch4 ch;
        wt_channels(rows, ch.c);
        return ch;
    };
    wt_ch4 g;  // texels.read_channels
    if (adj.shape[1] == 4) {
        g = channels_of(adj, 0);
    } else {
        wt_f4 rows[WT_L];
        for (int l = 0; l < WT_L; ++l) rows[l] = wt_read_channels(adj, base + (l < count ? l : count - 1));
        wt_channels(rows, g.c);
    }
    wt_vf w1[8], r[8];
    {
        float w1_rows[8][WT_L], r_rows[8][WT_L];
        for (int l = 0; l < WT_L; ++l)
            for (int j = 0; j < 8; ++j) w1_rows[j][l] = w1s.data[l][j], r_rows[j][l] = rs.data[l][j];
        __builtin_memcpy(w1, w1_rows, sizeof(w1));
        __builtin_memcpy(r, r_rows, sizeof(r));
    }
    // pixel_layers: colours and heights where weighted, 0 elsewhere; the colours the forward lane kept,
    // heights from a channel of them, or the height layers' it kept (wt_kept_column)
    wt_ch4 c[8];  // read only below num_layers
    wt_vf hv[8];
    for (int j = 0; j < 8; ++j) {
        hv[j] = zero;
        if (j >= n) continue;
        const wt_vi weighted = covered & (w1[j] > 0.0f);
        c[j] = channels_of(saved, 4 * j);
        for (int k = 0; k < 4; ++k) c[j][k] = wt_sel(weighted, c[j][k], zero);
        if (params.height_mode == WT_HEIGHT_CHANNEL) hv[j] = c[j][params.height_channel];
        if (params.height_mode == WT_HEIGHT_ARRAY) {
            float h[WT_L];
            const char* column =
                (const char*)saved.data + (long long)wt_kept_column(params, 1, false, j) * saved.strides[1];
            for (int l = 0; l < WT_L; ++l)
                h[l] = *(const float*)(column + (base + (l < count ? l : count - 1)) * saved.strides[0]);
            __builtin_memcpy(&hv[j], h, sizeof(wt_vf));
            hv[j] = wt_sel(weighted, hv[j], zero);
        }
    }
    auto dot4 = [&](const wt_ch4& a) __attribute__((always_inline)) {  // wp::dot(g, a)
        wt_vf s = zero;
        for (int k = 0; k < 4; ++k) s = s + g[k] * a[k];
        return s;
    };
    auto dot8 = [&](const wt_vf* a, const wt_vf* b) __attribute__((always_inline)) {  // wp::dot of two vec8s
        wt_vf s = zero;
        for (int j = 0; j < 8; ++j) s = s + a[j] * b[j];
        return s;
    };
    const wt_vf ones[8] = {one, one, one, one, one, one, one, one};
    wt_vf gw1[8], gc[8][4], g_t = zero, ghv[8];  // blend_backward (gc set below num_layers only)
    for (int j = 0; j < 8; ++j) gw1[j] = zero, ghv[j] = zero;
    if (params.height_mode == WT_HEIGHT_NONE) {
        for (int j = 0; j < n; ++j) {
            for (int k = 0; k < 4; ++k) gc[j][k] = g[k] * w1[j];
            gw1[j] = dot4(c[j]);
        }
    } else {
        wt_vf h[8], top = -1.0e30f;
        wt_vi arg = -1;
        for (int j = 0; j < 8; ++j) h[j] = hv[j] * w1[j];
        for (int j = 0; j < n; ++j) {
            const wt_vi higher = (w1[j] > 0.0f) & (h[j] >= top);
            top = wt_sel(higher, h[j], top);
            arg = (higher & j) | (~higher & arg);
        }
        wt_vf wh[8], v[8], gv[8], gh[8];
        for (int j = 0; j < 8; ++j) wh[j] = zero, gv[j] = zero, gh[j] = zero;
        for (int j = 0; j < n; ++j) wh[j] = wt_vmax(h[j] + t - top, zero);
        for (int j = 0; j < 8; ++j) v[j] = wh[j] * w1[j];
        const wt_vf v_total = dot8(v, ones);
        const wt_vf d = wt_vmax(v_total, eps);
        for (int j = 0; j < n; ++j) {
            const wt_vf share = v[j] / d;
            for (int k = 0; k < 4; ++k) gc[j][k] = g[k] * share;
            gv[j] = dot4(c[j]) / d;
        }
        const wt_vf gv_v = dot8(gv, v) / d;
        for (int j = 0; j < 8; ++j) gv[j] = wt_sel(v_total > eps, gv[j] - gv_v, gv[j]);
        wt_vf g_top = zero;
        for (int j = 0; j < n; ++j) {
            gw1[j] = gv[j] * wh[j];
            const wt_vi above = h[j] + t - top > 0.0f;
            const wt_vf ge = gv[j] * w1[j];
            gh[j] = wt_sel(above, ge, zero);
            g_t = wt_sel(above, g_t + ge, g_t);
            g_top = wt_sel(above, g_top - ge, g_top);
        }
        for (int j = 0; j < n; ++j) gh[j] = wt_sel(arg == j, gh[j] + g_top, gh[j]);
        for (int j = 0; j < n; ++j) {
            gw1[j] = gw1[j] + gh[j] * hv[j];
            ghv[j] = gh[j] * w1[j];
            if (params.height_mode == WT_HEIGHT_CHANNEL)
                gc[j][params.height_channel] = gc[j][params.height_channel] + ghv[j];
        }
    }
    wt_vf w0[8];  // weights_of's w0 and total
    for (int j = 0; j < 8; ++j) w0[j] = j < n ? wt_vmax(r[j], zero) : zero;
    const wt_vf total = dot8(w0, ones);
    wt_vf gw0[8];  // weights_backward
    for (int j = 0; j < 8; ++j) gw0[j] = gw1[j];
    if (params.normalize != 0) {
        const wt_vf s = wt_vmax(total, eps);
        const wt_vf shared = dot8(gw1, w0) / (s * s);
        for (int j = 0; j < 8; ++j) gw0[j] = wt_sel(total > eps, gw1[j] / s - shared, gw1[j] / s);
    }
    // The lane's gradients laid out as wt_lane_grads8 says, into the caller's matrix, every row of it
    // written: 0 for the other pixels, and for the colours of the layers past num_layers
    for (int j = n; j < 8; ++j)
        for (int l = 0; l < WT_L; ++l) __builtin_memset(out.data[l * 8 + j], 0, sizeof(wt_f4));
    for (int j = 0; j < n; ++j) {
        wt_vf gcj[4];
        for (int k = 0; k < 4; ++k) gcj[k] = wt_sel(covered, gc[j][k], zero);
        wt_f4 rows[WT_L];
        wt_rows_of_channels(gcj, rows);
        for (int l = 0; l < WT_L; ++l) __builtin_memcpy(out.data[l * 8 + j], &rows[l], sizeof(wt_f4));
    }
    g_t = wt_sel(covered, g_t, zero);
    __builtin_memcpy(out.data[WT_GRAD_TRANSITION], &g_t, sizeof(g_t));
    float raw[WT_L][8];  // each pixel's raw splat values' gradient, for the splat maps' adds below
    {
        float ghv_rows[8][WT_L], raw_rows[8][WT_L];
        for (int j = 0; j < 8; ++j) {
            const wt_vf gr = wt_sel(covered & (j < n ? r[j] > 0.0f : (wt_vi)0), gw0[j], zero);
            const wt_vf gh = wt_sel(covered, ghv[j], zero);
            __builtin_memcpy(raw_rows[j], &gr, sizeof(gr));
            __builtin_memcpy(ghv_rows[j], &gh, sizeof(gh));
        }
        for (int l = 0; l < WT_L; ++l)
            for (int j = 0; j < 8; ++j) {
                raw[l][j] = raw_rows[j][l];
                out.data[WT_GRAD_HEIGHT + (l * 8 + j) / 4][(l * 8 + j) % 4] = ghv_rows[j][l];
            }
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
}
