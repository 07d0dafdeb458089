"""Levels of detail and filter footprints: where a filter reads, and at which LOD.

A footprint is a ``vec4`` ``(lod, step_u, step_v, taps)``: the filter reads ``taps`` trilinear (or
bilinear, nearest) samples at ``uv + step · (k + 1/2 - taps/2)``, ``k = 0 .. taps - 1``, all at
``lod``, and averages them. Every filter but the anisotropic one has one tap and no step, which
reads ``uv`` itself, bit for bit as a single sample does; so has an anisotropic footprint of one tap.
"""

import warp as wp

from . import out_of_line
from .native import cpu_snippet
from .texels import FILTER_ANISOTROPIC, FILTER_TRILINEAR, FLOAT_MAX, SamplerArgs, TextureView

@wp.func_native(
    cpu_snippet("return wt_log2(x);\n", "return log2f(x);\n"),
    "adj_x += (1.0f / x) * (1.0f / wp::log(2.0f)) * adj_ret;\n",
)
def lod_log2(x: float) -> float:
    """``log2(x)`` of a positive normal ``x``, for LODs: ``wt_log2`` (``native/wt_log2.h``) on the
    CPU, the same bits as the CPU lanes' (NaN for any other ``x``; the header says how and how
    close), ``log2f`` on CUDA; its gradient is Warp's ``log2``'s. Every Warp module of warptex has
    that header (:func:`warptex.kernels.native.use`)."""
    ...


@wp.func
def footprint_lod(size: wp.vec2, uv_dx: wp.vec2, uv_dy: wp.vec2) -> float:
    """Unclamped level of detail ``log2(footprint)`` of a pixel with UV derivatives ``uv_dx``,
    ``uv_dy`` on a level-0 image of ``size`` (width, height) texels.

    The footprint is the longer of the two screen-space derivative vectors, measured in level-0
    texels (the isotropic rule of the OpenGL specification). A zero footprint gives a very negative
    LOD (about -50), never ``-inf``, so its gradient stays finite; a footprint too large for a float
    (derivatives past ~1e19 texels: the coarsest level) gives 64, never ``+inf``; a NaN derivative
    gives NaN.
    """
    a = wp.cw_mul(uv_dx, size)
    b = wp.cw_mul(uv_dy, size)
    aa = wp.dot(a, a)
    bb = wp.dot(b, b)
    lod = 0.5 * lod_log2(wp.min(wp.max(wp.max(aa, bb), 1.0e-30), FLOAT_MAX))
    return wp.where(aa + bb == aa + bb, lod, wp.nan)  # wp.max drops a NaN: put it back (a select, no branch)


@wp.func
def level0_size(tex: TextureView) -> wp.vec2:
    return wp.vec2(float(tex.level_width[0]), float(tex.level_height[0]))


@wp.func
def lod_from_derivatives(tex: TextureView, uv_dx: wp.vec2, uv_dy: wp.vec2) -> float:
    """:func:`footprint_lod` on ``tex``' level 0."""
    return footprint_lod(level0_size(tex), uv_dx, uv_dy)

@wp.func
def point_footprint(lod: float) -> wp.vec4:
    """The one-tap footprint of a given ``lod``."""
    return wp.vec4(lod, 0.0, 0.0, 1.0)


