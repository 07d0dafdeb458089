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

from . import hashing, out_of_line, specialised
from .filters import sample_footprint, sample_lod, sample_lod_outlined
from .footprint import footprint_mean, footprint_taps, footprint_uv, mip_levels
from .hashing import STREAM_CHEAP2_NOISE, STREAM_CHEAP2_OFFSET, STREAM_HASH4_CELL
from .hexgrid import hex_grid, hex_steps, hex_tap, hex_weights
from .scatter import scatter_footprint, scatter_lod
from .texels import SamplerArgs, TexelGrad, TextureView, finite_uv_lod, pick3

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
