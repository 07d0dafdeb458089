// Texel gradients for a lane of pixels (the twins of warptex.kernels.scatter). A lane's taps and
// weights are computed for every pixel first, then added pixel by pixel and read by read, in the
// order the scalar kernels add them: the same texels get the same sums in the same order, so the
// gradients are the same bits, and the same tile marks (scatter.mark_rows) are made.
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_sample.h"

constexpr int WT_MAX_READS = 12;
// A lane pixel's taps of one level, and the lane's (a row per field, so that the loop that fills
// them vectorises).
struct wt_texel_taps {
    int start, w, i0, i1, j0, j1;
    float fx, fy;
};
struct wt_lane_texel_taps {
    int start[WT_L], w[WT_L], i0[WT_L], i1[WT_L], j0[WT_L], j1[WT_L];
    float fx[WT_L], fy[WT_L];
};
typedef float wt_lane_f[WT_L];
typedef int wt_lane_i[WT_L];
typedef bool wt_lane_b[WT_L];
typedef wt_f4 wt_lane_f4[WT_L];

// scatter.scatter_levels for the lane, the address mode a constant: reads r = 0 .. reads - 1 (up to
// WT_MAX_READS) of every lane pixel, read r from *tex[r] into *grad[r], at the levels and fractions
// given, where active, adding g[r][l].
// twin: scatter.scatter_levels
template <class Tex, class Grad, class Smp>
WT_INLINE void wt_scatter_levels(const int address, const int reads, const Tex* const* tex, const Grad* const* grad,
                                 const Smp& smp, const wt_lane_f* u, const wt_lane_f* v, const wt_lane_i* level,
                                 const wt_lane_f* fraction, const wt_lane_i* layer, const wt_lane_b* active,
                                 const wt_lane_f4* g) {
    wt_lane_texel_taps taps[WT_MAX_READS]
                           [2];  // [read][fine, coarse], field by field, so that the loop below vectorises
    bool blend = false;          // a lane reads two levels (trilinear)
    for (int r = 0; r < reads; ++r)
        for (int l = 0; l < WT_L; ++l) blend |= smp.filter != WT_NEAREST && active[r][l] && fraction[r][l] > 0.0f;
    for (int r = 0; r < reads; ++r) {
        for (int pass = 0; pass < (blend ? 2 : 1); ++pass) {
            int k[WT_L], lw[WT_L], lh[WT_L], ls[WT_L];  // each lane's level, its size and offset
            for (int l = 0; l < WT_L; ++l) k[l] = pass == 0 || fraction[r][l] <= 0.0f ? level[r][l] : level[r][l] + 1;
            wt_level_sizes(*tex[r], k, lw, lh, ls);
            wt_lane_texel_taps& t = taps[r][pass];
            for (int l = 0; l < WT_L; ++l) {  // filters.nearest_tap / bilinear_taps
                const float ru = wt_reduce(u[r][l], address), rv = wt_reduce(v[r][l], address);
                const int w = lw[l], h = lh[l];
                t.w[l] = w;
                t.start[l] = ls[l] + layer[r][l] * h * w;
                if (smp.filter == WT_NEAREST) {
                    t.i0[l] = wt_address((int)wp::floor(ru * (float)w), w, address);
                    t.j0[l] = wt_address((int)wp::floor((1.0f - rv) * (float)h), h, address);
                } else {
                    const float x = ru * (float)w - 0.5f;
                    const float y = (1.0f - rv) * (float)h - 0.5f;
                    const float x0 = wp::floor(x);
                    const float y0 = wp::floor(y);
                    t.i0[l] = wt_address((int)x0, w, address);
                    t.i1[l] = wt_address((int)x0 + 1, w, address);
                    t.j0[l] = wt_address((int)y0, h, address);
                    t.j1[l] = wt_address((int)y0 + 1, h, address);
                    t.fx[l] = x - x0;
                    t.fy[l] = y - y0;
                }
            }
        }
    }
    auto tap = [&](int r, int pass, int l) __attribute__((always_inline)) -> wt_texel_taps {
        const wt_lane_texel_taps& t = taps[r][pass];
        return {t.start[l], t.w[l], t.i0[l], t.i1[l], t.j0[l], t.j1[l], t.fx[l], t.fy[l]};
    };
    // Each read's gradient array as a pointer and strides, taken once: the adds' stores could alias
    // the array structs, which the compiler would then read again after every add.
    struct wt_target {
        char* texels;
        long long stride;
        char* tiles;
        long long tile_stride;
        bool marks;
    };
    wt_target targets[WT_MAX_READS];
    for (int r = 0; r < reads; ++r)
        targets[r] = {(char*)grad[r]->texels.data, (long long)grad[r]->texels.strides[0], (char*)grad[r]->tiles.data,
                      (long long)grad[r]->tiles.strides[0], grad[r]->tiles.shape[0] > 0};
    auto add = [&](const wt_target& gr, const wt_texel_taps& t, int x, int y, const wt_f4 value)
                   __attribute__((always_inline)) {                       // scatter.scatter_texel
                       if (address != WT_BORDER || (x >= 0 && y >= 0)) {  // only the border mode has taps outside
                           float* p = (float*)(gr.texels + (long long)(t.start + y * t.w + x) * gr.stride);
                           for (int c = 0; c < 4; ++c) p[c] = p[c] + value[c];
                       }
                   };
    auto mark = [&](const wt_target& gr, const wt_texel_taps& t, int j)
                    __attribute__((always_inline)) {  // scatter.mark_rows
                        const int row = t.start + j * t.w;
                        int* tile = (int*)(gr.tiles + (long long)(row >> WT_TILE_SHIFT) * gr.tile_stride);
                        const int reach = (((row & ((1 << WT_TILE_SHIFT) - 1)) + 2 * t.w - 1) >> WT_TILE_SHIFT) + 1;
                        if (*tile < reach) *tile = reach;
                    };
    auto bilinear = [&](const wt_target& gr, const wt_texel_taps& t, const wt_f4 value)
                        __attribute__((always_inline)) {  // scatter.scatter_bilinear
                            const wt_f4 top = value * (1.0f - t.fy);
                            const wt_f4 bottom = value * t.fy;
                            add(gr, t, t.i0, t.j0, top * (1.0f - t.fx));
                            add(gr, t, t.i1, t.j0, top * t.fx);
                            add(gr, t, t.i0, t.j1, bottom * (1.0f - t.fx));
                            add(gr, t, t.i1, t.j1, bottom * t.fx);
                            if (gr.marks) {
                                if (t.j0 >= 0) mark(gr, t, t.j0);
                                if (t.j1 >= 0 && (t.j0 < 0 || t.j1 < t.j0 || t.j1 > t.j0 + 1)) mark(gr, t, t.j1);
                            }
                        };
    for (int l = 0; l < WT_L; ++l) {
        for (int r = 0; r < reads; ++r) {
            if (!active[r][l]) continue;
            const wt_target& gr = targets[r];
            if (smp.filter == WT_NEAREST) {
                const wt_texel_taps t = tap(r, 0, l);
                add(gr, t, t.i0, t.j0, g[r][l]);
                if (gr.marks && t.j0 >= 0) mark(gr, t, t.j0);
            } else {  // scatter.scatter_levels: the coarser level first
                wt_f4 finer = g[r][l];
                if (fraction[r][l] > 0.0f) {
                    finer = g[r][l] * (1.0f - fraction[r][l]);
                    bilinear(gr, tap(r, 1, l), g[r][l] * fraction[r][l]);
                }
                bilinear(gr, tap(r, 0, l), finer);
            }
        }
    }
}

