"""CPU lanes: native helpers that compute a lane of :data:`LANES` pixels at once.

Warp compiles a CPU launch as a scalar loop, one launch index at a time, and LLVM does not
vectorise across indices (Warp issues #1309, #1358, #1954): rewriting a scalar body as an unrolled
loop over 16 pixels inside one Warp launch index measured no faster here. A ``wp.func_native``
helper written for a lane, in phases, is: its UV arithmetic runs 16 lanes wide in SIMD registers,
and all 64 texel addresses of a lane are known before the first load, so the loads overlap.

Each helper computes *exactly* what the scalar ``@wp.func`` blocks it stands for compute, operation
for operation and in the same order (no contraction into fused multiply-adds: ``fp contract(off)``),
so a lane's outputs are the scalar kernel's bits; ``tests/test_lanes.py`` checks that in every
filter, address mode and layer case. Only the CPU compiles a body: on CUDA the helpers are empty and
never launched (one pixel per thread there, from the scalar kernel).

The lane kernels themselves are made by :func:`warptex.kernels.family.lane_kernel`.
"""

import warp as wp

#: Pixels per lane: one launch index of a lane kernel computes pixels ``LANES·t .. LANES·t + LANES - 1``
#: (fewer in a launch's last lane). 16 float32 lanes fill an AVX-512 register.
LANES = 16

# Shared by the helpers: the address modes and the scalar formulas of ``texels.reduce_coord`` and
# ``texels.address_near`` (same constants as ``texels.ADDRESS_*``), on one pixel.
_PRELUDE = r"""
#pragma clang fp contract(off)
typedef float wt_f4 __attribute__((ext_vector_type(4)));
enum { WT_L = %(lanes)d, WT_WRAP = 0, WT_CLAMP = 1, WT_MIRROR = 2, WT_BORDER = 3 };
const float wt_float_max = 3.4028234663852886e38f;
auto wt_reduce = [](float x, const int address) __attribute__((always_inline)) -> float {
    if (address == WT_WRAP) return x - __builtin_floorf(x);
    if (address == WT_MIRROR) return x - 2.0f * __builtin_floorf(0.5f * x);
    return x < -1.0f ? -1.0f : (x > 2.0f ? 2.0f : x);
};
auto wt_address = [](int i, int n, const int address) __attribute__((always_inline)) -> int {
    int r = i;
    if (address == WT_WRAP) {
        if (r < 0) r += n;
        else if (r >= n) r -= n;
    } else if (address == WT_CLAMP) {
        r = i < 0 ? 0 : (i > n - 1 ? n - 1 : i);
    } else if (address == WT_MIRROR) {
        if (r < 0) r = -1 - r;
        else if (r >= 2 * n) r -= 2 * n;
        if (r >= n) r = 2 * n - 1 - r;
    } else if (i < 0 || i >= n) {
        r = -1;
    }
    return r;
};
""" % {"lanes": LANES}

