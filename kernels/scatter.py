"""Texel gradients: the ``scatter_*`` twins of the filters, which add where the filters read.

Sampling is linear in the texels: the gradient of a sample with respect to the texel array is the
output gradient times each tap's filter weight, added into the texels the forward pass read. The
``scatter_*`` functions mirror the ``sample_*`` ones (the same taps, from the same ``*_taps``
functions) and add instead of read. The texel-gradient kernels built on them replace Warp's
generated adjoint where only texels need gradients: that adjoint replays every function's forward
pass inside its reverse pass and measured 4.7× slower on triplanar.
"""

import warp as wp

from . import out_of_line
from .filters import bilinear_taps_outlined, nearest_tap
from .footprint import footprint_taps, footprint_uv, mip_levels
from .texels import FILTER_NEAREST, FINITE_LIMIT, NOT_FINITE, TILE_MASK, TILE_SHIFT, SamplerArgs, TexelGrad, TextureView, exact_texel, finite_uv_lod, reduce_coord


@wp.func
def mark_rows(tiles: wp.array(dtype=wp.int32), start: wp.int32, w: wp.int32, j: wp.int32):
    """Mark rows ``j`` and ``j + 1`` of a level ``w`` texels wide (as :func:`texel` indexes it)
    as added into: the tile where row ``j`` starts records how many tiles the two rows reach.

    One mark per bilinear footprint, whose texels all lie in rows ``j0`` and ``j0 + 1``: a load
    and a rarely taken store. It costs a bilinear backward about 10%, where a mark per texel cost
    14-22%. Columns are not told apart: a mark covers whole rows."""
    row = start + j * w
    t = row >> TILE_SHIFT
    reach = (((row & TILE_MASK) + 2 * w - 1) >> TILE_SHIFT) + 1
    if tiles[t] < reach:
        tiles[t] = reach


@wp.func
def scatter_texel(grad: TexelGrad, start: wp.int32, w: wp.int32, xi: wp.int32, yi: wp.int32, g: wp.vec4):
    """Add ``g`` to the gradient of the texel :func:`texel` reads (nothing for the border colour):
    with a float atomic, or in fixed point where ``grad`` says so (:func:`exact_texel`)."""
    if xi >= 0 and yi >= 0:
        if grad.exponents.shape[0] > 0:
            exact_texel(grad.exponents, grad.fixed, start + yi * w + xi, g)
        else:
            wp.atomic_add(grad.texels, start + yi * w + xi, g)


@wp.kernel(enable_backward=False)
def exact_exponents(exponents: wp.array(dtype=wp.int32)):
    """Between the passes: each texel's largest |contribution| m (float bits, biased exponent
    ``b``: m < 2**(b - 126)) and count n replaced by the exponent ``e = 62 - c - (b - 126)``,
    ``c = ceil(log2(n))``, within float32's normal range: n terms below 2**(62 - c) each."""
    i = wp.tid()
    bits = exponents[2 * i]
    n = exponents[2 * i + 1]
    c = wp.int32(31)  # n < 0: 2**31 or more contributions (the count wrapped)
    if n >= 0:
        c = wp.int32(0)
        while c < 31 and (1 << c) < n:
            c += 1
    if bits >= FINITE_LIMIT:
        exponents[2 * i] = NOT_FINITE
    else:
        exponents[2 * i] = wp.clamp(62 - c + 126 - (bits >> 23), -126, 126)


@wp.kernel(enable_backward=False)
def add_exact(texels: wp.array(dtype=wp.vec4), exponents: wp.array(dtype=wp.int32), fixed: wp.array(dtype=wp.int64)):
    """After the passes: each texel's fixed-point sum, scaled back by ``2**-e`` (exact), added into
    its gradient with one float add (NaN where a contribution was not finite)."""
    i = wp.tid()
    e = exponents[2 * i]
    if e == NOT_FINITE:
        texels[i] = wp.vec4(wp.nan)
    elif fixed[4 * i] != wp.int64(0) or fixed[4 * i + 1] != wp.int64(0) or fixed[4 * i + 2] != wp.int64(0) or fixed[4 * i + 3] != wp.int64(0):
        inverse = wp.cast((127 - e) << 23, float)  # 2**-e, exactly
        s = wp.vec4(float(fixed[4 * i]), float(fixed[4 * i + 1]), float(fixed[4 * i + 2]), float(fixed[4 * i + 3]))
        texels[i] = texels[i] + s * inverse


