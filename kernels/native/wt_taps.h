// Stochastic taps for a lane: hashing.pcg4d / hash4_unit, hash4_taps and cheap2_taps (with
// value_noise, periodic_base and offset_tap), operation for operation (integer hashes; Warp's own
// wp::smoothstep, wp::lerp, wp::floor; no contraction): loops over the lane's pixels with no branch,
// which the compiler vectorises. Every tap is hashed, also the zero-weight ones the scalar blocks
// skip: those are not read. Hex's taps (hexgrid's blocks) likewise, in phases over the lane: the
// float64 grid and the hashes in loops with no branch, the rotations (wp::sin, wp::cos) and powers
// (wp::pow; none for a contrast of 1, as hexgrid.hex_weights) lane by lane.
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_sample.h"
#include "wt_scatter.h"

// The four hashes of (a, b, c, d) as floats in [0, 1).
// twin: hashing.hash4_unit
WT_INLINE void wt_hash4_unit(unsigned a, unsigned b, unsigned c, unsigned d, float* h) {
    unsigned x = a * 1664525u + 1013904223u, y = b * 1664525u + 1013904223u;
    unsigned z = c * 1664525u + 1013904223u, w = d * 1664525u + 1013904223u;
    x += y * w;
    y += z * x;
    z += x * y;
    w += y * z;
    x = x ^ (x >> 16u);
    y = y ^ (y >> 16u);
    z = z ^ (z >> 16u);
    w = w ^ (w >> 16u);
    x += y * w;
    y += z * x;
    z += x * y;
    w += y * z;
    const float inv = (float)(1.0 / 16777216.0);
    h[0] = (float)(x >> 8u) * inv;
    h[1] = (float)(y >> 8u) * inv;
    h[2] = (float)(z >> 8u) * inv;
    h[3] = (float)(w >> 8u) * inv;
}

// A tap's UV: the periodic base (bu, bv), mirrored by the hash where mirror, plus the hash's offset.
// twin: stochastic.offset_tap
WT_INLINE void wt_offset_tap(float bu, float bv, const float* h, int mirror, float& tu, float& tv) {
    const float su = mirror != 0 && h[2] < 0.5f ? -1.0f : 1.0f, sv = mirror != 0 && h[3] < 0.5f ? -1.0f : 1.0f;
    tu = su * bu + h[0];
    tv = sv * bv + h[1];
}

