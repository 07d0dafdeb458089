"""Stochastic texture sampling that breaks visible tiling: hash4, cheap2 and hex.

One building block, :func:`sample_stochastic`, samples a texture layer at ``uv`` over one filter
footprint (``warptex.kernels.sampling``: a LOD, and for the anisotropic filter taps along the
major axis); callers compute it from the *unperturbed* UV derivatives, so all taps read the same
mip levels and no mip seam appears at cell borders. ``params.method`` picks the technique at run
time:

* ``METHOD_NONE``: plain :func:`~warptex.kernels.sample_footprint`.
* ``METHOD_HASH4`` (Quilez, "texture repetition", technique 1): every integer cell
  ``(i, j)`` gets a hashed offset ``o`` and, with ``mirror``, per-axis signs ``s``; the four cells
  around ``uv`` are sampled at ``s * uv + o`` and blended bilinearly with weights
  ``b = smoothstep(blend_lo, blend_hi, frac(uv))``: ``lerp(lerp(a, b, bx), lerp(c, d, bx), by)``.
* ``METHOD_CHEAP2`` (Quilez technique 3): a smooth value noise ``k`` of ``uv * noise_frequency``
  picks ``l = k * noise_levels``; the two taps use the hashed offsets of indices ``floor(l)`` and
  ``floor(l) + 1`` and blend with ``smoothstep(blend_lo, blend_hi, frac(l))``.
* ``METHOD_HEX`` (Heitz & Neyret 2018; Mikkelsen 2022): ``uv * HEX_SCALE`` on a skewed
  equilateral triangle grid; the three vertices of the enclosing triangle each give an offset
  (and, with ``rotation > 0``, a rotation about the vertex centre); barycentric weights are raised
  to ``contrast`` and normalised. Without a histogram the taps are blended linearly; with one the
  texture holds Gaussianised values ``G`` and the blend is variance preserving,
  ``G = Σ wᵢ (Gᵢ - μ) / sqrt(Σ wᵢ²) + μ``, mapped back per channel by the inverse LUT of the mip
  level read (prefiltered LUTs, see ``warptex.histogram.prepare_histogram``; trilinear filtering
  blends the LUTs of its two levels) and the inverse decorrelation when ``decorrelate`` is set.

Offsets, signs and angles come from :func:`~warptex.kernels.hashing.hash4_unit` with the streams
below, so results are deterministic per seed on every device. Tap coordinates are formed from
``uv - 2 floor(uv / 2)`` (exact), which keeps precision for large UVs and is valid for the
periodic address modes (wrap, period 1; mirror, period 2), the only ones stochastic sampling takes.
"""

import warp as wp

from . import hashing, inlined, out_of_line, specialised
from .family import Kernels, family, lane_kernel, pixel_kernels
from .filters import sample_footprint, sample_lod, sample_lod_outlined
from .footprint import footprint_mean, footprint_taps, footprint_uv, mip_levels
from .hashing import STREAM_CHEAP2_NOISE, STREAM_CHEAP2_OFFSET, STREAM_HASH4_CELL, STREAM_HEX_VERTEX
from .hexgrid import HALF_SQRT3, HEX_SCALE, INV_SQRT3, PI, hex_grid, hex_steps, hex_tap, hex_weights
from .sampling import SampleArgs, SampleGrads, SamplePixels, sample_footprint_of, sample_layer
from .scatter import scatter_footprint, scatter_lod
from .lane_scatter import scatter_taps_lane
from .lanes import FOOTPRINT_CPP, LANES, SAMPLE_READS_CPP, accumulate_footprint_lane, cpu_snippet, lane_colours, lane_floats, lane_ints, lane_taps
from .texels import FILTER_ANISOTROPIC, SamplerArgs, TexelGrad, TextureView, finite_uv_lod, pick3, read_channels, write_channels

METHOD_NONE = wp.constant(0)
METHOD_HASH4 = wp.constant(1)
METHOD_CHEAP2 = wp.constant(2)
METHOD_HEX = wp.constant(3)