@out_of_line  # off the path of the other filters: inlined, it made trilinear sampling 5% slower
def anisotropic_footprint(size: wp.vec2, uv_dx: wp.vec2, uv_dy: wp.vec2, max_aniso: float) -> wp.vec4:
    """The anisotropic filter's footprint (see the section above) of a pixel with UV derivatives
    ``uv_dx``, ``uv_dy`` on a level-0 image of ``size`` texels.

    The pixel's footprint in texels is the parallelogram of ``a = uv_dx · size``, ``b = uv_dy ·
    size``; its ellipse (Heckbert's EWA; the D3D11 specification's anisotropic filter) has axes the
    singular values of the Jacobian ``J = [a b]``: ``major² = (A + C)/2 + sqrt(((A - C)/2)² + B²)``
    for ``J Jᵀ = [[A, B], [B, C]]``, and ``minor = |det J| / major``. The LOD is that of the minor
    axis, raised to ``major / max_aniso`` where needed so that ``taps = ceil(major / 2^lod) <=
    max_aniso`` trilinear taps, ``2^lod`` apart at most, cover the major axis' length, centred on
    the UV. The taps are weighted equally (a box along the axis): a pixel integrates its footprint
    uniformly, and a box matches that integral where a Gaussian would weight the middle and leave the
    ends under-filtered. One tap has no step. Footprints under 1e-6 or over 1e9 texels, or not
    finite, fall back to the isotropic one tap at :func:`footprint_lod` (level 0, or the coarsest
    level). :func:`uv_footprint` reads a round footprint's one tap inline instead of calling this.
    """
    a = wp.cw_mul(uv_dx, size)
    b = wp.cw_mul(uv_dy, size)
    A = a[0] * a[0] + b[0] * b[0]
    C = a[1] * a[1] + b[1] * b[1]
    area = A + C  # the squared footprint, |a|² + |b|²
    result = wp.vec4()
    # Within these bounds (1e-6 to 1e9 texels) nothing below overflows or underflows, so the
    # generated adjoint stays finite; outside them (and for NaN) one isotropic tap reads level 0
    # or the coarsest level anyway. Only the branch taken computes its LOD (one log2).
    if area > 1.0e-12 and area < 1.0e18:
        B = a[0] * a[1] + b[0] * b[1]
        h = 0.5 * (A - C)
        floor = 1.0e-6 * area
        root = wp.sqrt(wp.max(h * h + B * B, floor * floor))  # floored: no infinite slope where the footprint is round
        major2 = 0.5 * area + root
        major = wp.sqrt(major2)
        minor = wp.abs(a[0] * b[1] - a[1] * b[0]) / major
        extent = wp.max(minor, major / max_aniso)
        taps = wp.clamp(wp.ceil(major / extent - 1.0e-3), 1.0, max_aniso)  # a round footprint's rounding is one tap, not two
        if taps == 1.0:
            result = point_footprint(lod_log2(extent))  # one tap reads the UV itself: no step, no axis
        else:
            # The major axis: an eigenvector of J Jᵀ for major², the longer of its two expressions.
            v = wp.vec2(B, major2 - A)
            other = wp.vec2(major2 - C, B)
            if wp.dot(other, other) > wp.dot(v, v):
                v = other
            e = v / wp.length(v)  # |v|² >= floor² > 0
            step = e * (major / taps)
            result = wp.vec4(lod_log2(extent), step[0] / size[0], step[1] / size[1], taps)
    else:
        result = point_footprint(footprint_lod(size, uv_dx, uv_dy))
    return result


@wp.func
def round_footprint(a: wp.vec2, b: wp.vec2, aa: float, bb: float) -> bool:
    """Whether the footprint ``J = [a b]`` (level-0 texels; ``aa = |a|²``, ``bb = |b|²``) is round to
    float precision: ``(aa - bb)² + (a · b)² < (1e-6 · (aa + bb))²``. Then ``((aa - bb)/2)² + (a ·
    b)²``, which is ``((A - C)/2)² + B²`` of :func:`anisotropic_footprint` (``JᵀJ`` and ``J Jᵀ``
    have the same eigenvalues), is below its floor too: its axes are a circle's to float precision,
    ``a`` and ``b`` orthogonal and equally long. The test is strict, so it is false for a zero
    footprint, one so small that the right side underflows, and an infinite or NaN one: where it
    holds, ``aa + bb`` is positive and finite."""
    h = aa - bb
    ab = wp.dot(a, b)
    floor = 1.0e-6 * (aa + bb)
    return h * h + ab * ab < floor * floor


@wp.func_grad(round_footprint)
def adj_round_footprint(a: wp.vec2, b: wp.vec2, aa: float, bb: float, adj_ret: bool):
    """A test has no gradient. Without this, Warp's generated adjoint would multiply the test's
    intermediates by zero, and an overflowed one (huge derivatives) would make the gradient NaN."""
    pass


