"""Plane projections for a lane of pixels on the CPU (:mod:`.lanes`): what each pixel of a triplanar
lane reads from each projection, its UV, LOD and weight, computed 16 pixels at a time.

The scalar blocks of :mod:`.projection` and :mod:`.footprint` run one pixel at a time through Warp's
code, with a branch per projection and per test; in a triplanar lane on the benchmark's sphere they
took 59% of the time (timed with the TSC inside the kernel), the texture reads the rest.
:func:`triplanar_reads_lane` restates them in C++, operation for operation (Warp's own ``wp::``
functions or their exact vector twins, no contraction), on clang vectors of a value per lane pixel
(the weights' exponent and the other launch-wide choices are tested once, outside them; loops over
lanes that the compiler was left to vectorise did not all vectorise), so the reads are the scalar
blocks' bits; the LODs' ``log2`` is :func:`~.footprint.lod_log2`'s, 16 at a time. It covers every
filter (the anisotropic footprint's branches as selects) and both weights on the vectors: biplanar's
branches, which pick each pixel's axes, as selects too (pixel by pixel in C++ they took half a
biplanar lane's reads; the rare pairs whose powers underflow still go pixel by pixel).
"""

import warp as wp

from .faces import FaceTextures
from .family import lane_covered
from .lanes import FOOTPRINT_CPP, cpu_snippet, lane_colours, lane_ints, lane_reads
from .normal_lanes import UNIT_NORMALS_CPP
from .projection import BIPLANAR_EDGE, MAX_INT_EXPONENT, WEIGHT_EPS, WEIGHTS_BIPLANAR, ProjectionArgs, SurfacePixels
from .texels import SamplerArgs, TextureView

# One projection's reads at a tiling for the lane, projection.plane_uv and its footprint
# (plane_footprint, lanes.FOOTPRINT_CPP), given the lane's surface as vectors: also what a splat layer
# mapped triplanar reads (.splat_lanes).
PLANE_CPP = FOOTPRINT_CPP + r"""
// (u, v) and the footprint of projection `axis` at tiling t of `tex` (its level 0) on the lane's surface
// P, N, DX, DY: projection.plane_uv and plane_footprint.
auto wt_plane_reads = [&](const auto& proj, const auto& smp, int axis, float t, const auto& tex, const wt_vf* P, const wt_vf* N, const wt_vf* DX, const wt_vf* DY,
                          wt_vf& u, wt_vf& v, wt_footprint_lanes& fp) __attribute__((always_inline)) {
    float o0 = 0.0f, o1 = 0.0f;  // projection.origin_uv, in float64
    if (proj.origin_mode != 0) {
        const double a = axis == 0 ? proj.origin.c[2] : proj.origin.c[0];
        const double b = axis == 1 ? proj.origin.c[2] : proj.origin.c[1];
        const double td = (double)t;
        double ou = a * td, ov = b * td;
        if (proj.origin_mode == 1) {  // ORIGIN_FOLDED
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
    fp = wt_footprint(smp, (DX[c0] * t) * s, DX[c1] * t, (DY[c0] * t) * s, DY[c1] * t, width, height);  // plane_derivative
};
// Reads r = 0 .. count - 1 of a lane_reads matrix, read r of *texs[r] (lane pixel l's layer layers[l])
// over its footprint, into value in read order (wt_accumulate_footprint: value += w · sample where
// add, value = sample where not).
auto wt_accumulate_reads = [&](const auto* const* texs, const auto& smp, const int* layers, int count, int add, const wp::mat_t<21, WT_L, float>& at, wp::mat_t<WT_L, 4, float>& value) __attribute__((always_inline)) {
    for (int r = 0; r < count; ++r)
        wt_accumulate_footprint(*texs[r], smp, layers, at.data[r], at.data[3 + r], at.data[6 + r], at.data[12 + r], at.data[15 + r], at.data[18 + r], at.data[9 + r], add, value);
};
"""

_ACCUMULATE_READS = PLANE_CPP + r"""
const decltype(tex0)* texs[3] = {&tex0, &tex1, &tex2};
wp::mat_t<WT_L, 4, float> value;
wt_accumulate_reads(texs, smp, layers.c, count, add, reads, value);
return value;
"""


@wp.func_native(cpu_snippet(_ACCUMULATE_READS, "return {};\n"))
def accumulate_reads_lane(tex0: TextureView, tex1: TextureView, tex2: TextureView, smp: SamplerArgs, layers: lane_ints, count: wp.int32, add: wp.int32, reads: lane_reads) -> lane_colours:  # fmt: skip
    """Row ``l``: lane pixel ``l``'s reads ``r = 0 .. count - 1`` in ``reads``
    (:data:`~.lanes.lane_reads`), read ``r`` of ``tex_r`` (layer ``layers[l]``) over its footprint,
    blended in read order by their weights where ``add`` (``value += w · sample``: a pixel's
    projections), the one read's sample where not; 0 where the pixel reads nothing."""
    ...