@wp.struct
class StochasticArgs:
    """Options of :func:`sample_stochastic` (packed by ``warptex._pack.stochastic_args``).

    ``lut`` is ``[layers, lut_levels, channels, lut_size]`` flattened: entry ``i`` of channel ``c`` at
    mip level ``k`` is the value whose Gaussianised value, read at level ``k``, is
    ``lut_lo + (i + 0.5) / lut_size * (lut_hi - lut_lo)``. ``basis`` and ``centre`` (per layer) undo
    the decorrelation: ``rgb = basis * y + centre``. Unused arrays are empty.
    """

    method: wp.int32
    seed: wp.uint32
    blend_lo: float  # hash4 / cheap2 blend window of smoothstep
    blend_hi: float
    mirror: wp.int32  # hash4 / cheap2: random per-axis mirroring of each tap
    noise_frequency: float  # cheap2: value-noise lattice cells per UV unit
    noise_levels: float  # cheap2: distinct offsets swept by the noise, k * noise_levels
    contrast: float  # hex: barycentric weight exponent (>= 1)
    rotation: float  # hex: random rotation strength in [0, 1] (0: none)
    histogram: wp.int32  # hex: 1 when the texture is Gaussianised and lut is set
    mean: float  # hex: mean of the Gaussianised values
    lut: wp.array(dtype=float)
    lut_size: wp.int32
    lut_levels: wp.int32
    lut_lo: float
    lut_hi: float
    channels: wp.int32
    decorrelate: wp.int32
    basis: wp.array(dtype=wp.mat33)
    centre: wp.array(dtype=wp.vec3)


@wp.func
def periodic_base(uv: wp.vec2) -> wp.vec2:
    """``uv - 2 floor(uv / 2)``: the same texels as ``uv`` under wrap and mirror, exactly, in [0, 2)."""
    return uv - 2.0 * wp.vec2(wp.floor(0.5 * uv[0]), wp.floor(0.5 * uv[1]))


@wp.func
def offset_tap(base: wp.vec2, h: wp.vec4, mirror: wp.int32) -> wp.vec2:
    """``s * base + (h.x, h.y)``, with ``s`` = -1 on an axis where ``mirror`` is set and ``h.z``/``h.w`` < 0.5."""
    s = wp.vec2(1.0, 1.0)
    if mirror != 0:
        if h[2] < 0.5:
            s[0] = -1.0
        if h[3] < 0.5:
            s[1] = -1.0
    return wp.cw_mul(s, base) + wp.vec2(h[0], h[1])


@wp.func
def hash4_taps(uv: wp.vec2, params: StochasticArgs):
    """``(t0, t1, t2, t3, w)``: the four cells around ``uv``, each with its hashed offset (and
    mirror), and their smoothstep blend weights (a zero-weight tap is not hashed: half of every
    axis has a single tap)."""
    cell = wp.vec2(wp.floor(uv[0]), wp.floor(uv[1]))
    f = uv - cell
    base = periodic_base(uv)
    bx = wp.smoothstep(params.blend_lo, params.blend_hi, f[0])
    by = wp.smoothstep(params.blend_lo, params.blend_hi, f[1])
    ix = int(cell[0])
    iy = int(cell[1])
    w = wp.vec4((1.0 - bx) * (1.0 - by), bx * (1.0 - by), (1.0 - bx) * by, bx * by)
    t0 = base
    t1 = base
    t2 = base
    t3 = base
    if w[0] > 0.0:
        t0 = offset_tap(base, hashing.hash4_unit(ix, iy, params.seed, STREAM_HASH4_CELL), params.mirror)
    if w[1] > 0.0:
        t1 = offset_tap(base, hashing.hash4_unit(ix + 1, iy, params.seed, STREAM_HASH4_CELL), params.mirror)
    if w[2] > 0.0:
        t2 = offset_tap(base, hashing.hash4_unit(ix, iy + 1, params.seed, STREAM_HASH4_CELL), params.mirror)
    if w[3] > 0.0:
        t3 = offset_tap(base, hashing.hash4_unit(ix + 1, iy + 1, params.seed, STREAM_HASH4_CELL), params.mirror)
    return t0, t1, t2, t3, w