// wt_scatter_levels with the address mode a constant, once per mode.
// twin: scatter.scatter_levels
template <class Tex, class Grad, class Smp>
WT_INLINE void wt_scatter_levels_any(const int reads, const Tex* const* tex, const Grad* const* grad, const Smp& smp,
                                     const wt_lane_f* u, const wt_lane_f* v, const wt_lane_i* level,
                                     const wt_lane_f* fraction, const wt_lane_i* layer, const wt_lane_b* active,
                                     const wt_lane_f4* g) {
    switch (smp.address) {
    case WT_WRAP:
        wt_scatter_levels(WT_WRAP, reads, tex, grad, smp, u, v, level, fraction, layer, active, g);
        break;
    case WT_CLAMP:
        wt_scatter_levels(WT_CLAMP, reads, tex, grad, smp, u, v, level, fraction, layer, active, g);
        break;
    case WT_MIRROR:
        wt_scatter_levels(WT_MIRROR, reads, tex, grad, smp, u, v, level, fraction, layer, active, g);
        break;
    default:
        wt_scatter_levels(WT_BORDER, reads, tex, grad, smp, u, v, level, fraction, layer, active, g);
        break;
    }
}

// Up to twelve reads per lane pixel, read r from *texs[r] into *grads[r], at the rows u_rows[r],
// v_rows[r], lod_rows[r] and weight w_rows[r] of a value per lane pixel (a lane_reads matrix's: a
// pixel's projections, or two of them: a pixel's faces; a lane_taps matrix's: a stochastic lookup's
// taps, or three of them: a stochastic triplanar pixel's); a read adds where its weight is positive
// and its UV and LOD are finite (scatter.scatter_lod), and only into a gradient that is needed. It
// adds its share of the pixel's gradient g[l] (read r's own, gr[r], where per_read; else gr[0]):
// w · g where weigh (a blend of projections or taps), g itself where not.
// twin: scatter.scatter_lod
template <class Tex, class Grad, class Smp>
WT_INLINE void wt_scatter_rows(const Tex* const* texs, const Grad* const* grads, const Smp& smp, const int nreads,
                               const int* layers, const float* const* u_rows, const float* const* v_rows,
                               const float* const* lod_rows, const float* const* w_rows, const int weigh,
                               const wt_lane_colours* const* gr, const int per_read) {
    float us[WT_MAX_READS][WT_L], vs[WT_MAX_READS][WT_L], fractions[WT_MAX_READS][WT_L];
    int levels[WT_MAX_READS][WT_L], layer[WT_MAX_READS][WT_L];
    bool active[WT_MAX_READS][WT_L];
    wt_f4 gs[WT_MAX_READS][WT_L];
    wt_vi lane_layers;
    __builtin_memcpy(&lane_layers, layers, sizeof(lane_layers));
    for (int r = 0; r < nreads;
         ++r) {  // a lane of reads at a time (vector selects, the same values as the scalar formulas)
        wt_vf u, v, lod, w;
        __builtin_memcpy(&u, u_rows[r], sizeof(u));
        __builtin_memcpy(&v, v_rows[r], sizeof(v));
        __builtin_memcpy(&lod, lod_rows[r], sizeof(lod));
        __builtin_memcpy(&w, w_rows[r], sizeof(w));
        const wt_vi needed = grads[r]->texels.shape[0] > 0 ? -1 : 0;
        const wt_vi ok = needed & (w > 0.0f) & (wt_vabs(u) <= wt_float_max) & (wt_vabs(v) <= wt_float_max) &
                         (wt_vabs(lod) <= wt_float_max);
        const wt_vf zero = 0.0f;
        const wt_vf ur = wt_sel(ok, u, zero), vr = wt_sel(ok, v, zero);
        wt_vi level;
        wt_vf fraction;
        wt_mip_levels_lane(*texs[r], smp, wt_sel(ok, lod, zero), level, fraction);
        const int top = texs[r]->num_layers - 1;  // wp::clamp(layer, 0, top)
        wt_vi lr = lane_layers & ~(lane_layers < 0);
        const wt_vi over = lr > top;
        lr = ((lr & ~over) | (top & over)) & ok;
        __builtin_memcpy(us[r], &ur, sizeof(ur));
        __builtin_memcpy(vs[r], &vr, sizeof(vr));
        __builtin_memcpy(levels[r], &level, sizeof(level));
        __builtin_memcpy(fractions[r], &fraction, sizeof(fraction));
        __builtin_memcpy(layer[r], &lr, sizeof(lr));
        for (int l = 0; l < WT_L; ++l) {
            active[r][l] = ok[l] != 0;
            const wt_lane_colours& g = *gr[per_read ? r : 0];
            const wt_f4 gl = {g.data[l][0], g.data[l][1], g.data[l][2], g.data[l][3]};
            gs[r][l] = weigh ? w[l] * gl : gl;
        }
    }
    wt_scatter_levels_any(nreads, texs, grads, smp, us, vs, levels, fractions, layer, active, gs);
}

