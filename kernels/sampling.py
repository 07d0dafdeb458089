"""The sampling core: address modes, texel fetch, nearest/bilinear/trilinear filtering, LOD, mips.

Every technique in warptex samples textures through the ``@wp.func`` building blocks in this
module, so a texture is addressed and filtered the same way everywhere.

Texture storage (see :class:`TextureView`): the texels of all layers and all mip levels live in
one flat ``wp.array`` of ``vec4`` (unused channels are zero), level by level. Inside level ``k``,
the layers follow each other, each stored row-major with row 0 at the *top* of the image::

    index(layer, k, row, col) = level_offset[k] + (layer * h_k + row) * w_k + col

so level 0 of every layer is the contiguous prefix of the buffer, shaped ``(layers, H, W)``.

UV convention (OpenGL / trimesh): ``(0, 0)`` is the bottom-left corner of the image as viewed,
``(1, 1)`` the top-right. Texel ``(row i, col j)`` of a ``w × h`` level has its centre at
``u = (j + 0.5) / w``, ``v = 1 - (i + 0.5) / h``.
"""

import warp as wp

from . import ADJOINT_MODULE, out_of_line, specialised

# Filter modes (mirrored by ``warptex.Filter``).
FILTER_NEAREST = wp.constant(0)
FILTER_BILINEAR = wp.constant(1)
FILTER_TRILINEAR = wp.constant(2)
FILTER_ANISOTROPIC = wp.constant(3)  # trilinear taps along the footprint's major axis

# Address modes (mirrored by ``warptex.Address``).
ADDRESS_WRAP = wp.constant(0)
ADDRESS_CLAMP = wp.constant(1)
ADDRESS_MIRROR = wp.constant(2)
ADDRESS_BORDER = wp.constant(3)

# Where a sampling kernel takes its level of detail from.
LOD_NONE = wp.constant(0)  # level 0
LOD_CONSTANT = wp.constant(1)  # one value for every sample
LOD_PER_SAMPLE = wp.constant(2)  # an array of LODs
LOD_DERIVATIVES = wp.constant(3)  # from screen-space UV derivatives


# The largest finite float32: |x| <= FLOAT_MAX is false exactly for NaN and infinities.
FLOAT_MAX = wp.constant(3.4028234663852886e38)


@wp.struct
class TextureView:
    """A texture array with its mip chain, as kernels see it (layout in the module docstring)."""

    texels: wp.array(dtype=wp.vec4)
    level_offset: wp.array(dtype=wp.int32)
    level_width: wp.array(dtype=wp.int32)
    level_height: wp.array(dtype=wp.int32)
    num_levels: wp.int32
    num_layers: wp.int32


# Entries of a texel gradient per tile of :class:`TexelGrad`: 2**10 vec4 entries, 16 KB.
TILE_SHIFT = wp.constant(10)
TILE_MASK = wp.constant((1 << TILE_SHIFT) - 1)


@wp.struct
class TexelGrad:
    """A texel gradient, where the ``scatter_*`` functions add: ``texels``, laid out as a
    :class:`TextureView`'s texels (empty: not needed, nothing is added), and ``tiles``, one entry
    per ``2**TILE_SHIFT`` entries of ``texels`` (empty: not tracked). ``tiles[t] = k > 0`` says
    that the gradient may be non-zero in tiles ``t .. t + k - 1`` (see :func:`mark_rows`); 0, that
    nothing was added from tile ``t`` on (other marks may still reach over it).

    warptex's CPU threads add into private copies of a gradient, and sum into the real one only
    the tiles a copy marked (``warptex._launch``)."""

    texels: wp.array(dtype=wp.vec4)
    tiles: wp.array(dtype=wp.int32)


@wp.struct
class SamplerArgs:
    """How a texture is filtered and addressed, as kernels see it (packed from ``warptex.Sampler``)."""

    filter: wp.int32
    address: wp.int32
    border: wp.vec4
    lod_bias: float
    min_lod: float
    max_lod: float
    max_aniso: float  # the most taps of the anisotropic filter (>= 1)


