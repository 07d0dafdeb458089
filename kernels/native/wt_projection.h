// Plane projections for a lane of pixels: what each pixel of a triplanar lane reads from each
// projection, its UV, LOD and weight, a lane at a time. The scalar blocks of
// warptex.kernels.projection and .footprint restated operation for operation (Warp's own wp::
// functions or their exact vector twins, no contraction) on clang vectors of a value per lane pixel
// (the weights' exponent and the other launch-wide choices are tested once, outside them), so the
// reads are the scalar blocks' bits. Every filter (the anisotropic footprint's branches as
// selects) and both weights: biplanar's branches, which pick each pixel's axes, as selects too (the
// rare pairs whose powers underflow go pixel by pixel).
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_footprint.h"
#include "wt_normals.h"
#include "wt_sample.h"
#include "wt_scatter.h"

// (u, v) and the footprint of projection `axis` at tiling t of `tex` (its level 0) on the lane's
// surface P, N, DX, DY (projection.plane_uv and plane_footprint): also what a splat layer mapped
// triplanar reads.
// twin: projection.plane_uv
template <class Proj, class Smp, class Tex>
WT_INLINE void wt_plane_reads(const Proj& proj, const Smp& smp, int axis, float t, const Tex& tex, const wt_vf* P,
                              const wt_vf* N, const wt_vf* DX, const wt_vf* DY, wt_vf& u, wt_vf& v,
                              wt_footprint_lanes& fp) {
    float o0 = 0.0f, o1 = 0.0f;  // projection.origin_uv, in float64
    if (proj.origin_mode != 0) {
        const double a = axis == 0 ? proj.origin.c[2] : proj.origin.c[0];
        const double b = axis == 1 ? proj.origin.c[2] : proj.origin.c[1];
        const double td = (double)t;
        double ou = a * td, ov = b * td;
        if (proj.origin_mode == WT_ORIGIN_FOLDED) {
            ou = ou - wp::floor(ou * 0.5) * 2.0;
            ov = ov - wp::floor(ov * 0.5) * 2.0;
        }
        o0 = (float)ou;
        o1 = (float)ov;
    }
    const char* offset = (const char*)proj.offsets.data + (long long)axis * proj.offsets.strides[0];
    const float off0 = *(const float*)offset, off1 = *(const float*)(offset + proj.offsets.strides[1]);
    const float width = (float)wt_int(tex.level_width, 0), height = (float)wt_int(tex.level_height, 0);
    const int c0 = axis == 0 ? 2 : 0, c1 = axis == 1 ? 2 : 1;  // projection.plane_coords
    const wt_vf one = 1.0f;
    wt_vf s = one;  // projection.u_sign: sign_or_one(n.z) for Z, -sign_or_one(n[axis]) for X and Y
    if (proj.mirror_fix != 0) s = axis == 2 ? wt_sel(N[2] < 0.0f, -one, one) : -wt_sel(N[axis] < 0.0f, -one, one);
    u = (P[c0] * t + o0) * s + off0;
    v = (P[c1] * t + o1) + off1;
    fp = wt_footprint(smp, (DX[c0] * t) * s, DX[c1] * t, (DY[c0] * t) * s, DY[c1] * t, width,
                      height);  // plane_derivative
}

// Reads r = 0 .. count - 1 of a lane_reads matrix, read r of *texs[r] (lane pixel l's layer
// layers[r][l]) over its footprint, into value in read order (wt_accumulate_footprint: value += w ·
// sample where add, value = sample where not).
template <class Tex, class Smp, class Reads>
WT_INLINE void wt_accumulate_reads(const Tex* const* texs, const Smp& smp, const int* const* layers, int count, int add,
                                   const Reads& at, wt_lane_colours& value) {
    for (int r = 0; r < count; ++r)
        wt_accumulate_footprint(*texs[r], smp, layers[r], at.data[r], at.data[3 + r], at.data[6 + r], at.data[12 + r],
                                at.data[15 + r], at.data[18 + r], at.data[9 + r], add, value);
}

// Row l, lane pixel l's sample of read r of reads (layer layers[l]) over its footprint, where its
// weight is positive (wt_accumulate_footprint, add 0), read in place rather than copied into a
// matrix of that read alone first.
template <class Tex, class Smp, class Ints, class Reads>
WT_INLINE wt_lane_colours wt_read_lane(const Tex& tex, const Smp& smp, const Ints& layers, const Reads& reads, int r) {
    wt_lane_colours value;
    wt_accumulate_footprint(tex, smp, layers.c, reads.data[r], reads.data[3 + r], reads.data[6 + r], reads.data[12 + r],
                            reads.data[15 + r], reads.data[18 + r], reads.data[9 + r], 0, value);
    return value;
}