// A lane's lane_taps (stochastic.stochastic_taps and texels.finite_uv_lod of every pixel) from its
// UV and LOD rows tap_u, tap_v, tap_lod (lane pixels past count not read).
// twin: stochastic.stochastic_taps
template <class Params> WT_INLINE wt_lane_taps wt_stochastic_taps(const Params& params, const float* tap_u,
                                                                  const float* tap_v, const float* tap_lod, int count) {
    wt_lane_taps taps;
    for (int r = 0; r < 14; ++r)
        for (int l = 0; l < WT_L; ++l) taps.data[r][l] = 0.0f;
    float fin[WT_L];
    for (int l = 0; l < WT_L; ++l) {  // texels.finite_uv_lod
        const float u = tap_u[l], v = tap_v[l], lod = tap_lod[l];
        fin[l] = l < count && __builtin_fabsf(u) <= wt_float_max && __builtin_fabsf(v) <= wt_float_max &&
                         __builtin_fabsf(lod) <= wt_float_max
                     ? 1.0f
                     : 0.0f;
        taps.data[12][l] = lod;
        taps.data[13][l] = fin[l];
    }
    const float lo = params.blend_lo, hi = params.blend_hi;
    const unsigned seed = params.seed;
    if (params.method == WT_HASH4) {  // stochastic.hash4_taps
        for (int l = 0; l < WT_L; ++l) {
            const float u = fin[l] != 0.0f ? tap_u[l] : 0.0f, v = fin[l] != 0.0f ? tap_v[l] : 0.0f;
            const float cu = wp::floor(u), cv = wp::floor(v);
            const float bu = u - 2.0f * wp::floor(0.5f * u), bv = v - 2.0f * wp::floor(0.5f * v);  // periodic_base
            const float bx = wp::smoothstep(lo, hi, u - cu), by = wp::smoothstep(lo, hi, v - cv);
            const unsigned ix = (unsigned)(int)cu, iy = (unsigned)(int)cv;
            const float w[4] = {(1.0f - bx) * (1.0f - by), bx * (1.0f - by), (1.0f - bx) * by, bx * by};
            for (int k = 0; k < 4; ++k) {
                float h[4];
                wt_hash4_unit(ix + (unsigned)(k & 1), iy + (unsigned)(k >> 1), seed, (unsigned)WT_STREAM_CELL, h);
                wt_offset_tap(bu, bv, h, params.mirror, taps.data[3 * k][l], taps.data[3 * k + 1][l]);
                taps.data[3 * k + 2][l] = fin[l] != 0.0f ? w[k] : 0.0f;
            }
        }
    } else if (params.method == WT_CHEAP2) {  // stochastic.cheap2_taps
        for (int l = 0; l < WT_L; ++l) {
            const float u = fin[l] != 0.0f ? tap_u[l] : 0.0f, v = fin[l] != 0.0f ? tap_v[l] : 0.0f;
            const float pu = u * params.noise_frequency, pv = v * params.noise_frequency;  // value_noise
            const float cu = wp::floor(pu), cv = wp::floor(pv);
            const float fu = pu - cu, fv = pv - cv;
            const unsigned ix = (unsigned)(int)cu, iy = (unsigned)(int)cv;
            float a[4], b[4], c[4], d[4];
            wt_hash4_unit(ix, iy, seed, (unsigned)WT_STREAM_NOISE, a);
            wt_hash4_unit(ix + 1u, iy, seed, (unsigned)WT_STREAM_NOISE, b);
            wt_hash4_unit(ix, iy + 1u, seed, (unsigned)WT_STREAM_NOISE, c);
            wt_hash4_unit(ix + 1u, iy + 1u, seed, (unsigned)WT_STREAM_NOISE, d);
            const float sx = wp::smoothstep(0.0f, 1.0f, fu), sy = wp::smoothstep(0.0f, 1.0f, fv);
            const float noise = wp::lerp(wp::lerp(a[0], b[0], sx), wp::lerp(c[0], d[0], sx), sy);
            const float level = noise * params.noise_levels;
            const float index = wp::floor(level);
            const float t = wp::smoothstep(lo, hi, level - index);
            const float bu = u - 2.0f * wp::floor(0.5f * u), bv = v - 2.0f * wp::floor(0.5f * v);
            const unsigned ia = (unsigned)(int)index;
            float h0[4], h1[4];
            wt_hash4_unit(ia, 0u, seed, (unsigned)WT_STREAM_OFFSET, h0);
            wt_hash4_unit(ia + 1u, 0u, seed, (unsigned)WT_STREAM_OFFSET, h1);
            wt_offset_tap(bu, bv, h0, params.mirror, taps.data[0][l], taps.data[1][l]);
            wt_offset_tap(bu, bv, h1, params.mirror, taps.data[3][l], taps.data[4][l]);
            taps.data[2][l] = fin[l] != 0.0f ? 1.0f - t : 0.0f;
            taps.data[5][l] = fin[l] != 0.0f ? t : 0.0f;
        }
    } else {  // hexgrid: hex_grid (in float64), hex_steps, hex_tap, hex_weights, in phases over the lane
        const double scale = WT_HEX_SCALE, inv_sqrt3 = WT_INV_SQRT3,
                     half_sqrt3_64 = WT_HALF_SQRT3;  // wp.float64 of a constant: its value as a double
        const float half_sqrt3 = (float)WT_HALF_SQRT3, pi = (float)WT_PI, hex_scale = (float)WT_HEX_SCALE;
        const double limit = 1073741824.0;
        float f0[WT_L], f1[WT_L], bu[WT_L], bv[WT_L], hz[3][WT_L];
        int vi[3][WT_L], vj[3][WT_L], upper[WT_L];
        for (int l = 0; l < WT_L; ++l) {  // hex_grid, its vertices (hex_steps' order) and periodic_base
            const float u = fin[l] != 0.0f ? tap_u[l] : 0.0f, v = fin[l] != 0.0f ? tap_v[l] : 0.0f;
            const double px = (double)u * scale, py = (double)v * scale;
            const double sx = px - py * inv_sqrt3, sy = 2.0 * inv_sqrt3 * py;
            const double bx = wp::floor(sx), by = wp::floor(sy);
            f0[l] = (float)(sx - bx);
            f1[l] = (float)(sy - by);
            const double lx = bx >= limit || bx < -limit ? bx - wp::floor(bx / limit) * limit : bx;  // lattice_id
            const double ly = by >= limit || by < -limit ? by - wp::floor(by / limit) * limit : by;
            const int i = (int)lx, j = (int)ly;
            upper[l] = f0[l] + f1[l] >= 1.0f;
            vi[0][l] = upper[l] ? i + 1 : i, vj[0][l] = upper[l] ? j + 1 : j;
            vi[1][l] = i + 1, vj[1][l] = j;
            vi[2][l] = i, vj[2][l] = j + 1;
            bu[l] = u - 2.0f * wp::floor(0.5f * u);
            bv[l] = v - 2.0f * wp::floor(0.5f * v);
        }
        for (int k = 0; k < 3; ++k) {  // hex_tap: the vertex's hash and offset
            for (int l = 0; l < WT_L; ++l) {
                float h[4];
                wt_hash4_unit((unsigned)vi[k][l], (unsigned)vj[k][l], seed, (unsigned)WT_STREAM_HEX, h);
                taps.data[3 * k][l] = bu[l] + h[0];
                taps.data[3 * k + 1][l] = bv[l] + h[1];
                hz[k][l] = h[2];
            }
        }
        if (params.rotation != 0.0f) {  // hex_tap's rotation about the vertex centre, lane by lane
            for (int l = 0; l < WT_L; ++l) {
                if (fin[l] == 0.0f) continue;
                const float u = tap_u[l], v = tap_v[l];
                for (int k = 0; k < 3; ++k) {
                    float du, dv;
                    if (wp::abs(u) < 1.0e8f && wp::abs(v) < 1.0e8f) {  // hex_centre64
                        const double cu = ((double)vi[k][l] + 0.5 * (double)vj[k][l]) / scale,
                                     cv = half_sqrt3_64 * (double)vj[k][l] / scale;
                        du = (float)((double)u - cu);
                        dv = (float)((double)v - cv);
                    } else {
                        const float x = f0[l] - (k == 1 || (k == 0 && upper[l]) ? 1.0f : 0.0f),
                                    y = f1[l] - (k == 2 || (k == 0 && upper[l]) ? 1.0f : 0.0f);
                        du = (x + 0.5f * y) / hex_scale;
                        dv = (half_sqrt3 * y) / hex_scale;
                    }
                    const float theta = (2.0f * hz[k][l] - 1.0f) * pi * params.rotation;
                    const float cs = wp::cos(theta), sn = wp::sin(theta);
                    taps.data[3 * k][l] = taps.data[3 * k][l] + ((cs * du - sn * dv) - du);
                    taps.data[3 * k + 1][l] = taps.data[3 * k + 1][l] + ((sn * du + cs * dv) - dv);
                }
            }
        }
        float bary[3][WT_L], pw[3][WT_L];
        for (int l = 0; l < WT_L; ++l) {
            bary[0][l] = upper[l] ? f0[l] + f1[l] - 1.0f : 1.0f - f0[l] - f1[l];
            bary[1][l] = upper[l] ? 1.0f - f1[l] : f0[l];
            bary[2][l] = upper[l] ? 1.0f - f0[l] : f1[l];
        }
        for (int k = 0; k < 3; ++k)  // hex_weights (a contrast of 1 takes the weights as they are)
            for (int l = 0; l < WT_L; ++l) pw[k][l] = bary[k][l] > 0.0f ? bary[k][l] : 0.0f;
        if (params.contrast != 1.0f)
            for (int k = 0; k < 3; ++k)
                for (int l = 0; l < WT_L; ++l)
                    pw[k][l] = bary[k][l] > 0.0f ? wp::pow(bary[k][l], params.contrast) : 0.0f;
        for (int l = 0; l < WT_L; ++l) {
            const float total = pw[0][l] + pw[1][l] + pw[2][l];
            for (int k = 0; k < 3; ++k)
                taps.data[3 * k + 2][l] = fin[l] != 0.0f ? pw[k][l] / total : 0.0f;  // (a tap of weight 0 is not read)
        }
    }
    return taps;
}