@wp.func
def value_noise(p: wp.vec2, seed: wp.uint32) -> float:
    """Smooth value noise in [0, 1): hashed lattice values, bilinear with smoothstep (C1) weights."""
    cell = wp.vec2(wp.floor(p[0]), wp.floor(p[1]))
    f = p - cell
    ix = int(cell[0])
    iy = int(cell[1])
    a = hashing.hash4_unit(ix, iy, seed, STREAM_CHEAP2_NOISE)[0]
    b = hashing.hash4_unit(ix + 1, iy, seed, STREAM_CHEAP2_NOISE)[0]
    c = hashing.hash4_unit(ix, iy + 1, seed, STREAM_CHEAP2_NOISE)[0]
    d = hashing.hash4_unit(ix + 1, iy + 1, seed, STREAM_CHEAP2_NOISE)[0]
    sx = wp.smoothstep(0.0, 1.0, f[0])
    sy = wp.smoothstep(0.0, 1.0, f[1])
    return wp.lerp(wp.lerp(a, b, sx), wp.lerp(c, d, sx), sy)


@wp.func
def cheap2_taps(uv: wp.vec2, params: StochasticArgs):
    """``(t0, t1, w)``: two taps whose offsets are picked by low-frequency noise, and their blend
    weights ``(1 - t, t)`` from the noise's fraction (a zero-weight tap is not hashed)."""
    l = value_noise(uv * params.noise_frequency, params.seed) * params.noise_levels
    index = wp.floor(l)
    t = wp.smoothstep(params.blend_lo, params.blend_hi, l - index)
    base = periodic_base(uv)
    ia = int(index)
    t0 = base
    t1 = base
    if t < 1.0:
        t0 = offset_tap(base, hashing.hash4_unit(ia, 0, params.seed, STREAM_CHEAP2_OFFSET), params.mirror)
    if t > 0.0:
        t1 = offset_tap(base, hashing.hash4_unit(ia + 1, 0, params.seed, STREAM_CHEAP2_OFFSET), params.mirror)
    return t0, t1, wp.vec2(1.0 - t, t)


@wp.func
def inverse_lut(params: StochasticArgs, layer: wp.int32, level: wp.int32, c: wp.int32, g: float) -> float:
    """Linear interpolation of channel ``c``'s inverse LUT of mip ``level`` at ``g`` (ends clamped)."""
    n = params.lut_size
    x = wp.clamp((g - params.lut_lo) / (params.lut_hi - params.lut_lo) * float(n) - 0.5, 0.0, float(n - 1))
    i0 = wp.min(int(wp.floor(x)), n - 2)
    t = x - float(i0)
    k = wp.min(level, params.lut_levels - 1)
    start = ((layer * params.lut_levels + k) * params.channels + c) * n + i0
    return params.lut[start] * (1.0 - t) + params.lut[start + 1] * t


@wp.func
def hex_taps(uv: wp.vec2, params: StochasticArgs):
    """``(t0, t1, t2, w)``: the taps of the three vertices of the triangle around ``uv`` and their
    normalised weights."""
    bary, f, v0, v1, v2 = hex_grid(uv)
    base = periodic_base(uv)
    s0, s1, s2 = hex_steps(f)
    return hex_tap(uv, f, base, v0, s0, params.seed, params.rotation), hex_tap(uv, f, base, v1, s1, params.seed, params.rotation), hex_tap(uv, f, base, v2, s2, params.seed, params.rotation), hex_weights(bary, params.contrast)


@wp.func
def stochastic_taps(uv: wp.vec2, params: StochasticArgs):
    """``(t0, t1, t2, t3, w)``: the tap UVs of ``params.method`` (not ``METHOD_NONE``) at finite
    ``uv`` and their blend weights; unused taps have weight 0. hash4 uses four taps, cheap2 two,
    hex three (weights before the histogram blend)."""
    t0 = uv
    t1 = uv
    t2 = uv
    t3 = uv
    w = wp.vec4(0.0)
    if params.method == METHOD_HASH4:
        t0, t1, t2, t3, w = hash4_taps(uv, params)
    elif params.method == METHOD_CHEAP2:
        t0, t1, w2 = cheap2_taps(uv, params)
        w = wp.vec4(w2[0], w2[1], 0.0, 0.0)
    else:
        t0, t1, t2, w3 = hex_taps(uv, params)
        w = wp.vec4(w3[0], w3[1], w3[2], 0.0)
    return t0, t1, t2, t3, w


@wp.func
def pick_tap(k: wp.int32, t0: wp.vec2, t1: wp.vec2, t2: wp.vec2, t3: wp.vec2) -> wp.vec2:
    """Tap ``k`` of :func:`stochastic_taps` (``k`` is a constant in unrolled loops: no branch is left)."""
    return wp.where(k == 3, t3, pick3(t0, t1, t2, k))