// Whether a pixel of the lane reads a footprint of several taps (the anisotropic filter's) in one
// of reads r = 0 .. nreads - 1 (weights w_rows[r], taps taps_rows[r]).
WT_INLINE bool wt_several_taps(const int nreads, const float* const* w_rows, const float* const* taps_rows) {
    bool several = false;
    for (int r = 0; r < nreads; ++r)
        for (int l = 0; l < WT_L; ++l) several |= w_rows[r][l] > 0.0f && taps_rows[r][l] != 1.0f;
    return several;
}

// Taps into one gradient array, batched WT_L at a time through wt_scatter_levels_any as the lanes
// of one read, which adds its lanes in order: the taps add in the order they are pushed.
template <class Tex, class Grad, class Smp> struct wt_tap_batch {
    const Tex* tex[1];
    const Grad* grad[1];
    const Smp& smp;
    wt_lane_f us[1], vs[1], fractions[1];
    wt_lane_i levels[1], layer[1];
    wt_lane_b active[1];
    wt_lane_f4 gs[1];
    int n = 0;  // taps batched
    wt_tap_batch(const Tex& t, const Grad& g, const Smp& s) : tex{&t}, grad{&g}, smp(s) {}
    __attribute__((always_inline)) void push(float u, float v, int level, float fraction, int lr, const wt_f4& g) {
        us[0][n] = u, vs[0][n] = v, levels[0][n] = level, fractions[0][n] = fraction;
        layer[0][n] = lr, active[0][n] = true, gs[0][n] = g;
        if (++n == WT_L) flush();
    }
    __attribute__((noinline)) void flush() {  // one copy of the four address modes' adds per batch type
        if (n == 0) return;
        for (int l = n; l < WT_L; ++l) {
            us[0][l] = vs[0][l] = fractions[0][l] = 0.0f;
            levels[0][l] = layer[0][l] = 0;
            active[0][l] = false;
        }
        wt_scatter_levels_any(1, tex, grad, smp, us, vs, levels, fractions, layer, active, gs);
        n = 0;
    }
};