@wp.func
def address_near(i: wp.int32, n: wp.int32, address: wp.int32) -> wp.int32:
    """Map a texel index of a *reduced* coordinate onto ``[0, n)``; ``-1`` means "outside" for border.

    Nearest and bilinear filtering of a coordinate reduced by :func:`reduce_coord` read indices
    in ``[-1, n]`` for wrap and ``[-n - 1, 2n]`` for mirror (``v`` is flipped), which a compare
    and an add place: wrap is exact on ``[-n, 2n)``, mirror on ``[-2n, 4n)``. An integer remainder
    here, even on a branch never taken, measured a quarter of a bilinear sample's time: the compiler
    computes it speculatively. :func:`address_index` takes any index.
    """
    r = i
    if address == ADDRESS_WRAP:
        if r < 0:
            r += n
        elif r >= n:
            r -= n
    elif address == ADDRESS_CLAMP:
        r = wp.clamp(i, 0, n - 1)
    elif address == ADDRESS_MIRROR:
        if r < 0:
            r = -1 - r
        elif r >= 2 * n:
            r -= 2 * n
        if r >= n:
            r = 2 * n - 1 - r
    elif i < 0 or i >= n:
        r = -1
    return r


@wp.func
def address_index(i: wp.int32, n: wp.int32, address: wp.int32) -> wp.int32:
    """Map any integer texel index onto ``[0, n)``; ``-1`` means "outside" for the border mode."""
    r = i
    if address == ADDRESS_WRAP:
        r = i % n
        if r < 0:
            r += n
    elif address == ADDRESS_MIRROR:
        period = 2 * n
        r = i % period
        if r < 0:
            r += period
        if r >= n:
            r = period - 1 - r
    else:
        r = address_near(i, n, address)
    return r


@wp.func
def reduce_coord(u: float, address: wp.int32) -> float:
    """Bring a texture coordinate into one period of its address mode, exactly.

    ``u - floor(u)`` is exact in floating point, so a UV of 1000.25 addresses the same texels as
    0.25 does (scaling 1000.25 by the texture size first would lose the fraction). Clamp and border
    read constant values beyond one texture width, so the coordinate is clamped to ``[-1, 2]``,
    which also keeps the integer conversion in range.
    """
    r = u
    if address == ADDRESS_WRAP:
        r = u - wp.floor(u)
    elif address == ADDRESS_MIRROR:
        r = u - 2.0 * wp.floor(0.5 * u)
    else:
        r = wp.clamp(u, -1.0, 2.0)
    return r


@wp.func
def finite_uv_lod(uv: wp.vec2, lod: float) -> bool:
    """Whether ``uv`` and ``lod`` are finite: three compares (``wp.isfinite`` on them measured 20%
    of a bilinear sample's time on the CPU)."""
    return wp.abs(uv[0]) <= FLOAT_MAX and wp.abs(uv[1]) <= FLOAT_MAX and wp.abs(lod) <= FLOAT_MAX


@wp.func
def write_channels(out: wp.array2d(dtype=float), i: wp.int32, value: wp.vec4):
    """``out[i, c] = value[c]`` for the ``1..4`` channels of ``out``, unrolled (a loop over
    ``out.shape[1]`` measured a third slower than a bilinear tap)."""
    channels = out.shape[1]
    out[i, 0] = value[0]
    if channels > 1:
        out[i, 1] = value[1]
    if channels > 2:
        out[i, 2] = value[2]
    if channels > 3:
        out[i, 3] = value[3]


@wp.func
def texel(tex: TextureView, start: wp.int32, w: wp.int32, xi: wp.int32, yi: wp.int32, smp: SamplerArgs) -> wp.vec4:
    """The texel at addressed column ``xi``, row ``yi`` of the ``w``-wide image starting at
    ``start``, or the border colour where either index is ``-1``."""
    value = smp.border
    if xi >= 0 and yi >= 0:
        value = tex.texels[start + yi * w + xi]
    return value