@wp.func
def histogram_blend(tex: TextureView, layer: wp.int32, acc: wp.vec4, w: wp.vec4, lod: float, smp: SamplerArgs, params: StochasticArgs) -> wp.vec4:
    """The hex histogram blend of ``acc = Σ w_k (tap_k - mean)`` (Gaussianised taps): rescaled to
    the taps' variance, mapped through the inverse LUT of the levels ``lod`` reads, decorrelation
    undone."""
    g = acc / wp.sqrt(wp.dot(w, w)) + wp.vec4(params.mean)
    result = wp.vec4(0.0)
    lf = mip_levels(tex, lod, smp)
    level = int(lf[0])
    for c in range(4):
        if c < params.channels:
            channel = inverse_lut(params, layer, level, c, g[c])
            if lf[1] > 0.0:
                channel = channel * (1.0 - lf[1]) + inverse_lut(params, layer, level + 1, c, g[c]) * lf[1]
            result[c] = channel
    if params.decorrelate != 0:
        rgb = params.basis[layer] * wp.vec3(result[0], result[1], result[2]) + params.centre[layer]
        result = wp.vec4(rgb[0], rgb[1], rgb[2], result[3])
    return result


def _sample_stochastic(sample, taps, blend_histogram, name: str, decorate=wp.func):
    def sample_stochastic(tex: TextureView, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs, params: StochasticArgs) -> wp.vec4:
        """Sample ``layer`` at ``uv`` with the technique ``params.method`` over the footprint ``fp``
        (``warptex.kernels.sampling``), every tap at its LOD.

        Compute the footprint from the unperturbed UV derivatives. An anisotropic footprint's taps
        are each sampled with the technique, then averaged: the filter integrates the stochastic
        texture along the footprint. Non-finite ``uv`` or LOD give NaN in every channel.
        """
        lod = fp[0]
        result = wp.vec4(0.0)
        for j in range(footprint_taps(fp)):
            at = footprint_uv(uv, fp, j)
            value = wp.vec4(wp.nan)
            if params.method == METHOD_NONE:  # tested first: plain sampling measured 5% slower after the others' tests
                value = sample(tex, layer, at, lod, smp)
            elif finite_uv_lod(at, lod):
                t0, t1, t2, t3, w = taps(at, params)
                mean = wp.vec4(0.0)
                if params.histogram != 0:
                    mean = wp.vec4(params.mean)
                value = wp.vec4(0.0)
                for k in range(4):
                    if w[k] > 0.0:
                        value += w[k] * (sample(tex, layer, pick_tap(k, t0, t1, t2, t3), lod, smp) - mean)
                if params.histogram != 0:
                    value = blend_histogram(tex, layer, value, w, lod, smp, params)
            result += value
        return footprint_mean(result, fp)

    return decorate(specialised(sample_stochastic, name))


@out_of_line
def stochastic_taps_outlined(uv: wp.vec2, params: StochasticArgs):
    """:func:`stochastic_taps`, out of line (for :func:`sample_stochastic_outlined`)."""
    return stochastic_taps(uv, params)


@out_of_line
def histogram_blend_outlined(tex: TextureView, layer: wp.int32, acc: wp.vec4, w: wp.vec4, lod: float, smp: SamplerArgs, params: StochasticArgs) -> wp.vec4:
    """:func:`histogram_blend`, out of line (for :func:`sample_stochastic_outlined`)."""
    return histogram_blend(tex, layer, acc, w, lod, smp, params)


sample_stochastic = _sample_stochastic(sample_lod, stochastic_taps, histogram_blend, "sample_stochastic")
# For the generated-adjoint kernels: out of line, and built on out-of-line pieces, so that a Warp
# module holding several such kernels compiles each piece and its adjoint once.
sample_stochastic_outlined = _sample_stochastic(sample_lod_outlined, stochastic_taps_outlined, histogram_blend_outlined, "sample_stochastic_outlined", out_of_line)


