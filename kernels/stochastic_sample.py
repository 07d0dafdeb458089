"""The ``stochastic`` technique's kernels: stochastic sampling at given UVs (``warptex.stochastic``),
one pixel per launch index and, on the CPU, a lane of pixels per index, forward and texel gradient;
and the hex technique's taps for inspection. The sampling blocks they are built from are in
:mod:`.stochastic`.
"""

import warp as wp

from . import inlined, specialised
from .family import Kernels, family, lane_kernel, pixel_kernels
from .hashing import STREAM_CHEAP2_NOISE, STREAM_CHEAP2_OFFSET, STREAM_HASH4_CELL, STREAM_HEX_VERTEX
from .hexgrid import HALF_SQRT3, HEX_SCALE, INV_SQRT3, PI, hex_grid, hex_steps, hex_tap, hex_weights
from .lane_scatter import scatter_taps_lane
from .lanes import FOOTPRINT_CPP, LANES, accumulate_footprint_lane, cpu_snippet, lane_colours, lane_floats, lane_ints, lane_reads, lane_taps
from .sample_lanes import SAMPLE_READS_CPP
from .sampling import SampleArgs, SampleGrads, SamplePixels, sample_footprint_of, sample_layer
from .stochastic import METHOD_CHEAP2, METHOD_HASH4, METHOD_NONE, StochasticArgs, periodic_base, sample_stochastic, sample_stochastic_outlined, scatter_stochastic
from .texels import FILTER_ANISOTROPIC, SamplerArgs, TextureView, read_channels, write_channels

MODULE = "warptex.stochastic"


@wp.struct
class StochasticSampleArgs:
    """What every sample of a ``stochastic`` launch reads: ``sample`` as for ``sample`` (the
    per-sample LOD variants), and the technique's options."""

    sample: SampleArgs
    params: StochasticArgs


def _stochastic_body(sample, name: str):
    def body(args: StochasticSampleArgs, pixels: SamplePixels, i: wp.int32, out: wp.array2d(dtype=float)):
        """``out[i, c]`` = channel ``c`` of :func:`sample_stochastic` at ``pixels.uv[i]``."""
        a = args.sample
        write_channels(out, i, sample(a.tex, sample_layer(a, pixels, i), pixels.uv[i], sample_footprint_of(a, pixels, i), a.smp, args.params))

    return inlined(specialised(body, name))