_TRIPLANAR_READS = PLANE_CPP + UNIT_NORMALS_CPP + r"""
typedef wp::vec_t<2, float> wt_v2;
// projection.power_weight and biplanar_pair, operation for operation with Warp's own functions, for
// one pixel (the rare lanes the vectors below leave to them).
auto wt_power_weight = [](float r, float exponent) __attribute__((always_inline)) -> float {
    float w = 0.0f;
    if (exponent == 0.0f) {
        w = 1.0f;
    } else if (r > 0.0f) {
        const int k = (int)exponent;
        if ((float)k == exponent && k > 0 && k < %(max_int)d) {
            const float r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
            w = ((k & 1) != 0 ? r : 1.0f) * ((k & 2) != 0 ? r2 : 1.0f) * ((k & 4) != 0 ? r4 : 1.0f);
            w = w * ((k & 8) != 0 ? r8 : 1.0f) * ((k & 16) != 0 ? r8 * r8 : 1.0f);
        } else {
            w = wp::exp(exponent * wp::log(r));
        }
    }
    return w;
};
auto wt_biplanar_pair = [&](float major, float median, float exponent) __attribute__((always_inline)) -> wt_v2 {
    const float edge = (float)%(edge)r;
    const float b0 = wp::clamp((major - edge) / (1.0f - edge), 0.0f, 1.0f);
    const float b1 = wp::clamp((median - edge) / (1.0f - edge), 0.0f, 1.0f);
    wt_v2 w(wt_power_weight(b0, exponent), wt_power_weight(b1, exponent));
    if (w.c[0] + w.c[1] < (float)%(eps)r) {
        const float m = wp::max(b0, b1);
        if (m > 0.0f) w = wt_v2(wt_power_weight(b0 / m, exponent), wt_power_weight(b1 / m, exponent));
        else w = wt_v2(1.0f, 1.0f);
    }
    return w;
};
auto row = [](const auto& a, int i) __attribute__((always_inline)) -> const char* { return (const char*)a.data + (long long)i * a.strides[0]; };
auto f32 = [&](const auto& a, int i) __attribute__((always_inline)) -> float { return *(const float*)row(a, i); };
// projection.surface: the lane's pixels (the tail repeats pixel base, not read), in the projected space.
float p_[3][WT_L], n_[3][WT_L], dx_[3][WT_L], dy_[3][WT_L], mask_[1][WT_L];  // read into arrays, then as vectors
wt_rows(pixels.position, base, count, 3, p_);
wt_rows(pixels.normal, base, count, 3, n_);
wt_rows(pixels.position_dx, base, count, 3, dx_);
wt_rows(pixels.position_dy, base, count, 3, dy_);
wt_rows(pixels.mask, base, count, 1, mask_);
int covered_[WT_L];
for (int l = 0; l < WT_L; ++l) covered_[l] = l < count && mask_[0][l] != 0.0f ? -1 : 0;
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
wt_vi covered;
__builtin_memcpy(&covered, covered_, sizeof(covered));
for (int e = 0; e < 3; ++e) {
    __builtin_memcpy(&P[e], p_[e], sizeof(wt_vf));
    __builtin_memcpy(&N[e], n_[e], sizeof(wt_vf));
    __builtin_memcpy(&DX[e], dx_[e], sizeof(wt_vf));
    __builtin_memcpy(&DY[e], dy_[e], sizeof(wt_vf));
}
const wt_vf zero = 0.0f, one = 1.0f;
const float sharpness = f32(proj.sharpness, 0);
wt_vf W[3];
// projection.power_weight of a lane's r, its exponent the same in every lane: integer exponents by
// multiplication, others with exp and log lane by lane (where `active`).
auto wt_power_lanes = [&](wt_vf r, float exponent, wt_vi active) __attribute__((always_inline)) -> wt_vf {
    if (exponent == 0.0f) return one;
    const int k = (int)exponent;
    if ((float)k == exponent && k > 0 && k < %(max_int)d) {
        const wt_vf r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
        const wt_vf power = (((k & 1) != 0 ? r : one) * ((k & 2) != 0 ? r2 : one) * ((k & 4) != 0 ? r4 : one)) * ((k & 8) != 0 ? r8 : one) * ((k & 16) != 0 ? r8 * r8 : one);
        return wt_sel(r > 0.0f, power, zero);
    }
    float w[WT_L];
    for (int l = 0; l < WT_L; ++l) w[l] = active[l] && r[l] > 0.0f ? wp::exp(exponent * wp::log(r[l])) : 0.0f;
    wt_vf result;
    __builtin_memcpy(&result, w, sizeof(result));
    return result;
};
if (proj.weights == %(biplanar)d) {  // projection.biplanar_weights, each pixel's axes chosen by selects
    const wt_vf length0 = wt_vsqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);  // wp::length
    const wt_vi over = length0 > wt_float_max;  // |n|² overflowed: normals.unsquared
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
    const float edge = (float)%(edge)r;  // biplanar_pair
    const wt_vf b0 = wt_vmin(wt_vmax(zero, (major - edge) / (1.0f - edge)), one);  // wp::clamp(x, 0, 1) = fmin(fmax(0, x), 1)
    const wt_vf b1 = wt_vmin(wt_vmax(zero, (median - edge) / (1.0f - edge)), one);
    wt_vf p0 = wt_power_lanes(b0, exponent, weighed), p1 = wt_power_lanes(b1, exponent, weighed);
    const wt_vi underflowed = weighed & (p0 + p1 < (float)%(eps)r);
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
    const wt_vf total = wt_vmax(W[0] + W[1] + W[2], (float)%(eps)r);
    for (int e = 0; e < 3; ++e) W[e] = wt_sel(weighed, W[e] / total, zero);
} else {  // projection.triplanar_weights
    const wt_vf a0 = wt_vabs(N[0]), a1 = wt_vabs(N[1]), a2 = wt_vabs(N[2]);
    const wt_vf m = wt_vmax(wt_vmax(a0, a1), a2);
    const wt_vi weighed = covered & wt_finite(N[0]) & wt_finite(N[1]) & wt_finite(N[2]) & (m > 0.0f);
    const wt_vf R[3] = {a0 / m, a1 / m, a2 / m};  // |n| / max |n|
    for (int e = 0; e < 3; ++e) W[e] = wt_power_lanes(R[e], sharpness, weighed);
    const wt_vf total = wt_vmax(W[0] + W[1] + W[2], (float)%(eps)r);
    for (int e = 0; e < 3; ++e) W[e] = wt_sel(weighed, W[e] / total, zero);
}
if (side != 0) {  // faces.on_face: the - face where n[axis] < 0 (the normal as given), else the + face
    for (int axis = 0; axis < 3; ++axis) {
        const wt_vi negative = N[axis] < 0.0f;
        W[axis] = wt_sel(side == 2 ? negative : ~negative, W[axis], zero);
    }
}
if (unit_normals != 0) wt_unit_normals(N);  // triplanar.unit_base_normal: normal mapping reads on the unit normal
// Per projection: projection.plane_uv and plane_footprint, where its weight is > 0.
wp::mat_t<21, WT_L, float> reads;
for (int axis = 0; axis < 3; ++axis) {
    const float t = f32(proj.tiling, wp::min(axis, proj.tiling.shape[0] - 1));  // projection_tiling
    const auto& tex = side == 2 ? (axis == 0 ? faces.nx : (axis == 1 ? faces.ny : faces.nz)) : (axis == 0 ? faces.px : (axis == 1 ? faces.py : faces.pz));  // faces.on_axis
    wt_vf u, v;
    wt_footprint_lanes fp;
    wt_plane_reads(proj, smp, axis, t, tex, P, N, DX, DY, u, v, fp);
    wt_put_read(reads, axis, W[axis] > 0.0f, u, v, fp, W[axis]);
}
return reads;
""" % {"biplanar": int(WEIGHTS_BIPLANAR), "max_int": int(MAX_INT_EXPONENT), "edge": float(BIPLANAR_EDGE), "eps": float(WEIGHT_EPS)}


