// Texture reads for a lane: filtered samples of each lane pixel's level(s) and over its footprint,
// and `sample`'s reads, forward (the lanes of warptex.kernels.lanes.sample).
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_footprint.h"

typedef unsigned char wt_vb __attribute__((ext_vector_type(4 * WT_L)));  // a lane's packed RGBA8 texels

// The texels at index[l] of a unorm8 texture (the border colour where a border-mode read is not
// inside), decoded into a vector per channel: ch[c][l] is stored_texel(tex, index[l])[c], the code
// divided by 255 (its table's value for every code). sRGB's table lookups, per lane and channel,
// measured faster through wt_stored_texel and the transpose.
// twin: texels.stored_texel
template <class Tex> WT_INLINE void wt_unorm8_channels(const Tex& tex, const int* index, const bool* inside,
                                                       const int address, const wt_f4& border, wt_vf* ch) {
    const unsigned int* packed = (const unsigned int*)tex.packed;
    unsigned int p[WT_L];
    for (int l = 0; l < WT_L; ++l) p[l] = packed[address != WT_BORDER || inside[l] ? index[l] : 0];
    wt_vb P;
    __builtin_memcpy(&P, p, sizeof(P));
    // code / 255 correctly rounded, as the table holds it, without a divide (a vector divide per
    // channel and tap was the decode's cost): code · hi + code · lo, the product's low part fused,
    // where hi = 1/255 rounded and lo the rest. Exact for each of the 256 codes
    // (tests/test_formats.py checks them all). A channel's codes come out of the packed texels by one
    // byte shuffle (byte c of each, zero-extended).
    const float hi = 1.0f / 255.0f, lo = (float)(1.0 / 255.0 - (double)hi);
    const wt_vb zero = {};
#define WT_BYTE(c, l) 4 * l + c, 4 * WT_L, 4 * WT_L, 4 * WT_L
#if WT_L == 16
#define WT_CHANNEL(c)                                                                                                  \
    (wt_vi) __builtin_shufflevector(P, zero, WT_BYTE(c, 0), WT_BYTE(c, 1), WT_BYTE(c, 2), WT_BYTE(c, 3),               \
                                    WT_BYTE(c, 4), WT_BYTE(c, 5), WT_BYTE(c, 6), WT_BYTE(c, 7), WT_BYTE(c, 8),         \
                                    WT_BYTE(c, 9), WT_BYTE(c, 10), WT_BYTE(c, 11), WT_BYTE(c, 12), WT_BYTE(c, 13),     \
                                    WT_BYTE(c, 14), WT_BYTE(c, 15))
#else
#define WT_CHANNEL(c)                                                                                                  \
    (wt_vi) __builtin_shufflevector(P, zero, WT_BYTE(c, 0), WT_BYTE(c, 1), WT_BYTE(c, 2), WT_BYTE(c, 3),               \
                                    WT_BYTE(c, 4), WT_BYTE(c, 5), WT_BYTE(c, 6), WT_BYTE(c, 7))
#endif
    const wt_vi codes[4] = {WT_CHANNEL(0), WT_CHANNEL(1), WT_CHANNEL(2), WT_CHANNEL(3)};
#undef WT_CHANNEL
#undef WT_BYTE
    for (int c = 0; c < 4; ++c) {
        const wt_vf code = __builtin_convertvector(codes[c], wt_vf);
        ch[c] = __builtin_elementwise_fma(code, (wt_vf)hi, code * lo);
    }
    if (address == WT_BORDER)
        for (int c = 0; c < 4; ++c)
            for (int l = 0; l < WT_L; ++l)
                if (!inside[l]) ch[c][l] = border[c];
}

// What wt_sample_levels also gives where its caller asks (filters.sample_lod_derivatives' d/du,
// d/dv and d/dlod of each lane's filtered value; d/dlod where the biased LOD of each lane, lod, is
// inside the sampler's clamp): four channel vectors each (as the value's), or null.
struct wt_level_slopes {
    const float* lod;
    wt_vf *du, *dv, *dlod;
};

// w[WT_Q·K] .. w[WT_Q·K + WT_Q - 1], each four times, beside the rows of those pixels (wt_quad): a
// lane's bilinear blend a row at a time (wt_bilinear_quad).
template <int K> WT_INLINE wt_vf wt_quad_weights(wt_vf w) {
#if WT_L == 16
    return __builtin_shufflevector(w, w, 4 * K, 4 * K, 4 * K, 4 * K, 4 * K + 1, 4 * K + 1, 4 * K + 1, 4 * K + 1,
                                   4 * K + 2, 4 * K + 2, 4 * K + 2, 4 * K + 2, 4 * K + 3, 4 * K + 3, 4 * K + 3,
                                   4 * K + 3);
#else
    return __builtin_shufflevector(w, w, 2 * K, 2 * K, 2 * K, 2 * K, 2 * K + 1, 2 * K + 1, 2 * K + 1, 2 * K + 1);
#endif
}
// filters.sample_bilinear of pixels WT_Q·K .. WT_Q·K + WT_Q - 1 into their rows, from the rows of
// their four taps (taps[k][l]) and the weights FX, FY: each channel's operations as the channel
// vectors' blend in wt_sample_levels, so the bits are its.
template <int K> WT_INLINE void wt_bilinear_quad(const wt_f4 (*taps)[WT_L], wt_vf FX, wt_vf FY, wt_f4* rows) {
    const wt_vf fx = wt_quad_weights<K>(FX), fy = wt_quad_weights<K>(FY), gx = 1.0f - fx, gy = 1.0f - fy;
    const wt_vf top = wt_quad<K>(taps[0]) * gx + wt_quad<K>(taps[1]) * fx;
    const wt_vf bottom = wt_quad<K>(taps[2]) * gx + wt_quad<K>(taps[3]) * fx;
    const wt_vf value = top * gy + bottom * fy;
    __builtin_memcpy(rows + WT_Q * K, &value, sizeof(value));
}