@inlined
def scatter_stochastic_pixel(args: StochasticSampleArgs, pixels: SamplePixels, i: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """Add the gradient ``adj[i]`` of the stochastic body (linear blends only) into the texels it read."""
    a = args.sample
    scatter_stochastic(a.tex, grads.tex, sample_layer(a, pixels, i), pixels.uv[i], sample_footprint_of(a, pixels, i), a.smp, args.params, read_channels(adj, i))


stochastic_pixel = _stochastic_body(sample_stochastic, "stochastic_pixel")
stochastic_pixel_outlined = _stochastic_body(sample_stochastic_outlined, "stochastic_pixel_outlined")


# hashing.pcg4d / hash4_unit, hash4_taps and cheap2_taps (with value_noise, periodic_base and
# offset_tap) for a lane, operation for operation (integer hashes; Warp's own wp::smoothstep, wp::lerp,
# wp::floor; no contraction): loops over the lane's pixels with no branch, which the compiler
# vectorises. Every tap is hashed, also the zero-weight ones the scalar blocks skip: those are not read.
# Hex's taps (hexgrid's blocks) likewise, in phases over the lane: the float64 grid and the hashes in
# loops with no branch, the rotations (wp::sin, wp::cos) and powers (wp::pow; none for a contrast of
# 1, as hexgrid.hex_weights) lane by lane. The rules take a lane's UV and LOD rows (tap_u, tap_v,
# tap_lod) and pixel count, and fill `taps` (lanes.lane_taps): stochastic_taps and finite_uv_lod of
# every pixel, for `stochastic` (_TAPS) and for a triplanar lane's projections (_PROJECTION_TAPS).
_TAP_RULES = r"""
enum { WT_HASH4 = %(hash4)d, WT_CHEAP2 = %(cheap2)d, WT_STREAM_CELL = %(cell)d, WT_STREAM_OFFSET = %(offset)d, WT_STREAM_NOISE = %(noise)d, WT_STREAM_HEX = %(hex)d };
auto unit = [](unsigned a, unsigned b, unsigned c, unsigned d, float* h) __attribute__((always_inline)) {  // hash4_unit
    unsigned x = a * 1664525u + 1013904223u, y = b * 1664525u + 1013904223u, z = c * 1664525u + 1013904223u, w = d * 1664525u + 1013904223u;
    x += y * w; y += z * x; z += x * y; w += y * z;
    x = x ^ (x >> 16u); y = y ^ (y >> 16u); z = z ^ (z >> 16u); w = w ^ (w >> 16u);
    x += y * w; y += z * x; z += x * y; w += y * z;
    const float inv = (float)(1.0 / 16777216.0);
    h[0] = (float)(x >> 8u) * inv; h[1] = (float)(y >> 8u) * inv; h[2] = (float)(z >> 8u) * inv; h[3] = (float)(w >> 8u) * inv;
};
auto offset_tap = [](float bu, float bv, const float* h, int mirror, float& tu, float& tv) __attribute__((always_inline)) {
    const float su = mirror != 0 && h[2] < 0.5f ? -1.0f : 1.0f, sv = mirror != 0 && h[3] < 0.5f ? -1.0f : 1.0f;
    tu = su * bu + h[0];
    tv = sv * bv + h[1];
};
wp::mat_t<14, WT_L, float> taps;
for (int r = 0; r < 14; ++r) for (int l = 0; l < WT_L; ++l) taps.data[r][l] = 0.0f;
float fin[WT_L];
for (int l = 0; l < WT_L; ++l) {  // texels.finite_uv_lod
    const float u = tap_u[l], v = tap_v[l], lod = tap_lod[l];
    fin[l] = l < count && __builtin_fabsf(u) <= wt_float_max && __builtin_fabsf(v) <= wt_float_max && __builtin_fabsf(lod) <= wt_float_max ? 1.0f : 0.0f;
    taps.data[12][l] = lod;
    taps.data[13][l] = fin[l];
}
const float lo = params.blend_lo, hi = params.blend_hi;
const unsigned seed = params.seed;
if (params.method == WT_HASH4) {
    for (int l = 0; l < WT_L; ++l) {
        const float u = fin[l] != 0.0f ? tap_u[l] : 0.0f, v = fin[l] != 0.0f ? tap_v[l] : 0.0f;
        const float cu = wp::floor(u), cv = wp::floor(v);
        const float bu = u - 2.0f * wp::floor(0.5f * u), bv = v - 2.0f * wp::floor(0.5f * v);  // periodic_base
        const float bx = wp::smoothstep(lo, hi, u - cu), by = wp::smoothstep(lo, hi, v - cv);
        const unsigned ix = (unsigned)(int)cu, iy = (unsigned)(int)cv;
        const float w[4] = {(1.0f - bx) * (1.0f - by), bx * (1.0f - by), (1.0f - bx) * by, bx * by};
        for (int k = 0; k < 4; ++k) {
            float h[4];
            unit(ix + (unsigned)(k & 1), iy + (unsigned)(k >> 1), seed, (unsigned)WT_STREAM_CELL, h);
            offset_tap(bu, bv, h, params.mirror, taps.data[3 * k][l], taps.data[3 * k + 1][l]);
            taps.data[3 * k + 2][l] = fin[l] != 0.0f ? w[k] : 0.0f;
        }
    }
} else if (params.method == WT_CHEAP2) {
    for (int l = 0; l < WT_L; ++l) {
        const float u = fin[l] != 0.0f ? tap_u[l] : 0.0f, v = fin[l] != 0.0f ? tap_v[l] : 0.0f;
        const float pu = u * params.noise_frequency, pv = v * params.noise_frequency;  // value_noise
        const float cu = wp::floor(pu), cv = wp::floor(pv);
        const float fu = pu - cu, fv = pv - cv;
        const unsigned ix = (unsigned)(int)cu, iy = (unsigned)(int)cv;
        float a[4], b[4], c[4], d[4];
        unit(ix, iy, seed, (unsigned)WT_STREAM_NOISE, a);
        unit(ix + 1u, iy, seed, (unsigned)WT_STREAM_NOISE, b);
        unit(ix, iy + 1u, seed, (unsigned)WT_STREAM_NOISE, c);
        unit(ix + 1u, iy + 1u, seed, (unsigned)WT_STREAM_NOISE, d);
        const float sx = wp::smoothstep(0.0f, 1.0f, fu), sy = wp::smoothstep(0.0f, 1.0f, fv);
        const float noise = wp::lerp(wp::lerp(a[0], b[0], sx), wp::lerp(c[0], d[0], sx), sy);
        const float level = noise * params.noise_levels;  // cheap2_taps
        const float index = wp::floor(level);
        const float t = wp::smoothstep(lo, hi, level - index);
        const float bu = u - 2.0f * wp::floor(0.5f * u), bv = v - 2.0f * wp::floor(0.5f * v);
        const unsigned ia = (unsigned)(int)index;
        float h0[4], h1[4];
        unit(ia, 0u, seed, (unsigned)WT_STREAM_OFFSET, h0);
        unit(ia + 1u, 0u, seed, (unsigned)WT_STREAM_OFFSET, h1);
        offset_tap(bu, bv, h0, params.mirror, taps.data[0][l], taps.data[1][l]);
        offset_tap(bu, bv, h1, params.mirror, taps.data[3][l], taps.data[4][l]);
        taps.data[2][l] = fin[l] != 0.0f ? 1.0f - t : 0.0f;
        taps.data[5][l] = fin[l] != 0.0f ? t : 0.0f;
    }
} else {  // hexgrid: hex_grid (in float64), hex_steps, hex_tap, hex_weights, in phases over the lane
    const double scale = %(hex_scale)r, inv_sqrt3 = %(inv_sqrt3)r, half_sqrt3_64 = %(half_sqrt3)r;  // wp.float64 of a constant: its value as a double
    const float half_sqrt3 = (float)%(half_sqrt3)r, pi = (float)%(pi)r, hex_scale = (float)%(hex_scale)r;
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
            unit((unsigned)vi[k][l], (unsigned)vj[k][l], seed, (unsigned)WT_STREAM_HEX, h);
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
                if (wp::abs(u) < 1.0e8f && wp::abs(v) < 1.0e8f) {
                    const double cu = ((double)vi[k][l] + 0.5 * (double)vj[k][l]) / scale, cv = half_sqrt3_64 * (double)vj[k][l] / scale;  // hex_centre64
                    du = (float)((double)u - cu);
                    dv = (float)((double)v - cv);
                } else {
                    const float x = f0[l] - (k == 1 || (k == 0 && upper[l]) ? 1.0f : 0.0f), y = f1[l] - (k == 2 || (k == 0 && upper[l]) ? 1.0f : 0.0f);
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
            for (int l = 0; l < WT_L; ++l) pw[k][l] = bary[k][l] > 0.0f ? wp::pow(bary[k][l], params.contrast) : 0.0f;
    for (int l = 0; l < WT_L; ++l) {
        const float total = pw[0][l] + pw[1][l] + pw[2][l];
        for (int k = 0; k < 3; ++k) taps.data[3 * k + 2][l] = fin[l] != 0.0f ? pw[k][l] / total : 0.0f;  // (a tap of weight 0 is not read)
    }
}
""" % {"hash4": int(METHOD_HASH4), "cheap2": int(METHOD_CHEAP2), "cell": int(STREAM_HASH4_CELL), "offset": int(STREAM_CHEAP2_OFFSET), "noise": int(STREAM_CHEAP2_NOISE),
       "hex": int(STREAM_HEX_VERTEX), "hex_scale": float(HEX_SCALE), "inv_sqrt3": float(INV_SQRT3), "half_sqrt3": float(HALF_SQRT3), "pi": float(PI)}

_TAPS = FOOTPRINT_CPP + SAMPLE_READS_CPP + r"""
const float *tap_u = reads.data[0], *tap_v = reads.data[3], *tap_lod = reads.data[6];
""" + _TAP_RULES + "return taps;\n"

# A triplanar lane's projection `axis`: its taps from its read's UV and LOD (lanes.lane_reads), the
# weights of the pixels that do not read it (weight 0) set to 0, so that nothing reads them.
_PROJECTION_TAPS = r"""
const float *tap_u = reads.data[axis], *tap_v = reads.data[3 + axis], *tap_lod = reads.data[6 + axis];
""" + _TAP_RULES + r"""
for (int k = 0; k < 4; ++k)
    for (int l = 0; l < WT_L; ++l) taps.data[3 * k + 2][l] = reads.data[9 + axis][l] > 0.0f ? taps.data[3 * k + 2][l] : 0.0f;
return taps;
"""


@wp.func_native(cpu_snippet(_TAPS, "return {};\n"))
def stochastic_taps_lane(tex: TextureView, smp: SamplerArgs, params: StochasticArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2),
                         lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float, base: wp.int32) -> lane_taps:  # fmt: skip
    """The lane's :data:`~.lanes.lane_taps` from ``base``: every pixel's LOD
    (``sampling.sample_footprint_of``, one tap), whether its UV and LOD are finite, and its taps and
    their weights (0 where not finite)."""
    ...