@wp.func_native(cpu_snippet(_TRIPLANAR_READS, "return {};\n"))
def triplanar_reads_lane(faces: FaceTextures, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, unit_normals: wp.int32, side: wp.int32) -> lane_reads:
    """What the lane's pixels ``base .. base + count - 1`` read from each projection, with triplanar
    or biplanar weights (``proj.weights``): the UVs, footprints and weights of ``projection.projection_uv``,
    ``projection.projection_footprint`` and ``projection.projection_weights``, as
    :data:`~.lanes.lane_reads` (all 0 where a projection is not read: a zero weight, or an uncovered
    pixel). With ``unit_normals``, the UVs and footprints are those of the unit normal
    (``triplanar.unit_base_normal``, as normal mapping reads them; the weights are the normal's as
    given either way): a normal's tiny component can round to zero as it is scaled, which turns its
    mirror-fix sign. ``side``: 0, each projection read on ``faces``' texture of its axis (``px``,
    ``py``, ``pz``); with a texture per face (``faces.on_face``), 1 or 2, each projection read on the
    face of that side (``+``: ``px``, ``py``, ``pz``; ``-``: ``nx``, ``ny``, ``nz``), its weight 0 where
    the normal looks at the other face."""
    ...


@wp.func
def surface_covered(pixels: SurfacePixels, base: wp.int32, count: wp.int32) -> bool:
    """Whether the G-buffer covers any of the lane's pixels (``covered`` of ``family.lane_kernel``)."""
    return lane_covered(pixels.mask, base, count)