// lanes.stochastic.stochastic_taps_lane: the lane's taps from base: every pixel's LOD
// (sampling.sample_footprint_of, one tap), whether its UV and LOD are finite, its taps and weights.
template <class Tex, class Smp, class Params, class UV, class Lods, class Layers>
WT_INLINE wt_lane_taps wt_stochastic_taps_lane(const Tex& tex, const Smp& smp, const Params& params, const UV& uv,
                                               const UV& uv_dx, const UV& uv_dy, const Lods& lods, const Layers& layers,
                                               int constant_layer, int lod_source, float constant_lod, int base) {
    const wt_sample_reads s =
        wt_sample_reads_of(tex, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);
    return wt_stochastic_taps(params, s.reads.data[0], s.reads.data[3], s.reads.data[6], s.count);
}

// lanes.stochastic.projection_taps_lane: the taps of projection `axis` of a triplanar lane's reads,
// the weights of the pixels that do not read it (weight 0) set to 0, so that nothing reads them.
template <class Params, class At>
WT_INLINE wt_lane_taps wt_projection_taps_lane(const Params& params, const At& reads, int axis, int count) {
    wt_lane_taps taps = wt_stochastic_taps(params, reads.data[axis], reads.data[3 + axis], reads.data[6 + axis], count);
    for (int k = 0; k < 4; ++k)
        for (int l = 0; l < WT_L; ++l)
            taps.data[3 * k + 2][l] = reads.data[9 + axis][l] > 0.0f ? taps.data[3 * k + 2][l] : 0.0f;
    return taps;
}

