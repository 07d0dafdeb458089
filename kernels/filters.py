"""Filtering: nearest, bilinear and trilinear reads of one footprint, and their UV/LOD derivatives.

``sample_lod`` is the building block of every technique; ``sample_footprint`` reads a whole
footprint (:mod:`.footprint`). The ``*_outlined`` twins are the same functions kept out of line,
for the kernels with Warp's generated adjoint and the gradient paths, which call them from several
places.
"""

import warp as wp

from . import out_of_line, specialised
from .footprint import footprint_taps, footprint_uv, mip_levels
from .texels import FILTER_NEAREST, SamplerArgs, TextureView, address_near, finite_uv_lod, reduce_coord, texel

@wp.func
def nearest_tap(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs):
    """``(start, w, x, y)``: the texel that nearest filtering of one level reads, addressed
    (``-1``: border); ``uv`` already reduced by :func:`reduce_coord`."""
    w = tex.level_width[level]
    h = tex.level_height[level]
    x = int(wp.floor(uv[0] * float(w)))
    y = int(wp.floor((1.0 - uv[1]) * float(h)))
    start = tex.level_offset[level] + layer * h * w
    return start, w, address_near(x, w, smp.address), address_near(y, h, smp.address)


@wp.func
def sample_nearest(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs) -> wp.vec4:
    """Nearest texel of one level; ``uv`` already reduced by :func:`reduce_coord`."""
    start, w, x, y = nearest_tap(tex, layer, level, uv, smp)
    return texel(tex, start, w, x, y, smp)


@wp.func
def bilinear_taps(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs):
    """``(start, w, i0, i1, j0, j1, fx, fy)``: the two columns ``i`` and two rows ``j`` that bilinear
    filtering of one level reads, addressed (``-1``: border), and the fractions that weight them;
    ``uv`` already reduced by :func:`reduce_coord`. The columns and rows are addressed once each,
    not once per texel."""
    w = tex.level_width[level]
    h = tex.level_height[level]
    x = uv[0] * float(w) - 0.5
    y = (1.0 - uv[1]) * float(h) - 0.5
    x0 = wp.floor(x)
    y0 = wp.floor(y)
    start = tex.level_offset[level] + layer * h * w
    i0 = address_near(int(x0), w, smp.address)
    i1 = address_near(int(x0) + 1, w, smp.address)
    j0 = address_near(int(y0), h, smp.address)
    j1 = address_near(int(y0) + 1, h, smp.address)
    return start, w, i0, i1, j0, j1, x - x0, y - y0


@out_of_line
def bilinear_taps_outlined(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs):
    """:func:`bilinear_taps`, out of line: for the gradient paths (:func:`bilinear_derivatives`,
    ``scatter.scatter_levels``), which a gradient kernel holds beside the forward's reads. With a
    copy inlined at every call, each of its four addressings a branch on the address mode, NVRTC
    took 1.2-1.5× as long over ``warptex.splat8.grad`` and 1.2-1.5× over the triplanar gradient
    modules for sm_90 (2026-12-02). The forward paths keep the inline one."""
    start, w, i0, i1, j0, j1, fx, fy = bilinear_taps(tex, layer, level, uv, smp)
    return start, w, i0, i1, j0, j1, fx, fy


@wp.func
def sample_bilinear(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs) -> wp.vec4:
    """Bilinear filtering of one level; ``uv`` already reduced by :func:`reduce_coord`."""
    start, w, i0, i1, j0, j1, fx, fy = bilinear_taps(tex, layer, level, uv, smp)
    top = texel(tex, start, w, i0, j0, smp) * (1.0 - fx) + texel(tex, start, w, i1, j0, smp) * fx
    bottom = texel(tex, start, w, i0, j1, smp) * (1.0 - fx) + texel(tex, start, w, i1, j1, smp) * fx
    return top * (1.0 - fy) + bottom * fy