@wp.func
def fetch(tex: TextureView, layer: wp.int32, level: wp.int32, x: wp.int32, y: wp.int32, smp: SamplerArgs) -> wp.vec4:
    """One texel of ``level`` at column ``x``, row ``y`` (row 0 on top), after addressing."""
    w = tex.level_width[level]
    h = tex.level_height[level]
    start = tex.level_offset[level] + layer * h * w
    return texel(tex, start, w, address_index(x, w, smp.address), address_index(y, h, smp.address), smp)


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


@wp.func
def sample_bilinear(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs) -> wp.vec4:
    """Bilinear filtering of one level; ``uv`` already reduced by :func:`reduce_coord`."""
    start, w, i0, i1, j0, j1, fx, fy = bilinear_taps(tex, layer, level, uv, smp)
    top = texel(tex, start, w, i0, j0, smp) * (1.0 - fx) + texel(tex, start, w, i1, j0, smp) * fx
    bottom = texel(tex, start, w, i0, j1, smp) * (1.0 - fx) + texel(tex, start, w, i1, j1, smp) * fx
    return top * (1.0 - fy) + bottom * fy


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
    lod = 0.5 * wp.log2(wp.min(wp.max(wp.max(aa, bb), 1.0e-30), FLOAT_MAX))
    return wp.where(aa + bb == aa + bb, lod, wp.nan)  # wp.max drops a NaN: put it back (a select, no branch)


@wp.func
def level0_size(tex: TextureView) -> wp.vec2:
    return wp.vec2(float(tex.level_width[0]), float(tex.level_height[0]))


@wp.func
def lod_from_derivatives(tex: TextureView, uv_dx: wp.vec2, uv_dy: wp.vec2) -> float:
    """:func:`footprint_lod` on ``tex``' level 0."""
    return footprint_lod(level0_size(tex), uv_dx, uv_dy)


# -- footprints: where a filter reads, and at which LOD -----------------------------------------------
#
# A footprint is a ``vec4`` ``(lod, step_u, step_v, taps)``: the filter reads ``taps`` trilinear (or
# bilinear, nearest) samples at ``uv + step · (k + 1/2 - taps/2)``, ``k = 0 .. taps - 1``, all at
# ``lod``, and averages them. Every filter but the anisotropic one has one tap and no step, which
# reads ``uv`` itself, bit for bit as a single sample does; so has an anisotropic footprint of one tap.


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
            result = point_footprint(wp.log2(extent))  # one tap reads the UV itself: no step, no axis
        else:
            # The major axis: an eigenvector of J Jᵀ for major², the longer of its two expressions.
            v = wp.vec2(B, major2 - A)
            other = wp.vec2(major2 - C, B)
            if wp.dot(other, other) > wp.dot(v, v):
                v = other
            e = v / wp.length(v)  # |v|² >= floor² > 0
            step = e * (major / taps)
            result = wp.vec4(wp.log2(extent), step[0] / size[0], step[1] / size[1], taps)
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
        lod = 0.5 * wp.log2(axis2)
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
def sample_lod_call(tex: TextureView, layer: wp.int32, uv: wp.vec2, lod: float, smp: SamplerArgs) -> wp.vec4:
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
# For the generated-adjoint kernels: out of line, on the out-of-line sample_lod_call.
sample_footprint_call = _sample_footprint(sample_lod_call, "sample_footprint_call", out_of_line)