// stochastic.sample_stochastic of each read lane pixel (weight[l] > 0) over its footprint (u, v, lod,
// du, dv, taps: a lane_reads matrix's rows of one read), as a linear blend (no histogram): per
// footprint tap j, its UV (footprint.footprint_uv, for a one-tap footprint too), that UV's
// stochastic taps at the read's LOD (wt_stochastic_taps) read tap by tap from 0, NaN where the UV
// or the LOD is not finite, added into the result from 0; the result divided by the taps where
// there are several (footprint.footprint_mean). Rows of the lanes not read (or past count) are 0.
// twin: stochastic._sample_stochastic:sample_stochastic
template <class Tex, class Smp, class Params>
WT_INLINE void wt_stochastic_footprint(const Tex& tex, const Smp& smp, const Params& params, const int* layers,
                                       const float* u, const float* v, const float* lod, const float* du,
                                       const float* dv, const float* taps, const float* weight, int count,
                                       wt_lane_colours& result) {
    float zero[WT_L], one[WT_L];
    for (int l = 0; l < WT_L; ++l) {
        zero[l] = 0.0f, one[l] = 1.0f;
        for (int c = 0; c < 4; ++c) result.data[l][c] = 0.0f;
    }
    // Footprint taps queued pixel by pixel, in order, and read WT_L at a time whatever pixel they
    // are of: a pixel's taps still add into its result in order, and the lane's pixels with fewer
    // taps than the widest leave no lane of a read empty.
    float qu[WT_L], qv[WT_L], qlod[WT_L];
    int qlayer[WT_L], qpixel[WT_L];
    int m = 0;
    const float nan = __builtin_nanf("");
    auto drain = [&]() __attribute__((always_inline)) {
        for (int q = m; q < WT_L; ++q) qu[q] = qv[q] = qlod[q] = 0.0f, qlayer[q] = 0;
        const wt_lane_taps t = wt_stochastic_taps(params, qu, qv, qlod, m);  // weights 0 past m
        wt_lane_colours value;
        for (int k = 0; k < 4; ++k)
            wt_accumulate_footprint(tex, smp, qlayer, t.data[3 * k], t.data[3 * k + 1], t.data[12], zero, zero, one,
                                    t.data[3 * k + 2], 1, value);
        for (int q = 0; q < m; ++q) {
            const bool finite = t.data[13][q] != 0.0f;
            for (int c = 0; c < 4; ++c)
                result.data[qpixel[q]][c] = result.data[qpixel[q]][c] + (finite ? value.data[q][c] : nan);
        }
        m = 0;
    };
    for (int l = 0; l < WT_L; ++l) {
        if (l >= count || !(weight[l] > 0.0f)) continue;
        for (int j = 0; j < (int)taps[l]; ++j) {  // footprint.footprint_taps
            const float s = (float)j + 0.5f - 0.5f * taps[l];
            qu[m] = u[l] + du[l] * s, qv[m] = v[l] + dv[l] * s;  // footprint.footprint_uv
            qlod[m] = lod[l], qlayer[m] = layers[l], qpixel[m] = l;
            if (++m == WT_L) drain();
        }
    }
    if (m > 0) drain();
    for (int l = 0; l < WT_L; ++l)
        if (weight[l] > 0.0f && taps[l] != 1.0f)
            for (int c = 0; c < 4; ++c) result.data[l][c] = result.data[l][c] / taps[l];
}

