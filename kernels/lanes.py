"""CPU lanes: native helpers that compute a lane of :data:`LANES` pixels at once.

Warp compiles a CPU launch as a scalar loop, one launch index at a time, and LLVM does not
vectorise across indices (Warp issues #1309, #1358, #1954): rewriting a scalar body as an unrolled
loop over 16 pixels inside one Warp launch index measured no faster here. A ``wp.func_native``
helper written for a lane, in phases, is: its UV arithmetic runs 16 lanes wide in SIMD registers,
and all the texel addresses of a lane are known before the first load, so the loads overlap.

Each helper computes *exactly* what the scalar ``@wp.func`` blocks it stands for compute, operation
for operation and in the same order (no contraction into fused multiply-adds: ``fp contract(off)``;
Warp's own ``wp::floor`` and ``wp::clamp``), so a lane's outputs are the scalar kernel's bits;
``tests/test_lanes.py`` checks that in every filter, address mode, level and layer case. Only the
CPU compiles a body: on CUDA the helpers are empty and never launched (one pixel per thread there,
from the scalar kernels).

The lane kernels themselves are made by :func:`warptex.kernels.family.lane_kernel`; a technique's
lane body (a ``@wp.func``) reads its pixels, calls these helpers and writes its outputs. The
texel-gradient twins of these helpers are in :mod:`.lane_scatter`.
"""

import warp as wp

from .footprint import LOG2_CPP
from .texels import SamplerArgs, TextureView

#: Pixels per lane: one launch index of a lane kernel computes pixels ``LANES·t .. LANES·t + LANES - 1``
#: (fewer in a launch's last lane). 16 float32 lanes fill an AVX-512 register.
LANES = 16

#: A lane of floats or ints (one per pixel), and a lane of RGBA values (a row per pixel).
lane_floats = wp.types.vector(length=LANES, dtype=wp.float32)
lane_ints = wp.types.vector(length=LANES, dtype=wp.int32)
lane_colours = wp.types.matrix(shape=(LANES, 4), dtype=wp.float32)
#: Per read (up to 3 per pixel: a triplanar pixel's projections) and lane pixel (column), what is read:
#: rows ``3 q + r`` of read ``r``'s UV ``u`` (``q = 0``) and ``v`` (1), its LOD (2), its weight (3; 0:
#: not read) and the rest of its footprint (footprint.py): step ``u`` (4), step ``v`` (5), taps (6).
lane_reads = wp.types.matrix(shape=(21, LANES), dtype=wp.float32)
#: Per lane pixel (column), a stochastic lookup's four taps: rows ``3 k``, ``3 k + 1`` tap ``k``'s UV,
#: ``3 k + 2`` its weight (0: not read), 12 the pixel's LOD, 13 whether its UV and LOD are finite (1, 0).
lane_taps = wp.types.matrix(shape=(14, LANES), dtype=wp.float32)