// projection.power_weight, operation for operation with Warp's own functions, for one pixel (the
// rare lanes the vectors leave to it).
// twin: projection.power_weight
WT_INLINE float wt_power_weight(float r, float exponent) {
    float w = 0.0f;
    if (exponent == 0.0f) {
        w = 1.0f;
    } else if (r > 0.0f) {
        const int k = (int)exponent;
        if ((float)k == exponent && k > 0 && k < WT_MAX_INT_EXPONENT) {
            const float r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
            w = ((k & 1) != 0 ? r : 1.0f) * ((k & 2) != 0 ? r2 : 1.0f) * ((k & 4) != 0 ? r4 : 1.0f);
            w = w * ((k & 8) != 0 ? r8 : 1.0f) * ((k & 16) != 0 ? r8 * r8 : 1.0f);
        } else {
            w = wp::exp(exponent * wp::log(r));
        }
    }
    return w;
}

// twin: projection.biplanar_pair
WT_INLINE wt_v2 wt_biplanar_pair(float major, float median, float exponent) {
    const float edge = (float)WT_BIPLANAR_EDGE;
    const float b0 = wp::clamp((major - edge) / (1.0f - edge), 0.0f, 1.0f);
    const float b1 = wp::clamp((median - edge) / (1.0f - edge), 0.0f, 1.0f);
    wt_v2 w(wt_power_weight(b0, exponent), wt_power_weight(b1, exponent));
    if (w.c[0] + w.c[1] < (float)WT_WEIGHT_EPS) {
        const float m = wp::max(b0, b1);
        if (m > 0.0f)
            w = wt_v2(wt_power_weight(b0 / m, exponent), wt_power_weight(b1 / m, exponent));
        else
            w = wt_v2(1.0f, 1.0f);
    }
    return w;
}

// projection.power_weight of a lane's r, its exponent the same in every lane: integer exponents by
// multiplication, others with exp and log lane by lane (where `active`).
// twin: projection.power_weight
WT_INLINE wt_vf wt_power_lanes(wt_vf r, float exponent, wt_vi active) {
    const wt_vf zero = 0.0f, one = 1.0f;
    if (exponent == 0.0f) return one;
    const int k = (int)exponent;
    if ((float)k == exponent && k > 0 && k < WT_MAX_INT_EXPONENT) {
        const wt_vf r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
        const wt_vf power = (((k & 1) != 0 ? r : one) * ((k & 2) != 0 ? r2 : one) * ((k & 4) != 0 ? r4 : one)) *
                            ((k & 8) != 0 ? r8 : one) * ((k & 16) != 0 ? r8 * r8 : one);
        return wt_sel(r > 0.0f, power, zero);
    }
    float w[WT_L];
    for (int l = 0; l < WT_L; ++l) w[l] = active[l] && r[l] > 0.0f ? wp::exp(exponent * wp::log(r[l])) : 0.0f;
    wt_vf result;
    __builtin_memcpy(&result, w, sizeof(result));
    return result;
}

// projection.biplanar_weights of the lane, each pixel's axes chosen by selects.
// twin: projection.biplanar_weights
WT_INLINE void wt_biplanar_weights(const wt_vf* N, wt_vi covered, float sharpness, wt_vf* W) {
    const wt_vf zero = 0.0f, one = 1.0f;
    const wt_vf length0 = wt_vsqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);  // wp::length
    const wt_vi over = length0 > wt_float_max;                                // |n|² overflowed: normals.unsquared
    const wt_vf largest = wt_vmax(wt_vmax(wt_vabs(N[0]), wt_vabs(N[1])), wt_vabs(N[2]));
    wt_vf U[3];
    for (int e = 0; e < 3; ++e) U[e] = wt_sel(over, N[e] / largest, N[e]);
    const wt_vf length = wt_sel(over, wt_vsqrt(U[0] * U[0] + U[1] * U[1] + U[2] * U[2]), length0);
    const wt_vi weighed = covered & wt_finite(N[0]) & wt_finite(N[1]) & wt_finite(N[2]) & (length > 0.0f);
    const wt_vf divisor = wt_sel(weighed, length, one);
    const wt_vf a0 = wt_vabs(U[0]) / divisor, a1 = wt_vabs(U[1]) / divisor, a2 = wt_vabs(U[2]) / divisor;
    const float exponent = sharpness / 8.0f;
    const wt_vi minor_z = (a2 <= a0) & (a2 <= a1), minor_y = ~minor_z & (a1 <= a0), minor_x = ~minor_z & ~minor_y;
    const wt_vf major = wt_sel(minor_x, a1, a0), median = wt_sel(minor_z, a1, a2);
    const float edge = (float)WT_BIPLANAR_EDGE;  // biplanar_pair
    const wt_vf b0 =
        wt_vmin(wt_vmax(zero, (major - edge) / (1.0f - edge)), one);  // wp::clamp(x, 0, 1) = fmin(fmax(0, x), 1)
    const wt_vf b1 = wt_vmin(wt_vmax(zero, (median - edge) / (1.0f - edge)), one);
    wt_vf p0 = wt_power_lanes(b0, exponent, weighed), p1 = wt_power_lanes(b1, exponent, weighed);
    const wt_vi underflowed = weighed & (p0 + p1 < (float)WT_WEIGHT_EPS);
    if (__builtin_reduce_or(underflowed)) {  // both powers underflowed (or a diagonal): biplanar_pair's own fallback
        for (int l = 0; l < WT_L; ++l) {
            if (!underflowed[l]) continue;
            const wt_v2 pair = wt_biplanar_pair(major[l], median[l], exponent);
            p0[l] = pair.c[0];
            p1[l] = pair.c[1];
        }
    }
    W[0] = wt_sel(minor_x, zero, p0);
    W[1] = wt_sel(minor_z, p1, wt_sel(minor_y, zero, p0));
    W[2] = wt_sel(minor_z, zero, p1);
    const wt_vf total = wt_vmax(W[0] + W[1] + W[2], (float)WT_WEIGHT_EPS);
    for (int e = 0; e < 3; ++e) W[e] = wt_sel(weighed, W[e] / total, zero);
}

