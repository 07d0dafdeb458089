"""Texel formats: how a texture stores its texels (:class:`Format`), and the host side of the
compact ones: 8-bit decode tables, encoding and decoding, and mip levels built in linear space.
Kernels read every format through :func:`warptex.kernels.texels.stored_texel`."""

from __future__ import annotations

import enum

import numpy as np
import warp as wp

from warptex import io
from warptex.png import codes, colour_channels
from warptex._warp import active_tape, replay
from warptex.kernels import texels as kx
from warptex.kernels.sampling import downsample_kernel


class Format(str, enum.Enum):
    """How a texture stores its texels (``format=`` of :class:`Texture` and :class:`TextureArray`).

    Every technique reads every format: a texel is decoded to float32 when it is read, before it is
    filtered, and filtering is float32 arithmetic, so a texture of any format samples as the
    float32 texture of its decoded texels does (bit for bit).

    - ``FLOAT32``: 16 bytes a texel, values as given.
    - ``FLOAT16``: IEEE half floats, 8 bytes a texel (HDR maps; half EXR files load as it).
    - ``UNORM8``: 8-bit codes ``k`` meaning ``k / 255``, 4 bytes a texel, whatever the channel
      count: data such as normal, height and splat maps.
    - ``SRGB8``: 8-bit codes whose colour channels are sRGB-encoded, decoded with the exact
      IEC 61966-2-1 curve (alpha, the last of 2 or 4 channels, is ``k / 255``), as GPUs read
      ``SRGB8_ALPHA8``: colour photos and game textures. Mips are box-filtered in linear space and
      encoded back.

    Floats stored as 8 bits are clipped to ``[0, 1]`` and rounded to the nearest code (sRGB
    colour after encoding). Mips of the three compact formats are built on the host from level
    0's decoded texels; their gradients land in a float32 gradient (:meth:`TextureArray.grad`).
    """

    FLOAT32 = "float32"
    FLOAT16 = "float16"
    UNORM8 = "unorm8"
    SRGB8 = "srgb8"


#: Bytes a texel takes in each format.
TEXEL_BYTES = {Format.FLOAT32: 16, Format.FLOAT16: 8, Format.UNORM8: 4, Format.SRGB8: 4}
EIGHT_BIT = (Format.UNORM8, Format.SRGB8)
KERNEL_FORMAT = {Format.FLOAT32: kx.FORMAT_FLOAT32, Format.FLOAT16: kx.FORMAT_FLOAT16, Format.UNORM8: kx.FORMAT_UNORM8, Format.SRGB8: kx.FORMAT_8BIT}
#: Rows of a coarser level built at a time from an 8-bit or half level (bounds the host memory a mip chain takes).
_MIP_BAND_ROWS = 256


def texture_format(value, func: str) -> Format:
    """``value`` (a :class:`Format` or its name) as a :class:`Format`."""
    try:
        return Format(value.lower() if isinstance(value, str) else value)
    except (ValueError, AttributeError):
        raise ValueError(f"{func}(): format must be one of {[f.value for f in Format]}, got {value!r}") from None


def decode_table(fmt: Format, channels: int) -> np.ndarray:
    """The float32 values of the 8-bit codes of ``fmt``: ``table[256 c + k]`` is channel ``c``'s code
    ``k``, the value :func:`warptex.io.read_image` decodes it to (:func:`warptex.io.code_values`:
    sRGB colour for ``SRGB8``), so a texture made from a file holds the values ``read_image`` returns."""
    unorm, srgb = io.code_values(255)
    table = np.tile(unorm, 4)
    if fmt is Format.SRGB8:
        for c in range(colour_channels(channels)):
            table[256 * c : 256 * (c + 1)] = srgb
    return table


def encode(values: np.ndarray, fmt: Format) -> np.ndarray:
    """Float texels ``[..., C]`` (linear) as ``fmt`` stores them: ``[..., 4]`` of float32, float16
    or uint8 codes (unused channels zero). 8-bit codes are what a PNG of the values holds
    (:func:`warptex.png.codes`: clipped to ``[0, 1]``, sRGB colour encoded, rounded)."""
    out = np.zeros(values.shape[:-1] + (4,), dtype={Format.FLOAT32: np.float32, Format.FLOAT16: np.float16}.get(fmt, np.uint8))
    out[..., : values.shape[-1]] = values if fmt not in EIGHT_BIT else codes(values, data=fmt is Format.UNORM8, bits=8)
    return out