# What every helper shares: the scalar formulas of texels.reduce_coord, texels.address_near,
# footprint.mip_levels and filters.sample_levels, written for the lane (same ADDRESS_* and FILTER_*
# constants as texels.py).
_CORE = r"""
#pragma clang fp contract(off)
typedef float wt_f4 __attribute__((ext_vector_type(4)));
enum { WT_L = %(lanes)d, WT_WRAP = 0, WT_CLAMP = 1, WT_MIRROR = 2, WT_BORDER = 3, WT_NEAREST = 0, WT_TRILINEAR = 2, WT_ANISOTROPIC = 3 };
const float wt_float_max = 3.4028234663852886e38f;
auto wt_reduce = [](float x, const int address) __attribute__((always_inline)) -> float {  // texels.reduce_coord
    if (address == WT_WRAP) return x - wp::floor(x);
    if (address == WT_MIRROR) return x - 2.0f * wp::floor(0.5f * x);
    return wp::clamp(x, -1.0f, 2.0f);
};
auto wt_address = [](int i, int n, const int address) __attribute__((always_inline)) -> int {  // texels.address_near
    int r = i;
    if (address == WT_WRAP) {
        if (r < 0) r += n;
        else if (r >= n) r -= n;
    } else if (address == WT_CLAMP) {
        r = wp::clamp(i, 0, n - 1);
    } else if (address == WT_MIRROR) {
        if (r < 0) r = -1 - r;
        else if (r >= 2 * n) r -= 2 * n;
        if (r >= n) r = 2 * n - 1 - r;
    } else if (i < 0 || i >= n) {
        r = -1;
    }
    return r;
};
auto wt_mip_levels = [](const auto& tex, const auto& smp, float lod, int& level, float& fraction) __attribute__((always_inline)) {  // footprint.mip_levels
    const float c = wp::clamp(wp::clamp(lod + smp.lod_bias, smp.min_lod, smp.max_lod), 0.0f, (float)(tex.num_levels - 1));
    const bool trilinear = smp.filter >= WT_TRILINEAR;
    level = (int)(trilinear ? wp::floor(c) : wp::floor(c + 0.5f));
    fraction = trilinear ? c - wp::floor(c) : 0.0f;
};
// A value per lane pixel as a clang vector, and Warp's wp::max, wp::min, wp::abs, wp::isfinite on it,
// exactly (selects and bit operations; a comparison gives a mask, -1 or 0, per lane pixel).
typedef float wt_vf __attribute__((ext_vector_type(WT_L)));
typedef int wt_vi __attribute__((ext_vector_type(WT_L)));
auto wt_sel = [](wt_vi mask, wt_vf a, wt_vf b) __attribute__((always_inline)) -> wt_vf { return (wt_vf)(((wt_vi)a & mask) | ((wt_vi)b & ~mask)); };
auto wt_vmax = [&](wt_vf a, wt_vf b) __attribute__((always_inline)) -> wt_vf { return wt_sel(a >= b, a, wt_sel(b == b, b, a)); };
auto wt_vmin = [&](wt_vf a, wt_vf b) __attribute__((always_inline)) -> wt_vf { return wt_sel(a <= b, a, wt_sel(b == b, b, a)); };
auto wt_vabs = [](wt_vf a) __attribute__((always_inline)) -> wt_vf { return (wt_vf)((wt_vi)a & 0x7fffffff); };
auto wt_finite = [](wt_vf a) __attribute__((always_inline)) -> wt_vi { return a - a == 0.0f; };
auto wt_vsqrt = [](wt_vf x) __attribute__((always_inline)) -> wt_vf { float a[WT_L]; __builtin_memcpy(a, &x, sizeof(a)); for (int l = 0; l < WT_L; ++l) a[l] = wp::sqrt(a[l]); __builtin_memcpy(&x, a, sizeof(a)); return x; };
auto wt_mip_levels_lane = [&](const auto& tex, const auto& smp, wt_vf lod, wt_vi& level, wt_vf& fraction) __attribute__((always_inline)) {  // wt_mip_levels, lane by lane
    const wt_vf clamped = wt_vmin(wt_vmax((wt_vf)smp.min_lod, lod + smp.lod_bias), (wt_vf)smp.max_lod);  // wp::clamp(x, a, b) = fmin(fmax(a, x), b)
    const wt_vf c = wt_vmin(wt_vmax((wt_vf)0.0f, clamped), (wt_vf)(float)(tex.num_levels - 1));
    // c >= 0 (fmax(0, NaN) is 0), so truncation is wp::floor
    if (smp.filter >= WT_TRILINEAR) {
        level = __builtin_convertvector(c, wt_vi);
        fraction = c - __builtin_convertvector(level, wt_vf);
    } else {
        level = __builtin_convertvector(c + 0.5f, wt_vi);
        fraction = 0.0f;
    }
};
auto wt_int = [](const wp::array_t<int>& a, int k) __attribute__((always_inline)) -> int {
    return *(const int*)((const char*)a.data + (long long)k * a.strides[0]);
};
// Rows base .. base + WT_L - 1 of an array of `dims` floats a row (dims <= 3; the rows past count
// repeat row base) as `dims` arrays of a value per lane pixel. Where the rows are packed (as the API's
// contiguous inputs are) one load, not the gathers LLVM makes of strided rows, and a prefetch of the
// rows 4 lanes on: random texel reads keep the miss buffers full, and the hardware's own prefetch of
// the row stream then falls behind. Together they took a bilinear lookup of 1M random UVs (1 thread,
// interleaved runs) from 16-19 to 7-10 ms and of the benchmark sphere from 5.3 to 3.7 ms.
typedef float wt_row[WT_L];
auto wt_rows = [](const auto& a, int base, int count, const int dims, wt_row* out) __attribute__((always_inline)) {
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
};
// Sixteen RGBA rows (a lane's texels) as four vectors of a channel per lane pixel, and back: the
// blends then run 16 pixels wide, not a pixel's 4 channels at a time (two-source permutes).
typedef float wt_f8 __attribute__((ext_vector_type(8)));
static_assert(WT_L == 16, "the transposes below are written for lanes of 16");
auto wt_channels = [](const wt_f4* t, wt_vf* ch) __attribute__((always_inline)) {
    wt_vf q[4];  // pixels 4k .. 4k + 3, RGBA each
    for (int k = 0; k < 4; ++k) {
        const wt_f8 lo = __builtin_shufflevector(t[4 * k], t[4 * k + 1], 0, 1, 2, 3, 4, 5, 6, 7);
        const wt_f8 hi = __builtin_shufflevector(t[4 * k + 2], t[4 * k + 3], 0, 1, 2, 3, 4, 5, 6, 7);
        q[k] = __builtin_shufflevector(lo, hi, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    }
    const wt_vf rg0 = __builtin_shufflevector(q[0], q[1], 0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29);
    const wt_vf ba0 = __builtin_shufflevector(q[0], q[1], 2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31);
    const wt_vf rg1 = __builtin_shufflevector(q[2], q[3], 0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29);
    const wt_vf ba1 = __builtin_shufflevector(q[2], q[3], 2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31);
    ch[0] = __builtin_shufflevector(rg0, rg1, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    ch[1] = __builtin_shufflevector(rg0, rg1, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
    ch[2] = __builtin_shufflevector(ba0, ba1, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    ch[3] = __builtin_shufflevector(ba0, ba1, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
};
auto wt_rows_of_channels = [](const wt_vf* ch, wt_f4* t) __attribute__((always_inline)) {
    const wt_vf rg0 = __builtin_shufflevector(ch[0], ch[1], 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);  // r, g of pixels 0 .. 7
    const wt_vf rg1 = __builtin_shufflevector(ch[0], ch[1], 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
    const wt_vf ba0 = __builtin_shufflevector(ch[2], ch[3], 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23);
    const wt_vf ba1 = __builtin_shufflevector(ch[2], ch[3], 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
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
};
// The size (w, h) and offset of each lane's level k[l] of tex; read once where every lane reads one
// level, as neighbouring pixels mostly do (per lane, the reads are AVX-512 gathers).
auto wt_level_sizes = [&](const auto& tex, const int* k, int* w, int* h, int* start) __attribute__((always_inline)) {
    bool one = true;
    for (int l = 0; l < WT_L; ++l) one &= k[l] == k[0];
    if (one) {
        const int w0 = wt_int(tex.level_width, k[0]), h0 = wt_int(tex.level_height, k[0]), start0 = wt_int(tex.level_offset, k[0]);
        for (int l = 0; l < WT_L; ++l) w[l] = w0, h[l] = h0, start[l] = start0;
    } else {
        for (int l = 0; l < WT_L; ++l) w[l] = wt_int(tex.level_width, k[l]), h[l] = wt_int(tex.level_height, k[l]), start[l] = wt_int(tex.level_offset, k[l]);
    }
};
// res[l] = filters.sample_levels(tex, layer[l], (u[l], v[l]), level[l], fraction[l], smp) for every
// lane. Each level read is cut in two: every lane's addresses and weights, then every lane's loads,
// so that the loads are in flight together. Compiled once per address mode (below).
auto wt_sample_levels = [&](const int address, const auto& tex, const auto& smp, const float* u, const float* v, const int* level, const float* fraction, const int* layer, wt_f4* res) __attribute__((always_inline)) {
    const char* tb = (const char*)tex.texels.data;
    const long long ts = tex.texels.strides[0];
    const wt_f4 border = {smp.border.c[0], smp.border.c[1], smp.border.c[2], smp.border.c[3]};
    auto load = [&](int index, bool inside) __attribute__((always_inline)) -> wt_f4 {  // texels.texel
        wt_f4 t;
        if (address != WT_BORDER) {  // only the border mode reads outside
            __builtin_memcpy(&t, tb + (long long)index * ts, 16);
            return t;
        }
        __builtin_memcpy(&t, tb + (inside ? (long long)index : 0) * ts, 16);
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
    if (smp.filter == WT_NEAREST) {  // filters.sample_nearest
        wt_level_sizes(tex, level, lw, lh, ls);
        for (int l = 0; l < WT_L; ++l) {
            const int w = lw[l], h = lh[l], start = ls[l];
            const int x = wt_address((int)wp::floor(ru[l] * (float)w), w, address);
            const int y = wt_address((int)wp::floor((1.0f - rv[l]) * (float)h), h, address);
            index[0][l] = start + layer[l] * h * w + y * w + x;
            inside[0][l] = address != WT_BORDER || (x >= 0 && y >= 0);  // only the border mode reads outside
        }
        for (int l = 0; l < WT_L; ++l) res[l] = load(index[0][l], inside[0][l]);
        return;
    }
    float fx[WT_L], fy[WT_L];
    wt_vf R[4];  // the result's channels
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
        // filters.sample_bilinear, and the blend of filters.sample_levels, a channel of 16 pixels at a time
        wt_vf taps[4][4], FX, FY;
        for (int k = 0; k < 4; ++k) {
            wt_f4 t[WT_L];
            _Pragma("clang loop unroll(full)") for (int l = 0; l < WT_L; ++l) t[l] = load(index[k][l], inside[k][l]);
            wt_channels(t, taps[k]);
        }
        __builtin_memcpy(&FX, fx, sizeof(FX));
        __builtin_memcpy(&FY, fy, sizeof(FY));
        const wt_vf GX = 1.0f - FX, GY = 1.0f - FY;
        for (int c = 0; c < 4; ++c) {
            const wt_vf top = taps[0][c] * GX + taps[1][c] * FX;
            const wt_vf bottom = taps[2][c] * GX + taps[3][c] * FX;
            const wt_vf value = top * GY + bottom * FY;
            if (pass == 0) {
                R[c] = value;
            } else {
                wt_vf F;
                __builtin_memcpy(&F, fraction, sizeof(F));
                R[c] = wt_sel(F > 0.0f, R[c] * (1.0f - F) + value * F, R[c]);
            }
        }
    }
    wt_rows_of_channels(R, res);
};
// wt_sample_levels with the address mode a constant, once per mode (a mode tested per texel
// measured slower).
auto wt_sample_levels_any = [&](const auto& tex, const auto& smp, const float* u, const float* v, const int* level, const float* fraction, const int* layer, wt_f4* res) __attribute__((always_inline)) {
    switch (smp.address) {
        case WT_WRAP: wt_sample_levels(WT_WRAP, tex, smp, u, v, level, fraction, layer, res); break;
        case WT_CLAMP: wt_sample_levels(WT_CLAMP, tex, smp, u, v, level, fraction, layer, res); break;
        case WT_MIRROR: wt_sample_levels(WT_MIRROR, tex, smp, u, v, level, fraction, layer, res); break;
        default: wt_sample_levels(WT_BORDER, tex, smp, u, v, level, fraction, layer, res); break;
    }
};
// filters.sample_footprint of each read lane (weight > 0): one tap reads (u, v) itself; a footprint
// of several taps (the anisotropic filter's) the mean of its taps at footprint.footprint_uv, summed
// in tap order, times 1 / taps. Lanes past their taps, not read, or not finite read (0, 0) at level 0.
// Into out: out[l] + weight[l] · sample where add (a blend of reads), the sample itself where not; the
// other lanes' rows as they are.
auto wt_accumulate_footprint = [&](const auto& tex, const auto& smp, const int* layers, const float* u, const float* v, const float* lod, const float* du, const float* dv,
                                   const float* taps, const float* weight, int add, wp::mat_t<WT_L, 4, float>& out) __attribute__((always_inline)) {
    float us[WT_L], vs[WT_L], fractions[WT_L];
    int levels[WT_L], layer[WT_L];
    bool read[WT_L], finite[WT_L];
    int most = 0;  // the most taps of a read lane
    for (int l = 0; l < WT_L; ++l) {
        read[l] = weight[l] > 0.0f;
        layer[l] = read[l] ? wp::clamp(layers[l], 0, tex.num_layers - 1) : 0;  // valid (the API checks), clamped all the same
        wt_mip_levels(tex, smp, read[l] ? lod[l] : 0.0f, levels[l], fractions[l]);
        const int n = read[l] ? (int)taps[l] : 0;  // footprint.footprint_taps
        most = n > most ? n : most;
    }
    wt_f4 total[WT_L], single[WT_L];  // the taps' sum; a one-tap footprint's sample itself
    for (int l = 0; l < WT_L; ++l) total[l] = (wt_f4){0.0f, 0.0f, 0.0f, 0.0f};
    for (int k = 0; k < most; ++k) {
        bool tap[WT_L];
        for (int l = 0; l < WT_L; ++l) {
            const bool one = taps[l] == 1.0f;
            const float s = (float)k + 0.5f - 0.5f * taps[l];
            const float tu = one ? u[l] : u[l] + du[l] * s;  // footprint.footprint_uv
            const float tv = one ? v[l] : v[l] + dv[l] * s;
            tap[l] = read[l] && k < (int)taps[l];
            finite[l] = __builtin_fabsf(tu) <= wt_float_max && __builtin_fabsf(tv) <= wt_float_max && __builtin_fabsf(lod[l]) <= wt_float_max;  // texels.finite_uv_lod
            const bool ok = tap[l] && finite[l];
            us[l] = ok ? tu : 0.0f;
            vs[l] = ok ? tv : 0.0f;
        }
        wt_f4 result[WT_L];
        wt_sample_levels_any(tex, smp, us, vs, levels, fractions, layer, result);
        const wt_f4 nan4 = __builtin_nanf("");
        for (int l = 0; l < WT_L; ++l) {
            const wt_f4 r = finite[l] ? result[l] : nan4;
            if (k == 0) single[l] = r;
            if (tap[l]) total[l] = total[l] + r;
        }
    }
    for (int l = 0; l < WT_L; ++l) {
        if (!read[l]) continue;
        const wt_f4 r = taps[l] == 1.0f ? single[l] : total[l] * (1.0f / taps[l]);
        for (int c = 0; c < 4; ++c) out.data[l][c] = add ? out.data[l][c] + weight[l] * r[c] : r[c];
    }
};
""" % {"lanes": LANES} + LOG2_CPP