// projection.triplanar_weights of the lane.
// twin: projection.triplanar_weights
WT_INLINE void wt_triplanar_weights(const wt_vf* N, wt_vi covered, float sharpness, wt_vf* W) {
    const wt_vf zero = 0.0f;
    const wt_vf a0 = wt_vabs(N[0]), a1 = wt_vabs(N[1]), a2 = wt_vabs(N[2]);
    const wt_vf m = wt_vmax(wt_vmax(a0, a1), a2);
    const wt_vi weighed = covered & wt_finite(N[0]) & wt_finite(N[1]) & wt_finite(N[2]) & (m > 0.0f);
    const wt_vf R[3] = {a0 / m, a1 / m, a2 / m};  // |n| / max |n|
    for (int e = 0; e < 3; ++e) W[e] = wt_power_lanes(R[e], sharpness, weighed);
    const wt_vf total = wt_vmax(W[0] + W[1] + W[2], (float)WT_WEIGHT_EPS);
    for (int e = 0; e < 3; ++e) W[e] = wt_sel(weighed, W[e] / total, zero);
}

// twin: slopes.power_slope
WT_INLINE float wt_power_slope(float r, float exponent) {
    float s = 0.0f;
    if (r > 0.0f) s = wp::mul(wt_power_weight(r, exponent), wp::log(r));
    return s;
}

// twin: slopes.normalised_slope
WT_INLINE wt_v3 wt_normalised_slope(const wt_v3& w, const wt_v3& dw) {
    const float total = wp::add(wp::add(w.c[0], w.c[1]), w.c[2]);
    wt_v3 d = wp::div(dw, (float)WT_WEIGHT_EPS);
    if (total >= (float)WT_WEIGHT_EPS)
        d = wp::div(wp::sub(dw, wp::mul(w, wp::div(wp::add(wp::add(dw.c[0], dw.c[1]), dw.c[2]), total))), total);
    return d;
}

// twin: slopes.biplanar_pair_slope
WT_INLINE void wt_biplanar_pair_slope(float major, float median, float exponent, wt_v2& w, wt_v2& d) {
    const float edge = (float)WT_BIPLANAR_EDGE;
    const float b0 = wp::clamp(wp::div(wp::sub(major, edge), wp::sub(1.0f, edge)), 0.0f, 1.0f);
    const float b1 = wp::clamp(wp::div(wp::sub(median, edge), wp::sub(1.0f, edge)), 0.0f, 1.0f);
    w = wt_v2(wt_power_weight(b0, exponent), wt_power_weight(b1, exponent));
    d = wt_v2(wt_power_slope(b0, exponent), wt_power_slope(b1, exponent));
    if (wp::add(w.c[0], w.c[1]) < (float)WT_WEIGHT_EPS) {
        const float m = wp::max(b0, b1);
        w = wt_v2(1.0f, 1.0f);
        d = wt_v2(0.0f, 0.0f);
        if (m > 0.0f) {
            w = wt_v2(wt_power_weight(wp::div(b0, m), exponent), wt_power_weight(wp::div(b1, m), exponent));
            d = wt_v2(wt_power_slope(wp::div(b0, m), exponent), wt_power_slope(wp::div(b1, m), exponent));
        }
    }
}

