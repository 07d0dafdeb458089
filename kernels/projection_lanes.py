"""Plane projections for a lane of pixels on the CPU (:mod:`.lanes`): what each pixel of a triplanar
lane reads from each projection, its UV, LOD and weight, computed 16 pixels at a time.

The scalar blocks of :mod:`.projection` and :mod:`.footprint` run one pixel at a time through Warp's
code, with a branch per projection and per test; in a triplanar lane on the benchmark's sphere they
took 59% of the time (timed with the TSC inside the kernel), the texture reads the rest.
:func:`triplanar_reads_lane` restates them in C++, operation for operation (Warp's own ``wp::``
functions, no contraction), in loops over the lane that the compiler vectorises (the weights' exponent
and the other launch-wide choices are tested once, outside the loops), so the reads are the scalar
blocks' bits; the LODs' ``log2`` is :func:`~.footprint.lod_log2`'s, 16 at a time. It covers the
common case, triplanar weights and a one-tap filter (every filter but the anisotropic one);
:mod:`.triplanar_lanes` takes every other case pixel by pixel through the scalar blocks.
"""

import warp as wp

from .faces import FaceTextures
from .lanes import cpu_snippet, lane_reads
from .projection import ProjectionArgs, SurfacePixels
from .texels import SamplerArgs