// lanes.stochastic.stochastic_footprint_lane: row l, stochastic.sample_stochastic (a linear blend)
// of pixel base + l over its footprint (sampling.sample_footprint_of, wt_sample_reads_of),
// wt_stochastic_footprint's: NaN where its UV or LOD is not finite.
template <class Tex, class Smp, class Params, class UV, class Lods, class Layers>
WT_INLINE wt_lane_colours wt_stochastic_footprint_lane(const Tex& tex, const Smp& smp, const Params& params,
                                                       const UV& uv, const UV& uv_dx, const UV& uv_dy, const Lods& lods,
                                                       const Layers& layers, int constant_layer, int lod_source,
                                                       float constant_lod, int base) {
    const wt_sample_reads s =
        wt_sample_reads_of(tex, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);
    const wt_lane_reads& at = s.reads;
    wt_lane_colours out;
    wt_stochastic_footprint(tex, smp, params, s.layer, at.data[0], at.data[3], at.data[6], at.data[12], at.data[15],
                            at.data[18], at.data[9], s.count, out);
    return out;
}

// lanes.stochastic.stochastic_read_lane: row l, stochastic.sample_stochastic (a linear blend) of
// read `axis` of a triplanar lane's reads (layer layers[l]) over its footprint where its weight
// is positive (wt_stochastic_footprint's: NaN where its UV or LOD is not finite), else 0.
template <class Tex, class Smp, class Params, class Ints>
WT_INLINE wt_lane_colours wt_stochastic_read_lane(const Tex& tex, const Smp& smp, const Params& params,
                                                  const Ints& layers, const wt_lane_reads& reads, int axis, int count) {
    wt_lane_colours out;
    wt_stochastic_footprint(tex, smp, params, layers.c, reads.data[axis], reads.data[3 + axis], reads.data[6 + axis],
                            reads.data[12 + axis], reads.data[15 + axis], reads.data[18 + axis], reads.data[9 + axis],
                            count, out);
    return out;
}

