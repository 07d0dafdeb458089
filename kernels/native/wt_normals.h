// Normal mapping's arithmetic for a lane of pixels: each projection's sample decoded, mirror-fixed,
// blended with the unit surface normal and swizzled back, the projections blended by their weights
// and the blend normalised in world space, and the gradient of all that in the samples, a lane
// wide. Each function computes what the scalar blocks of warptex.kernels.normals and .triplanar
// compute, operation for operation and in the same order (Warp's wp::mul of a matrix and a vector
// column by column; wp::length and wp::dot as Warp writes them; each branch computed in every lane
// and chosen by selects; the rare blends past ~1.8e19 lane by lane with Warp's own functions).
#pragma once
#include "wt_config.h"
#include "wt_core.h"

// normals.direction of one v past ~1.8e19 (|v|² overflowed): normals.unsquared, then normalised.
// twin: normals.unsquared
WT_INLINE wt_v3 wt_unsquared_direction(const wt_v3& n) {
    return wp::normalize(wp::div(n, wp::max(wt_v3(wp::abs(n.c[0]), wp::abs(n.c[1]), wp::abs(n.c[2])))));
}

// normal_blend.unit_base_normal for the lane, in place: normals.direction where |n| > 0, on vectors
// (wp::length's and wp::normalize's own expressions, the same bits), lane by lane past ~1.8e19
// (|n|² overflowed: normals.unsquared first).
// twin: normal_blend.unit_base_normal
WT_INLINE void wt_unit_normals(wt_vf* N) {
    const wt_vf length = wt_vsqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);
    const wt_vi scaled = length > 0.0f;
    const wt_vf n0 = N[0], n1 = N[1], n2 = N[2], divisor = wt_sel(scaled, length, (wt_vf)1.0f);
    for (int e = 0; e < 3; ++e) N[e] = wt_sel(scaled, N[e] / divisor, N[e]);
    if (!__builtin_reduce_or(length > wt_float_max)) return;
    for (int l = 0; l < WT_L; ++l) {
        if (length[l] > wt_float_max) {
            const wt_v3 d = wt_unsquared_direction(wt_v3(n0[l], n1[l], n2[l]));
            for (int e = 0; e < 3; ++e) N[e][l] = d.c[e];
        }
    }
}