// projection.biplanar_axes of one pixel's normal n: the minor axis' index (-1 for a zero or
// non-finite normal), the major and median components of the unit |n| into major and median.
// twin: projection.biplanar_axes
WT_INLINE int wt_biplanar_axes(const wt_v3& n, float& major, float& median) {
    wt_v3 u = n;
    float length = wp::length(n);
    if (length > wt_float_max) {  // |n|² overflowed: normals.unsquared
        u = wp::div(n, wp::max(wt_v3(wp::abs(n.c[0]), wp::abs(n.c[1]), wp::abs(n.c[2]))));
        length = wp::length(u);
    }
    major = 0.0f, median = 0.0f;
    if (!(wp::isfinite(n) && length > 0.0f)) return -1;
    const wt_v3 a = wp::div(wt_v3(wp::abs(u.c[0]), wp::abs(u.c[1]), wp::abs(u.c[2])), length);
    if (a.c[2] <= a.c[0] && a.c[2] <= a.c[1]) {
        major = a.c[0], median = a.c[1];
        return 2;
    }
    if (a.c[1] <= a.c[0]) {
        major = a.c[0], median = a.c[2];
        return 1;
    }
    major = a.c[1], median = a.c[2];
    return 0;
}

// twin: projection.biplanar_spread
WT_INLINE wt_v3 wt_biplanar_spread(const wt_v2& pair, int minor) {
    if (minor == 2) return wt_v3(pair.c[0], pair.c[1], 0.0f);
    if (minor == 1) return wt_v3(pair.c[0], 0.0f, pair.c[1]);
    return wt_v3(0.0f, pair.c[0], pair.c[1]);
}

// slopes.projection_weights_slope of one pixel's normal n (the projected space's), with Warp's
// own functions in the scalar blocks' order (only the sharpness' gradient needs it: pixel by pixel).
// twin: slopes.projection_weights_slope
template <class Proj> WT_INLINE wt_v3 wt_weights_slope(const Proj& proj, const wt_v3& n) {
    const float sharpness = wt_float(proj.sharpness, 0);
    wt_v3 d(0.0f);
    if (proj.weights == WT_WEIGHTS_BIPLANAR) {  // biplanar_weights_slope
        float major, median;
        const int minor = wt_biplanar_axes(n, major, median);
        if (minor >= 0) {
            wt_v2 pair, slope;
            wt_biplanar_pair_slope(major, median, wp::div(sharpness, 8.0f), pair, slope);
            d = wp::div(wt_normalised_slope(wt_biplanar_spread(pair, minor), wt_biplanar_spread(slope, minor)), 8.0f);
        }
    } else {  // triplanar_weights_slope
        const wt_v3 a(wp::abs(n.c[0]), wp::abs(n.c[1]), wp::abs(n.c[2]));
        const float m = wp::max(a);
        if (wp::isfinite(n) && m > 0.0f) {
            const float r0 = wp::div(a.c[0], m), r1 = wp::div(a.c[1], m), r2 = wp::div(a.c[2], m);
            const wt_v3 w(wt_power_weight(r0, sharpness), wt_power_weight(r1, sharpness),
                          wt_power_weight(r2, sharpness));
            d = wt_normalised_slope(
                w, wt_v3(wt_power_slope(r0, sharpness), wt_power_slope(r1, sharpness), wt_power_slope(r2, sharpness)));
        }
    }
    return d;
}

