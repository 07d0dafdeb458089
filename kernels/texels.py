"""Textures as kernels see them: storage, samplers, address modes, texel fetch, channel I/O.

Texture storage (see :class:`TextureView`): the texels of all layers and all mip levels live in
one flat buffer of four channels a texel (unused channels are zero), level by level: a
``wp.array`` of ``vec4`` for float32 textures, half vectors or packed 8-bit codes for the compact
formats (``FORMAT_*``), read through :func:`stored_texel`. Inside level ``k``,
the layers follow each other, each stored row-major with row 0 at the *top* of the image::

    index(layer, k, row, col) = level_offset[k] + (layer * h_k + row) * w_k + col

so level 0 of every layer is the contiguous prefix of the buffer, shaped ``(layers, H, W)``.

UV convention (OpenGL / trimesh): ``(0, 0)`` is the bottom-left corner of the image as viewed,
``(1, 1)`` the top-right. Texel ``(row i, col j)`` of a ``w × h`` level has its centre at
``u = (j + 0.5) / w``, ``v = 1 - (i + 0.5) / h``.

Every technique addresses and fetches texels through the ``@wp.func`` blocks here; filtering is in
:mod:`.filters`, footprints and levels of detail in :mod:`.footprint`, texel gradients in
:mod:`.scatter`.
"""

import functools
from typing import Any

import warp as wp

from . import out_of_line

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


# Texel formats (``warptex.Format``): how :class:`TextureView` stores its texels.
FORMAT_FLOAT32 = wp.constant(0)  # vec4 of float32, in ``texels``
FORMAT_FLOAT16 = wp.constant(1)  # vec4 of float16, at ``packed``
FORMAT_8BIT = wp.constant(2)  # four 8-bit codes in a uint32 (channel c in bits 8c..8c+7), at
# ``packed``, decoded by the table at ``decode``: channel c's code k is decode[256 c + k] (srgb8)
FORMAT_UNORM8 = wp.constant(3)  # FORMAT_8BIT whose table is k / 255 in every channel (unorm8): the
# lanes divide instead of looking up (float32(k) / 255 is the table's value for every k)
FORMAT_FLOAT32_PACKED = wp.constant(4)  # float32 vec4 at ``packed``: how a generated adjoint whose texel
# gradient is summed in fixed point reads a float32 texture (``texels`` empty: Warp's adjoint of
# an array read would add with float atomics; :func:`adj_packed_texel` adds at ``exact`` instead)


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
    # Other formats than FORMAT_FLOAT32 (``texels`` then only carries their gradient): where their
    # texels are, and FORMAT_8BIT's decode table (4 x 256 float32). Addresses rather than arrays:
    # every array field of the struct is code in each adjoint a generated-adjoint kernel takes of it
    # (three more arrays made ``warptex.adjoint.triplanar`` compile 24 -> 36 s for sm_90).
    texel_format: wp.int32
    packed: wp.uint64  # vec4h (FORMAT_FLOAT16), uint32 (FORMAT_8BIT) or vec4 (FORMAT_FLOAT32_PACKED) per texel
    decode: wp.uint64
    # 0, or where a generated adjoint sums this texture's gradient in fixed point: two uint64, the
    # addresses of :func:`exact_texel`'s ``exponents`` and ``fixed`` (0 in the first pass).
    exact: wp.uint64


def level_table(sizes: tuple, num_layers: int, device) -> tuple:
    """``(offsets, level_offset, level_height, level_width)`` of a :class:`TextureView` whose
    levels have ``sizes`` ``((h, w), ...)``: each level's first entry (a tuple), then the same and
    the levels' sizes as int32 arrays on ``device``. Shared by the textures of that shape (kernels
    only read them): making the three arrays was ~0.1 ms of every texture, and the PyTorch bridge
    wraps its tensors in a new texture every call."""
    return _level_table(sizes, num_layers, device.alias)  # (a Warp device is not hashable: its name is)