@wp.func
def sample_levels(tex: TextureView, layer: wp.int32, uv: wp.vec2, level: wp.int32, fraction: float, smp: SamplerArgs) -> wp.vec4:
    """Filter finite ``uv`` on ``level``, blended with ``level + 1`` by ``fraction`` when it is
    positive (``fraction`` is 0 for nearest and bilinear; see :func:`mip_levels`)."""
    r = wp.vec2(reduce_coord(uv[0], smp.address), reduce_coord(uv[1], smp.address))
    result = wp.vec4(0.0)
    if smp.filter == FILTER_NEAREST:
        result = sample_nearest(tex, layer, level, r, smp)
    else:
        result = sample_bilinear(tex, layer, level, r, smp)
        if fraction > 0.0:
            finer = result
            result = finer * (1.0 - fraction) + sample_bilinear(tex, layer, level + 1, r, smp) * fraction
    return result


@wp.func
def sample_lod(tex: TextureView, layer: wp.int32, uv: wp.vec2, lod: float, smp: SamplerArgs) -> wp.vec4:
    """Sample ``layer`` at ``uv`` with level of detail ``lod``: the building block of every technique.

    The levels read are those of :func:`mip_levels`. Non-finite ``uv`` or ``lod`` give NaN in
    every channel.
    """
    result = wp.vec4(wp.nan)
    if finite_uv_lod(uv, lod):
        lf = mip_levels(tex, lod, smp)
        result = sample_levels(tex, layer, uv, int(lf[0]), lf[1], smp)
    return result


@out_of_line
def sample_lod_outlined(tex: TextureView, layer: wp.int32, uv: wp.vec2, lod: float, smp: SamplerArgs) -> wp.vec4:
    """:func:`sample_lod`, out of line: for the kernels with Warp's generated adjoint, which call
    it from several places; a Warp module then compiles one copy of it and of its adjoint."""
    return sample_lod(tex, layer, uv, lod, smp)


def _sample_footprint(sample, name: str, decorate=wp.func):
    def sample_taps(tex: TextureView, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs) -> wp.vec4:
        """The mean of the footprint's taps."""
        result = wp.vec4(0.0)
        for k in range(footprint_taps(fp)):
            result += sample(tex, layer, footprint_uv(uv, fp, k), fp[0], smp)
        return result * (1.0 / fp[3])

    taps = out_of_line(specialised(sample_taps, name + "_taps"))

    def sample_footprint(tex: TextureView, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs) -> wp.vec4:
        """Sample ``layer`` at ``uv`` over the footprint ``fp``: the mean of its taps, each read by
        :func:`sample_lod`; one tap is ``sample_lod`` at ``fp``'s LOD itself.

        The one-tap case (every filter but the anisotropic one) is inline and the loop out of line:
        a loop on the common path made trilinear sampling 3-8% slower, and a loop inlined at every
        call made the splat modules compile twice as long.
        """
        result = wp.vec4()
        if fp[3] == 1.0:
            result = sample(tex, layer, uv, fp[0], smp)
        else:
            result = taps(tex, layer, uv, fp, smp)
        return result

    return decorate(specialised(sample_footprint, name))


sample_footprint = _sample_footprint(sample_lod, "sample_footprint")
# For the generated-adjoint kernels: out of line, on the out-of-line sample_lod_outlined.
sample_footprint_outlined = _sample_footprint(sample_lod_outlined, "sample_footprint_outlined", out_of_line)

# -- UV and LOD derivatives ---------------------------------------------------------------------------
#
# ``sample_lod`` and its derivatives with respect to ``uv`` and ``lod``, in one pass and as Warp's
# adjoint takes them (zero for nearest filtering, across a clamp or a floor), for hand-written
# gradients of parameters that move the UVs (tiling) and of ``sample``'s own UVs and LODs.


@out_of_line
def bilinear_derivatives(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs):
    """``(value, d/du, d/dv)`` of :func:`sample_bilinear` (same arguments; ``uv`` reduced)."""
    start, w, i0, i1, j0, j1, fx, fy = bilinear_taps_outlined(tex, layer, level, uv, smp)
    t00 = texel(tex, start, w, i0, j0, smp)
    t10 = texel(tex, start, w, i1, j0, smp)
    t01 = texel(tex, start, w, i0, j1, smp)
    t11 = texel(tex, start, w, i1, j1, smp)
    top = t00 * (1.0 - fx) + t10 * fx
    bottom = t01 * (1.0 - fx) + t11 * fx
    d_fx = (t10 - t00) * (1.0 - fy) + (t11 - t01) * fy
    return top * (1.0 - fy) + bottom * fy, d_fx * float(w), (bottom - top) * -float(tex.level_height[level])