# footprint.uv_footprint for a lane, and a lane_reads matrix's rows of a read: after _CORE, for the
# helpers that work out footprints (.projection_lanes, .sample_lanes).
FOOTPRINT_CPP = r"""
// footprint.uv_footprint for the lane: the footprint (lod, step u, step v, taps) of UV derivatives
// (dx0, dx1), (dy0, dy1) on a level-0 image of width × height texels. Every branch of the scalar block
// is computed for every lane and chosen by selects; one log2 a lane, as the scalar block takes it.
struct wt_footprint_lanes { wt_vf lod, du, dv, taps; };
auto wt_vceil = [](wt_vf x) __attribute__((always_inline)) -> wt_vf { float a[WT_L]; __builtin_memcpy(a, &x, sizeof(a)); for (int l = 0; l < WT_L; ++l) a[l] = wp::ceil(a[l]); __builtin_memcpy(&x, a, sizeof(a)); return x; };
auto wt_footprint = [&](const auto& smp, wt_vf dx0, wt_vf dx1, wt_vf dy0, wt_vf dy1, float width, float height) __attribute__((always_inline)) -> wt_footprint_lanes {
    const wt_vf zero = 0.0f, one = 1.0f;
    const wt_vf a0 = dx0 * width, a1 = dx1 * height, b0 = dy0 * width, b1 = dy1 * height;  // level-0 texels
    const wt_vf aa = a0 * a0 + a1 * a1, bb = b0 * b0 + b1 * b1;
    wt_vf arg = wt_vmin(wt_vmax(wt_vmax(aa, bb), 1.0e-30f), wt_float_max);  // footprint_lod's: log2 of the longer axis
    wt_vi ellipse = 0;  // an anisotropic footprint's LOD, log2(extent), not halved and not NaN-checked
    wt_footprint_lanes fp = {zero, zero, zero, one};
    if (smp.filter == WT_ANISOTROPIC) {
        const wt_vf h = aa - bb, ab = a0 * b0 + a1 * b1, round_floor = 1.0e-6f * (aa + bb);
        const wt_vi round = h * h + ab * ab < round_floor * round_floor;  // round_footprint
        const wt_vf A = a0 * a0 + b0 * b0, C = a1 * a1 + b1 * b1, area = A + C;  // anisotropic_footprint
        const wt_vf B = a0 * a1 + b0 * b1, half_diff = 0.5f * (A - C), floor = 1.0e-6f * area;
        const wt_vf root = wt_vsqrt(wt_vmax(half_diff * half_diff + B * B, floor * floor));
        const wt_vf major2 = 0.5f * area + root, major = wt_vsqrt(major2);
        const wt_vf minor = wt_vabs(a0 * b1 - a1 * b0) / major;
        const wt_vf extent = wt_vmax(minor, major / smp.max_aniso);
        const wt_vf taps = wt_vmin(wt_vmax(one, wt_vceil(major / extent - 1.0e-3f)), (wt_vf)smp.max_aniso);  // wp.clamp(x, 1, max_aniso)
        const wt_vf o0 = major2 - C, o1 = B;  // the major axis: the longer of two eigenvector expressions
        const wt_vi other = o0 * o0 + o1 * o1 > B * B + (major2 - A) * (major2 - A);
        const wt_vf v0 = wt_sel(other, o0, B), v1 = wt_sel(other, o1, major2 - A);
        const wt_vf length = wt_vsqrt(v0 * v0 + v1 * v1);
        const wt_vf scale = major / taps;
        ellipse = ~round & (area > 1.0e-12f) & (area < 1.0e18f);
        const wt_vi several = ellipse & (taps != 1.0f);
        arg = wt_sel(round, 0.5f * (aa + bb), wt_sel(ellipse, extent, arg));
        fp.du = wt_sel(several, ((v0 / length) * scale) / width, zero);
        fp.dv = wt_sel(several, ((v1 / length) * scale) / height, zero);
        fp.taps = wt_sel(ellipse, taps, one);
    }
    float args[WT_L], logs[WT_L];
    __builtin_memcpy(args, &arg, sizeof(args));
    for (int l = 0; l < WT_L; ++l) logs[l] = wt_log2(args[l]);  // footprint.lod_log2
    wt_vf log;
    __builtin_memcpy(&log, logs, sizeof(log));
    fp.lod = wt_sel(ellipse, log, wt_sel(aa + bb == aa + bb, 0.5f * log, __builtin_nanf("")));
    return fp;
};
// Read r's rows of a lane_reads matrix: u, v, lod, weight, step u, step v, taps (zero where not read).
auto wt_put_read = [&](wp::mat_t<21, WT_L, float>& out, int r, wt_vi read, wt_vf u, wt_vf v, const wt_footprint_lanes& fp, wt_vf weight) __attribute__((always_inline)) {
    const wt_vf zero = 0.0f;
    const wt_vf rows[7] = {wt_sel(read, u, zero), wt_sel(read, v, zero), wt_sel(read, fp.lod, zero), wt_sel(read, weight, zero), wt_sel(read, fp.du, zero), wt_sel(read, fp.dv, zero), wt_sel(read, fp.taps, zero)};
    for (int q = 0; q < 7; ++q) __builtin_memcpy(out.data[3 * q + r], &rows[q], sizeof(wt_vf));
};
"""