// res[c][l] = filters.sample_levels(tex, layer[l], (u[l], v[l]), level[l], fraction[l], smp)[c] for
// every lane and channel: a vector per channel, as the footprint reads sum and blend them (rows
// were transposed here and straight back there). The address mode is a constant
// (wt_sample_levels_any compiles it once per mode: a mode tested per texel measured slower). Each
// level read is cut in two: every lane's addresses and weights, then every lane's loads, so that
// the loads are in flight together. With slopes (not null), also the value's derivatives as
// filters.sample_lod_derivatives takes them (the same value, bit for bit): bilinear_derivatives of
// each level read, blended as the values are; 0 for nearest. With rows (not null), the value as
// rows (rows[l][c] = res[c][l]) for a caller that stores rows, and res is scratch: a float32 read of
// one level (bilinear, no slopes) then blends the rows as loaded, four pixels a vector, with no
// transpose there or back (a third of a coherent bilinear lookup's shuffles).
// twin: filters.sample_levels
template <class Tex, class Smp>
WT_INLINE void wt_sample_levels(const int address, const Tex& tex, const Smp& smp, const float* u, const float* v,
                                const int* level, const float* fraction, const int* layer, wt_vf* res,
                                const wt_level_slopes* slopes = nullptr, wt_f4* rows = nullptr) {
    const wt_f4 border = {smp.border.c[0], smp.border.c[1], smp.border.c[2], smp.border.c[3]};
    auto load = [&](int index, bool inside) __attribute__((always_inline)) -> wt_f4 {  // texels.texel
        if (address != WT_BORDER) return wt_stored_texel(tex, index);  // only the border mode reads outside
        const wt_f4 t = wt_stored_texel(tex, inside ? (long long)index : 0);
        return inside ? t : border;
    };
    float ru[WT_L], rv[WT_L];
    bool blend = false;  // a lane reads two levels (trilinear)
    for (int l = 0; l < WT_L; ++l) {
        ru[l] = wt_reduce(u[l], address);
        rv[l] = wt_reduce(v[l], address);
        blend |= fraction[l] > 0.0f;
    }
    int index[4][WT_L];
    bool inside[4][WT_L];
    int lw[WT_L], lh[WT_L], ls[WT_L];  // each lane's level's size and offset
    if (smp.filter == WT_NEAREST) {    // filters.sample_nearest
        wt_level_sizes(tex, level, lw, lh, ls);
        for (int l = 0; l < WT_L; ++l) {
            const int w = lw[l], h = lh[l], start = ls[l];
            const int x = wt_address((int)wp::floor(ru[l] * (float)w), w, address);
            const int y = wt_address((int)wp::floor((1.0f - rv[l]) * (float)h), h, address);
            index[0][l] = start + layer[l] * h * w + y * w + x;
            inside[0][l] = address != WT_BORDER || (x >= 0 && y >= 0);  // only the border mode reads outside
        }
        wt_f4 texels[WT_L];
        wt_f4* to = rows ? rows : texels;  // a nearest read's rows are its value
        for (int l = 0; l < WT_L; ++l) to[l] = load(index[0][l], inside[0][l]);
        if (!rows) wt_channels(texels, res);
        if (slopes)
            for (int c = 0; c < 4; ++c) slopes->du[c] = slopes->dv[c] = slopes->dlod[c] = 0.0f;
        return;
    }
    float fx[WT_L], fy[WT_L];
    wt_vf* R = res;                                       // the result's channels
    wt_vf DU[4], DV[4], DLOD[4];                          // with slopes: their channels
    for (int pass = 0; pass < (blend ? 2 : 1); ++pass) {  // the level, then (trilinear) the next one
        int read[WT_L];
        for (int l = 0; l < WT_L; ++l) read[l] = pass == 0 || fraction[l] <= 0.0f ? level[l] : level[l] + 1;
        wt_level_sizes(tex, read, lw, lh, ls);
        for (int l = 0; l < WT_L; ++l) {  // filters.bilinear_taps
            const int w = lw[l], h = lh[l], start = ls[l];
            const int s = start + layer[l] * h * w;
            const float x = ru[l] * (float)w - 0.5f;
            const float y = (1.0f - rv[l]) * (float)h - 0.5f;
            const float x0 = wp::floor(x);
            const float y0 = wp::floor(y);
            const int i0 = wt_address((int)x0, w, address), i1 = wt_address((int)x0 + 1, w, address);
            const int j0 = wt_address((int)y0, h, address), j1 = wt_address((int)y0 + 1, h, address);
            index[0][l] = s + j0 * w + i0;
            index[1][l] = s + j0 * w + i1;
            index[2][l] = s + j1 * w + i0;
            index[3][l] = s + j1 * w + i1;
            inside[0][l] = address != WT_BORDER || (i0 >= 0 && j0 >= 0);
            inside[1][l] = address != WT_BORDER || (i1 >= 0 && j0 >= 0);
            inside[2][l] = address != WT_BORDER || (i0 >= 0 && j1 >= 0);
            inside[3][l] = address != WT_BORDER || (i1 >= 0 && j1 >= 0);
            fx[l] = x - x0;
            fy[l] = y - y0;
        }
        // filters.sample_bilinear, and the blend of filters.sample_levels, a channel of a lane at a time
        if (rows && !blend && !slopes && tex.texel_format == WT_FLOAT32) {  // the rows as loaded, blended
            // Both loops unrolled: with the taps' loop kept, each texel went to the stack by a 16-byte
            // store and came back four at a time by 64-byte loads that no store could forward.
            wt_f4 t[4][WT_L];
            _Pragma("clang loop unroll(full)") for (int k = 0; k < 4; ++k)
                _Pragma("clang loop unroll(full)") for (int l = 0; l < WT_L; ++l) t[k][l] =
                    load(index[k][l], inside[k][l]);
            wt_vf X, Y;
            __builtin_memcpy(&X, fx, sizeof(X));
            __builtin_memcpy(&Y, fy, sizeof(Y));
            wt_bilinear_quad<0>(t, X, Y, rows);
            wt_bilinear_quad<1>(t, X, Y, rows);
            wt_bilinear_quad<2>(t, X, Y, rows);
            wt_bilinear_quad<3>(t, X, Y, rows);
            return;
        }
        wt_vf taps[4][4], FX, FY;
        for (int k = 0; k < 4; ++k) {
            if (tex.texel_format == WT_UNORM8) {  // a channel of every lane's codes at a time, no transpose
                wt_unorm8_channels(tex, index[k], inside[k], address, border, taps[k]);
                continue;
            }
            wt_f4 t[WT_L];
            _Pragma("clang loop unroll(full)") for (int l = 0; l < WT_L; ++l) t[l] = load(index[k][l], inside[k][l]);
            wt_channels(t, taps[k]);
        }
        __builtin_memcpy(&FX, fx, sizeof(FX));
        __builtin_memcpy(&FY, fy, sizeof(FY));
        const wt_vf GX = 1.0f - FX, GY = 1.0f - FY;
        wt_vf F, W, H;  // with slopes: the fraction, the level's size
        wt_vi clamped;  // and where the biased LOD is inside the sampler's clamp
        if (slopes) {
            __builtin_memcpy(&F, fraction, sizeof(F));
            int sizes[2][WT_L], inside_clamp[WT_L];
            for (int l = 0; l < WT_L; ++l) {
                sizes[0][l] = lw[l], sizes[1][l] = lh[l];
                const float biased = slopes->lod[l] + smp.lod_bias;
                inside_clamp[l] = biased >= smp.min_lod && biased < smp.max_lod ? -1 : 0;
            }
            wt_vi SW, SH;
            __builtin_memcpy(&SW, sizes[0], sizeof(SW));
            __builtin_memcpy(&SH, sizes[1], sizeof(SH));
            __builtin_memcpy(&clamped, inside_clamp, sizeof(clamped));
            W = __builtin_convertvector(SW, wt_vf), H = __builtin_convertvector(SH, wt_vf);
        }
        for (int c = 0; c < 4; ++c) {
            const wt_vf top = taps[0][c] * GX + taps[1][c] * FX;
            const wt_vf bottom = taps[2][c] * GX + taps[3][c] * FX;
            const wt_vf value = top * GY + bottom * FY;
            const wt_vf fine = pass == 0 ? value : R[c];  // pass 1: the finer level's value
            if (pass == 0) {
                R[c] = value;
            } else {
                __builtin_memcpy(&F, fraction, sizeof(F));
                R[c] = wt_sel(F > 0.0f, R[c] * (1.0f - F) + value * F, R[c]);
            }
            if (!slopes) continue;
            const wt_vf du =
                ((taps[1][c] - taps[0][c]) * GY + (taps[3][c] - taps[2][c]) * FY) * W;  // bilinear_derivatives
            const wt_vf dv = (bottom - top) * -H;
            if (pass == 0) {
                DU[c] = du, DV[c] = dv, DLOD[c] = 0.0f;
            } else {  // sample_lod_derivatives' blend of two levels, where a lane reads two
                const wt_vi two = F > 0.0f;
                DLOD[c] = wt_sel(two & clamped, value - fine, DLOD[c]);
                DU[c] = wt_sel(two, DU[c] * (1.0f - F) + du * F, DU[c]);
                DV[c] = wt_sel(two, DV[c] * (1.0f - F) + dv * F, DV[c]);
            }
        }
    }
    if (slopes)
        for (int c = 0; c < 4; ++c) slopes->du[c] = DU[c], slopes->dv[c] = DV[c], slopes->dlod[c] = DLOD[c];
    if (rows) wt_rows_of_channels(res, rows);
}