_TRIPLANAR_READS = r"""
typedef wp::vec_t<3, float> wt_v3;
auto row = [](const auto& a, int i) __attribute__((always_inline)) -> const char* { return (const char*)a.data + (long long)i * a.strides[0]; };
auto f32 = [&](const auto& a, int i) __attribute__((always_inline)) -> float { return *(const float*)row(a, i); };
auto v3 = [&](const auto& a, int i) __attribute__((always_inline)) -> wt_v3 { wt_v3 r; __builtin_memcpy(&r, row(a, i), 12); return r; };
// projection.surface: the lane's pixels (the tail repeats pixel base, not read), in the projected space.
float P[3][WT_L], N[3][WT_L], DX[3][WT_L], DY[3][WT_L];
bool covered[WT_L];
for (int l = 0; l < WT_L; ++l) {
    const int i = base + (l < count ? l : 0);
    covered[l] = l < count && f32(pixels.mask, i) != 0.0f;
    wt_v3 p = v3(pixels.position, i), n = v3(pixels.normal, i), dx = v3(pixels.position_dx, i), dy = v3(pixels.position_dy, i);
    if (proj.object_space != 0) {  // projection.object_space
        p = wp::transform_point(proj.world_to_object, p);
        n = wp::mul(proj.normal_to_object, n);
        dx = wp::transform_vector(proj.world_to_object, dx);
        dy = wp::transform_vector(proj.world_to_object, dy);
    }
    for (int e = 0; e < 3; ++e) {
        P[e][l] = p.c[e];
        N[e][l] = n.c[e];
        DX[e][l] = dx.c[e];
        DY[e][l] = dy.c[e];
    }
}
// projection.triplanar_weights, with power_weight's integer exponents by multiplication.
const float sharpness = f32(proj.sharpness, 0);
const int k = (int)sharpness;
const bool by_squares = (float)k == sharpness && k > 0 && k < 32;
float W[3][WT_L];
bool weighed[WT_L];
float R[3][WT_L];  // |n| / max |n|
for (int l = 0; l < WT_L; ++l) {
    const float a0 = wp::abs(N[0][l]), a1 = wp::abs(N[1][l]), a2 = wp::abs(N[2][l]);
    const float m = wp::max(wp::max(a0, a1), a2);
    weighed[l] = covered[l] && wp::isfinite(N[0][l]) && wp::isfinite(N[1][l]) && wp::isfinite(N[2][l]) && m > 0.0f;
    R[0][l] = a0 / m;
    R[1][l] = a1 / m;
    R[2][l] = a2 / m;
}
for (int e = 0; e < 3; ++e) {  // power_weight, its exponent the same in every lane
    if (sharpness == 0.0f) {
        for (int l = 0; l < WT_L; ++l) W[e][l] = 1.0f;
    } else if (by_squares) {
        const bool b1 = (k & 1) != 0, b2 = (k & 2) != 0, b4 = (k & 4) != 0, b8 = (k & 8) != 0, b16 = (k & 16) != 0;
        for (int l = 0; l < WT_L; ++l) {
            const float r = R[e][l], r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
            const float power = ((b1 ? r : 1.0f) * (b2 ? r2 : 1.0f) * (b4 ? r4 : 1.0f)) * (b8 ? r8 : 1.0f) * (b16 ? r8 * r8 : 1.0f);
            W[e][l] = r > 0.0f ? power : 0.0f;
        }
    } else {
        for (int l = 0; l < WT_L; ++l) W[e][l] = weighed[l] && R[e][l] > 0.0f ? wp::exp(sharpness * wp::log(R[e][l])) : 0.0f;
    }
}
for (int l = 0; l < WT_L; ++l) {
    const float total = wp::max(W[0][l] + W[1][l] + W[2][l], 1.0e-20f);  // WEIGHT_EPS
    for (int e = 0; e < 3; ++e) W[e][l] = weighed[l] ? W[e][l] / total : 0.0f;
}
// Per projection: projection.plane_uv and footprint.uv_footprint's one tap, where its weight is > 0.
wp::mat_t<12, WT_L, float> reads;  // rows 3 q + axis: u (q = 0), v, lod, weight
for (int axis = 0; axis < 3; ++axis) {
    const float t = f32(proj.tiling, wp::min(axis, proj.tiling.shape[0] - 1));  // projection_tiling
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
    const auto& tex = axis == 0 ? faces.px : (axis == 1 ? faces.py : faces.pz);  // faces.on_axis
    const float width = (float)wt_int(tex.level_width, 0), height = (float)wt_int(tex.level_height, 0);
    const int c0 = axis == 0 ? 2 : 0, c1 = axis == 1 ? 2 : 1;  // projection.plane_coords
    float u[WT_L], v[WT_L], lod_of[WT_L];
    bool finite[WT_L];
    for (int l = 0; l < WT_L; ++l) {
        float s = 1.0f;  // projection.u_sign
        if (proj.mirror_fix != 0) s = axis == 2 ? (N[2][l] < 0.0f ? -1.0f : 1.0f) : -(N[axis][l] < 0.0f ? -1.0f : 1.0f);
        u[l] = (P[c0][l] * t + o0) * s + off0;
        v[l] = (P[c1][l] * t + o1) + off1;
        const float ax = (DX[c0][l] * t) * s * width, ay = (DX[c1][l] * t) * height;  // plane_derivative × level-0 size
        const float bx = (DY[c0][l] * t) * s * width, by = (DY[c1][l] * t) * height;
        const float aa = ax * ax + ay * ay, bb = bx * bx + by * by;
        lod_of[l] = wp::min(wp::max(wp::max(aa, bb), 1.0e-30f), wt_float_max);
        finite[l] = aa + bb == aa + bb;
    }
    for (int l = 0; l < WT_L; ++l) {
        const bool read = W[axis][l] > 0.0f;
        const float lod = 0.5f * wt_log2(lod_of[l]);  // footprint.lod_log2
        reads.data[axis][l] = read ? u[l] : 0.0f;
        reads.data[3 + axis][l] = read ? v[l] : 0.0f;
        reads.data[6 + axis][l] = read ? (finite[l] ? lod : __builtin_nanf("")) : 0.0f;
        reads.data[9 + axis][l] = W[axis][l];
    }
}
return reads;
"""


@wp.func_native(cpu_snippet(_TRIPLANAR_READS, "return {};\n"))
def triplanar_reads_lane(faces: FaceTextures, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32) -> lane_reads:
    """What the lane's pixels ``base .. base + count - 1`` read from each projection with triplanar
    weights and a one-tap filter (``smp``'s filter is not the anisotropic one): the UVs, LODs and
    weights of ``projection.projection_uv``, ``projection.projection_footprint`` and
    ``projection.projection_weights``, as :func:`~.triplanar_lanes.lane_bodies` gathers them: rows
    ``3 q + axis`` of the UVs' ``u`` (``q = 0``) and ``v`` (1), the LODs (2) and the weights (3).
    Where a projection is not read (a zero weight, or an uncovered pixel), all four are 0."""
    ...