def decode(stored: np.ndarray, fmt: Format, channels: int) -> np.ndarray:
    """Stored texels ``[..., 4]`` of ``fmt`` (uint8 codes for 8-bit formats) as float32 ``[..., C]``."""
    if fmt in EIGHT_BIT:
        offsets = np.arange(channels, dtype=np.uint16) * 256  # channel c's codes index table[256 c:]
        return decode_table(fmt, channels)[stored[..., :channels] + offsets]
    return stored[..., :channels].astype(np.float32)


def _box_weights(n0: int, n1: int) -> tuple[np.ndarray, np.ndarray]:
    """The box filter from ``n0`` texels to ``n1`` along one axis, as ``downsample_kernel`` weighs
    it: coarse texel ``j`` is ``sum_t weight[j, t] * fine[index[j, t]]``, the fine texels its cell
    ``[j n0 / n1, (j + 1) n0 / n1)`` overlaps, each by the overlap times ``n1 / n0``."""
    lo = np.arange(n1, dtype=np.float64) * n0 / n1
    hi = np.arange(1, n1 + 1, dtype=np.float64) * n0 / n1
    taps = int(np.max(np.ceil(hi) - np.floor(lo)))
    index = np.floor(lo).astype(np.int64)[:, None] + np.arange(taps)[None, :]
    weight = np.clip(np.minimum(hi[:, None], index + 1.0) - np.maximum(lo[:, None], index), 0.0, None) * (n1 / n0)
    return np.minimum(index, n0 - 1), weight


def coarser_level(stored: np.ndarray, fmt: Format, channels: int, size: tuple[int, int]) -> np.ndarray:
    """The next mip level of ``stored`` (``[L, h, w, 4]`` as ``fmt`` stores it), of ``size``: its
    texels decoded, box-filtered in linear space, encoded back; a band of rows at a time, so that
    the float copy is a band's."""
    (ry, wy), (rx, wx) = _box_weights(stored.shape[1], size[0]), _box_weights(stored.shape[2], size[1])
    # Halving an axis (a power-of-two chain's every level) reads its taps t as every second texel
    # from t: the same texels and weights (0.5) as the index arrays, without gathering them.
    halve_y, halve_x = stored.shape[1] == 2 * size[0], stored.shape[2] == 2 * size[1]
    out = np.empty((stored.shape[0],) + tuple(size) + (4,), dtype=stored.dtype)
    for j0 in range(0, size[0], _MIP_BAND_ROWS):
        j1 = min(size[0], j0 + _MIP_BAND_ROWS)
        first = int(ry[j0:j1].min())
        fine = decode(stored[:, first : int(ry[j0:j1].max()) + 1], fmt, channels)
        rows = sum((fine[:, t::2] if halve_y else fine[:, ry[j0:j1, t] - first]).astype(np.float64) * wy[j0:j1, t, None, None] for t in range(ry.shape[1]))
        out[:, j0:j1] = encode(sum((rows[:, :, t::2] if halve_x else rows[:, :, rx[:, t]]) * wx[:, t, None] for t in range(rx.shape[1])), fmt)
    return out


def stored(data: np.ndarray, fmt: Format, channels: int) -> np.ndarray:
    """``data`` (``[..., C]`` float texels, or uint8 codes of an 8-bit ``fmt``) as ``fmt`` stores it,
    ``[..., 4]``."""
    if data.dtype == np.uint8:
        out = np.zeros(data.shape[:-1] + (4,), dtype=np.uint8)
        out[..., :channels] = data
        return out
    return encode(data, fmt)


def mip_chain(level0: np.ndarray, fmt: Format, channels: int, sizes: list[tuple[int, int]]) -> list[np.ndarray]:
    """Every level of ``sizes``, stored as ``fmt`` stores them, from ``level0`` (stored): each the
    :func:`coarser_level` of the one before."""
    levels = [level0]
    for size in sizes[1:]:
        levels.append(coarser_level(levels[-1], fmt, channels, size))
    return levels


def packed(levels: list[np.ndarray], fmt: Format) -> np.ndarray:
    """Stored levels one after another, as a compact texture's store holds them: a uint32 per texel
    (8-bit) or ``[n, 4]`` float16."""
    flat = np.concatenate([x.reshape(-1, 4) for x in levels])
    return flat.view(np.uint32).reshape(-1) if fmt in EIGHT_BIT else flat


