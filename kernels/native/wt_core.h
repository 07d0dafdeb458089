// What every lane helper shares: the scalar formulas of addressing and mip levels, a value per lane
// pixel as a clang vector (with Warp's wp::max, wp::min, wp::abs... on it, exactly: selects and bit
// operations), reading a lane's rows, transposing a lane's RGBA rows, and each lane's level sizes.
#pragma once
#include "wt_config.h"

typedef float wt_f4 __attribute__((ext_vector_type(4)));
typedef float wt_f8 __attribute__((ext_vector_type(8)));
typedef float wt_vf __attribute__((ext_vector_type(WT_L)));  // a float per lane pixel
typedef int wt_vi __attribute__((ext_vector_type(WT_L)));    // an int (a mask: -1 or 0) per lane pixel
typedef float wt_row[WT_L];
typedef wp::vec_t<2, float> wt_v2;
typedef wp::vec_t<3, float> wt_v3;
typedef wp::vec_t<4, float> wt_v4;
typedef wp::mat_t<3, 3, float> wt_m3;
typedef wp::mat_t<WT_L, 4, float> wt_lane_colours;  // lanes.lane_colours: a row per lane pixel
typedef wp::mat_t<21, WT_L, float> wt_lane_reads;   // lanes.lane_reads
typedef wp::mat_t<14, WT_L, float> wt_lane_taps;    // lanes.lane_taps

constexpr float wt_float_max = 3.4028234663852886e38f;

// Entry `index` of a texture's texel chain, decoded to float32 from its format. A float32 chain is
// contiguous (TextureArray.around refuses any other), so its entries are 16 bytes apart: a constant
// stride saves a multiply per texel read (4-8% of coherent bilinear's time).
// twin: texels.stored_texel
template <class Tex> WT_INLINE wt_f4 wt_stored_texel(const Tex& tex, long long index) {
    wt_f4 t;
    if (tex.texel_format == WT_FLOAT32) {
        __builtin_memcpy(&t, (const char*)tex.texels.data + index * (long long)sizeof(wt_f4), 16);
    } else if (tex.texel_format == WT_FLOAT16) {
        typedef _Float16 wt_h4 __attribute__((ext_vector_type(4)));
        wt_h4 h;
        __builtin_memcpy(&h, (const char*)tex.packed + index * 8, 8);
        t = __builtin_convertvector(h, wt_f4);  // exact: every half is a float
    } else {
        unsigned int p;
        __builtin_memcpy(&p, (const char*)tex.packed + index * 4, 4);
        const float* d = (const float*)tex.decode;
        t = (wt_f4){d[p & 255u], d[256u + ((p >> 8) & 255u)], d[512u + ((p >> 16) & 255u)], d[768u + (p >> 24)]};
    }
    return t;
}

// twin: texels.reduce_coord
WT_INLINE float wt_reduce(float x, const int address) {
    if (address == WT_WRAP) return x - wp::floor(x);
    if (address == WT_MIRROR) return x - 2.0f * wp::floor(0.5f * x);
    return wp::clamp(x, -1.0f, 2.0f);
}

// twin: texels.address_near
WT_INLINE int wt_address(int i, int n, const int address) {
    int r = i;
    if (address == WT_WRAP) {
        if (r < 0)
            r += n;
        else if (r >= n)
            r -= n;
    } else if (address == WT_CLAMP) {
        r = wp::clamp(i, 0, n - 1);
    } else if (address == WT_MIRROR) {
        if (r < 0)
            r = -1 - r;
        else if (r >= 2 * n)
            r -= 2 * n;
        if (r >= n) r = 2 * n - 1 - r;
    } else if (i < 0 || i >= n) {
        r = -1;
    }
    return r;
}

// twin: footprint.mip_levels
template <class Tex, class Smp>
WT_INLINE void wt_mip_levels(const Tex& tex, const Smp& smp, float lod, int& level, float& fraction) {
    const float c =
        wp::clamp(wp::clamp(lod + smp.lod_bias, smp.min_lod, smp.max_lod), 0.0f, (float)(tex.num_levels - 1));
    const bool trilinear = smp.filter >= WT_TRILINEAR;
    level = (int)(trilinear ? wp::floor(c) : wp::floor(c + 0.5f));
    fraction = trilinear ? c - wp::floor(c) : 0.0f;
}