// add(first, group) once per gradient array that reads r = 0 .. nreads - 1 add into, where it is
// needed: read `first` the first into it, group[r] whether read r adds into it.
template <int MaxReads = WT_MAX_READS, class Grad, class Add>
WT_INLINE void wt_each_grad_array(const int nreads, const Grad* const* grads, Add&& add) {
    bool done[MaxReads] = {};
    for (int first = 0; first < nreads; ++first) {
        if (done[first] || grads[first]->texels.shape[0] == 0) continue;
        bool group[MaxReads] = {};
        for (int r = first; r < nreads; ++r)
            group[r] = done[r] = grads[r]->texels.shape[0] > 0 && grads[r]->texels.data == grads[first]->texels.data;
        add(first, group);
    }
}

// wt_scatter_rows where reads have footprints of several taps (the anisotropic filter's; footprint
// rows du, dv, taps too): scatter.scatter_footprint of each read with a positive weight into a
// gradient that is needed, pixel by pixel, read by read, each footprint's taps in order: tap k of a
// footprint of n taps at (u + du · s, v + dv · s), s = k + 1/2 - n/2, adds the read's share times
// 1 / n (a one-tap footprint its share at (u, v) itself); a tap whose UV or LOD is not finite adds
// nothing. The taps of each gradient array go through a wt_tap_batch in that order: the reads into
// one array (a texture shared by projections, or a splat layer's) keep the scalar kernels' order,
// and reads into other arrays (a texture per axis) add apart, each array's in that order. Read r
// samples the array layers layers[r · layer_stride + l] (a layer per lane pixel, the same for
// every read where layer_stride is 0); up to MaxReads reads where a caller sets it (a splat's face
// layers: every layer's reads at once).
// twin: scatter.scatter_footprint
template <int MaxReads = WT_MAX_READS, class Tex, class Grad, class Smp> WT_INLINE void
wt_scatter_footprint_rows(const Tex* const* texs, const Grad* const* grads, const Smp& smp, const int nreads,
                          const int* layers, const float* const* u_rows, const float* const* v_rows,
                          const float* const* lod_rows, const float* const* du_rows, const float* const* dv_rows,
                          const float* const* taps_rows, const float* const* w_rows, const int weigh,
                          const wt_lane_colours* const* gr, const int per_read, const int layer_stride = 0) {
    wt_each_grad_array<MaxReads>(nreads, grads, [&](const int first, const bool* group) __attribute__((always_inline)) {
        wt_tap_batch<Tex, Grad, Smp> batch(*texs[first], *grads[first], smp);
        for (int l = 0; l < WT_L; ++l) {
            for (int r = first; r < nreads; ++r) {
                const float w = w_rows[r][l], lod = lod_rows[r][l];
                if (!group[r] || !(w > 0.0f) || !(__builtin_fabsf(lod) <= wt_float_max)) continue;
                const wt_lane_colours& g = *gr[per_read ? r : 0];
                const wt_f4 gl = {g.data[l][0], g.data[l][1], g.data[l][2], g.data[l][3]};
                const wt_f4 share = weigh ? w * gl : gl;
                const float taps = taps_rows[r][l], u = u_rows[r][l], v = v_rows[r][l];
                const float du = du_rows[r][l], dv = dv_rows[r][l];
                const bool one = taps == 1.0f;
                const int count = one ? 1 : (int)taps;  // footprint.footprint_taps
                const wt_f4 tap_share = one ? share : share * (1.0f / taps);
                int level;
                float fraction;
                wt_mip_levels(*texs[r], smp, lod, level, fraction);
                const int lr = wp::clamp(layers[r * layer_stride + l], 0, texs[r]->num_layers - 1);
                for (int k = 0; k < count; ++k) {
                    const float s = (float)k + 0.5f - 0.5f * taps;
                    const float tu = one ? u : u + du * s, tv = one ? v : v + dv * s;  // footprint.footprint_uv
                    if (!(__builtin_fabsf(tu) <= wt_float_max && __builtin_fabsf(tv) <= wt_float_max)) continue;
                    batch.push(tu, tv, level, fraction, lr, tap_share);
                }
            }
        }
        batch.flush();
    });
}