_SAMPLE_LEVELS = _PRELUDE + r"""
// Pixels base .. base + count - 1 of the launch (the lane's tail repeats pixel base, not stored).
const int n = uv.shape[0];
const int count = n - base < WT_L ? n - base : WT_L;
const wt_f4 border4 = {border.c[0], border.c[1], border.c[2], border.c[3]};
const char* tb = (const char*)texels.data;
const long long ts = texels.strides[0];
float u[WT_L], v[WT_L];
int layer[WT_L];
bool finite[WT_L];
// Phase 1: UVs (non-finite ones replaced, their outputs NaN: texels.finite_uv_lod) and layers
// (texels.resolve_layer).
for (int l = 0; l < WT_L; ++l) {
    const float* p = (const float*)((const char*)uv.data + (long long)(base + (l < count ? l : 0)) * uv.strides[0]);
    finite[l] = __builtin_fabsf(p[0]) <= wt_float_max && __builtin_fabsf(p[1]) <= wt_float_max;
    u[l] = finite[l] ? p[0] : 0.0f;
    v[l] = finite[l] ? p[1] : 0.0f;
    layer[l] = constant_layer;
}
if (layers.shape[0] > 0) {
    for (int l = 0; l < WT_L; ++l) {
        const int k = *(const int*)((const char*)layers.data + (long long)(base + (l < count ? l : 0)) * layers.strides[0]);
        layer[l] = k < 0 ? 0 : (k > num_layers - 1 ? num_layers - 1 : k);
    }
}
auto load = [&](int index, bool inside) __attribute__((always_inline)) -> wt_f4 {  // texels.texel
    wt_f4 t;
    __builtin_memcpy(&t, tb + (inside ? (long long)index : 0) * ts, 16);
    return inside ? t : border4;
};
// Phase 2, one level (filters.sample_nearest, filters.bilinear_taps and sample_bilinear): every
// lane's addresses and weights first, then the loads, so that they are in flight together.
auto filter_level = [&](const int address, int start, int w, int h, wt_f4* res) __attribute__((always_inline)) {
    float ru[WT_L], rv[WT_L];
    for (int l = 0; l < WT_L; ++l) {  // texels.reduce_coord
        ru[l] = wt_reduce(u[l], address);
        rv[l] = wt_reduce(v[l], address);
    }
    int index[4][WT_L];
    bool inside[4][WT_L];
    if (filter == 0) {  // FILTER_NEAREST
        for (int l = 0; l < WT_L; ++l) {
            const int x = wt_address((int)__builtin_floorf(ru[l] * (float)w), w, address);
            const int y = wt_address((int)__builtin_floorf((1.0f - rv[l]) * (float)h), h, address);
            index[0][l] = start + layer[l] * h * w + y * w + x;
            inside[0][l] = address != WT_BORDER || (x >= 0 && y >= 0);  // only the border mode reads outside
        }
        for (int l = 0; l < WT_L; ++l) res[l] = load(index[0][l], inside[0][l]);
        return;
    }
    float fx[WT_L], fy[WT_L];
    for (int l = 0; l < WT_L; ++l) {
        const int s = start + layer[l] * h * w;
        const float x = ru[l] * (float)w - 0.5f;
        const float y = (1.0f - rv[l]) * (float)h - 0.5f;
        const float x0 = __builtin_floorf(x);
        const float y0 = __builtin_floorf(y);
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
    for (int l = 0; l < WT_L; ++l) {
        const wt_f4 top = load(index[0][l], inside[0][l]) * (1.0f - fx[l]) + load(index[1][l], inside[1][l]) * fx[l];
        const wt_f4 bottom = load(index[2][l], inside[2][l]) * (1.0f - fx[l]) + load(index[3][l], inside[3][l]) * fx[l];
        res[l] = top * (1.0f - fy[l]) + bottom * fy[l];
    }
};
// filters.sample_levels, compiled once per address mode (a mode tested per texel measured slower).
wt_f4 result[WT_L];
auto sample_levels = [&](const int address) __attribute__((always_inline)) {
    filter_level(address, start0, w0, h0, result);
    if (filter != 0 && fraction > 0.0f) {  // trilinear: blended with the next level
        wt_f4 coarse[WT_L];
        filter_level(address, start1, w1, h1, coarse);
        for (int l = 0; l < WT_L; ++l) result[l] = result[l] * (1.0f - fraction) + coarse[l] * fraction;
    }
};
switch (address) {
    case WT_WRAP: sample_levels(WT_WRAP); break;
    case WT_CLAMP: sample_levels(WT_CLAMP); break;
    case WT_MIRROR: sample_levels(WT_MIRROR); break;
    default: sample_levels(WT_BORDER); break;
}
// Phase 3: texels.write_channels.
char* ob = (char*)out.data;
const wt_f4 nan4 = __builtin_nanf("");
const int channels = out.shape[1];
if (channels == 4 && out.strides[1] == 4) {
    for (int l = 0; l < count; ++l) {
        const wt_f4 r = finite[l] ? result[l] : nan4;
        __builtin_memcpy(ob + (long long)(base + l) * out.strides[0], &r, 16);
    }
} else {
    for (int l = 0; l < count; ++l) {
        const wt_f4 r = finite[l] ? result[l] : nan4;
        char* row = ob + (long long)(base + l) * out.strides[0];
        for (int c = 0; c < channels; ++c) *(float*)(row + (long long)c * out.strides[1]) = r[c];
    }
}
"""


@wp.func_native("#if !defined(__CUDA_ARCH__)\n" + _SAMPLE_LEVELS + "#endif\n")
def sample_levels_lane(
    texels: wp.array(dtype=wp.vec4),
    uv: wp.array(dtype=wp.vec2),
    layers: wp.array(dtype=wp.int32),
    out: wp.array2d(dtype=float),
    base: wp.int32,
    start0: wp.int32,
    w0: wp.int32,
    h0: wp.int32,
    start1: wp.int32,
    w1: wp.int32,
    h1: wp.int32,
    fraction: float,
    constant_layer: wp.int32,
    num_layers: wp.int32,
    filter: wp.int32,
    address: wp.int32,
    border: wp.vec4,
):
    """``out[i] =`` :func:`~warptex.kernels.filters.sample_levels` at ``uv[i]`` for the lane's
    pixels ``i = base ..`` (NaN where ``uv[i]`` is not finite): the level at ``start0`` (``w0 × h0``;
    layer ``layers[i]`` clamped, or ``constant_layer`` where ``layers`` is empty), blended by
    ``fraction`` with the next (``start1``, ``w1 × h1``) when it is positive."""
    ...