# -- texel gradients ---------------------------------------------------------------------------------
#
# Sampling is linear in the texels: the gradient of a sample with respect to the texel array is the
# output gradient times each tap's filter weight, added into the texels the forward pass read. The
# ``scatter_*`` functions mirror the ``sample_*`` ones (the same taps, from the same ``*_taps``
# functions) and add instead of read. The texel-gradient kernels built on them replace Warp's
# generated adjoint where only texels need gradients: that adjoint replays every function's forward
# pass inside its reverse pass and measured 4.7× slower on triplanar.


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
    """Add ``g`` to the gradient of the texel :func:`texel` reads (nothing for the border colour)."""
    if xi >= 0 and yi >= 0:
        wp.atomic_add(grad.texels, start + yi * w + xi, g)


@wp.func
def scatter_bilinear(grad: TexelGrad, start: wp.int32, w: wp.int32, i0: wp.int32, i1: wp.int32, j0: wp.int32, j1: wp.int32, fx: float, fy: float, g: wp.vec4):
    """Add ``g`` times each bilinear weight into the four texels of :func:`bilinear_taps`, and
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
            start, w, i0, i1, j0, j1, fx, fy = bilinear_taps(tex, layer, level + 1, r, smp)
            scatter_bilinear(grad, start, w, i0, i1, j0, j1, fx, fy, g * fraction)
        start, w, i0, i1, j0, j1, fx, fy = bilinear_taps(tex, layer, level, r, smp)
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


# -- UV and LOD derivatives ---------------------------------------------------------------------------
#
# ``sample_lod`` and its derivatives with respect to ``uv`` and ``lod``, in one pass and as Warp's
# adjoint takes them (zero for nearest filtering, across a clamp or a floor), for hand-written
# gradients of parameters that move the UVs (tiling).


@wp.func
def bilinear_derivatives(tex: TextureView, layer: wp.int32, level: wp.int32, uv: wp.vec2, smp: SamplerArgs):
    """``(value, d/du, d/dv)`` of :func:`sample_bilinear` (same arguments; ``uv`` reduced)."""
    start, w, i0, i1, j0, j1, fx, fy = bilinear_taps(tex, layer, level, uv, smp)
    t00 = texel(tex, start, w, i0, j0, smp)
    t10 = texel(tex, start, w, i1, j0, smp)
    t01 = texel(tex, start, w, i0, j1, smp)
    t11 = texel(tex, start, w, i1, j1, smp)
    top = t00 * (1.0 - fx) + t10 * fx
    bottom = t01 * (1.0 - fx) + t11 * fx
    d_fx = (t10 - t00) * (1.0 - fy) + (t11 - t01) * fy
    return top * (1.0 - fy) + bottom * fy, d_fx * float(w), (bottom - top) * -float(tex.level_height[level])


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


@wp.func
def read_channels(a: wp.array2d(dtype=float), i: wp.int32) -> wp.vec4:
    """Row ``i`` of a ``(n, 1..4)`` float array as a ``vec4`` (missing channels 0): the reverse of
    :func:`write_channels`, for output gradients."""
    channels = a.shape[1]
    value = wp.vec4(a[i, 0], 0.0, 0.0, 0.0)
    if channels > 1:
        value[1] = a[i, 1]
    if channels > 2:
        value[2] = a[i, 2]
    if channels > 3:
        value[3] = a[i, 3]
    return value


@wp.func
def resolve_layer(tex: TextureView, i: wp.int32, layers: wp.array(dtype=wp.int32), constant_layer: wp.int32) -> wp.int32:
    """Sample ``i``'s layer: ``layers[i]`` clamped to the array when per-sample layers are given."""
    layer = constant_layer
    if layers.shape[0] > 0:
        layer = wp.clamp(layers[i], 0, tex.num_layers - 1)
    return layer