// lanes.projection.triplanar_reads_lane: what the lane's pixels base .. base + count - 1 read from
// each projection, with triplanar or biplanar weights (proj.weights): projection.projection_uv,
// projection_footprint and projection_weights, into the rows of reads (all 0 where a projection is
// not read; every row is written). unit_normals: the UVs, footprints and faces of the unit normal
// (normal_blend.unit_base_normal, as normal mapping reads them; the weights are the normal's as
// given). side: 0, each projection on faces' texture of its axis (px, py, pz); 1 or 2, on the + or
// - face of that axis, weight 0 where the normal looks at the other face.
// twin: projection.projection_weights
template <class Faces, class Proj, class Smp, class Pixels, class Reads>
WT_INLINE void wt_triplanar_reads_into(const Faces& faces, const Proj& proj, const Smp& smp, const Pixels& pixels,
                                       int base, int count, int unit_normals, int side, Reads& reads,
                                       wt_vf* surface = nullptr) {
    // projection.surface: the lane's pixels (the tail repeats pixel base, not read), in the projected space.
    float p_[3][WT_L], n_[3][WT_L], dx_[3][WT_L], dy_[3][WT_L], mask_[1][WT_L];  // read into arrays, then as vectors
    wt_rows(pixels.position, base, count, 3, p_);
    wt_rows(pixels.normal, base, count, 3, n_);
    wt_rows(pixels.position_dx, base, count, 3, dx_);
    wt_rows(pixels.position_dy, base, count, 3, dy_);
    wt_rows(pixels.mask, base, count, 1, mask_);
    const wt_vi covered = wt_covered(mask_[0], count);
    if (proj.object_space != 0) {  // projection.object_space
        for (int l = 0; l < WT_L; ++l) {
            wt_v3 p, n, dx, dy;
            for (int e = 0; e < 3; ++e) p.c[e] = p_[e][l], n.c[e] = n_[e][l], dx.c[e] = dx_[e][l], dy.c[e] = dy_[e][l];
            p = wp::transform_point(proj.world_to_object, p);
            n = wp::mul(proj.normal_to_object, n);
            dx = wp::transform_vector(proj.world_to_object, dx);
            dy = wp::transform_vector(proj.world_to_object, dy);
            for (int e = 0; e < 3; ++e) p_[e][l] = p.c[e], n_[e][l] = n.c[e], dx_[e][l] = dx.c[e], dy_[e][l] = dy.c[e];
        }
    }
    wt_vf P[3], N[3], DX[3], DY[3];
    for (int e = 0; e < 3; ++e) {
        __builtin_memcpy(&P[e], p_[e], sizeof(wt_vf));
        __builtin_memcpy(&N[e], n_[e], sizeof(wt_vf));
        __builtin_memcpy(&DX[e], dx_[e], sizeof(wt_vf));
        __builtin_memcpy(&DY[e], dy_[e], sizeof(wt_vf));
    }
    const float sharpness = wt_float(proj.sharpness, 0);
    wt_vf W[3];
    if (proj.weights == WT_WEIGHTS_BIPLANAR)
        wt_biplanar_weights(N, covered, sharpness, W);
    else
        wt_triplanar_weights(N, covered, sharpness, W);
    if (unit_normals != 0)
        wt_unit_normals(N);  // normal_blend.unit_base_normal: normal mapping reads on the unit normal
    if (surface)             // where asked, the surface in the projected space: P, N (the normal the reads use), DX, DY
        for (int e = 0; e < 3; ++e)
            surface[e] = P[e], surface[3 + e] = N[e], surface[6 + e] = DX[e], surface[9 + e] = DY[e];
    if (side != 0) {  // faces.on_face: the - face where n[axis] < 0 (the normal it reads on), else the + face
        for (int axis = 0; axis < 3; ++axis) {
            const wt_vi negative = N[axis] < 0.0f;
            W[axis] = wt_sel(side == 2 ? negative : ~negative, W[axis], (wt_vf)0.0f);
        }
    }
    // Per projection: projection.plane_uv and plane_footprint, where its weight is > 0.
    for (int axis = 0; axis < 3; ++axis) {
        const float t = wt_float(proj.tiling, wp::min(axis, proj.tiling.shape[0] - 1));  // projection_tiling
        // faces.on_axis
        const auto& tex = side == 2 ? (axis == 0 ? faces.nx : (axis == 1 ? faces.ny : faces.nz))
                                    : (axis == 0 ? faces.px : (axis == 1 ? faces.py : faces.pz));
        wt_vf u, v;
        wt_footprint_lanes fp;
        wt_plane_reads(proj, smp, axis, t, tex, P, N, DX, DY, u, v, fp);
        wt_put_read(reads, axis, W[axis] > 0.0f, u, v, fp, W[axis]);
    }
}
// wt_triplanar_reads_into as a lane_reads matrix, which the lane bodies pass on.
template <class Faces, class Proj, class Smp, class Pixels>
WT_INLINE wt_lane_reads wt_triplanar_reads_lane(const Faces& faces, const Proj& proj, const Smp& smp,
                                                const Pixels& pixels, int base, int count, int unit_normals, int side) {
    wt_lane_reads reads;
    wt_triplanar_reads_into(faces, proj, smp, pixels, base, count, unit_normals, side, reads);
    return reads;
}

// lanes.projection.triplanar_colour_lane: row base + l of out, lane pixel l's colour, its
// projections' samples (on faces' texture of each axis, layer layers[l]) blended by their weights in
// read order (wt_accumulate_reads, add 1), from wt_triplanar_reads_into's reads, in rows that are
// not zeroed first (every row is written) and never copied.
// twin: triplanar._bodies:colour
template <class Faces, class Proj, class Smp, class Pixels, class Ints, class Out>
WT_INLINE void wt_triplanar_colour_lane(const Faces& faces, const Proj& proj, const Smp& smp, const Pixels& pixels,
                                        int base, int count, const Ints& layers, const Out& out) {
    wt_lane_read_rows reads;
    wt_triplanar_reads_into(faces, proj, smp, pixels, base, count, 0, 0, reads);
    const decltype(&faces.px) texs[3] = {&faces.px, &faces.py, &faces.pz};
    const int* per_read[3] = {layers.c, layers.c, layers.c};
    wt_lane_colours value;
    wt_accumulate_reads(texs, smp, per_read, 3, 1, reads, value);
    wt_write_lane(out, base, count, value);
}