@functools.lru_cache(maxsize=256)
def _level_table(sizes: tuple, num_layers: int, device: str) -> tuple:
    offsets, start = [], 0
    for h, w in sizes:
        offsets.append(start)
        start += int(num_layers * h * w)
    table = [offsets, [int(h) for h, _ in sizes], [int(w) for _, w in sizes]]
    return (tuple(offsets), *(wp.array(values, dtype=wp.int32, device=device) for values in table))


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

    On the CPU, the chunks of a backward pass past the first add into private copies of a
    gradient, and only the tiles a copy marked are added into the real one (``warptex._accumulate``).

    On CUDA, where one launch adds with atomics, a deterministic backward sums in fixed point
    instead (:func:`exact_texel`): ``exponents`` (two per texel; empty:
    plain float atomics into ``texels``) and ``fixed`` (four int64 per texel; empty: the first
    pass, which only bounds each texel's contributions). ``texels`` then only says the gradient is
    needed: :func:`~warptex.kernels.scatter.add_exact` adds the sums in afterwards."""

    texels: wp.array(dtype=wp.vec4)
    tiles: wp.array(dtype=wp.int32)
    exponents: wp.array(dtype=wp.int32)
    fixed: wp.array(dtype=wp.int64)


# A deterministic texel gradient on CUDA (warptex._accumulate.exact_sums), for the hand-written
# gradients (``TexelGrad``) and Warp's generated adjoints (:func:`packed_texel`) alike: float atomics add in
# whatever order the threads reach them, so their sums change in the last bits from run to run.
# Integer addition is associative: the contributions are added as int64 in fixed point, each
# texel with a power-of-two scale 2**e, so that neither the order nor the thread count can change
# a bit. Two passes of the same gradient kernel (or adjoint): the first counts each texel's contributions (n)
# and keeps the largest |component| m (as its float bits, which order as the values do for
# x >= 0); the second adds rint(contribution * 2**e), with e chosen so that each term is below
# 2**62 / n: the int64 sum cannot overflow. Each contribution is then exact to m * 2**(c - 62),
# c = ceil(log2(n)): the sum is the exact sum of contributions rounded far below float32's step.
FINITE_LIMIT = wp.constant(0x7F800000)  # the float bits of +inf: larger bits are not finite
NOT_FINITE = wp.constant(-(1 << 20))  # an exponent that marks a texel some non-finite contribution reached


@out_of_line
def exact_texel(exponents: wp.array(dtype=wp.int32), fixed: wp.array(dtype=wp.int64), index: wp.int32, g: wp.vec4):
    """One pass of the fixed-point sum (see above) for the contribution ``g`` to texel ``index``:
    ``exponents`` holds two int32 per texel, ``fixed`` four int64 (empty: the first pass)."""
    if fixed.shape[0] == 0:  # the first pass: the count, and the largest |component| as float bits
        m = wp.max(wp.max(wp.abs(g[0]), wp.abs(g[1])), wp.max(wp.abs(g[2]), wp.abs(g[3])))
        bits = FINITE_LIMIT
        if wp.isfinite(g):
            bits = wp.cast(m, wp.int32)
        wp.atomic_max(exponents, 2 * index, bits)
        wp.atomic_add(exponents, 2 * index + 1, 1)
    else:
        e = exponents[2 * index]
        if e != NOT_FINITE:
            scale = wp.cast((e + 127) << 23, float)  # 2**e, exactly
            for c in range(4):
                wp.atomic_add(fixed, 4 * index + c, wp.int64(wp.rint(g[c] * scale)))


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
        value = stored_texel(tex, start + yi * w + xi)
    return value


@wp.func
def stored_texel(tex: TextureView, index: wp.int32) -> wp.vec4:
    """Entry ``index`` of the texel chain, decoded to float32 from the texture's format: a texel is
    decoded before it is filtered, as GPUs filter sRGB textures."""
    value = wp.vec4(0.0)
    if tex.texel_format == FORMAT_FLOAT32:
        value = tex.texels[index]
    else:
        value = packed_texel(tex.texel_format, tex.packed, tex.decode, tex.exact, index)
    return value


@out_of_line
def packed_texel(texel_format: wp.int32, packed: wp.uint64, decode: wp.uint64, exact: wp.uint64, index: wp.int32) -> wp.vec4:
    """:func:`stored_texel` of a texture not read as an array of float32 texels. 8-bit texels are
    decoded per channel by the texture's table (the exact sRGB curve for sRGB colour), half floats
    converted exactly, float32 ones (:data:`FORMAT_FLOAT32_PACKED`) read as they are.
    Out of line, on the view's scalars (not the struct, which a call would copy): one copy a
    module, not one a texel read."""
    value = wp.vec4(0.0)
    if texel_format == FORMAT_FLOAT32_PACKED:
        value = wp.array(ptr=packed, shape=(index + 1,), dtype=wp.vec4)[index]
    elif texel_format == FORMAT_FLOAT16:
        h = wp.array(ptr=packed, shape=(index + 1,), dtype=wp.vec4h)[index]
        value = wp.vec4(float(h[0]), float(h[1]), float(h[2]), float(h[3]))
    else:
        p = wp.array(ptr=packed, shape=(index + 1,), dtype=wp.uint32)[index]
        table = wp.array(ptr=decode, shape=(1024,), dtype=float)
        value = wp.vec4(
            table[int(p & wp.uint32(255))],
            table[256 + int((p >> wp.uint32(8)) & wp.uint32(255))],
            table[512 + int((p >> wp.uint32(16)) & wp.uint32(255))],
            table[768 + int(p >> wp.uint32(24))],
        )
    return value


@wp.func_grad(packed_texel)
def adj_packed_texel(texel_format: wp.int32, packed: wp.uint64, decode: wp.uint64, exact: wp.uint64, index: wp.int32, adj_ret: wp.vec4):
    """The texel's gradient in fixed point where ``exact`` says so (a float32 texture read by a
    generated adjoint on CUDA, see :data:`FORMAT_FLOAT32_PACKED`), else none: a compact format's
    texels take theirs from the hand-written gradients only (``warptex._op`` refuses Warp's
    generated adjoint for them)."""
    if exact != wp.uint64(0):
        at = wp.array(ptr=exact, shape=(2,), dtype=wp.uint64)
        entries = wp.int32(0)
        if at[1] != wp.uint64(0):
            entries = 4 * index + 4
        exact_texel(wp.array(ptr=at[0], shape=(2 * index + 2,), dtype=wp.int32), wp.array(ptr=at[1], shape=(entries,), dtype=wp.int64), index, adj_ret)


@wp.func
def fetch(tex: TextureView, layer: wp.int32, level: wp.int32, x: wp.int32, y: wp.int32, smp: SamplerArgs) -> wp.vec4:
    """One texel of ``level`` at column ``x``, row ``y`` (row 0 on top), after addressing."""
    w = tex.level_width[level]
    h = tex.level_height[level]
    start = tex.level_offset[level] + layer * h * w
    return texel(tex, start, w, address_index(x, w, smp.address), address_index(y, h, smp.address), smp)


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
def pick3(a: Any, b: Any, c: Any, k: wp.int32):
    """Value ``k`` (0, 1 or 2) of three (a texture, a gradient, a tap: chosen, then used by one call;
    ``k`` is a constant in unrolled loops, where no branch is left)."""
    value = a
    if k == 1:
        value = b
    elif k == 2:
        value = c
    return value