@wp.func
def resolve_layer_and_footprint(
    tex: TextureView,
    i: wp.int32,
    uv_dx: wp.array(dtype=wp.vec2),
    uv_dy: wp.array(dtype=wp.vec2),
    lods: wp.array(dtype=float),
    layers: wp.array(dtype=wp.int32),
    smp: SamplerArgs,
    lod_source: wp.int32,
    constant_lod: float,
    constant_layer: wp.int32,
):
    """Sample ``i``'s layer (per-sample indices clamped to the array) and footprint, by
    ``lod_source`` (a given LOD: one tap): the argument conventions of :func:`sample_kernel`,
    shared by every per-UV sampling kernel."""
    layer = resolve_layer(tex, i, layers, constant_layer)
    fp = point_footprint(0.0)
    if lod_source == LOD_CONSTANT:
        fp = point_footprint(constant_lod)
    elif lod_source == LOD_PER_SAMPLE:
        fp = point_footprint(lods[i])
    elif lod_source == LOD_DERIVATIVES:
        fp = texture_footprint(tex, uv_dx[i], uv_dy[i], smp)
    return layer, fp


# -- kernels --------------------------------------------------------------------------------------------
#
# A per-sample operation has three kernels (``warptex._op.Kernels``): the forward pass without Warp's
# generated adjoint; its hand-written texel gradient, whose arguments are the forward's inputs, then
# the gradient arrays it adds into, then the outputs' gradients; and the forward again with the
# generated adjoint, in a Warp module of its own, compiled only when that adjoint is recorded (when
# UVs, LODs or derivatives need gradients).

MODULE = "warptex.sample"
GRAD_MODULE = MODULE + ".grad"
MIPS_MODULE = "warptex.mips"


def _sample_kernel(module: str, enable_backward: bool, sample):
    @wp.kernel(enable_backward=enable_backward, module=module)
    def sample_kernel(
        tex: TextureView,
        uv: wp.array(dtype=wp.vec2),
        uv_dx: wp.array(dtype=wp.vec2),
        uv_dy: wp.array(dtype=wp.vec2),
        lods: wp.array(dtype=float),
        layers: wp.array(dtype=wp.int32),
        smp: SamplerArgs,
        lod_source: wp.int32,
        constant_lod: float,
        constant_layer: wp.int32,
        out: wp.array2d(dtype=float),
    ):
        """``out[i, c]`` = channel ``c`` of the texture sampled at ``uv[i]``.

        Per-sample layer indices are clamped to the array; optional arrays may be null when unused.
        """
        i = wp.tid()
        layer, fp = resolve_layer_and_footprint(tex, i, uv_dx, uv_dy, lods, layers, smp, lod_source, constant_lod, constant_layer)
        write_channels(out, i, sample(tex, layer, uv[i], fp, smp))

    return sample_kernel


def _sample_level_kernel(module: str, enable_backward: bool):
    @wp.kernel(enable_backward=enable_backward, module=module)
    def sample_level_kernel(
        tex: TextureView,
        uv: wp.array(dtype=wp.vec2),
        layers: wp.array(dtype=wp.int32),
        smp: SamplerArgs,
        level: wp.int32,
        fraction: float,
        constant_layer: wp.int32,
        out: wp.array2d(dtype=float),
    ):
        """:func:`sample_kernel` for one LOD shared by every sample, resolved on the host to ``level``
        and ``fraction`` (as :func:`mip_levels` does): the level's size and offset are then the same
        for every sample, which measured a third faster than deriving them per sample."""
        i = wp.tid()
        layer = resolve_layer(tex, i, layers, constant_layer)
        result = wp.vec4(wp.nan)
        if finite_uv_lod(uv[i], 0.0):
            result = sample_levels(tex, layer, uv[i], level, fraction, smp)
        write_channels(out, i, result)

    return sample_level_kernel


sample_kernel = _sample_kernel(MODULE, False, sample_footprint)
sample_level_kernel = _sample_level_kernel(MODULE, enable_backward=False)
sample_adjoint_kernel = _sample_kernel(ADJOINT_MODULE, True, sample_footprint_call)
sample_level_adjoint_kernel = _sample_level_kernel(ADJOINT_MODULE, enable_backward=True)