// The rows of up to six reads (a lane_reads matrix's rows of a read: UV, LOD, weight, footprint),
// read r's at u[r], v[r]...: reads 0 .. 2 of a matrix (wt_rows_of), or each projection's on its +
// and - face (wt_face_rows); N reads where a caller sets it (a splat's face layers).
template <int N> struct wt_read_rows_n {
    const float *u[N], *v[N], *lod[N], *w[N], *du[N], *dv[N], *taps[N];
};
typedef wt_read_rows_n<6> wt_read_rows;
// Read r of `rows`: read `axis` of `at`.
template <int N, class At> WT_INLINE void wt_put_rows(wt_read_rows_n<N>& rows, int r, const At& at, int axis) {
    rows.u[r] = at.data[axis], rows.v[r] = at.data[3 + axis], rows.lod[r] = at.data[6 + axis];
    rows.w[r] = at.data[9 + axis], rows.du[r] = at.data[12 + axis], rows.dv[r] = at.data[15 + axis];
    rows.taps[r] = at.data[18 + axis];
}
// Reads 0 .. 2 of `at` (a wt_lane_reads, or a wt_lane_read_rows).
template <class At> WT_INLINE wt_read_rows wt_rows_of(const At& at) {
    wt_read_rows rows;
    for (int r = 0; r < 3; ++r) wt_put_rows(rows, r, at, r);
    return rows;
}
// A texture per face: each projection's read on its + face (of `plus`) and on its - face (of
// `minus`), in the order x+, x-, y+, y-, z+, z-.
WT_INLINE wt_read_rows wt_face_rows(const wt_lane_reads& plus, const wt_lane_reads& minus) {
    wt_read_rows rows;
    for (int r = 0; r < 6; ++r) wt_put_rows(rows, r, r % 2 == 0 ? plus : minus, r / 2);
    return rows;
}

// wt_scatter_rows of reads r = 0 .. nreads - 1 of `rows`; where a read has several taps (the
// anisotropic filter's), wt_scatter_footprint_rows.
template <class Tex, class Grad, class Smp>
WT_INLINE void wt_scatter_read_rows(const Tex* const* texs, const Grad* const* grads, const Smp& smp, const int nreads,
                                    const int* layers, const wt_read_rows& rows, const int weigh,
                                    const wt_lane_colours* const* gr, const int per_read) {
    if (wt_several_taps(nreads, rows.w, rows.taps)) {
        wt_scatter_footprint_rows(texs, grads, smp, nreads, layers, rows.u, rows.v, rows.lod, rows.du, rows.dv,
                                  rows.taps, rows.w, weigh, gr, per_read);
        return;
    }
    wt_scatter_rows(texs, grads, smp, nreads, layers, rows.u, rows.v, rows.lod, rows.w, weigh, gr, per_read);
}

// wt_scatter_rows of the reads of a lane_reads matrix `at`.
template <class Tex, class Grad, class Smp, class At>
WT_INLINE void wt_scatter_lod_of(const Tex* const* texs, const Grad* const* grads, const Smp& smp, const int nreads,
                                 const int* layers, const At& at, const int weigh, const wt_lane_colours* const* gr,
                                 const int per_read) {
    wt_scatter_read_rows(texs, grads, smp, nreads, layers, wt_rows_of(at), weigh, gr, per_read);
}