@wp.func
def uv_footprint(size: wp.vec2, uv_dx: wp.vec2, uv_dy: wp.vec2, smp: SamplerArgs) -> wp.vec4:
    """The footprint that ``smp``'s filter reads for UV derivatives ``uv_dx``, ``uv_dy`` on a level-0
    image of ``size`` texels: anisotropic, or one tap at :func:`footprint_lod`.

    A round anisotropic footprint (:func:`round_footprint`) is one tap, here inline, for about
    trilinear's work: at ``log2(sqrt(area / 2))``, ``area = |a|² + |b|²``, where trilinear reads
    ``log2(max(|a|, |b|))``. Both axes are ``sqrt(area / 2)`` to a relative 1e-6 there, so that LOD
    is the minor axis' (what :func:`anisotropic_footprint` computes) to 1.5e-6, and trilinear's to
    1.5e-6 too (``a`` and ``b`` are orthogonal and equally long). Its gradient is the one the
    ellipse's formulas have at a circle (half along each of ``a`` and ``b``), not trilinear's (all
    along the longer one). Every other anisotropic footprint goes out of line.
    """
    a = wp.cw_mul(uv_dx, size)
    b = wp.cw_mul(uv_dy, size)
    aa = wp.dot(a, a)
    bb = wp.dot(b, b)
    result = wp.vec4()
    if smp.filter == FILTER_ANISOTROPIC and not round_footprint(a, b, aa, bb):
        result = anisotropic_footprint(size, uv_dx, uv_dy, smp.max_aniso)
    else:
        # One tap: footprint_lod's operations (so trilinear's bits), or a round footprint's mean axis.
        # One log2 for both keeps this code, inlined at every footprint, small: a second one made
        # the sm_90 code of warptex.splat8.grad 3% larger.
        axis2 = 0.0
        if smp.filter == FILTER_ANISOTROPIC:
            axis2 = 0.5 * (aa + bb)  # round: positive and finite
        else:
            axis2 = wp.min(wp.max(wp.max(aa, bb), 1.0e-30), FLOAT_MAX)
        lod = 0.5 * lod_log2(axis2)
        result = point_footprint(wp.where(aa + bb == aa + bb, lod, wp.nan))
    return result


@wp.func
def texture_footprint(tex: TextureView, uv_dx: wp.vec2, uv_dy: wp.vec2, smp: SamplerArgs) -> wp.vec4:
    """:func:`uv_footprint` on ``tex``' level 0."""
    return uv_footprint(level0_size(tex), uv_dx, uv_dy, smp)


@wp.func
def footprint_mean(total: wp.vec4, fp: wp.vec4) -> wp.vec4:
    """``total / taps``: the mean of a sum over the footprint's taps (or a gradient's share of each).
    One tap, the case of every filter but the anisotropic one, skips the four divisions, which
    measured several percent of a sample's time."""
    result = total
    if fp[3] != 1.0:
        result = total / fp[3]
    return result


@wp.func
def footprint_taps(fp: wp.vec4) -> wp.int32:
    return int(fp[3])


@wp.func
def footprint_uv(uv: wp.vec2, fp: wp.vec4, k: wp.int32) -> wp.vec2:
    """Tap ``k``'s UV: ``uv`` itself for a one-tap footprint."""
    return uv + wp.vec2(fp[1], fp[2]) * (float(k) + 0.5 - 0.5 * fp[3])


@wp.func
def mip_levels(tex: TextureView, lod: float, smp: SamplerArgs) -> wp.vec2:
    """``(level, fraction)`` that ``lod`` reads: the sampler's bias and ``[min_lod, max_lod]`` clamp,
    then the chain's. Nearest and bilinear read level ``floor(lod + 0.5)`` (fraction 0); trilinear
    (and each anisotropic tap) blends ``floor(lod)`` and the next level by the fraction."""
    l = wp.clamp(wp.clamp(lod + smp.lod_bias, smp.min_lod, smp.max_lod), 0.0, float(tex.num_levels - 1))
    result = wp.vec2(wp.floor(l + 0.5), 0.0)
    if smp.filter >= FILTER_TRILINEAR:  # trilinear, and the anisotropic filter's taps
        result = wp.vec2(wp.floor(l), l - wp.floor(l))
    return result


@wp.func
def lod_scale_slope(tex: TextureView, uv_dx: wp.vec2, uv_dy: wp.vec2, scale: float) -> float:
    """``d/ds lod_from_derivatives(tex, uv_dx · s, uv_dy · s)`` at ``s = scale``: ``1 / (s ln 2)``,
    or 0 where the footprint is outside the floor and ceiling that keep the LOD finite."""
    size = wp.vec2(float(tex.level_width[0]), float(tex.level_height[0]))
    a = wp.cw_mul(uv_dx * scale, size)
    b = wp.cw_mul(uv_dy * scale, size)
    rho2 = wp.max(wp.dot(a, a), wp.dot(b, b))
    slope = 0.0
    if rho2 > 1.0e-30 and rho2 < FLOAT_MAX:
        slope = 1.0 / (scale * 0.6931471805599453)
    return slope