@wp.func
def sample_levels_derivatives(tex: TextureView, layer: wp.int32, uv: wp.vec2, level: wp.int32, fraction: float, smp: SamplerArgs):
    """``(d/du, d/dv)`` of :func:`sample_levels` (same arguments, ``uv`` finite), as
    :func:`sample_lod_derivatives` takes them for its levels: zero for nearest filtering."""
    d_u = wp.vec4(0.0)
    d_v = wp.vec4(0.0)
    if smp.filter != FILTER_NEAREST:
        r = wp.vec2(reduce_coord(uv[0], smp.address), reduce_coord(uv[1], smp.address))
        value, d_u, d_v = bilinear_derivatives(tex, layer, level, r, smp)
        if fraction > 0.0:
            coarse, c_u, c_v = bilinear_derivatives(tex, layer, level + 1, r, smp)
            d_u = d_u * (1.0 - fraction) + c_u * fraction
            d_v = d_v * (1.0 - fraction) + c_v * fraction
    return d_u, d_v


@wp.func
def sample_lod_derivatives(tex: TextureView, layer: wp.int32, uv: wp.vec2, lod: float, smp: SamplerArgs):
    """``(value, d/du, d/dv, d/dlod)`` of :func:`sample_lod` (same arguments; the value is the same
    bits). Non-finite ``uv`` or ``lod`` give a NaN value and zero derivatives. ``reduce_coord`` has
    slope 1 where it does not clamp; where clamp and border clamp ``u``, all four taps read the
    same edge texel or the border colour, so the derivative is zero there by itself."""
    value = wp.vec4(wp.nan)
    d_u = wp.vec4(0.0)
    d_v = wp.vec4(0.0)
    d_lod = wp.vec4(0.0)
    if finite_uv_lod(uv, lod):
        lf = mip_levels(tex, lod, smp)
        level = int(lf[0])
        fraction = lf[1]
        r = wp.vec2(reduce_coord(uv[0], smp.address), reduce_coord(uv[1], smp.address))
        if smp.filter == FILTER_NEAREST:
            value = sample_nearest(tex, layer, level, r, smp)
        else:
            value, d_u, d_v = bilinear_derivatives(tex, layer, level, r, smp)
            if fraction > 0.0:  # trilinear between two levels (mip_levels' clamp to the chain is inactive then)
                coarse, c_u, c_v = bilinear_derivatives(tex, layer, level + 1, r, smp)
                biased = lod + smp.lod_bias
                if biased >= smp.min_lod and biased < smp.max_lod:
                    d_lod = coarse - value
                value = value * (1.0 - fraction) + coarse * fraction
                d_u = d_u * (1.0 - fraction) + c_u * fraction
                d_v = d_v * (1.0 - fraction) + c_v * fraction
    return value, d_u, d_v, d_lod


@out_of_line  # a loop of sample_lod_derivatives; inlined at each use, splat8.grad took 33 s for sm_90
def sample_footprint_derivatives(tex: TextureView, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs):
    """``(value, d/du, d/dv, d/dlod, d/dspread)`` of :func:`sample_footprint`: the taps'
    :func:`sample_lod_derivatives`, averaged; ``d/dspread`` is the derivative along a scale ``s`` of
    the step between taps (``step · s`` at ``s = 1``), which moves with a tiling as the UV does."""
    value = wp.vec4(0.0)
    d_u = wp.vec4(0.0)
    d_v = wp.vec4(0.0)
    d_lod = wp.vec4(0.0)
    d_spread = wp.vec4(0.0)
    for k in range(footprint_taps(fp)):
        offset = float(k) + 0.5 - 0.5 * fp[3]
        v, tap_u, tap_v, tap_lod = sample_lod_derivatives(tex, layer, footprint_uv(uv, fp, k), fp[0], smp)
        value += v
        d_u += tap_u
        d_v += tap_v
        d_lod += tap_lod
        d_spread += (tap_u * fp[1] + tap_v * fp[2]) * offset
    return value / fp[3], d_u / fp[3], d_v / fp[3], d_lod / fp[3], d_spread / fp[3]