// Every read's share of one gradient g[l] per lane pixel.
template <class Tex, class Grad, class Smp, class At>
WT_INLINE void wt_scatter_lod(const Tex* const* texs, const Grad* const* grads, const Smp& smp, const int nreads,
                              const int* layers, const At& at, const int weigh, const wt_lane_colours& g) {
    const wt_lane_colours* gr[1] = {&g};
    wt_scatter_lod_of(texs, grads, smp, nreads, layers, at, weigh, gr, 0);
}

// Add g · d (wp.dot, Warp's own, so the bits are the one-pixel body's) into entry k of a
// per-sample gradient of 1 (a LOD's) or 2 (a UV's: g · d[0], g · d[1]) floats (wp.atomic_add).
template <class A> WT_INLINE void wt_add_dots(const A& grad, int k, int dims, const wt_f4& g, const wt_f4* d) {
    float* row = (float*)((char*)grad.data + (long long)k * grad.strides[0]);
    const wt_v4 gv(g[0], g[1], g[2], g[3]);
    for (int e = 0; e < dims; ++e) row[e] = row[e] + wp::dot(gv, wt_v4(d[e][0], d[e][1], d[e][2], d[e][3]));
}

// sampling.scatter_sample_level's adds of (g · d/du, g · d/dv) into uv_grad[base + l] for the
// lane's active pixels, the slopes wt_sample_levels gives (filters.sample_levels_derivatives').
// Out of line: inlined, it made the texel-only lane 4% more instructions (callgrind).
// twin: filters.sample_levels_derivatives
template <class Tex, class UVGrad, class Smp>
WT_OUTLINE void wt_add_level_uv_slopes(const Tex& tex, const UVGrad& uv_grad, const Smp& smp, const float* u,
                                       const float* v, const int* levels, const float* fractions, const int* layer,
                                       const bool* active, const wt_f4* g, int base, int count) {
    const float lods[WT_L] = {};  // read for d/dlod only, which is not wanted here
    wt_vf value[4], DU[4], DV[4], DLOD[4];
    const wt_level_slopes slopes = {lods, DU, DV, DLOD};
    wt_sample_levels_any(tex, smp, u, v, levels, fractions, layer, value, &slopes);
    wt_f4 d[2][WT_L];
    wt_rows_of_channels(DU, d[0]);
    wt_rows_of_channels(DV, d[1]);
    for (int l = 0; l < count; ++l) {
        if (!active[l]) continue;
        const wt_f4 dl[2] = {d[0][l], d[1][l]};
        wt_add_dots(uv_grad, base + l, 2, g[l], dl);
    }
}

// lanes.scatter.scatter_levels_lane: scatter.scatter_levels of the gradient adj[i] for the lane's
// pixels i = base .. whose uv[i] is finite, their layer, one level for all, where grad is needed;
// where uv_grad is (not empty), sampling.scatter_sample_level's adds of (g · d/du, g · d/dv) into
// uv_grad[i], the slopes wt_sample_levels gives (filters.sample_levels_derivatives').
// twin: sampling.scatter_sample_level
template <class Tex, class Grad, class UVGrad, class Smp, class UV, class Layers, class Adj>
WT_INLINE void wt_scatter_levels_lane(const Tex& tex, const Grad& grad, const UVGrad& uv_grad, const Smp& smp,
                                      const UV& uv, const Layers& layers, int constant_layer, int level, float fraction,
                                      const Adj& adj, int base) {
    const int n = uv.shape[0];
    const int count = n - base < WT_L ? n - base : WT_L;
    float u[1][WT_L], v[1][WT_L], fractions[1][WT_L];
    int levels[1][WT_L], layer[1][WT_L];
    bool active[1][WT_L];
    wt_f4 g[1][WT_L];
    float p[2][WT_L];
    wt_rows(uv, base, count, 2, p);
    for (int l = 0; l < WT_L; ++l) {
        const int k = base + (l < count ? l : 0);
        const bool finite = __builtin_fabsf(p[0][l]) <= wt_float_max && __builtin_fabsf(p[1][l]) <= wt_float_max;
        active[0][l] = l < count && finite;
        u[0][l] = active[0][l] ? p[0][l] : 0.0f;
        v[0][l] = active[0][l] ? p[1][l] : 0.0f;
        levels[0][l] = level;
        fractions[0][l] = fraction;
        layer[0][l] = layers.shape[0] > 0 ? wp::clamp(wt_int(layers, k), 0, tex.num_layers - 1)
                                          : constant_layer;  // texels.resolve_layer
        g[0][l] = wt_read_channels(adj, k);
    }
    if (grad.texels.shape[0] > 0) {
        const Tex* texs[1] = {&tex};
        const Grad* grads[1] = {&grad};
        wt_scatter_levels_any(1, texs, grads, smp, u, v, levels, fractions, layer, active, g);
    }
    if (uv_grad.shape[0] > 0)
        wt_add_level_uv_slopes(tex, uv_grad, smp, u[0], v[0], levels[0], fractions[0], layer[0], active[0], g[0], base,
                               count);
}