// wt_scatter_footprint_rows for stochastic lookups (stochastic.scatter_stochastic; a linear blend):
// each read of `rows` with a positive weight and a finite LOD, pixel by pixel and read by read, into a
// gradient that is needed, adds its share (w · g[l] where weigh, g[l] where not; g: read r's own
// gradient gr[r] where per_read, else gr[0]) divided by its
// footprint's taps where several (footprint.footprint_mean) through each footprint tap in order: at
// the tap's UV (footprint.footprint_uv, for one tap too), where finite, that UV's stochastic taps at
// the read's LOD in order, each with a positive weight w_k adding w_k times that share. The
// footprint taps go through wt_stochastic_taps WT_L at a time in that order, and their stochastic
// taps through a wt_tap_batch per gradient array: every texel gets the scalar kernel's sums in its
// order, and no footprint's taps need holding (up to 64 per read). Layers as
// wt_scatter_footprint_rows takes them; the N reads `rows` holds at most.
// twin: stochastic.scatter_stochastic
template <int N, class Tex, class Grad, class Smp, class Params> WT_INLINE void
wt_scatter_stochastic_rows(const Tex* const* texs, const Grad* const* grads, const Smp& smp, const Params& params,
                           const int nreads, const int* layers, const wt_read_rows_n<N>& rows, const int weigh,
                           const wt_lane_colours* const* gr, const int per_read, const int layer_stride = 0) {
    wt_each_grad_array<N>(nreads, grads, [&](const int first, const bool* group) __attribute__((always_inline)) {
        wt_tap_batch<Tex, Grad, Smp> batch(*texs[first], *grads[first], smp);
        float fu[WT_L], fv[WT_L], flod[WT_L], fraction[WT_L];  // footprint taps waiting for their taps
        int level[WT_L], lr[WT_L];
        wt_f4 share[WT_L];
        int m = 0;
        auto drain = [&]() __attribute__((always_inline)) {
            for (int q = m; q < WT_L; ++q) fu[q] = fv[q] = flod[q] = 0.0f;
            const wt_lane_taps t = wt_stochastic_taps(params, fu, fv, flod, m);
            for (int q = 0; q < m; ++q) {
                if (t.data[13][q] == 0.0f) continue;  // texels.finite_uv_lod of the footprint tap
                for (int k = 0; k < 4; ++k) {
                    const float w = t.data[3 * k + 2][q], tu = t.data[3 * k][q], tv = t.data[3 * k + 1][q];
                    if (!(w > 0.0f) || !(__builtin_fabsf(tu) <= wt_float_max && __builtin_fabsf(tv) <= wt_float_max))
                        continue;  // scatter.scatter_lod adds nothing
                    batch.push(tu, tv, level[q], fraction[q], lr[q], w * share[q]);
                }
            }
            m = 0;
        };
        for (int l = 0; l < WT_L; ++l) {
            for (int r = first; r < nreads; ++r) {
                const float w = rows.w[r][l], lod = rows.lod[r][l];
                if (!group[r] || !(w > 0.0f) || !(__builtin_fabsf(lod) <= wt_float_max)) continue;
                const wt_lane_colours& g = *gr[per_read ? r : 0];
                const wt_f4 gl = {g.data[l][0], g.data[l][1], g.data[l][2], g.data[l][3]};
                const wt_f4 read_share = weigh ? w * gl : gl;
                const float taps = rows.taps[r][l], u = rows.u[r][l], v = rows.v[r][l];
                const float du = rows.du[r][l], dv = rows.dv[r][l];
                const wt_f4 tap_share = taps != 1.0f ? read_share / taps : read_share;  // footprint.footprint_mean
                int read_level;
                float read_fraction;
                wt_mip_levels(*texs[r], smp, lod, read_level, read_fraction);
                const int read_layer = wp::clamp(layers[r * layer_stride + l], 0, texs[r]->num_layers - 1);
                for (int j = 0; j < (int)taps; ++j) {  // footprint.footprint_taps
                    const float s = (float)j + 0.5f - 0.5f * taps;
                    fu[m] = u + du * s, fv[m] = v + dv * s, flod[m] = lod;  // footprint.footprint_uv
                    level[m] = read_level, fraction[m] = read_fraction, lr[m] = read_layer, share[m] = tap_share;
                    if (++m == WT_L) drain();
                }
            }
        }
        if (m > 0) drain();
        batch.flush();
    });
}