@wp.func
def scatter_stochastic(tex: TextureView, grad: TexelGrad, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs, params: StochasticArgs, g: wp.vec4):
    """Add the gradient ``g`` of :func:`sample_stochastic` (same arguments) into the texels it
    reads: each tap's weight times ``g``. Linear blends only (no histogram, which is not linear
    in the texels)."""
    if params.method == METHOD_NONE:
        scatter_footprint(tex, grad, layer, uv, fp, smp, g)
    else:
        lod = fp[0]
        share = footprint_mean(g, fp)
        for j in range(footprint_taps(fp)):
            at = footprint_uv(uv, fp, j)
            if finite_uv_lod(at, lod):
                t0, t1, t2, t3, w = stochastic_taps(at, params)
                for k in range(4):
                    if w[k] > 0.0:
                        scatter_lod(tex, grad, layer, pick_tap(k, t0, t1, t2, t3), lod, smp, w[k] * share)


@wp.func
def sample_plain(tex: TextureView, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs, params: StochasticArgs) -> wp.vec4:
    """:func:`sample_stochastic` for ``METHOD_NONE`` without the stochastic code (``params`` is not
    read), for the plain variants of kernels that take either."""
    return sample_footprint(tex, layer, uv, fp, smp)


@wp.func
def scatter_plain(tex: TextureView, grad: TexelGrad, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs, params: StochasticArgs, g: wp.vec4):
    """:func:`scatter_stochastic` for ``METHOD_NONE`` without the stochastic code."""
    scatter_footprint(tex, grad, layer, uv, fp, smp, g)


# -- kernels (see .family) ------------------------------------------------------------------------

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
# Hex's taps (hexgrid's blocks: a float64 grid, rotations, powers) go pixel by pixel, with Warp's own
# wp::floor, wp::sin, wp::cos and wp::pow.
_TAPS = FOOTPRINT_CPP + SAMPLE_READS_CPP + r"""
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
    const float u = reads.data[0][l], v = reads.data[3][l], lod = reads.data[6][l];
    fin[l] = l < count && __builtin_fabsf(u) <= wt_float_max && __builtin_fabsf(v) <= wt_float_max && __builtin_fabsf(lod) <= wt_float_max ? 1.0f : 0.0f;
    taps.data[12][l] = lod;
    taps.data[13][l] = fin[l];
}
const float lo = params.blend_lo, hi = params.blend_hi;
const unsigned seed = params.seed;
if (params.method == WT_HASH4) {
    for (int l = 0; l < WT_L; ++l) {
        const float u = fin[l] != 0.0f ? reads.data[0][l] : 0.0f, v = fin[l] != 0.0f ? reads.data[3][l] : 0.0f;
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
        const float u = fin[l] != 0.0f ? reads.data[0][l] : 0.0f, v = fin[l] != 0.0f ? reads.data[3][l] : 0.0f;
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
} else {  // hexgrid: hex_grid (in float64), hex_steps, hex_tap, hex_weights
    const double scale = %(hex_scale)r, inv_sqrt3 = %(inv_sqrt3)r, half_sqrt3_64 = %(half_sqrt3)r;  // wp.float64 of a constant: its value as a double
    const float half_sqrt3 = (float)%(half_sqrt3)r, pi = (float)%(pi)r, hex_scale = (float)%(hex_scale)r;
    auto lattice_id = [](double b) __attribute__((always_inline)) -> int {
        const double limit = 1073741824.0;
        if (b >= limit || b < -limit) b = b - wp::floor(b / limit) * limit;
        return (int)b;
    };
    for (int l = 0; l < WT_L; ++l) {
        if (fin[l] == 0.0f) continue;
        const float u = reads.data[0][l], v = reads.data[3][l];
        const double px = (double)u * scale, py = (double)v * scale;
        const double sx = px - py * inv_sqrt3, sy = 2.0 * inv_sqrt3 * py;
        const double bx = wp::floor(sx), by = wp::floor(sy);
        const float f0 = (float)(sx - bx), f1 = (float)(sy - by);
        const int i = lattice_id(bx), j = lattice_id(by);
        const bool upper = f0 + f1 >= 1.0f;
        float bary[3] = {1.0f - f0 - f1, f0, f1};
        int vi[3] = {i, i + 1, i}, vj[3] = {j, j, j + 1};
        float step_u[3] = {0.0f, 1.0f, 0.0f}, step_v[3] = {0.0f, 0.0f, 1.0f};
        if (upper) {
            bary[0] = f0 + f1 - 1.0f; bary[1] = 1.0f - f1; bary[2] = 1.0f - f0;
            vi[0] = i + 1; vj[0] = j + 1;
            step_u[0] = 1.0f; step_v[0] = 1.0f;
        }
        const float bu = u - 2.0f * wp::floor(0.5f * u), bv = v - 2.0f * wp::floor(0.5f * v);  // periodic_base
        for (int k = 0; k < 3; ++k) {  // hex_tap
            float h[4];
            unit((unsigned)vi[k], (unsigned)vj[k], seed, (unsigned)WT_STREAM_HEX, h);
            float tu = bu + h[0], tv = bv + h[1];
            if (params.rotation != 0.0f) {
                float du, dv;
                if (wp::abs(u) < 1.0e8f && wp::abs(v) < 1.0e8f) {
                    const double cu = ((double)vi[k] + 0.5 * (double)vj[k]) / scale, cv = half_sqrt3_64 * (double)vj[k] / scale;  // hex_centre64
                    du = (float)((double)u - cu);
                    dv = (float)((double)v - cv);
                } else {
                    const float x = f0 - step_u[k], y = f1 - step_v[k];
                    du = (x + 0.5f * y) / hex_scale;
                    dv = (half_sqrt3 * y) / hex_scale;
                }
                const float theta = (2.0f * h[2] - 1.0f) * pi * params.rotation;
                const float cs = wp::cos(theta), sn = wp::sin(theta);
                tu = tu + ((cs * du - sn * dv) - du);
                tv = tv + ((sn * du + cs * dv) - dv);
            }
            taps.data[3 * k][l] = tu;
            taps.data[3 * k + 1][l] = tv;
        }
        float pw[3];
        for (int k = 0; k < 3; ++k) pw[k] = bary[k] > 0.0f ? wp::pow(bary[k], params.contrast) : 0.0f;  // hex_weights
        const float total = pw[0] + pw[1] + pw[2];
        for (int k = 0; k < 3; ++k) taps.data[3 * k + 2][l] = pw[k] / total;
    }
}
return taps;
""" % {"hash4": int(METHOD_HASH4), "cheap2": int(METHOD_CHEAP2), "cell": int(STREAM_HASH4_CELL), "offset": int(STREAM_CHEAP2_OFFSET), "noise": int(STREAM_CHEAP2_NOISE),
       "hex": int(STREAM_HEX_VERTEX), "hex_scale": float(HEX_SCALE), "inv_sqrt3": float(INV_SQRT3), "half_sqrt3": float(HALF_SQRT3), "pi": float(PI)}