def store_array(flat: np.ndarray, fmt: Format, device) -> wp.array:
    """The device array of a compact texture's store, from :func:`packed` texels."""
    return wp.array(flat, dtype=wp.uint32 if fmt in EIGHT_BIT else wp.vec4h, device=device)


def unpacked(raw: np.ndarray, fmt: Format) -> np.ndarray:
    """Texels of a compact store (its ``.numpy()``) as ``[n, 4]`` uint8 codes or float16."""
    return raw.view(np.uint8).reshape(-1, 4) if fmt in EIGHT_BIT else raw.reshape(-1, 4)


def file_format(image: np.ndarray, data: bool) -> Format:
    """The format that keeps an image of :func:`warptex.io.read_texels` as precise as its file."""
    if image.dtype == np.uint8:
        return Format.UNORM8 if data else Format.SRGB8
    return Format.FLOAT16 if image.dtype == np.float16 else Format.FLOAT32


def as_format(image: np.ndarray, data: bool, fmt: Format) -> np.ndarray:
    """An image of :func:`warptex.io.read_texels` as a texture of ``fmt`` takes it: a file's 8-bit
    codes as they are for its own format, else decoded to the linear floats they stand for."""
    kept = file_format(image, data)
    if image.dtype == np.uint8 and fmt is not kept:
        return decode(image, kept, image.shape[-1])
    return image


def gradient_carrier(count: int, requires_grad: bool, device) -> wp.array:
    """What the view's ``texels`` holds for a texture not stored as float32. Kernels read its texels
    from the packed store, never from here; the backward machinery finds a texture's texel gradient
    as ``view.texels.grad`` (``wp.Tape.get_adjoint``, the hand-written gradients). So with
    ``requires_grad`` this is a ``vec4`` array of the chain's length whose ``.grad`` is a float32
    gradient of every level; it aliases that gradient's memory rather than hold a float32 copy of
    the texels, and is never read. Without, it is empty."""
    if not requires_grad:
        return wp.empty(0, dtype=wp.vec4, device=device)
    grad = wp.zeros(count, dtype=wp.vec4, device=device)
    carrier = wp.array(ptr=grad.ptr, shape=(count,), dtype=wp.vec4, device=device)
    carrier.grad = grad
    carrier.warptex_carrier = True  # warptex._op refuses Warp's generated adjoint for it (which reads no packed texels)
    return carrier


def build_mips(view, chain: wp.array, sizes: list[tuple[int, int]], num_layers: int) -> None:
    """Levels 1.. of a float32 chain from level 0, by the box filter level after level (a kept
    launch each, ``warptex._warp.replay``); inside a ``wp.Tape``, with their backward pass
    recorded as one step (:func:`carry_mip_gradients`), not as a launch each: a small texture's
    levels were most of a call that built its mips on the tape (the torch bridge's)."""
    for k in range(len(sizes) - 1):
        h, w = sizes[k + 1]
        replay(downsample_kernel, (num_layers, h, w), (view, k, chain), chain.device)
    carry_mip_gradients(view, chain, sizes, num_layers)


def carry_mip_gradients(view, chain: wp.array, sizes: list[tuple[int, int]], num_layers: int) -> None:
    """Inside a ``wp.Tape``: record the backward pass of a mip chain (:func:`build_mips`', or one
    built on the host for a texture not stored as float32). It runs the box filter's adjoint,
    coarsest level first, so each level's gradient is carried down to level 0 (a compact
    encoding of each level taken as exact) and cleared: what Warp's recording of each launch
    would run, bit for bit.

    For a compact texture ``chain`` is the gradient carrier (:func:`gradient_carrier`), whose
    texels are its gradient's memory: the adjoint reads the view's texels only to replay a sum that
    it does not keep, and writes nothing but gradients. A float32 chain's adjoint is a view whose
    texels are the chain's gradient, as ``wp.Tape.get_adjoint`` makes it."""
    tape = active_tape()
    if tape is None or chain.grad is None or len(sizes) < 2:
        return

    def backward() -> None:
        adj = view
        if not getattr(chain, "warptex_carrier", False):
            adj = kx.TextureView()
            adj.texels = chain.grad
        for k in reversed(range(len(sizes) - 1)):
            h, w = sizes[k + 1]
            wp.launch(downsample_kernel, dim=(num_layers, h, w), inputs=[view, k], outputs=[chain], adj_inputs=[adj, 0], adj_outputs=[chain.grad], adjoint=True, device=chain.device)

    tape.record_func(backward=backward, arrays=[chain])