def cpu_snippet(body: str, cuda: str = "") -> str:
    """A native helper's snippet: the shared core and ``body`` on the CPU, ``cuda`` (never run: lane
    kernels are CPU-only) when NVRTC compiles it."""
    return "#if !defined(__CUDA_ARCH__)\n" + _CORE + body + "#else\n" + cuda + "#endif\n"


_ACCUMULATE_FOOTPRINT = r"""
wp::mat_t<WT_L, 4, float> out = acc;
wt_accumulate_footprint(tex, smp, layers.c, u.c, v.c, lod.c, du.c, dv.c, taps.c, weight.c, add, out);
return out;
"""


@wp.func_native(cpu_snippet(_ACCUMULATE_FOOTPRINT, "return acc;\n"))
def accumulate_footprint_lane(tex: TextureView, smp: SamplerArgs, layers: lane_ints, u: lane_floats, v: lane_floats,
                              lod: lane_floats, du: lane_floats, dv: lane_floats, taps: lane_floats, weight: lane_floats, add: wp.int32, acc: lane_colours) -> lane_colours:  # fmt: skip
    """``acc`` with, in every lane ``l`` whose ``weight[l] > 0``, ``s =``
    :func:`~warptex.kernels.filters.sample_footprint` of layer ``layers[l]`` (a valid layer) at
    ``(u[l], v[l])`` over the footprint ``(lod, du, dv, taps)[l]`` (NaN where a tap's UV or the LOD
    is not finite) added as ``acc[l] + weight[l] · s`` (``add``: a blend of projections or layers,
    ``value += w · sample``), or put in its place (not ``add``: ``value = sample``); the other
    lanes' rows as they are."""
    ...