@wp.func_native(cpu_snippet(_PROJECTION_TAPS, "return {};\n"))
def projection_taps_lane(params: StochasticArgs, reads: lane_reads, axis: wp.int32, count: wp.int32) -> lane_taps:
    """The :data:`~.lanes.lane_taps` of projection ``axis`` of a triplanar lane's ``reads``
    (:data:`~.lanes.lane_reads`): each pixel's stochastic taps of that read's UV at its LOD, their
    weights 0 where the pixel does not read the projection or its UV or LOD is not finite."""
    ...


@wp.func
def stochastic_lane_taps(args: StochasticSampleArgs, pixels: SamplePixels, base: wp.int32, count: wp.int32):
    """``(taps, layers)``: the lane's stochastic taps (:data:`~.lanes.lane_taps`; one-tap footprints:
    each reads its UV itself), worked out natively (:func:`stochastic_taps_lane`), and each pixel's
    layer."""
    a = args.sample
    taps = stochastic_taps_lane(a.tex, a.smp, args.params, pixels.uv, pixels.uv_dx, pixels.uv_dy, pixels.lods, pixels.layers, a.constant_layer, a.lod_source, a.constant_lod, base)
    layers = lane_ints()
    for l in range(count):
        layers[l] = sample_layer(a, pixels, base + l)
    return taps, layers