// lanes.stochastic.scatter_stochastic_footprint_lane: stochastic.scatter_stochastic of adj[i] for
// the lane's pixels i = base .. over their footprints (wt_sample_reads_of's reads), every filter's.
// twin: stochastic.scatter_stochastic
template <class Tex, class Grad, class Smp, class Params, class UV, class Lods, class Layers, class Adj>
WT_INLINE void wt_scatter_stochastic_footprint_lane(const Tex& tex, const Grad& grad, const Smp& smp,
                                                    const Params& params, const UV& uv, const UV& uv_dx,
                                                    const UV& uv_dy, const Lods& lods, const Layers& layers,
                                                    int constant_layer, int lod_source, float constant_lod,
                                                    const Adj& adj, int base) {
    const wt_sample_reads s =
        wt_sample_reads_of(tex, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, base);
    const Tex* texs[1] = {&tex};
    const Grad* grads[1] = {&grad};
    const wt_lane_colours g = wt_adj_lane(adj, base, s.count);
    const wt_lane_colours* gr[1] = {&g};
    wt_scatter_stochastic_rows(texs, grads, smp, params, 1, s.layer, wt_rows_of(s.reads), 0, gr, 0);
}

// lanes.stochastic.scatter_stochastic_reads_lanes: stochastic.scatter_stochastic of a stochastic
// triplanar lane's three projections over their footprints, every filter's: projection a's share
// (w · g_a[l] where weigh, else g_a[l]) into grad_a (a texture per axis), pixel by pixel in
// projection and tap order.
// twin: stochastic.scatter_stochastic
template <class Tex, class Grad, class Smp, class Params, class Ints>
WT_INLINE void wt_scatter_stochastic_reads_lanes(const Tex& tex0, const Tex& tex1, const Tex& tex2, const Grad& grad0,
                                                 const Grad& grad1, const Grad& grad2, const Smp& smp,
                                                 const Params& params, const Ints& layers, const wt_lane_reads& reads,
                                                 const int weigh, const wt_lane_colours& g0, const wt_lane_colours& g1,
                                                 const wt_lane_colours& g2) {
    const Tex* texs[3] = {&tex0, &tex1, &tex2};
    const Grad* grads[3] = {&grad0, &grad1, &grad2};
    const wt_lane_colours* gr[3] = {&g0, &g1, &g2};
    wt_scatter_stochastic_rows(texs, grads, smp, params, 3, layers.c, wt_rows_of(reads), weigh, gr, 1);
}

// lanes.stochastic.scatter_stochastic_face_reads_lanes: stochastic.scatter_stochastic with a texture
// per face, every filter's: each projection's read on its + face (rows of `plus`) and on its - face
// (rows of `minus`; a pixel reads one of the two), in the order x+, x-, y+, y-, z+, z-, each adding
// its projection's gradient g_a[l] (times w where weigh) through its stochastic taps.
// twin: stochastic.scatter_stochastic
template <class Tex, class Grad, class Smp, class Params, class Ints>
WT_INLINE void wt_scatter_stochastic_face_reads_lanes(const Tex& tex_px, const Tex& tex_nx, const Tex& tex_py,
                                                      const Tex& tex_ny, const Tex& tex_pz, const Tex& tex_nz,
                                                      const Grad& grad_px, const Grad& grad_nx, const Grad& grad_py,
                                                      const Grad& grad_ny, const Grad& grad_pz, const Grad& grad_nz,
                                                      const Smp& smp, const Params& params, const Ints& layers,
                                                      const wt_lane_reads& plus, const wt_lane_reads& minus, int weigh,
                                                      const wt_lane_colours& g0, const wt_lane_colours& g1,
                                                      const wt_lane_colours& g2) {
    const Tex* texs[6] = {&tex_px, &tex_nx, &tex_py, &tex_ny, &tex_pz, &tex_nz};
    const Grad* grads[6] = {&grad_px, &grad_nx, &grad_py, &grad_ny, &grad_pz, &grad_nz};
    const wt_lane_colours* gr[6] = {&g0, &g0, &g1, &g1, &g2, &g2};
    wt_scatter_stochastic_rows(texs, grads, smp, params, 6, layers.c, wt_face_rows(plus, minus), weigh, gr, 1);
}