@wp.func_native(cpu_snippet(_TAPS, "return {};\n"))
def stochastic_taps_lane(tex: TextureView, smp: SamplerArgs, params: StochasticArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2),
                         lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float, base: wp.int32) -> lane_taps:  # fmt: skip
    """The lane's :data:`~.lanes.lane_taps` from ``base``: every pixel's LOD
    (``sampling.sample_footprint_of``, one tap), whether its UV and LOD are finite, and its taps and
    their weights (0 where not finite)."""
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
def lane_taps_linear(args: StochasticSampleArgs) -> bool:
    """Whether the lanes take the launch tap by tap: a linear blend (no histogram) of one-tap
    footprints (not the anisotropic filter) of a stochastic method."""
    return args.sample.smp.filter != FILTER_ANISOTROPIC and args.params.histogram == 0 and args.params.method != METHOD_NONE


@inlined
def stochastic_lane(args: StochasticSampleArgs, pixels: SamplePixels, base: wp.int32, out: wp.array2d(dtype=float)):
    """:func:`stochastic_pixel` for the lane of pixels from ``base`` (:mod:`.lanes`), on the CPU:
    the lane's taps (:func:`stochastic_lane_taps`), then read natively, tap by tap, with
    ``lanes.accumulate_footprint_lane`` (``value += w · sample``, as :func:`sample_stochastic`
    blends them, from 0). A histogram's blend (not linear), the anisotropic filter's footprints
    (several taps, each with its stochastic taps) and plain sampling go pixel by pixel through the
    body."""
    count = wp.min(out.shape[0] - base, LANES)
    if not lane_taps_linear(args):
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
    if not lane_taps_linear(args):
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