@wp.kernel(enable_backward=False, module=GRAD_MODULE)
def sample_texel_grad_kernel(
    tex: TextureView,
    uv: wp.array(dtype=wp.vec2),
    uv_dx: wp.array(dtype=wp.vec2),
    uv_dy: wp.array(dtype=wp.vec2),
    lods: wp.array(dtype=float),
    layers: wp.array(dtype=wp.int32),
    smp: SamplerArgs,
    lod_source: wp.int32,
    constant_lod: float,
    constant_layer: wp.int32,
    grad: TexelGrad,
    adj_out: wp.array2d(dtype=float),
):
    """Add the gradient of :func:`sample_kernel` (same inputs) with respect to the texels into
    ``grad``, given its output's gradient ``adj_out``."""
    i = wp.tid()
    layer, fp = resolve_layer_and_footprint(tex, i, uv_dx, uv_dy, lods, layers, smp, lod_source, constant_lod, constant_layer)
    scatter_footprint(tex, grad, layer, uv[i], fp, smp, read_channels(adj_out, i))


@wp.kernel(enable_backward=False, module=GRAD_MODULE)
def sample_level_texel_grad_kernel(
    tex: TextureView,
    uv: wp.array(dtype=wp.vec2),
    layers: wp.array(dtype=wp.int32),
    smp: SamplerArgs,
    level: wp.int32,
    fraction: float,
    constant_layer: wp.int32,
    grad: TexelGrad,
    adj_out: wp.array2d(dtype=float),
):
    """Add the gradient of :func:`sample_level_kernel` (same inputs) with respect to the texels into
    ``grad``, given its output's gradient ``adj_out``."""
    i = wp.tid()
    if finite_uv_lod(uv[i], 0.0):
        scatter_levels(tex, grad, resolve_layer(tex, i, layers, constant_layer), uv[i], level, fraction, smp, read_channels(adj_out, i))


@wp.kernel(module=MIPS_MODULE)
def downsample_kernel(tex: TextureView, level: wp.int32, texels: wp.array(dtype=wp.vec4)):
    """Box-filter ``level`` into ``level + 1`` of every layer, for any (non-power-of-two) size.

    Launched over ``(layers, h_{k+1}, w_{k+1})``. Each coarse texel covers an axis-aligned
    rectangle of ``w_k / w_{k+1}`` by ``h_k / h_{k+1}`` fine texels and is the area-weighted mean
    of the fine texels it overlaps, so odd sizes lose nothing and a constant stays constant.
    ``texels`` is ``tex.texels``, passed separately so the tape sees the write; the two levels are
    disjoint, so the backward pass carries gradients of level ``k + 1`` down to level ``k``.
    """
    layer, row, col = wp.tid()
    w0 = tex.level_width[level]
    h0 = tex.level_height[level]
    w1 = tex.level_width[level + 1]
    h1 = tex.level_height[level + 1]
    # Cell edges as exact integer ratios, so the last cell ends exactly on the last fine texel.
    x_lo = float(col * w0) / float(w1)
    x_hi = float((col + 1) * w0) / float(w1)
    y_lo = float(row * h0) / float(h1)
    y_hi = float((row + 1) * h0) / float(h1)
    src = tex.level_offset[level] + layer * h0 * w0
    norm = float(w1 * h1) / float(w0 * h0)  # applied to each term, so that texels near FLOAT_MAX do not overflow the sum
    acc = wp.vec4(0.0)
    for y in range(int(wp.floor(y_lo)), wp.min(int(wp.ceil(y_hi)), h0)):
        wy = wp.min(y_hi, float(y + 1)) - wp.max(y_lo, float(y))
        for x in range(int(wp.floor(x_lo)), wp.min(int(wp.ceil(x_hi)), w0)):
            wx = wp.min(x_hi, float(x + 1)) - wp.max(x_lo, float(x))
            acc += texels[src + y * w0 + x] * (wx * wy * norm)
    texels[tex.level_offset[level + 1] + (layer * h1 + row) * w1 + col] = acc