// wp::where(mask, a, b) per lane pixel, by bits.
WT_INLINE wt_vf wt_sel(wt_vi mask, wt_vf a, wt_vf b) { return (wt_vf)(((wt_vi)a & mask) | ((wt_vi)b & ~mask)); }
// wp::max: fmax (a NaN operand gives the other).
WT_INLINE wt_vf wt_vmax(wt_vf a, wt_vf b) { return wt_sel(a >= b, a, wt_sel(b == b, b, a)); }
// wp::min: fmin.
WT_INLINE wt_vf wt_vmin(wt_vf a, wt_vf b) { return wt_sel(a <= b, a, wt_sel(b == b, b, a)); }
// wp::abs
WT_INLINE wt_vf wt_vabs(wt_vf a) { return (wt_vf)((wt_vi)a & 0x7fffffff); }
// wp::isfinite, as a mask
WT_INLINE wt_vi wt_finite(wt_vf a) { return a - a == 0.0f; }
// f (a scalar Warp builtin) lane by lane: the same bits as Warp's one-pixel call
template <typename F> WT_INLINE wt_vf wt_lanewise(wt_vf x, F f) {
    float a[WT_L];
    __builtin_memcpy(a, &x, sizeof(a));
    for (int l = 0; l < WT_L; ++l) a[l] = f(a[l]);
    __builtin_memcpy(&x, a, sizeof(a));
    return x;
}
// wp::sqrt, lane by lane
WT_INLINE wt_vf wt_vsqrt(wt_vf x) {
    return wt_lanewise(x, [](float v) { return wp::sqrt(v); });
}
// wp::ceil, lane by lane
WT_INLINE wt_vf wt_vceil(wt_vf x) {
    return wt_lanewise(x, [](float v) { return wp::ceil(v); });
}

// wt_mip_levels, lane by lane.
// twin: footprint.mip_levels
template <class Tex, class Smp>
WT_INLINE void wt_mip_levels_lane(const Tex& tex, const Smp& smp, wt_vf lod, wt_vi& level, wt_vf& fraction) {
    // wp::clamp(x, a, b) = fmin(fmax(a, x), b)
    const wt_vf clamped = wt_vmin(wt_vmax((wt_vf)smp.min_lod, lod + smp.lod_bias), (wt_vf)smp.max_lod);
    const wt_vf c = wt_vmin(wt_vmax((wt_vf)0.0f, clamped), (wt_vf)(float)(tex.num_levels - 1));
    // c >= 0 (fmax(0, NaN) is 0), so truncation is wp::floor
    if (smp.filter >= WT_TRILINEAR) {
        level = __builtin_convertvector(c, wt_vi);
        fraction = c - __builtin_convertvector(level, wt_vf);
    } else {
        level = __builtin_convertvector(c + 0.5f, wt_vi);
        fraction = 0.0f;
    }
}

// Entry k of an int array.
WT_INLINE int wt_int(const wp::array_t<int>& a, int k) {
    return *(const int*)((const char*)a.data + (long long)k * a.strides[0]);
}

// Entry k of a float array.
template <class A> WT_INLINE float wt_float(const A& a, int k) {
    return *(const float*)((const char*)a.data + (long long)k * a.strides[0]);
}