// texels.read_channels of the output gradients adj[i] of the lane's pixels i = base .. base + count
// - 1 (the lane's tail repeats pixel base).
template <class Adj> WT_INLINE wt_lane_colours wt_adj_lane(const Adj& adj, int base, int count) {
    wt_lane_colours g;
    for (int l = 0; l < WT_L; ++l) {
        const char* row = (const char*)adj.data + (long long)(base + (l < count ? l : 0)) * adj.strides[0];
        for (int c = 0; c < 4; ++c)
            g.data[l][c] = c < adj.shape[1] ? *(const float*)(row + (long long)c * adj.strides[1]) : 0.0f;
    }
    return g;
}

// lanes.scatter.scatter_footprint_lane: scatter.scatter_footprint of adj[i] for the lane's pixels
// i = base .. (wt_sample_reads_of's reads; footprints of several taps through wt_scatter_lod's
// wt_scatter_footprint_rows), where grad is needed; where uv_grad and lod_grad are (not empty),
// sampling.scatter_sample's adds of (g · d/du, g · d/dv) and g · d/dlod into them, the slopes
// wt_footprint_slopes gives (filters.sample_footprint_derivatives').
// twin: sampling.scatter_sample
template <class Tex, class Grad, class UVGrad, class LodGrad, class Smp, class UV, class Lods, class Layers, class Adj>
WT_INLINE void wt_scatter_footprint_lane(const Tex& tex, const Grad& grad, const UVGrad& uv_grad,
                                         const LodGrad& lod_grad, const Smp& smp, const UV& uv, const UV& uv_dx,
                                         const UV& uv_dy, const Lods& lods, const Layers& layers, int constant_layer,
                                         int lod_source, float constant_lod, const Adj& adj, int base) {
    const wt_sample_reads s =
        wt_sample_reads_of(tex, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);
    const wt_lane_colours g = wt_adj_lane(adj, base, s.count);
    if (grad.texels.shape[0] > 0) {
        const Tex* texs[1] = {&tex};
        const Grad* grads[1] = {&grad};
        wt_scatter_lod(texs, grads, smp, 1, s.layer, s.reads, 0, g);
    }
    if (uv_grad.shape[0] == 0 && lod_grad.shape[0] == 0) return;
    const wt_lane_reads& at = s.reads;
    int layer[WT_L];  // texels.resolve_layer: wt_sample_reads_of's, clamped to the array
    for (int l = 0; l < WT_L; ++l) layer[l] = wp::clamp(s.layer[l], 0, tex.num_layers - 1);
    wt_f4 forward[WT_L], value[WT_L], d_u[WT_L], d_v[WT_L], d_lod[WT_L], d_spread[WT_L];
    wt_footprint_slopes(tex, smp, layer, at.data[0], at.data[3], at.data[6], at.data[12], at.data[15], at.data[18],
                        at.data[9], forward, value, d_u, d_v, d_lod, d_spread);
    for (int l = 0; l < s.count; ++l) {
        wt_f4 gl;
        __builtin_memcpy(&gl, g.data[l], 16);
        const wt_f4 duv[2] = {d_u[l], d_v[l]};
        if (uv_grad.shape[0] > 0) wt_add_dots(uv_grad, base + l, 2, gl, duv);
        if (lod_grad.shape[0] > 0) wt_add_dots(lod_grad, base + l, 1, gl, &d_lod[l]);
    }
}