@wp.func
def lane_taps_linear(smp: SamplerArgs, params: StochasticArgs) -> bool:
    """Whether the lanes take a lookup tap by tap: a linear blend (no histogram) of one-tap
    footprints (not the anisotropic filter) of a stochastic method (``stochastic``'s lanes, and
    those of stochastic triplanar)."""
    return smp.filter != FILTER_ANISOTROPIC and params.histogram == 0 and params.method != METHOD_NONE


@inlined
def stochastic_lane(args: StochasticSampleArgs, pixels: SamplePixels, base: wp.int32, out: wp.array2d(dtype=float)):
    """:func:`stochastic_pixel` for the lane of pixels from ``base`` (:mod:`.lanes`), on the CPU:
    the lane's taps (:func:`stochastic_lane_taps`), then read natively, tap by tap, with
    ``lanes.accumulate_footprint_lane`` (``value += w · sample``, as :func:`sample_stochastic`
    blends them, from 0). A histogram's blend (not linear), the anisotropic filter's footprints
    (several taps, each with its stochastic taps) and plain sampling go pixel by pixel through the
    body."""
    count = wp.min(out.shape[0] - base, LANES)
    if not lane_taps_linear(args.sample.smp, args.params):
        for l in range(count):
            stochastic_pixel(args, pixels, base + l, out)
    else:
        a = args.sample
        taps, layers = stochastic_lane_taps(args, pixels, base, count)
        zero = lane_floats()
        one = lane_floats(1.0)
        value = lane_colours()
        for k in range(4):
            value = accumulate_footprint_lane(a.tex, a.smp, layers, taps[3 * k], taps[3 * k + 1], taps[12], zero, zero, one, taps[3 * k + 2], 1, value)
        for l in range(count):
            result = wp.vec4(wp.nan)
            if taps[13, l] != 0.0:
                result = wp.vec4(0.0) + value[l]  # the body's `result += value`, from 0
            write_channels(out, base + l, result)