// The tiling's, offsets' and sharpness' gradients of a lane's plain projection reads
// (slopes.add_plane_slopes), where each is needed (its array in grads not empty): each read's
// projection.plane_sample_slope, from its wt_footprint_slopes (the tiling's: d/du · du/dt + d/dv ·
// dv/dt + d/dlod · dlod/dt + d/dspread / t, on the projected surface wt_triplanar_reads_into hands
// back: its slope coords, the mirror-fix sign of the normal the reads use, wt_lod_scale_slope; the
// offsets': d/du and d/dv), then with the read's gradient wg = w · g[axis][l] where weigh
// (colour's), g[axis][l] where not (normal mapping's stored samples): dot(wg, slope) into the
// tiling, dot(wg, d/du) and dot(wg, d/dv) into the read's offsets, and dw[axis] · dot(g[axis][l],
// value) into the sharpness (dw: the pixel's wt_weights_slope; only where weigh). Added pixel by
// pixel and projection by projection (Warp's wp::dot and wp::mul, so the sums are the one-pixel
// kernel's bits).
// twin: slopes.add_plane_slopes
template <class Tex, class Grads, class Proj, class Smp>
WT_OUTLINE void wt_add_plane_slopes_outlined(const Tex* const* texs, const Grads& grads, const Proj& proj,
                                             const Smp& smp, const int* layers, const wt_lane_read_rows& reads,
                                             const wt_vf* surface, int count, const wt_lane_colours* const* g,
                                             int weigh) {
    const int tiling = grads.tiling.shape[0] > 0, offsets = grads.offsets.shape[0] > 0;
    const int sharpness = weigh && grads.sharpness.shape[0] > 0;
    const float o[3] = {(float)proj.origin.c[0], (float)proj.origin.c[1], (float)proj.origin.c[2]};
    wt_f4 slope[3][WT_L], value[3][WT_L], d_u[3][WT_L], d_v[3][WT_L];
    for (int axis = 0; axis < 3; ++axis) {  // projection.plane_sample_slope of each read
        const Tex& tex = *texs[axis];
        const float t = wt_float(proj.tiling, wp::min(axis, proj.tiling.shape[0] - 1));  // projection_tiling
        const float width = (float)wt_int(tex.level_width, 0), height = (float)wt_int(tex.level_height, 0);
        wt_f4 f[WT_L], d_lod[WT_L], d_spread[WT_L];
        const float* weight = reads.data[9 + axis];
        wt_footprint_slopes(tex, smp, layers, reads.data[axis], reads.data[3 + axis], reads.data[6 + axis],
                            reads.data[12 + axis], reads.data[15 + axis], reads.data[18 + axis], weight, f, value[axis],
                            d_u[axis], d_v[axis], d_lod, d_spread);
        if (!tiling) continue;
        const int c0 = axis == 0 ? 2 : 0, c1 = axis == 1 ? 2 : 1;  // projection.plane_coords
        for (int l = 0; l < count; ++l) {
            if (!(weight[l] > 0.0f)) continue;
            const float normal = surface[3 + axis][l];
            float s = 1.0f;  // projection.u_sign
            if (proj.mirror_fix != 0) s = axis == 2 ? (normal < 0.0f ? -1.0f : 1.0f) : -(normal < 0.0f ? -1.0f : 1.0f);
            const float cu = (surface[c0][l] + o[c0]) * s, cv = surface[c1][l] + o[c1];  // projection.slope_coords
            const float lod_slope = wt_lod_scale_slope(width, height, surface[6 + c0][l], surface[6 + c1][l],
                                                       surface[9 + c0][l], surface[9 + c1][l], t);
            slope[axis][l] = d_u[axis][l] * cu + d_v[axis][l] * cv + d_lod[l] * lod_slope + d_spread[l] / t;
        }
    }
    for (int l = 0; l < count; ++l) {  // pixel by pixel, projection by projection
        wt_v3 dw(0.0f);
        if (sharpness && (reads.data[9][l] > 0.0f || reads.data[10][l] > 0.0f || reads.data[11][l] > 0.0f))
            dw = wt_weights_slope(proj, wt_v3(surface[3][l], surface[4][l], surface[5][l]));
        for (int axis = 0; axis < 3; ++axis) {
            const float w = reads.data[9 + axis][l];
            if (!(w > 0.0f)) continue;
            const wt_v4 gl(g[axis]->data[l][0], g[axis]->data[l][1], g[axis]->data[l][2], g[axis]->data[l][3]);
            const wt_v4 wg = weigh ? wp::mul(w, gl) : gl;
            if (tiling) {
                const wt_f4& d = slope[axis][l];
                float* at = (float*)((char*)grads.tiling.data +
                                     (long long)wp::min(axis, grads.tiling.shape[0] - 1) * grads.tiling.strides[0]);
                *at = *at + wp::dot(wg, wt_v4(d[0], d[1], d[2], d[3]));
            }
            if (offsets) {
                const wt_f4 &du = d_u[axis][l], &dv = d_v[axis][l];
                char* row = (char*)grads.offsets.data + (long long)axis * grads.offsets.strides[0];
                float* at_u = (float*)row;
                float* at_v = (float*)(row + grads.offsets.strides[1]);
                *at_u = *at_u + wp::dot(wg, wt_v4(du[0], du[1], du[2], du[3]));
                *at_v = *at_v + wp::dot(wg, wt_v4(dv[0], dv[1], dv[2], dv[3]));
            }
            if (sharpness) {
                const wt_f4& v = value[axis][l];
                float* at = (float*)grads.sharpness.data;
                *at = *at + wp::mul(dw.c[axis], wp::dot(gl, wt_v4(v[0], v[1], v[2], v[3])));
            }
        }
    }
}