// wt_sample_levels with the address mode a constant, once per mode. Out of line: the four modes'
// bodies are the bulk of every lane module's code, and a module's many reads call this one copy
// (inlined at each, they multiplied its compile time, for no measured speed).
// twin: filters.sample_levels
template <class Tex, class Smp>
WT_OUTLINE void wt_sample_levels_any(const Tex& tex, const Smp& smp, const float* u, const float* v, const int* level,
                                     const float* fraction, const int* layer, wt_vf* res,
                                     const wt_level_slopes* slopes = nullptr, wt_f4* rows = nullptr) {
    switch (smp.address) {
    case WT_WRAP:
        wt_sample_levels(WT_WRAP, tex, smp, u, v, level, fraction, layer, res, slopes, rows);
        break;
    case WT_CLAMP:
        wt_sample_levels(WT_CLAMP, tex, smp, u, v, level, fraction, layer, res, slopes, rows);
        break;
    case WT_MIRROR:
        wt_sample_levels(WT_MIRROR, tex, smp, u, v, level, fraction, layer, res, slopes, rows);
        break;
    default:
        wt_sample_levels(WT_BORDER, tex, smp, u, v, level, fraction, layer, res, slopes, rows);
        break;
    }
}

// filters.sample_footprint_derivatives of each read lane (weight[l] > 0): (value, d/du, d/dv,
// d/dlod, d/dspread) of its footprint's taps, each tap's sample_lod_derivatives at
// footprint.footprint_uv summed in tap order from 0, then divided by the taps; and from the same
// taps, forward[l], filters.sample_footprint's value (a one-tap footprint's sample itself, else the
// sum times 1 / taps: wt_accumulate_footprint's). Lanes past their taps, not read, or not finite
// read (0, 0) at level 0; a tap not finite gives a NaN value and zero derivatives. A one-tap
// footprint's step is 0 (wt_footprint), so footprint_uv reads at its UV as sample_footprint does.
// Rows of the lanes not read are 0. Lane l reads array layer layer[l]. A channel of every lane at a
// time (per lane pixel, with branches and scalar divides, it was a third of the fit's kept forward
// outside the texel reads); the operations of each element are the scalar block's, so the bits are.
// twin: filters.sample_footprint_derivatives
template <class Tex, class Smp>
WT_INLINE void wt_footprint_slopes(const Tex& tex, const Smp& smp, const int* layer, const float* u, const float* v,
                                   const float* lod, const float* du, const float* dv, const float* taps,
                                   const float* weight, wt_f4* forward, wt_f4* value, wt_f4* d_u, wt_f4* d_v,
                                   wt_f4* d_lod, wt_f4* d_spread) {
    float us[WT_L], vs[WT_L], fractions[WT_L], lods[WT_L];
    int levels[WT_L], layers[WT_L], read[WT_L];
    int most = 0;  // the most taps of a read lane
    for (int l = 0; l < WT_L; ++l) {
        read[l] = weight[l] > 0.0f ? -1 : 0;
        layers[l] = layer[l];
        lods[l] = read[l] ? lod[l] : 0.0f;
        wt_mip_levels(tex, smp, lods[l], levels[l], fractions[l]);
        const int n = read[l] ? (int)taps[l] : 0;  // footprint.footprint_taps
        most = n > most ? n : most;
    }
    wt_vf TAPS, DU, DV;
    __builtin_memcpy(&TAPS, taps, sizeof(TAPS));
    __builtin_memcpy(&DU, du, sizeof(DU));
    __builtin_memcpy(&DV, dv, sizeof(DV));
    wt_vi READ;
    __builtin_memcpy(&READ, read, sizeof(READ));
    const wt_vf zero = 0.0f, nan = __builtin_nanf("");
    wt_vf F[4], V[4], U[4], W[4], L[4], S[4];  // forward, value, d/du, d/dv, d/dlod, d/dspread
    for (int c = 0; c < 4; ++c) F[c] = V[c] = U[c] = W[c] = L[c] = S[c] = zero;
    for (int k = 0; k < most; ++k) {
        float offset[WT_L];
        int tap[WT_L], finite[WT_L];
        for (int l = 0; l < WT_L; ++l) {
            offset[l] = (float)k + 0.5f - 0.5f * taps[l];
            const float tu = u[l] + du[l] * offset[l];  // footprint.footprint_uv, for one tap too
            const float tv = v[l] + dv[l] * offset[l];
            tap[l] = read[l] && k < (int)taps[l] ? -1 : 0;
            finite[l] = __builtin_fabsf(tu) <= wt_float_max && __builtin_fabsf(tv) <= wt_float_max &&
                                __builtin_fabsf(lods[l]) <= wt_float_max
                            ? -1
                            : 0;  // texels.finite_uv_lod
            const bool ok = tap[l] && finite[l];
            us[l] = ok ? tu : 0.0f;
            vs[l] = ok ? tv : 0.0f;
        }
        wt_vf channels[4][4];  // the value, d/du, d/dv, d/dlod
        const wt_level_slopes slopes = {lods, channels[1], channels[2], channels[3]};
        wt_sample_levels_any(tex, smp, us, vs, levels, fractions, layers, channels[0], &slopes);
        wt_vi TAP, FINITE;
        wt_vf OFFSET;
        __builtin_memcpy(&TAP, tap, sizeof(TAP));
        __builtin_memcpy(&FINITE, finite, sizeof(FINITE));
        __builtin_memcpy(&OFFSET, offset, sizeof(OFFSET));
        for (int c = 0; c < 4; ++c) {
            const wt_vf tap_u = wt_sel(FINITE, channels[1][c], zero), tap_v = wt_sel(FINITE, channels[2][c], zero);
            const wt_vf r = wt_sel(FINITE, channels[0][c], nan);
            if (k == 0) F[c] = wt_sel(TAP, r, F[c]);
            V[c] = wt_sel(TAP, V[c] + r, V[c]);
            U[c] = wt_sel(TAP, U[c] + tap_u, U[c]);
            W[c] = wt_sel(TAP, W[c] + tap_v, W[c]);
            L[c] = wt_sel(TAP, L[c] + wt_sel(FINITE, channels[3][c], zero), L[c]);
            S[c] = wt_sel(TAP, S[c] + (tap_u * DU + tap_v * DV) * OFFSET, S[c]);
        }
    }
    const wt_vi SEVERAL = READ & (TAPS != 1.0f);
    const wt_vf inv = 1.0f / TAPS;  // lanes not read may divide by 0: not kept
    for (int c = 0; c < 4; ++c) {
        F[c] = wt_sel(SEVERAL, V[c] * inv, F[c]);
        V[c] = wt_sel(READ, V[c] / TAPS, zero), U[c] = wt_sel(READ, U[c] / TAPS, zero);
        W[c] = wt_sel(READ, W[c] / TAPS, zero), L[c] = wt_sel(READ, L[c] / TAPS, zero);
        S[c] = wt_sel(READ, S[c] / TAPS, zero);
    }
    wt_rows_of_channels(F, forward);
    wt_rows_of_channels(V, value);
    wt_rows_of_channels(U, d_u);
    wt_rows_of_channels(W, d_v);
    wt_rows_of_channels(L, d_lod);
    wt_rows_of_channels(S, d_spread);
}

