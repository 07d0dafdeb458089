// Filter footprints for a lane: the LOD, the anisotropic filter's step and taps of each pixel's UV
// derivatives, and a lane_reads matrix's rows of a read.
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_log2.h"

// A lane's footprints: lod, step u, step v, taps.
struct wt_footprint_lanes {
    wt_vf lod, du, dv, taps;
};

// The footprint (lod, step u, step v, taps) of UV derivatives (dx0, dx1), (dy0, dy1) on a level-0
// image of width × height texels. Every branch of the scalar block is computed for every lane and
// chosen by selects; one log2 a lane, as the scalar block takes it.
// twin: footprint.uv_footprint
template <class Smp> WT_INLINE wt_footprint_lanes wt_footprint(const Smp& smp, wt_vf dx0, wt_vf dx1, wt_vf dy0,
                                                               wt_vf dy1, float width, float height) {
    const wt_vf zero = 0.0f, one = 1.0f;
    const wt_vf a0 = dx0 * width, a1 = dx1 * height, b0 = dy0 * width, b1 = dy1 * height;  // level-0 texels
    const wt_vf aa = a0 * a0 + a1 * a1, bb = b0 * b0 + b1 * b1;
    wt_vf arg = wt_vmin(wt_vmax(wt_vmax(aa, bb), 1.0e-30f), wt_float_max);  // footprint_lod's: log2 of the longer axis
    wt_vi ellipse = 0;  // an anisotropic footprint's LOD, log2(extent), not halved and not NaN-checked
    wt_footprint_lanes fp = {zero, zero, zero, one};
    if (smp.filter == WT_ANISOTROPIC) {
        const wt_vf h = aa - bb, ab = a0 * b0 + a1 * b1, round_floor = 1.0e-6f * (aa + bb);
        const wt_vi round = h * h + ab * ab < round_floor * round_floor;         // round_footprint
        const wt_vf A = a0 * a0 + b0 * b0, C = a1 * a1 + b1 * b1, area = A + C;  // anisotropic_footprint
        const wt_vf B = a0 * a1 + b0 * b1, half_diff = 0.5f * (A - C), floor = 1.0e-6f * area;
        const wt_vf root = wt_vsqrt(wt_vmax(half_diff * half_diff + B * B, floor * floor));
        const wt_vf major2 = 0.5f * area + root, major = wt_vsqrt(major2);
        const wt_vf minor = wt_vabs(a0 * b1 - a1 * b0) / major;
        const wt_vf extent = wt_vmax(minor, major / smp.max_aniso);
        // wp.clamp(x, 1, max_aniso)
        const wt_vf taps = wt_vmin(wt_vmax(one, wt_vceil(major / extent - 1.0e-3f)), (wt_vf)smp.max_aniso);
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
}

// A lane_reads matrix's rows, not zeroed first as a wt_lane_reads is (its 21 rows, 1.3 KB, zeroed
// per layer and lane were 7% of a splat's forward): for a caller that reads only the reads it
// has written (wt_put_read).
struct wt_lane_read_rows {
    float data[21][WT_L];
};

// Read r's rows of a lane_reads matrix: u, v, lod, weight, step u, step v, taps (zero where not read).
template <class Reads> WT_INLINE void wt_put_read(Reads& out, int r, wt_vi read, wt_vf u, wt_vf v,
                                                  const wt_footprint_lanes& fp, wt_vf weight) {
    const wt_vf zero = 0.0f;
    const wt_vf rows[7] = {wt_sel(read, u, zero),      wt_sel(read, v, zero),     wt_sel(read, fp.lod, zero),
                           wt_sel(read, weight, zero), wt_sel(read, fp.du, zero), wt_sel(read, fp.dv, zero),
                           wt_sel(read, fp.taps, zero)};
    for (int q = 0; q < 7; ++q) __builtin_memcpy(out.data[3 * q + r], &rows[q], sizeof(wt_vf));
}

// footprint.lod_scale_slope: d lod / d s of the footprint of UV derivatives (dx0, dx1), (dy0, dy1)
// scaled by s, at s = scale, on a level-0 image of width × height texels.
// twin: footprint.lod_scale_slope
WT_INLINE float wt_lod_scale_slope(float width, float height, float dx0, float dx1, float dy0, float dy1, float scale) {
    const float a0 = (dx0 * scale) * width, a1 = (dx1 * scale) * height;
    const float b0 = (dy0 * scale) * width, b1 = (dy1 * scale) * height;
    const float rho2 = wp::max(a0 * a0 + a1 * a1, b0 * b0 + b1 * b1);
    return rho2 > (float)1.0e-30 && rho2 < wt_float_max ? 1.0f / (scale * (float)0.6931471805599453) : 0.0f;
}