@inlined
def scatter_stochastic_lane(args: StochasticSampleArgs, pixels: SamplePixels, base: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """:func:`scatter_stochastic_pixel` for the lane of pixels from ``base``, on the CPU: the
    lane's taps, then their adds natively (``lane_scatter.scatter_taps_lane``), pixel by pixel and
    tap by tap as the body adds them; what :func:`stochastic_lane` takes pixel by pixel, likewise."""
    count = wp.min(adj.shape[0] - base, LANES)
    if not lane_taps_linear(args.sample.smp, args.params):
        for l in range(count):
            scatter_stochastic_pixel(args, pixels, base + l, grads, adj)
    else:
        taps, layers = stochastic_lane_taps(args, pixels, base, count)
        g = lane_colours()
        for l in range(count):
            g[l] = read_channels(adj, base + l)
        scatter_taps_lane(args.sample.tex, grads.tex, args.sample.smp, layers, taps, g)


@family()
def stochastic_kernels() -> Kernels:
    """The ``stochastic`` kernels (per-sample LODs, as ``sample_kernels(level=False)``): the
    hand-written gradient reaches the texels (linear blends: no histogram)."""
    kernels = pixel_kernels("stochastic", module=MODULE, args=StochasticSampleArgs, pixels=SamplePixels, out=wp.array2d(dtype=float),
                            body=stochastic_pixel, scatter=scatter_stochastic_pixel, grads=SampleGrads, adjoint_body=stochastic_pixel_outlined)  # fmt: skip
    lanes = lane_kernel(stochastic_lane, StochasticSampleArgs, SamplePixels, wp.array2d(dtype=float), module=MODULE, name="stochastic_lanes")
    grad_lanes = lane_kernel(scatter_stochastic_lane, StochasticSampleArgs, SamplePixels, wp.array2d(dtype=float), grads_t=SampleGrads, module=MODULE + ".grad", name="stochastic_texel_grad_lanes")
    return Kernels(*kernels, grads=("args.sample.tex",), lanes=lanes, texel_grad_lanes=grad_lanes)


@wp.kernel(enable_backward=False, module=MODULE)
def hex_taps_kernel(
    uv: wp.array(dtype=wp.vec2),
    params: StochasticArgs,
    weights: wp.array(dtype=wp.vec3),
    vertices: wp.array2d(dtype=wp.vec2i),
    taps: wp.array2d(dtype=wp.vec2),
):
    """The hex technique's taps at ``uv[i]``: normalised weights, vertex ids and tap UVs (3 each)."""
    i = wp.tid()
    bary, f, v0, v1, v2 = hex_grid(uv[i])
    weights[i] = hex_weights(bary, params.contrast)
    base = periodic_base(uv[i])
    s0, s1, s2 = hex_steps(f)
    vertices[i, 0] = v0
    vertices[i, 1] = v1
    vertices[i, 2] = v2
    taps[i, 0] = hex_tap(uv[i], f, base, v0, s0, params.seed, params.rotation)
    taps[i, 1] = hex_tap(uv[i], f, base, v1, s1, params.seed, params.rotation)
    taps[i, 2] = hex_tap(uv[i], f, base, v2, s2, params.seed, params.rotation)