// wt_add_plane_slopes_outlined where any of the three gradients is needed: out of line, so that a
// texel-only gradient's lane keeps the code it had without them (inlined, callgrind put the
// texel-only forward+backward of the terrain at 2093.2 instructions a sample against 1906.9,
// biplanar, and 2552.0 against 2379.2, triplanar).
template <class Tex, class Grads, class Proj, class Smp>
WT_INLINE void wt_add_plane_slopes(const Tex* const* texs, const Grads& grads, const Proj& proj, const Smp& smp,
                                   const int* layers, const wt_lane_read_rows& reads, const wt_vf* surface, int count,
                                   const wt_lane_colours* const* g, int weigh) {
    if (grads.tiling.shape[0] > 0 || grads.offsets.shape[0] > 0 || (weigh && grads.sharpness.shape[0] > 0))
        wt_add_plane_slopes_outlined(texs, grads, proj, smp, layers, reads, surface, count, g, weigh);
}

// lanes.projection.triplanar_scatter_lane: the texel gradients of plain colour's reads (each
// projection's share w · g[l] of lane pixel l's output gradient adj[base + l], into the gradient
// of its axis's texture, layer layers[l]), from wt_triplanar_reads_into's reads in rows that are
// not zeroed first and never copied, added pixel by pixel and read by read (wt_scatter_lod); then
// colour_grad's adds into the tiling's, offsets' and sharpness' gradients where they are needed
// (wt_add_plane_slopes).
// twin: triplanar._bodies:colour_grad
template <class Faces, class Grads, class Proj, class Smp, class Pixels, class Ints, class Adj>
WT_INLINE void wt_triplanar_scatter_lane(const Faces& faces, const Grads& grads, const Proj& proj, const Smp& smp,
                                         const Pixels& pixels, int base, int count, const Ints& layers,
                                         const Adj& adj) {
    wt_lane_read_rows reads;
    wt_vf surface[12];  // P, N, DX, DY of the lane, for the tiling's slopes
    wt_triplanar_reads_into(faces, proj, smp, pixels, base, count, 0, 0, reads, surface);
    const decltype(&faces.px) texs[3] = {&faces.px, &faces.py, &faces.pz};
    const decltype(&grads.px) grad[3] = {&grads.px, &grads.py, &grads.pz};
    const wt_lane_colours g = wt_adj_lane(adj, base, count);
    wt_scatter_lod(texs, grad, smp, 3, layers.c, reads, 1, g);
    const wt_lane_colours* gr[3] = {&g, &g, &g};
    wt_add_plane_slopes(texs, grads, proj, smp, layers.c, reads, surface, count, gr, 1);
}

// Normal mapping's reads of the lane, on the unit normal (wt_triplanar_reads_into's unit_normals,
// each projection on faces' texture of its axis), in rows that are not zeroed first and never
// copied; each projection's sample s[axis] (row l: lane pixel l's, where its weight is > 0, else
// 0) read in place (wt_read_lane).
template <class Faces, class Proj, class Smp, class Pixels, class Ints>
WT_INLINE void wt_normal_samples_into(const Faces& faces, const Proj& proj, const Smp& smp, const Pixels& pixels,
                                      int base, int count, const Ints& layers, wt_lane_read_rows& reads,
                                      wt_lane_colours* s) {
    wt_triplanar_reads_into(faces, proj, smp, pixels, base, count, 1, 0, reads);
    s[0] = wt_read_lane(faces.px, smp, layers, reads, 0);
    s[1] = wt_read_lane(faces.py, smp, layers, reads, 1);
    s[2] = wt_read_lane(faces.pz, smp, layers, reads, 2);
}