// Rows base .. base + WT_L - 1 of an array of `dims` floats a row (dims <= 3; the rows past count
// repeat row base) as `dims` arrays of a value per lane pixel. Where the rows are packed (as the
// API's contiguous inputs are) one load, not the gathers LLVM makes of strided rows, and a prefetch
// of the rows 4 lanes on: random texel reads keep the miss buffers full, and the hardware's own
// prefetch of the row stream then falls behind. Together they took a bilinear lookup of 1M random
// UVs (1 thread, interleaved runs) from 16-19 to 7-10 ms and of the benchmark sphere from 5.3 to
// 3.7 ms.
template <class A> WT_INLINE void wt_rows(const A& a, int base, int count, const int dims, wt_row* out) {
    const char* data = (const char*)a.data;
    const long long stride = a.strides[0];
    if (count == WT_L && stride == 4 * dims) {
        for (int b = 0; b < 4 * dims * WT_L; b += 64) __builtin_prefetch(data + (base + 4 * WT_L) * stride + b);
        float packed[3 * WT_L];
        __builtin_memcpy(packed, data + base * stride, 4 * dims * WT_L);
        for (int l = 0; l < WT_L; ++l)
            for (int e = 0; e < dims; ++e) out[e][l] = packed[dims * l + e];
    } else {
        for (int l = 0; l < WT_L; ++l) {
            const float* row = (const float*)(data + (base + (l < count ? l : 0)) * stride);
            for (int e = 0; e < dims; ++e) out[e][l] = row[e];
        }
    }
}

// wt_rows as `dims` vectors.
template <class A> WT_INLINE void wt_row_vectors(const A& a, int base, int count, const int dims, wt_vf* out) {
    wt_row rows[3];
    wt_rows(a, base, count, dims, rows);
    for (int d = 0; d < dims; ++d) __builtin_memcpy(&out[d], rows[d], sizeof(wt_vf));
}