// twin: normals.sign_or_one
WT_INLINE wt_vf wt_sign_or_one(wt_vf x) { return wt_sel(x < 0.0f, (wt_vf)-1.0f, (wt_vf)1.0f); }
WT_INLINE wt_vf wt_length3(const wt_vf* v) { return wt_vsqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }
WT_INLINE wt_vf wt_dot3(const wt_vf* a, const wt_vf* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// wp::mul(m, v) (transposed: wp::mul(wp::transpose(m), v)): the columns times v's components, added in order.
WT_INLINE void wt_mul3(const wt_m3& m, const wt_vf* v, wt_vf* r, bool transposed) {
    for (int k = 0; k < 3; ++k) r[k] = (transposed ? m.data[0][k] : m.data[k][0]) * v[0];
    for (int j = 1; j < 3; ++j)
        for (int k = 0; k < 3; ++k) r[k] = r[k] + (transposed ? m.data[j][k] : m.data[k][j]) * v[j];
}

// wp::normalize(v): v over its length where that is > 0, else 0.
WT_INLINE void wt_normalize3(const wt_vf* v, wt_vf length, wt_vf* u) {
    const wt_vi positive = length > 0.0f;
    const wt_vf divisor = wt_sel(positive, length, (wt_vf)1.0f);
    for (int e = 0; e < 3; ++e) u[e] = wt_sel(positive, v[e] / divisor, (wt_vf)0.0f);
}

// normals.direction, the lanes whose |v|² overflows lane by lane.
// twin: normals.direction
WT_INLINE void wt_direction(const wt_vf* v, wt_vf* u) {
    const wt_vf length = wt_length3(v);
    wt_normalize3(v, length, u);
    if (!__builtin_reduce_or(length > wt_float_max)) return;
    for (int l = 0; l < WT_L; ++l) {
        if (length[l] > wt_float_max) {
            const wt_v3 d = wt_unsquared_direction(wt_v3(v[0][l], v[1][l], v[2][l]));
            for (int e = 0; e < 3; ++e) u[e][l] = d.c[e];
        }
    }
}

// normals.decode_normal: the slopes and z (x, y, z before the normalisation: xyz) and the unit t.
// twin: normals.decode_normal
template <class NM> WT_INLINE void wt_decode(const wt_vf* s, const NM& nm, wt_vf* xyz, wt_vf& r, wt_vf* t) {
    xyz[0] = s[0] * 2.0f - 1.0f;
    xyz[1] = s[1] * 2.0f - 1.0f;
    if (nm.flip_green != 0) xyz[1] = -xyz[1];
    r = 1.0f - xyz[0] * xyz[0] - xyz[1] * xyz[1];
    xyz[2] = nm.channels >= 3 ? s[2] * 2.0f - 1.0f : wt_sel(r > 0.0f, wt_vsqrt(r), (wt_vf)0.0f);
    const wt_vf scaled[3] = {xyz[0] * nm.strength, xyz[1] * nm.strength, xyz[2]};
    wt_normalize3(scaled, wt_length3(scaled), t);
}

// projection.u_sign: the mirror fix of projection `axis`.
// twin: projection.u_sign
WT_INLINE wt_vf wt_u_sign(const wt_vf* n, int axis, int mirror_fix) {
    if (mirror_fix == 0) return (wt_vf)1.0f;
    return axis == 2 ? wt_sign_or_one(n[2]) : -wt_sign_or_one(n[axis]);
}

// projection.plane_coords: projection `axis`' base normal.
// twin: projection.plane_coords
WT_INLINE void wt_base(const wt_vf* n, int axis, wt_vf* b) {
    b[0] = axis == 0 ? n[2] : n[0];
    b[1] = axis == 1 ? n[2] : n[1];
    b[2] = n[axis];
}

// normals.to_world: r.zyx for X, r.xzy for Y, r for Z (each its own inverse: also from world axes).
// twin: normals.to_world
WT_INLINE void wt_to_world(const wt_vf* r, int axis, wt_vf* out) {
    const int k[3][3] = {{2, 1, 0}, {0, 2, 1}, {0, 1, 2}};
    for (int e = 0; e < 3; ++e) out[e] = r[k[axis][e]];
}

// normal_blend.projected_normal: projection `axis`' normal (sample s) in world axes.
// twin: normal_blend.projected_normal
template <class Proj, class NM> WT_INLINE void wt_projected_normal(const wt_vf* s, int axis, const wt_vf* n,
                                                                   const Proj& proj, const NM& nm, wt_vf* out) {
    wt_vf xyz[3], r2, t[3], b[3], r[3];
    wt_decode(s, nm, xyz, r2, t);
    t[0] = t[0] * wt_u_sign(n, axis, proj.mirror_fix);
    wt_base(n, axis, b);
    if (nm.blend == WT_BLEND_UDN) {  // normals.blend_projected
        r[0] = t[0] + b[0], r[1] = t[1] + b[1], r[2] = b[2];
    } else if (nm.blend == WT_BLEND_RNM) {
        const wt_vf n1[3] = {b[0], b[1], wt_vabs(b[2]) + 1.0f}, n2[3] = {-t[0], -t[1], t[2]};
        const wt_vf q = wt_dot3(n1, n2) / n1[2];
        for (int e = 0; e < 3; ++e) r[e] = n1[e] * q - n2[e];
        r[2] = r[2] * wt_sign_or_one(b[2]);
    } else {
        r[0] = t[0] + b[0], r[1] = t[1] + b[1], r[2] = t[2] * b[2];
    }
    wt_to_world(r, axis, out);
}

// The blend of the projections' normals (before normal_blend.unit_normal), where their weights are > 0.
template <class Proj, class NM> WT_INLINE void wt_total(const wt_vf (*S)[4], const wt_vf* W, const wt_vf* n,
                                                        const Proj& proj, const NM& nm, wt_vf* total) {
    for (int e = 0; e < 3; ++e) total[e] = 0.0f;
    for (int axis = 0; axis < 3; ++axis) {
        const wt_vi read = W[axis] > 0.0f;
        if (!__builtin_reduce_or(read)) continue;
        wt_vf pn[3];
        wt_projected_normal(S[axis], axis, n, proj, nm, pn);
        for (int e = 0; e < 3; ++e) total[e] = total[e] + wt_sel(read, W[axis] * pn[e], (wt_vf)0.0f);
    }
}

// normal_blend.unit_normal: the blend in world space, normalised (the surface normal where it cancels out).
// twin: normal_blend.unit_normal
template <class Proj> WT_INLINE void wt_unit_normal(const wt_vf* total, const wt_vf* n, const Proj& proj, wt_vf* out) {
    wt_vf world[3], surface[3], a[3], b[3];
    wt_mul3(proj.normal_to_world, total, world, false);
    wt_mul3(proj.normal_to_world, n, surface, false);
    const wt_vi blended =
        (wt_length3(world) > 1.0e-12f) & wt_finite(world[0]) & wt_finite(world[1]) & wt_finite(world[2]);
    const wt_vi kept =
        (wt_length3(surface) > 0.0f) & wt_finite(surface[0]) & wt_finite(surface[1]) & wt_finite(surface[2]);
    wt_direction(world, a);
    wt_direction(surface, b);
    for (int e = 0; e < 3; ++e) out[e] = wt_sel(blended, a[e], wt_sel(kept, b[e], (wt_vf)0.0f));
}

// The stored intermediates of lane pixels base .. base + count - 1 (the rest repeat pixel base) as
// vectors: mask, unit normal (normal_blend.stored_blend's: normal_to_object always applied), weights,
// samples.
template <class Proj, class Normals, class Mask, class Weights, class Samples>
WT_INLINE void wt_stored(const Proj& proj, const Normals& normal, const Mask& mask, const Weights& weights,
                         const Samples& samples, int base, int count, wt_vi& covered, wt_vf* N, wt_vf* W,
                         wt_vf (*S)[4]) {
    float m_[1][WT_L];
    wt_vf raw[3];
    wt_rows(mask, base, count, 1, m_);
    wt_row_vectors(normal, base, count, 3, raw);
    wt_row_vectors(weights, base, count, 3, W);
    for (int axis = 0; axis < 3; ++axis) {  // each projection's RGBA rows, then a vector per channel
        wt_f4 rows[WT_L];
        for (int l = 0; l < WT_L; ++l)
            __builtin_memcpy(&rows[l],
                             (const char*)samples.data + (long long)(base + (l < count ? l : 0)) * samples.strides[0] +
                                 axis * samples.strides[1],
                             sizeof(wt_f4));
        wt_channels(rows, S[axis]);
    }
    covered = wt_covered(m_[0], count);
    wt_mul3(proj.normal_to_object, raw, N, false);
    wt_unit_normals(N);
}

// Row l of a lane_colours: (x, y, z, 0) of lane pixel l, 0 where it is not covered.
WT_INLINE wt_lane_colours wt_lane_normals(const wt_vf* r, wt_vi covered) {
    wt_lane_colours out;
    for (int l = 0; l < WT_L; ++l)
        for (int e = 0; e < 4; ++e) out.data[l][e] = e < 3 && covered[l] ? r[e][l] : 0.0f;
    return out;
}

// lanes.normals.surface_normals_lane: row l, lane pixel l's normal as normal mapping's pixel body
// makes it (x, y, z, 0), from its projections' weights (rows 9-11 of reads) and samples sx, sy, sz;
// 0 where the pixel is not covered.
template <class Proj, class NM, class Pixels, class Reads>
WT_INLINE wt_lane_colours wt_surface_normals_lane(const Proj& proj, const NM& nm, const Pixels& pixels, int base,
                                                  int count, const Reads& reads, const wt_lane_colours& sx,
                                                  const wt_lane_colours& sy, const wt_lane_colours& sz) {
    float m_[1][WT_L];
    wt_vf N[3], W[3], S[3][4], total[3], r[3];
    wt_row_vectors(pixels.normal, base, count, 3, N);
    wt_rows(pixels.mask, base, count, 1, m_);
    const wt_vi covered = wt_covered(m_[0], count);
    for (int e = 0; e < 3; ++e) __builtin_memcpy(&W[e], reads.data[9 + e], sizeof(wt_vf));
    if (proj.object_space != 0) {  // projection.surface
        const wt_vf raw[3] = {N[0], N[1], N[2]};
        wt_mul3(proj.normal_to_object, raw, N, false);
    }
    wt_unit_normals(N);
    const wt_lane_colours* samples[3] = {&sx, &sy, &sz};
    for (int axis = 0; axis < 3; ++axis) {
        wt_f4 rows[WT_L];
        __builtin_memcpy(rows, samples[axis]->data, sizeof(rows));
        wt_channels(rows, S[axis]);
    }
    wt_total(S, W, N, proj, nm, total);
    wt_unit_normal(total, N, proj, r);
    return wt_lane_normals(r, covered);
}

// lanes.normals.stored_normals_lane: row l, lane pixel l's normal made from its stored weights and
// samples (normal_blend.normal_from_samples), (x, y, z, 0); 0 where it is not covered.
// twin: normal_blend.normal_from_samples
template <class Proj, class NM, class Normals, class Mask, class Weights, class Samples>
WT_INLINE wt_lane_colours wt_stored_normals_lane(const Proj& proj, const NM& nm, const Normals& normal,
                                                 const Mask& mask, const Weights& weights, const Samples& samples,
                                                 int base, int count) {
    wt_vi covered;
    wt_vf N[3], W[3], S[3][4], total[3], r[3];
    wt_stored(proj, normal, mask, weights, samples, base, count, covered, N, W, S);
    wt_total(S, W, N, proj, nm, total);
    wt_unit_normal(total, N, proj, r);
    return wt_lane_normals(r, covered);
}

// twin: normals.normalize_grad
WT_INLINE void wt_normalize_grad(const wt_vf* v, const wt_vf* g, wt_vf* out) {
    const wt_vf d = wt_length3(v);
    const wt_vi positive = d > 0.0f;
    const wt_vf invd = 1.0f / wt_sel(positive, d, (wt_vf)1.0f);
    wt_vf u[3];
    wt_normalize3(v, d, u);
    const wt_vf ug = wt_dot3(u, g);
    for (int e = 0; e < 3; ++e) out[e] = wt_sel(positive, g[e] * invd - u[e] * ug * invd, (wt_vf)0.0f);
}

// normals.direction_grad, the lanes whose |v|² overflows lane by lane with Warp's own functions.
// twin: normals.direction_grad
WT_INLINE void wt_direction_grad(const wt_vf* v, const wt_vf* g, wt_vf* out) {
    wt_normalize_grad(v, g, out);
    const wt_vf length = wt_length3(v);
    if (!__builtin_reduce_or(length > wt_float_max)) return;
    for (int l = 0; l < WT_L; ++l) {
        if (length[l] > wt_float_max) {
            const wt_v3 n(v[0][l], v[1][l], v[2][l]), gg(g[0][l], g[1][l], g[2][l]);
            const float m = wp::max(wt_v3(wp::abs(n.c[0]), wp::abs(n.c[1]), wp::abs(n.c[2])));
            const wt_v3 s = wp::div(n, m);
            wt_v3 r(0.0f);
            const float d = wp::length(s);
            if (d > 0.0f) {
                const float invd = 1.0f / d;
                const wt_v3 u = wp::normalize(s);
                r = wp::sub(wp::mul(gg, invd), wp::mul(wp::mul(u, wp::dot(u, gg)), invd));
            }
            r = wp::div(r, m);
            for (int e = 0; e < 3; ++e) out[e][l] = r.c[e];
        }
    }
}

// normals.decode_normal_grad: the gradient in the texel's four channels (the fourth 0).
// twin: normals.decode_normal_grad
template <class NM> WT_INLINE void wt_decode_grad(const wt_vf* s, const NM& nm, const wt_vf* g, wt_vf* out) {
    wt_vf xyz[3], r, t[3], gt[3];
    wt_decode(s, nm, xyz, r, t);
    const wt_vf scaled[3] = {xyz[0] * nm.strength, xyz[1] * nm.strength, xyz[2]};
    wt_normalize_grad(scaled, g, gt);
    wt_vf gx = gt[0] * nm.strength, gy = gt[1] * nm.strength, gz = 0.0f;
    if (nm.channels >= 3) {
        gz = gt[2];
    } else {  // z = sqrt(1 - x² - y²) where that is > 0
        const wt_vi root = r > 0.0f;
        gx = wt_sel(root, gx - gt[2] * xyz[0] / xyz[2], gx);
        gy = wt_sel(root, gy - gt[2] * xyz[1] / xyz[2], gy);
    }
    if (nm.flip_green != 0) gy = -gy;
    out[0] = gx * 2.0f, out[1] = gy * 2.0f, out[2] = gz * 2.0f, out[3] = 0.0f;
}

// normal_blend.projected_normal_grad (normals.blend_projected_grad inline): projection `axis`'
// gradient in its sample.
// twin: normal_blend.projected_normal_grad
template <class Proj, class NM> WT_INLINE void wt_projected_normal_grad(const wt_vf* s, int axis, const wt_vf* n,
                                                                        const Proj& proj, const NM& nm, const wt_vf* g,
                                                                        wt_vf* out) {
    wt_vf b[3], gw[3], gt[3];
    const wt_vf sign = wt_u_sign(n, axis, proj.mirror_fix);
    wt_base(n, axis, b);
    wt_to_world(g, axis, gw);
    if (nm.blend == WT_BLEND_UDN) {
        gt[0] = gw[0], gt[1] = gw[1], gt[2] = 0.0f;
    } else if (nm.blend == WT_BLEND_RNM) {
        const wt_vf n1[3] = {b[0], b[1], wt_vabs(b[2]) + 1.0f}, gr[3] = {gw[0], gw[1], gw[2] * wt_sign_or_one(b[2])};
        const wt_vf q = wt_dot3(n1, gr) / n1[2];
        wt_vf gn2[3];
        for (int e = 0; e < 3; ++e) gn2[e] = n1[e] * q - gr[e];
        gt[0] = -gn2[0], gt[1] = -gn2[1], gt[2] = gn2[2];
    } else {
        gt[0] = gw[0], gt[1] = gw[1], gt[2] = gw[2] * b[2];
    }
    gt[0] = gt[0] * sign;
    wt_decode_grad(s, nm, gt, out);
}

// lanes.normals.stored_normals_grad_lane: normal_blend.normal_from_samples_grad for the lane: the
// gradient adj[i] of lane pixel i's normal added into grad[i, axis], the gradient of its stored
// sample of each projection it reads (nothing where grad is empty).
// twin: normal_blend.normal_from_samples_grad
template <class Proj, class NM, class Normals, class Mask, class Weights, class Samples, class Adj, class Grad>
WT_INLINE void wt_stored_normals_grad_lane(const Proj& proj, const NM& nm, const Normals& normal, const Mask& mask,
                                           const Weights& weights, const Samples& samples, int base, int count,
                                           const Adj& adj, const Grad& grad) {
    if (grad.shape[0] == 0) return;
    wt_vi covered;
    wt_vf N[3], W[3], S[3][4], total[3], world[3], A[3], gw[3], g[3];
    wt_stored(proj, normal, mask, weights, samples, base, count, covered, N, W, S);
    wt_total(S, W, N, proj, nm, total);
    float a_[3][WT_L];
    for (int l = 0; l < WT_L; ++l)
        for (int e = 0; e < 3; ++e)
            a_[e][l] = *(const float*)((const char*)adj.data +
                                       (long long)(base + (l < count ? l : 0)) * adj.strides[0] + e * adj.strides[1]);
    for (int e = 0; e < 3; ++e) __builtin_memcpy(&A[e], a_[e], sizeof(wt_vf));
    // normal_blend.unit_normal_grad
    wt_mul3(proj.normal_to_world, total, world, false);
    const wt_vi blended =
        (wt_length3(world) > 1.0e-12f) & wt_finite(world[0]) & wt_finite(world[1]) & wt_finite(world[2]);
    wt_direction_grad(world, A, gw);
    wt_mul3(proj.normal_to_world, gw, g, true);
    for (int e = 0; e < 3; ++e) g[e] = wt_sel(blended, g[e], (wt_vf)0.0f);
    for (int axis = 0; axis < 3; ++axis) {
        const wt_vi read = covered & (W[axis] > 0.0f);
        if (!__builtin_reduce_or(read)) continue;
        const wt_vf wg[3] = {W[axis] * g[0], W[axis] * g[1], W[axis] * g[2]};
        wt_vf gs[4];
        wt_projected_normal_grad(S[axis], axis, N, proj, nm, wg, gs);
        wt_f4 rows[WT_L];
        wt_rows_of_channels(gs, rows);
        for (int l = 0; l < count; ++l) {
            if (!read[l]) continue;
            char* row = (char*)grad.data + (long long)(base + l) * grad.strides[0] + axis * grad.strides[1];
            wt_f4 sum;
            __builtin_memcpy(&sum, row, sizeof(sum));
            sum = sum + rows[l];
            __builtin_memcpy(row, &sum, sizeof(sum));
        }
    }
}