// lanes.scatter.scatter_taps_lane: stochastic.scatter_stochastic of one-tap footprints: tap k of
// pixel l at (u_k, v_k), rows 3k, 3k + 1 of `taps`, all at the pixel's LOD (row 12), adds w_k · g[l]
// (w_k: row 3k + 2) into grad where w_k > 0, pixel by pixel and tap by tap.
// twin: stochastic.scatter_stochastic
template <class Tex, class Grad, class Smp, class Ints>
WT_INLINE void wt_scatter_taps_lane(const Tex& tex, const Grad& grad, const Smp& smp, const Ints& layers,
                                    const wt_lane_taps& taps, const wt_lane_colours& g) {
    const float* u[4] = {taps.data[0], taps.data[3], taps.data[6], taps.data[9]};
    const float* v[4] = {taps.data[1], taps.data[4], taps.data[7], taps.data[10]};
    const float* w[4] = {taps.data[2], taps.data[5], taps.data[8], taps.data[11]};
    const float* lod[4] = {taps.data[12], taps.data[12], taps.data[12], taps.data[12]};
    const Tex* texs[4] = {&tex, &tex, &tex, &tex};
    const Grad* grads[4] = {&grad, &grad, &grad, &grad};
    const wt_lane_colours* gr[1] = {&g};
    wt_scatter_rows(texs, grads, smp, 4, layers.c, u, v, lod, w, 1, gr, 0);
}

// lanes.scatter.scatter_face_reads_lanes: a texture per face: each projection's read on its + face
// (rows of `plus`) and on its - face (rows of `minus`; a pixel reads one of the two), in the order
// x+, x-, y+, y-, z+, z-, each adding its projection's gradient g_a[l], times w where weigh.
template <class Tex, class Grad, class Smp, class Ints> WT_INLINE void wt_scatter_face_reads_lanes(
    const Tex& tex_px, const Tex& tex_nx, const Tex& tex_py, const Tex& tex_ny, const Tex& tex_pz, const Tex& tex_nz,
    const Grad& grad_px, const Grad& grad_nx, const Grad& grad_py, const Grad& grad_ny, const Grad& grad_pz,
    const Grad& grad_nz, const Smp& smp, const Ints& layers, const wt_lane_reads& plus, const wt_lane_reads& minus,
    int weigh, const wt_lane_colours& g0, const wt_lane_colours& g1, const wt_lane_colours& g2) {
    const Tex* texs[6] = {&tex_px, &tex_nx, &tex_py, &tex_ny, &tex_pz, &tex_nz};
    const Grad* grads[6] = {&grad_px, &grad_nx, &grad_py, &grad_ny, &grad_pz, &grad_nz};
    const wt_lane_colours* gr[6] = {&g0, &g0, &g1, &g1, &g2, &g2};
    wt_scatter_read_rows(texs, grads, smp, 6, layers.c, wt_face_rows(plus, minus), weigh, gr, 1);
}

// lanes.scatter.scatter_projection_taps_lanes: scatter_stochastic of each projection's one-tap
// footprints, projection by projection (tap k of projection a: rows 3k, 3k + 1 of taps_a, its LOD
// row 12, weight row 3k + 2), each adding w_k · g_a[l] into grad_a, pixel by pixel and read by read
// as the scalar colour gradient adds them.
template <class Tex, class Grad, class Smp, class Ints> WT_INLINE void
wt_scatter_projection_taps_lanes(const Tex& tex0, const Tex& tex1, const Tex& tex2, const Grad& grad0,
                                 const Grad& grad1, const Grad& grad2, const Smp& smp, const Ints& layers,
                                 const wt_lane_taps& taps0, const wt_lane_taps& taps1, const wt_lane_taps& taps2,
                                 const wt_lane_colours& g0, const wt_lane_colours& g1, const wt_lane_colours& g2) {
    const wt_lane_taps* taps[3] = {&taps0, &taps1, &taps2};
    const Tex* axis_texs[3] = {&tex0, &tex1, &tex2};
    const Grad* axis_grads[3] = {&grad0, &grad1, &grad2};
    const wt_lane_colours* axis_g[3] = {&g0, &g1, &g2};
    const float *u[12], *v[12], *lod[12], *w[12];
    const Tex* texs[12];
    const Grad* grads[12];
    const wt_lane_colours* gr[12];
    for (int a = 0; a < 3; ++a) {
        for (int k = 0; k < 4; ++k) {
            const int r = 4 * a + k;
            u[r] = taps[a]->data[3 * k], v[r] = taps[a]->data[3 * k + 1], w[r] = taps[a]->data[3 * k + 2],
            lod[r] = taps[a]->data[12];
            texs[r] = axis_texs[a], grads[r] = axis_grads[a], gr[r] = axis_g[a];
        }
    }
    wt_scatter_rows(texs, grads, smp, 12, layers.c, u, v, lod, w, 1, gr, 1);
}