@out_of_line
def scatter_bilinear(grad: TexelGrad, start: wp.int32, w: wp.int32, i0: wp.int32, i1: wp.int32, j0: wp.int32, j1: wp.int32, fx: float, fy: float, g: wp.vec4):
    """Add ``g`` times each bilinear weight into the four texels of :func:`~.filters.bilinear_taps`, and
    mark their rows where tiles are tracked."""
    top = g * (1.0 - fy)
    bottom = g * fy
    scatter_texel(grad, start, w, i0, j0, top * (1.0 - fx))
    scatter_texel(grad, start, w, i1, j0, top * fx)
    scatter_texel(grad, start, w, i0, j1, bottom * (1.0 - fx))
    scatter_texel(grad, start, w, i1, j1, bottom * fx)
    if grad.tiles.shape[0] > 0:
        if j0 >= 0:
            mark_rows(grad.tiles, start, w, j0)  # rows j0 and j0 + 1
        if j1 >= 0 and (j0 < 0 or j1 < j0 or j1 > j0 + 1):  # j1 is neither j0 nor j0 + 1 (j0 a border row, or j1 wrapped)
            mark_rows(grad.tiles, start, w, j1)


@wp.func
def scatter_levels(tex: TextureView, grad: TexelGrad, layer: wp.int32, uv: wp.vec2, level: wp.int32, fraction: float, smp: SamplerArgs, g: wp.vec4):
    """Add the gradient ``g`` of :func:`sample_levels` (same arguments) into the texels it reads."""
    r = wp.vec2(reduce_coord(uv[0], smp.address), reduce_coord(uv[1], smp.address))
    if smp.filter == FILTER_NEAREST:
        start, w, x, y = nearest_tap(tex, layer, level, r, smp)
        scatter_texel(grad, start, w, x, y, g)
        if grad.tiles.shape[0] > 0 and y >= 0:
            mark_rows(grad.tiles, start, w, y)
    else:
        finer = g
        if fraction > 0.0:
            finer = g * (1.0 - fraction)
            start, w, i0, i1, j0, j1, fx, fy = bilinear_taps_outlined(tex, layer, level + 1, r, smp)
            scatter_bilinear(grad, start, w, i0, i1, j0, j1, fx, fy, g * fraction)
        start, w, i0, i1, j0, j1, fx, fy = bilinear_taps_outlined(tex, layer, level, r, smp)
        scatter_bilinear(grad, start, w, i0, i1, j0, j1, fx, fy, finer)


@wp.func
def scatter_lod(tex: TextureView, grad: TexelGrad, layer: wp.int32, uv: wp.vec2, lod: float, smp: SamplerArgs, g: wp.vec4):
    """Add the gradient ``g`` of :func:`sample_lod` (same arguments) into the texels it reads;
    non-finite ``uv`` or ``lod`` read nothing and add nothing."""
    if finite_uv_lod(uv, lod):
        lf = mip_levels(tex, lod, smp)
        scatter_levels(tex, grad, layer, uv, int(lf[0]), lf[1], smp, g)


@out_of_line
def scatter_taps(tex: TextureView, grad: TexelGrad, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs, g: wp.vec4):
    """:func:`scatter_footprint` for several taps, out of line."""
    share = g * (1.0 / fp[3])
    for k in range(footprint_taps(fp)):
        scatter_lod(tex, grad, layer, footprint_uv(uv, fp, k), fp[0], smp, share)


@wp.func
def scatter_footprint(tex: TextureView, grad: TexelGrad, layer: wp.int32, uv: wp.vec2, fp: wp.vec4, smp: SamplerArgs, g: wp.vec4):
    """Add the gradient ``g`` of :func:`sample_footprint` (same arguments) into the texels it reads."""
    if fp[3] == 1.0:
        scatter_lod(tex, grad, layer, uv, fp[0], smp, g)
    else:
        scatter_taps(tex, grad, layer, uv, fp, smp, g)