// filters.sample_footprint of each read lane (weight > 0): one tap reads (u, v) itself; a footprint
// of several taps (the anisotropic filter's) the mean of its taps at footprint.footprint_uv, summed
// in tap order, times 1 / taps. Lanes past their taps, not read, or not finite read (0, 0) at level
// 0. Into out: out[l] + weight[l] · sample where add (a blend of reads), the sample itself where
// not; the other lanes' rows as they are. With sampled (not null), also each read lane's sample
// itself there, 0 in the other lanes' rows: what a kept forward keeps of a read it adds.
// twin: filters.sample_footprint
template <class Tex, class Smp>
WT_INLINE void wt_accumulate_footprint(const Tex& tex, const Smp& smp, const int* layers, const float* u,
                                       const float* v, const float* lod, const float* du, const float* dv,
                                       const float* taps, const float* weight, int add, wt_lane_colours& out,
                                       wt_lane_colours* sampled = nullptr) {
    float us[WT_L], vs[WT_L], fractions[WT_L];
    int levels[WT_L], layer[WT_L];
    bool read[WT_L];
    int most = 0;  // the most taps of a read lane
    for (int l = 0; l < WT_L; ++l) {
        read[l] = weight[l] > 0.0f;
        layer[l] =
            read[l] ? wp::clamp(layers[l], 0, tex.num_layers - 1) : 0;  // valid (the API checks), clamped all the same
        wt_mip_levels(tex, smp, read[l] ? lod[l] : 0.0f, levels[l], fractions[l]);
        const int n = read[l] ? (int)taps[l] : 0;  // footprint.footprint_taps
        most = n > most ? n : most;
    }
    // A channel of every lane at a time: the taps' sum T and a one-tap footprint's sample itself S
    // (per lane pixel, with branches and a scalar divide, it measured 4-5% of a splat's time)
    wt_vf T[4] = {0.0f, 0.0f, 0.0f, 0.0f}, S[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    for (int k = 0; k < most; ++k) {
        int tap[WT_L], ok_lod[WT_L];  // masks: the lane reads tap k; its UV and LOD are finite
        for (int l = 0; l < WT_L; ++l) {
            const bool one = taps[l] == 1.0f;
            const float s = (float)k + 0.5f - 0.5f * taps[l];
            const float tu = one ? u[l] : u[l] + du[l] * s;  // footprint.footprint_uv
            const float tv = one ? v[l] : v[l] + dv[l] * s;
            const bool t = read[l] && k < (int)taps[l];
            const bool f = __builtin_fabsf(tu) <= wt_float_max && __builtin_fabsf(tv) <= wt_float_max &&
                           __builtin_fabsf(lod[l]) <= wt_float_max;  // texels.finite_uv_lod
            tap[l] = t ? -1 : 0;
            ok_lod[l] = f ? -1 : 0;
            us[l] = t && f ? tu : 0.0f;
            vs[l] = t && f ? tv : 0.0f;
        }
        wt_vf R[4];
        wt_sample_levels_any(tex, smp, us, vs, levels, fractions, layer, R);
        wt_vi TAP, FINITE;
        __builtin_memcpy(&TAP, tap, sizeof(TAP));
        __builtin_memcpy(&FINITE, ok_lod, sizeof(FINITE));
        for (int c = 0; c < 4; ++c) {
            const wt_vf r = wt_sel(FINITE, R[c], (wt_vf)__builtin_nanf(""));
            if (k == 0) S[c] = r;
            T[c] = wt_sel(TAP, T[c] + r, T[c]);
        }
    }
    wt_vf TAPS, W;
    __builtin_memcpy(&TAPS, taps, sizeof(TAPS));
    __builtin_memcpy(&W, weight, sizeof(W));
    const wt_vi READ = W > 0.0f, ONE = TAPS == 1.0f;
    const wt_vf inv = 1.0f / TAPS;  // lanes not read may divide by 0: not kept
    wt_f4 rows[WT_L];
    __builtin_memcpy(rows, out.data, sizeof(rows));
    wt_vf O[4], K[4];
    wt_channels(rows, O);
    for (int c = 0; c < 4; ++c) {
        const wt_vf r = wt_sel(ONE, S[c], T[c] * inv);
        O[c] = wt_sel(READ, add ? O[c] + W * r : r, O[c]);
        K[c] = wt_sel(READ, r, (wt_vf)0.0f);
    }
    wt_rows_of_channels(O, rows);
    __builtin_memcpy(out.data, rows, sizeof(rows));
    if (sampled) {
        wt_rows_of_channels(K, rows);
        __builtin_memcpy(sampled->data, rows, sizeof(rows));
    }
}

// lanes.accumulate_footprint_lane: acc with each read lane's sample over its footprint added (or in place).
template <class Tex, class Smp, class Ints, class Floats, class Colours>
WT_INLINE wt_lane_colours wt_accumulate_footprint_lane(const Tex& tex, const Smp& smp, const Ints& layers,
                                                       const Floats& u, const Floats& v, const Floats& lod,
                                                       const Floats& du, const Floats& dv, const Floats& taps,
                                                       const Floats& weight, int add, const Colours& acc) {
    wt_lane_colours out = acc;
    wt_accumulate_footprint(tex, smp, layers.c, u.c, v.c, lod.c, du.c, dv.c, taps.c, weight.c, add, out);
    return out;
}

// Writes sample r (a wt_f4) into row base + l of out (texels.write_channels), l < count.
// twin: texels.write_channels
template <class A> WT_INLINE void wt_write_row(const A& out, int row_index, const wt_f4& r) {
    char* row = (char*)out.data + (long long)row_index * out.strides[0];
    const int channels = out.shape[1];
    if (channels == 4 && out.strides[1] == 4) {
        __builtin_memcpy(row, &r, 16);
    } else {
        for (int c = 0; c < channels; ++c) *(float*)(row + (long long)c * out.strides[1]) = r[c];
    }
}

// Outputs of at least this many bytes are written by streaming stores (wt_store_lane).
#define WT_STREAM_BYTES (4ll << 20)

// Whether a whole lane's rows (count == WT_L) of out are packed RGBA floats, 16 bytes a row.
template <class A> WT_INLINE bool wt_packed_lane(const A& out, int count) {
    return count == WT_L && out.shape[1] == 4 && out.strides[1] == 4 && out.strides[0] == 16;
}

// A whole lane's rows (wt_packed_lane) into rows base .. base + WT_L - 1 of out: one copy, or, where
// out is WT_STREAM_BYTES or more and the rows start a cache line, four streaming stores of a line
// each. For `sample`'s lanes, which are bound by memory: a large output is read back long after its
// lanes wrote it, if at all, and streamed, its lines neither are read before they are written nor
// take the cache's place of the texels. Bilinear forward, 2 threads, 2^20 random UVs of a 2048²
// unorm8 texture (16 MB): 8.25-10.39 -> 7.25-8.10 ms (three interleaved pairs). The lanes of the
// other techniques copy (wt_write_lane): streamed, the stochastic sphere rows went from 13.1 to
// 15.3-15.7 ms on 2 threads (hash4; cheap2 and hex alike), for a reason not found. Streaming
// stores are weakly ordered: the end of a launch reaches the threads that read its output through
// locked instructions (the thread pool's locks), which drain the write-combining buffers. An
// sfence a lane cost more than the stores saved (sphere 3.4 -> 4.4 ms).
template <class A> WT_INLINE void wt_store_lane(const A& out, int base, const void* rows) {
    char* to = (char*)out.data + (long long)base * 16;
    if (out.shape[0] * 16ll >= WT_STREAM_BYTES && ((unsigned long long)to & 63) == 0) {
        wt_vf lines[4];
        __builtin_memcpy(lines, rows, sizeof(lines));
        for (int k = 0; k < 4; ++k) __builtin_nontemporal_store(lines[k], (wt_vf*)to + k);
        return;
    }
    __builtin_memcpy(to, rows, 16 * WT_L);
}

// lanes.sample.write_lane: rows base .. base + count - 1 of out, the lane's rows of value (one copy
// a row where out's rows are packed RGBA; Warp's element stores, a branch a channel, were 6% of a
// biplanar forward).
// twin: texels.write_channels
template <class A> WT_INLINE void wt_write_lane(const A& out, int base, int count, const wt_lane_colours& value) {
    for (int l = 0; l < count; ++l) {
        wt_f4 r;
        __builtin_memcpy(&r, value.data[l], 16);
        wt_write_row(out, base + l, r);
    }
}

// lanes.sample.write_covered_lane: wt_write_lane of the rows of the lane's pixels whose mask row is
// not 0, and 0 in the others' rows.
// twin: texels.write_channels
template <class A, class Mask> WT_INLINE void wt_write_covered_lane(const A& out, int base, int count,
                                                                    const wt_lane_colours& value, const Mask& mask) {
    for (int l = 0; l < count; ++l) {
        wt_f4 r = 0.0f;
        if (wt_float(mask, base + l) != 0.0f) __builtin_memcpy(&r, value.data[l], 16);
        wt_write_row(out, base + l, r);
    }
}

// What a lane of `sample` reads (sampling.sample_footprint_of and texels.resolve_layer for the
// lane's pixels base .. base + count - 1; the tail repeats pixel base and is not read): read 0 of a
// lane_reads matrix (weight 1), and each pixel's layer (clamped where it is read).
struct wt_sample_reads {
    int count;
    int layer[WT_L];
    wt_lane_reads reads;
};
// twin: sampling.sample_footprint_of
template <class Tex, class Smp, class UV, class Lods, class Layers>
WT_INLINE wt_sample_reads wt_sample_reads_of(const Tex& tex, const Smp& smp, const UV& uv, const UV& uv_dx,
                                             const UV& uv_dy, const Lods& lods, const Layers& layers,
                                             int constant_layer, int lod_source, float constant_lod, int base) {
    wt_sample_reads out;
    const int n = uv.shape[0];
    const int count = n - base < WT_L ? n - base : WT_L;
    out.count = count;
    wt_vf U[2];
    wt_row_vectors(uv, base, count, 2, U);
    wt_footprint_lanes fp = {(wt_vf)0.0f, (wt_vf)0.0f, (wt_vf)0.0f, (wt_vf)1.0f};  // footprint.point_footprint(0)
    if (lod_source == WT_LOD_DERIVATIVES) {                                        // footprint.texture_footprint
        wt_vf DX[2], DY[2];
        wt_row_vectors(uv_dx, base, count, 2, DX);
        wt_row_vectors(uv_dy, base, count, 2, DY);
        fp = wt_footprint(smp, DX[0], DX[1], DY[0], DY[1], (float)wt_int(tex.level_width, 0),
                          (float)wt_int(tex.level_height, 0));
    } else if (lod_source == WT_LOD_PER_SAMPLE) {
        wt_vf lod[1];
        wt_row_vectors(lods, base, count, 1, lod);
        fp.lod = lod[0];
    } else if (lod_source == WT_LOD_CONSTANT) {
        fp.lod = constant_lod;
    }
    int in_lane[WT_L];
    for (int l = 0; l < WT_L; ++l) {
        out.layer[l] = layers.shape[0] > 0 ? wt_int(layers, base + (l < count ? l : 0)) : constant_layer;
        in_lane[l] = l < count ? -1 : 0;
    }
    wt_vi read;
    __builtin_memcpy(&read, in_lane, sizeof(read));
    wt_put_read(out.reads, 0, read, U[0], U[1], fp, (wt_vf)1.0f);
    return out;
}

// Asks the memory for the texels of a compact format (float16, unorm8, srgb8) that the lane after
// this one (pixels next .., when there are any) will read at `level`: each pixel's bilinear
// footprint's top row and the row below it (a nearest read is in one of them). A hint, with no
// effect on any value: at random UVs a lane's loads wait on memory, and an out-of-order core cannot
// reach the next lane's loads past this lane's work, so they overlap this lane's instead. (A plain C
// loop over 2^20 random UVs of a 16 MB RGBA8 texture took 0.70x its time with this, on 2 threads
// of a 2-core AMD EPYC host.)
template <class Tex, class UV, class Layers>
WT_INLINE void wt_prefetch_levels_lane(const int address, const Tex& tex, const UV& uv, const Layers& layers,
                                       int constant_layer, int level, int next) {
    const int n = uv.shape[0];
    if (next >= n) return;
    const int count = n - next < WT_L ? n - next : WT_L;
    wt_vf U[2];
    wt_row_vectors(uv, next, count, 2, U);
    const int w = wt_int(tex.level_width, level), h = wt_int(tex.level_height, level);
    const wt_vi finite = wt_finite(U[0]) & wt_finite(U[1]);
    wt_vf ru = wt_sel(finite, U[0], (wt_vf)0.0f), rv = wt_sel(finite, U[1], (wt_vf)0.0f);
    if (address == WT_WRAP) {  // wt_reduce's
        ru -= __builtin_elementwise_floor(ru), rv -= __builtin_elementwise_floor(rv);
    } else if (address == WT_MIRROR) {
        ru -= 2.0f * __builtin_elementwise_floor(0.5f * ru), rv -= 2.0f * __builtin_elementwise_floor(0.5f * rv);
    } else {
        ru = wt_vmin(wt_vmax(ru, (wt_vf)-1.0f), (wt_vf)2.0f), rv = wt_vmin(wt_vmax(rv, (wt_vf)-1.0f), (wt_vf)2.0f);
    }
    // The texel's column and rows, folded into the level as the address modes fold them, to a texel
    // beside it at worst (a wrap at the level's edge): a hint need not be exact.
    wt_vi i = __builtin_convertvector(__builtin_elementwise_floor(ru * (float)w - 0.5f), wt_vi);
    wt_vi j = __builtin_convertvector(__builtin_elementwise_floor((1.0f - rv) * (float)h - 0.5f), wt_vi);
    if (address == WT_MIRROR) i = i >= w ? 2 * w - 1 - i : i, j = j >= h ? 2 * h - 1 - j : j;
    i = __builtin_elementwise_min(__builtin_elementwise_max(i, (wt_vi)0), (wt_vi)(w - 1));
    const wt_vi j0 = __builtin_elementwise_min(__builtin_elementwise_max(j, (wt_vi)0), (wt_vi)(h - 1));
    const wt_vi j1 = __builtin_elementwise_min(j0 + 1, (wt_vi)(h - 1));
    const int start = wt_int(tex.level_offset, level);
    wt_vi first = start + constant_layer * h * w + i;
    if (layers.shape[0] > 0)
        for (int l = 0; l < WT_L; ++l)
            first[l] =
                start + wp::clamp(wt_int(layers, next + (l < count ? l : 0)), 0, tex.num_layers - 1) * h * w + i[l];
    const wt_vi top = first + j0 * w, bottom = first + j1 * w;
    const char* data = (const char*)tex.packed;  // a compact format's texels
    const long long stride = tex.texel_format == WT_FLOAT16 ? 8 : 4;
    int rows[2][WT_L];  // the tail's lanes repeat pixel next's
    __builtin_memcpy(rows[0], &top, sizeof(top));
    __builtin_memcpy(rows[1], &bottom, sizeof(bottom));
    for (int l = 0; l < WT_L; ++l) {
        __builtin_prefetch(data + (long long)rows[0][l] * stride);
        __builtin_prefetch(data + (long long)rows[1][l] * stride);
    }
}

// wt_prefetch_levels_lane with the address mode a constant, once per mode; out of line, as only a
// lane of spread UVs calls it.
template <class Tex, class UV, class Layers>
WT_OUTLINE void wt_prefetch_levels_any(const int address, const Tex& tex, const UV& uv, const Layers& layers,
                                       int constant_layer, int level, int next) {
    switch (address) {
    case WT_WRAP:
        wt_prefetch_levels_lane(WT_WRAP, tex, uv, layers, constant_layer, level, next);
        break;
    case WT_CLAMP:
        wt_prefetch_levels_lane(WT_CLAMP, tex, uv, layers, constant_layer, level, next);
        break;
    case WT_MIRROR:
        wt_prefetch_levels_lane(WT_MIRROR, tex, uv, layers, constant_layer, level, next);
        break;
    default:
        wt_prefetch_levels_lane(WT_BORDER, tex, uv, layers, constant_layer, level, next);
        break;
    }
}

// lanes.sample.sample_levels_lane: out[i] = filters.sample_levels at uv[i] (NaN where it is not
// finite) for the lane's pixels i = base .. (the lane's tail repeats pixel base, not stored).
// twin: filters.sample_levels
template <class Tex, class Smp, class UV, class Layers, class Out>
WT_INLINE void wt_sample_levels_lane(const Tex& tex, const Smp& smp, const UV& uv, const Layers& layers,
                                     int constant_layer, int level, float fraction, const Out& out, int base) {
    const int n = uv.shape[0];
    const int count = n - base < WT_L ? n - base : WT_L;
    float u[WT_L], v[WT_L], fractions[WT_L];
    int levels[WT_L], layer[WT_L];
    bool finite[WT_L];
    float raw[2][WT_L];
    wt_rows(uv, base, count, 2, raw);
    for (int l = 0; l < WT_L; ++l) {  // texels.finite_uv_lod: a non-finite UV reads (0, 0), its output NaN
        // & rather than &&: the branch of && kept this loop scalar where the CPU has no AVX-512
        finite[l] = (__builtin_fabsf(raw[0][l]) <= wt_float_max) & (__builtin_fabsf(raw[1][l]) <= wt_float_max);
        u[l] = finite[l] ? raw[0][l] : 0.0f;
        v[l] = finite[l] ? raw[1][l] : 0.0f;
        levels[l] = level;
        fractions[l] = fraction;
        layer[l] = constant_layer;
    }
    if (layers.shape[0] > 0) {  // texels.resolve_layer
        for (int l = 0; l < WT_L; ++l)
            layer[l] = wp::clamp(wt_int(layers, base + (l < count ? l : 0)), 0, tex.num_layers - 1);
    }
    // The next lane's texels, first, in a compact format, where this lane's first and last pixels
    // are further apart than it has pixels, in the level's rows (random UVs, a minified level): a
    // coherent lane's texels are in the cache or on the hardware prefetcher's stream, and hints for
    // them took 10-25% more time for a cached bilinear lookup. (The spread of all the lane's pixels, or the
    // call inlined, cost a coherent lookup 5 instructions a sample.) float32's 16-byte texels
    // gained nothing from them, and an earlier prefetch of the next lane's rows cost float32 26% on
    // another host (docs/performance.md).
    const float rows = __builtin_fabsf(v[WT_L - 1] - v[0]) * (float)wt_int(tex.level_height, level);
    if (tex.texel_format != WT_FLOAT32 && rows > (float)WT_L)
        wt_prefetch_levels_any(smp.address, tex, uv, layers, constant_layer, level, base + WT_L);
    wt_vf scratch[4];
    alignas(64) wt_f4 result[WT_L];  // rows stored a vector of four at a time
    wt_sample_levels_any(tex, smp, u, v, levels, fractions, layer, scratch, nullptr, result);
    for (int l = 0; l < WT_L; ++l)
        if (!finite[l]) result[l] = __builtin_nanf("");
    if (wt_packed_lane(out, count)) {
        wt_store_lane(out, base, result);
        return;
    }
    for (int l = 0; l < count; ++l) wt_write_row(out, base + l, result[l]);
}

// lanes.sample.sample_footprint_lane: out[i] = filters.sample_footprint at uv[i] over the footprint
// that lod_source gives, for the lane's pixels i = base ...
// twin: filters.sample_footprint
template <class Tex, class Smp, class UV, class Lods, class Layers, class Out>
WT_INLINE void wt_sample_footprint_lane(const Tex& tex, const Smp& smp, const UV& uv, const UV& uv_dx, const UV& uv_dy,
                                        const Lods& lods, const Layers& layers, int constant_layer, int lod_source,
                                        float constant_lod, const Out& out, int base) {
    const wt_sample_reads s =
        wt_sample_reads_of(tex, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);
    const wt_lane_reads& reads = s.reads;
    wt_lane_colours value;
    wt_accumulate_footprint(tex, smp, s.layer, reads.data[0], reads.data[3], reads.data[6], reads.data[12],
                            reads.data[15], reads.data[18], reads.data[9], 0, value);
    if (wt_packed_lane(out, s.count)) {
        wt_store_lane(out, base, value.data);
        return;
    }
    wt_write_lane(out, base, s.count, value);
}