// lanes.projection.triplanar_normals_lane: row l, lane pixel l's normal as normal mapping's pixel
// body makes it (x, y, z, 0; 0 where it is not covered), from wt_normal_samples_into's reads and
// samples (wt_surface_normals_lane), in one call.
// twin: triplanar._bodies:normal
template <class Faces, class Proj, class NM, class Smp, class Pixels, class Ints>
WT_INLINE wt_lane_colours wt_triplanar_normals_lane(const Faces& faces, const Proj& proj, const NM& nm, const Smp& smp,
                                                    const Pixels& pixels, int base, int count, const Ints& layers) {
    wt_lane_read_rows reads;
    wt_lane_colours s[3];
    wt_normal_samples_into(faces, proj, smp, pixels, base, count, layers, reads, s);
    return wt_surface_normals_lane(proj, nm, pixels, base, count, reads, s[0], s[1], s[2]);
}

// lanes.projection.triplanar_samples_lane: what normal mapping's first step stores for lane pixels
// i = base .. base + count - 1 (wt_normal_samples_into's): weights[i], the projections' weights
// (0 where the pixel is not covered), and samples[i, axis], each projection's sample (0 where its
// weight is 0).
// twin: triplanar._bodies:samples
template <class Faces, class Proj, class Smp, class Pixels, class Ints, class Samples, class Weights>
WT_INLINE void wt_triplanar_samples_lane(const Faces& faces, const Proj& proj, const Smp& smp, const Pixels& pixels,
                                         int base, int count, const Ints& layers, const Samples& samples,
                                         const Weights& weights) {
    wt_lane_read_rows reads;
    wt_lane_colours s[3];
    wt_normal_samples_into(faces, proj, smp, pixels, base, count, layers, reads, s);
    for (int l = 0; l < count; ++l) {
        *wp::address(weights, base + l) = wt_v3(reads.data[9][l], reads.data[10][l], reads.data[11][l]);
        for (int axis = 0; axis < 3; ++axis) {
            const float* row = s[axis].data[l];
            *wp::address(samples, base + l, axis) =
                reads.data[9 + axis][l] > 0.0f ? wt_v4(row[0], row[1], row[2], row[3]) : wt_v4(0.0f);
        }
    }
}

// lanes.projection.triplanar_scatter_samples_lane: the gradients adj[i, axis] of the samples normal
// mapping's first step stored (i = base .. base + count - 1), each added (not weighted) into the
// texels of its projection's read on the unit normal, pixel by pixel and read by read
// (wt_scatter_lod_of), with the reads in rows that are not zeroed first and never copied; where
// the tiling's or the offsets' gradient is needed, each read's adds into them (wt_add_plane_slopes).
// twin: triplanar._bodies:samples_grad
template <class Faces, class Grads, class Proj, class Smp, class Pixels, class Ints, class Adj>
WT_INLINE void wt_triplanar_scatter_samples_lane(const Faces& faces, const Grads& grads, const Proj& proj,
                                                 const Smp& smp, const Pixels& pixels, int base, int count,
                                                 const Ints& layers, const Adj& adj) {
    wt_lane_read_rows reads;
    wt_vf surface[12];  // P, N (unit), DX, DY of the lane, for the tiling's slopes
    wt_triplanar_reads_into(faces, proj, smp, pixels, base, count, 1, 0, reads, surface);
    wt_lane_colours g[3];  // row l: lane pixel l's gradient of each projection's sample (0 past count)
    for (int l = 0; l < count; ++l)
        for (int axis = 0; axis < 3; ++axis) {
            const wt_v4 a = *wp::address(adj, base + l, axis);
            for (int c = 0; c < 4; ++c) g[axis].data[l][c] = a.c[c];
        }
    const decltype(&faces.px) texs[3] = {&faces.px, &faces.py, &faces.pz};
    const decltype(&grads.px) grad[3] = {&grads.px, &grads.py, &grads.pz};
    const wt_lane_colours* gr[3] = {&g[0], &g[1], &g[2]};
    wt_scatter_lod_of(texs, grad, smp, 3, layers.c, reads, 0, gr, 1);
    wt_add_plane_slopes(texs, grads, proj, smp, layers.c, reads, surface, count, gr, 0);
}