// A lane's RGBA rows (wt_f4 each) as four vectors of a channel per lane pixel, and back: the blends
// then run a lane wide, not a pixel's 4 channels at a time (two-source permutes). WT_Q pixels'
// rows fill one vector (a quad: 4 pixels at 16 lanes, 2 at 8).
static_assert(WT_L == 16 || WT_L == 8, "the transposes below are written for lanes of 16 and 8");
constexpr int WT_Q = WT_L / 4;
// Pixels WT_Q·K .. WT_Q·K + WT_Q - 1 of a lane's RGBA rows t, RGBA each, as one vector: the
// transpose's first step, and what a bilinear blend of rows reads (wt_bilinear_quad).
template <int K> WT_INLINE wt_vf wt_quad(const wt_f4* t) {
#if WT_L == 16
    const wt_f8 lo = __builtin_shufflevector(t[4 * K], t[4 * K + 1], 0, 1, 2, 3, 4, 5, 6, 7);
    const wt_f8 hi = __builtin_shufflevector(t[4 * K + 2], t[4 * K + 3], 0, 1, 2, 3, 4, 5, 6, 7);
    return __builtin_shufflevector(lo, hi, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
#else
    return __builtin_shufflevector(t[2 * K], t[2 * K + 1], 0, 1, 2, 3, 4, 5, 6, 7);
#endif
}
#if WT_L == 16
WT_INLINE void wt_channels(const wt_f4* t, wt_vf* ch) {
    const wt_vf q[4] = {wt_quad<0>(t), wt_quad<1>(t), wt_quad<2>(t), wt_quad<3>(t)};
    const wt_vf rg0 = __builtin_shufflevector(q[0], q[1], 0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29);
    const wt_vf ba0 = __builtin_shufflevector(q[0], q[1], 2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31);
    const wt_vf rg1 = __builtin_shufflevector(q[2], q[3], 0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29);
    const wt_vf ba1 = __builtin_shufflevector(q[2], q[3], 2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31);
    ch[0] = __builtin_shufflevector(rg0, rg1, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    ch[1] = __builtin_shufflevector(rg0, rg1, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
    ch[2] = __builtin_shufflevector(ba0, ba1, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    ch[3] = __builtin_shufflevector(ba0, ba1, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
}
WT_INLINE void wt_rows_of_channels(const wt_vf* ch, wt_f4* t) {
    // r, g of pixels 0 .. 7, then 8 .. 15; b, a likewise
    const wt_vf rg0 = __builtin_shufflevector(ch[0], ch[1], 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    const wt_vf rg1 =
        __builtin_shufflevector(ch[0], ch[1], 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
    const wt_vf ba0 = __builtin_shufflevector(ch[2], ch[3], 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    const wt_vf ba1 =
        __builtin_shufflevector(ch[2], ch[3], 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
    wt_vf q[4];
    q[0] = __builtin_shufflevector(rg0, ba0, 0, 8, 16, 24, 1, 9, 17, 25, 2, 10, 18, 26, 3, 11, 19, 27);
    q[1] = __builtin_shufflevector(rg0, ba0, 4, 12, 20, 28, 5, 13, 21, 29, 6, 14, 22, 30, 7, 15, 23, 31);
    q[2] = __builtin_shufflevector(rg1, ba1, 0, 8, 16, 24, 1, 9, 17, 25, 2, 10, 18, 26, 3, 11, 19, 27);
    q[3] = __builtin_shufflevector(rg1, ba1, 4, 12, 20, 28, 5, 13, 21, 29, 6, 14, 22, 30, 7, 15, 23, 31);
    for (int k = 0; k < 4; ++k) {
        t[4 * k] = __builtin_shufflevector(q[k], q[k], 0, 1, 2, 3);
        t[4 * k + 1] = __builtin_shufflevector(q[k], q[k], 4, 5, 6, 7);
        t[4 * k + 2] = __builtin_shufflevector(q[k], q[k], 8, 9, 10, 11);
        t[4 * k + 3] = __builtin_shufflevector(q[k], q[k], 12, 13, 14, 15);
    }
}

#else
WT_INLINE void wt_channels(const wt_f4* t, wt_vf* ch) {
    const wt_vf q[4] = {wt_quad<0>(t), wt_quad<1>(t), wt_quad<2>(t), wt_quad<3>(t)};
    const wt_vf rg0 = __builtin_shufflevector(q[0], q[1], 0, 4, 8, 12, 1, 5, 9, 13);
    const wt_vf ba0 = __builtin_shufflevector(q[0], q[1], 2, 6, 10, 14, 3, 7, 11, 15);
    const wt_vf rg1 = __builtin_shufflevector(q[2], q[3], 0, 4, 8, 12, 1, 5, 9, 13);
    const wt_vf ba1 = __builtin_shufflevector(q[2], q[3], 2, 6, 10, 14, 3, 7, 11, 15);
    ch[0] = __builtin_shufflevector(rg0, rg1, 0, 1, 2, 3, 8, 9, 10, 11);
    ch[1] = __builtin_shufflevector(rg0, rg1, 4, 5, 6, 7, 12, 13, 14, 15);
    ch[2] = __builtin_shufflevector(ba0, ba1, 0, 1, 2, 3, 8, 9, 10, 11);
    ch[3] = __builtin_shufflevector(ba0, ba1, 4, 5, 6, 7, 12, 13, 14, 15);
}
WT_INLINE void wt_rows_of_channels(const wt_vf* ch, wt_f4* t) {
    // r, g of pixels 0 .. 3, then 4 .. 7; b, a likewise
    const wt_vf rg0 = __builtin_shufflevector(ch[0], ch[1], 0, 1, 2, 3, 8, 9, 10, 11);
    const wt_vf rg1 = __builtin_shufflevector(ch[0], ch[1], 4, 5, 6, 7, 12, 13, 14, 15);
    const wt_vf ba0 = __builtin_shufflevector(ch[2], ch[3], 0, 1, 2, 3, 8, 9, 10, 11);
    const wt_vf ba1 = __builtin_shufflevector(ch[2], ch[3], 4, 5, 6, 7, 12, 13, 14, 15);
    wt_vf q[4];
    q[0] = __builtin_shufflevector(rg0, ba0, 0, 4, 8, 12, 1, 5, 9, 13);
    q[1] = __builtin_shufflevector(rg0, ba0, 2, 6, 10, 14, 3, 7, 11, 15);
    q[2] = __builtin_shufflevector(rg1, ba1, 0, 4, 8, 12, 1, 5, 9, 13);
    q[3] = __builtin_shufflevector(rg1, ba1, 2, 6, 10, 14, 3, 7, 11, 15);
    for (int k = 0; k < 4; ++k) {
        t[2 * k] = __builtin_shufflevector(q[k], q[k], 0, 1, 2, 3);
        t[2 * k + 1] = __builtin_shufflevector(q[k], q[k], 4, 5, 6, 7);
    }
}
#endif

// The size (w, h) and offset of each lane's level k[l] of tex; read once where every lane reads
// one level, as neighbouring pixels mostly do (per lane, the reads are AVX-512 gathers).
// Whether every lane reads one level is asked of the whole vector: a loop over k[1..] compiled to
// loads straddling the vector stores that had just written k, a store-forwarding stall per call.
template <class Tex> WT_INLINE void wt_level_sizes(const Tex& tex, const int* k, int* w, int* h, int* start) {
    wt_vi K;
    __builtin_memcpy(&K, k, sizeof(K));
    const bool one = !__builtin_reduce_or(K ^ k[0]);
    if (one) {
        const int w0 = wt_int(tex.level_width, k[0]), h0 = wt_int(tex.level_height, k[0]),
                  start0 = wt_int(tex.level_offset, k[0]);
        for (int l = 0; l < WT_L; ++l) w[l] = w0, h[l] = h0, start[l] = start0;
        return;
    }
#if defined(__AVX512F__) && WT_L == 16
    // Up to 16 levels (a 32768² texture has 16): each table in one register, a lane's entry picked
    // by a permute (the loop below compiles to gathers, slow on AMD's AVX-512).
    if (tex.num_levels <= 16 && tex.level_width.strides[0] == 4 && tex.level_height.strides[0] == 4 &&
        tex.level_offset.strides[0] == 4) {
        typedef int g16 __attribute__((vector_size(64)));
        const unsigned short mask = (unsigned short)((1u << tex.num_levels) - 1u);  // no entry past the tables
        const g16 zero = {}, index = (g16)K;
        const g16 W = __builtin_ia32_permvarsi512(
            __builtin_ia32_loaddqusi512_mask((const int*)tex.level_width.data, zero, mask), index);
        const g16 H = __builtin_ia32_permvarsi512(
            __builtin_ia32_loaddqusi512_mask((const int*)tex.level_height.data, zero, mask), index);
        const g16 S = __builtin_ia32_permvarsi512(
            __builtin_ia32_loaddqusi512_mask((const int*)tex.level_offset.data, zero, mask), index);
        __builtin_memcpy(w, &W, sizeof(W));
        __builtin_memcpy(h, &H, sizeof(H));
        __builtin_memcpy(start, &S, sizeof(S));
        return;
    }
#endif
    for (int l = 0; l < WT_L; ++l)
        w[l] = wt_int(tex.level_width, k[l]), h[l] = wt_int(tex.level_height, k[l]),
        start[l] = wt_int(tex.level_offset, k[l]);
}

// Whether each of the lane's count pixels is covered (its mask row != 0), as a mask per lane pixel.
WT_INLINE wt_vi wt_covered(const float* mask, int count) {
    int c[WT_L];
    for (int l = 0; l < WT_L; ++l) c[l] = l < count && mask[l] != 0.0f ? -1 : 0;
    wt_vi covered;
    __builtin_memcpy(&covered, c, sizeof(covered));
    return covered;
}

// Rows base .. base + count - 1 of a 2-D float array set to 0 (one memset where the rows are
// packed: Warp's element stores took 77 ns a lane of 16 RGBA rows).
// twin: family.zero_rows
template <class A> WT_INLINE void wt_zero_rows(const A& out, int base, int count) {
    char* row = (char*)out.data + (long long)base * out.strides[0];
    const int channels = out.shape[1];
    if (out.strides[1] == 4 && out.strides[0] == 4 * channels) {
        __builtin_memset(row, 0, (size_t)count * channels * 4);
    } else {
        for (int l = 0; l < count; ++l, row += out.strides[0])
            for (int c = 0; c < channels; ++c) *(float*)(row + (long long)c * out.strides[1]) = 0.0f;
    }
}

// texels.read_channels of row k of a 2-D float array (up to 4 channels; the rest 0).
// twin: texels.read_channels
template <class A> WT_INLINE wt_f4 wt_read_channels(const A& a, int k) {
    wt_f4 r = {0.0f, 0.0f, 0.0f, 0.0f};
    const char* row = (const char*)a.data + (long long)k * a.strides[0];
    for (int c = 0; c < a.shape[1] && c < 4; ++c) r[c] = *(const float*)(row + (long long)c * a.strides[1]);
    return r;
}
