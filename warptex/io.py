"""Image file I/O: PNG/JPG (and other Pillow formats) here, OpenEXR in :mod:`warptex.exr` (re-exported).

Conventions used throughout ``warptex``:

* Images are ``numpy.float32`` arrays shaped ``[height, width, channels]``
  (1-4 channels for colour images; EXR G-buffers may hold more).
* Row 0 of an array is the top row of the image file.
* Colour is linear. 8/16-bit colour files are sRGB-encoded and are decoded on
  read (and encoded on write) unless ``data=True`` is passed, for maps whose
  values are used as-is (normals, splat weights, heights). Alpha is never
  sRGB-converted.
* EXR files are linear and may hold any channel names.
* Writers are atomic: the file is written under a temporary name in the
  target's directory and renamed onto the target only once complete.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

from warptex._files import _as_image, _atomic_output, _checked_input_path, _checked_output_path, _fspath, process_alive  # noqa: F401 (re-exported)
from warptex.exr import EXR_MAGIC, _read_exr, exr_attributes, exr_channel_names, exr_layers, read_exr
from warptex.exr_writer import ExrWriter, write_exr
from warptex.png import PngWriter, codes

__all__ = [
    "srgb_to_linear",
    "linear_to_srgb",
    "read_image",
    "read_texels",
    "read_exr",
    "exr_channel_names",
    "exr_layers",
    "exr_attributes",
    "write_png",
    "write_exr",
    "PngWriter",
    "ExrWriter",
]

_REC709_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
_SIXTEEN_BIT_MODES = ("I;16", "I;16L", "I;16B", "I;16N", "I")
# Pillow modes that need converting before use; everything not listed here
# (and not 16-bit or float) is converted to RGB (CMYK, YCbCr, LAB, HSV, RGBX...).
_PIL_MODE_MAP = {"L": "L", "LA": "LA", "RGB": "RGB", "RGBA": "RGBA",
                 "1": "L", "La": "LA", "PA": "RGBA", "RGBa": "RGBA"}


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Decode sRGB values to linear with the exact IEC 61966-2-1 curve.

    Args:
        x: Array-like of sRGB-encoded values, nominally in [0, 1].

    Returns:
        float32 array of the same shape. Input is not clipped: values below
        0.04045 (including negatives) follow the linear segment ``x / 12.92``,
        values above 1 follow the power segment. NaN stays NaN.
    """
    x = np.asarray(x, dtype=np.float64)
    power = ((np.maximum(x, 0.04045) + 0.055) / 1.055) ** 2.4
    return np.where(x <= 0.04045, x / 12.92, power).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Encode linear values to sRGB with the exact IEC 61966-2-1 curve.

    Args:
        x: Array-like of linear values.

    Returns:
        float32 array of the same shape in [0, 1]. The input is clipped to
        [0, 1] before encoding; NaN stays NaN.
    """
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    power = 1.055 * np.maximum(x, 0.0031308) ** (1.0 / 2.4) - 0.055
    return np.where(x <= 0.0031308, x * 12.92, power).astype(np.float32)


def read_image(path, *, data: bool = False, channels=None, layer: str | None = None) -> np.ndarray:
    """Read an image file as a linear float32 array.

    EXR files (recognised by their magic bytes, whatever the extension) are
    read with :func:`read_exr`; they are linear, so ``data`` has no effect.
    Everything else is decoded with Pillow: 8-bit values are divided by 255,
    16-bit grayscale (modes ``I;16``/``I``, clipped to [0, 65535]) by 65535,
    and 32-bit float images (mode ``F``) are returned unchanged. Palette
    images become RGB (RGBA if they have transparency), ``LA`` keeps its two
    channels (gray, alpha), other modes such as CMYK become RGB. 16-bit
    colour PNGs (gray+alpha, RGB, RGBA: common for normal and height maps),
    which Pillow would read at 8 bits, are decoded with libpng (through
    ``imagecodecs``) and divided by 65535. Multi-frame files yield their
    first frame; EXIF orientation is not applied.

    Args:
        path: ``str`` or ``os.PathLike`` of the file.
        data: If False, colour channels are sRGB-decoded to linear; if True,
            values are used as-is. Alpha is never sRGB-decoded.
        channels: For EXR, a sequence of channel names to read, in order
            (default chosen by :func:`read_exr`). For other formats, an int
            1-4 forcing the channel count: gray is replicated to RGB, RGB
            becomes Rec.709 luminance (computed after decoding), a missing
            alpha is filled with 1 and an unwanted one dropped.
        layer: For EXR, the layer to read (``"diffuse"`` for ``diffuse.R``,
            ``diffuse.G``...; see :func:`read_exr`, which also says which layer
            is read without one). Other formats have no layers.

    Returns:
        float32 array shaped [H, W, C].

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        ValueError: If ``path`` is a directory, cannot be decoded, or
            ``channels`` or ``layer`` is invalid (an EXR with several layers
            and no default one needs ``layer``).
        TypeError: If ``channels`` has the wrong type for the file format.
    """
    return _read(path, data, channels, layer, "read_image", keep=False)


def read_texels(path, *, data: bool = False, channels=None, layer: str | None = None) -> np.ndarray:
    """Read an image file as :func:`read_image` does, in the file's own precision where a texture
    can keep it (``Texture.from_file`` stores it so):

    - an 8-bit PNG/JPG (or other 8-bit Pillow image): its ``uint8`` codes as stored, sRGB-encoded
      colour unless ``data=True`` says the file holds data. :func:`read_image` returns
      ``srgb_to_linear(codes / 255)`` (``codes / 255`` for data) of the same codes, alpha
      ``codes / 255``; ``channels`` that ask for Rec.709 luminance of an RGB file give that, in
      float32, since luminance is computed after decoding;
    - an EXR whose channels read are all half-float: ``float16``;
    - anything else (16-bit and float files): ``read_image``'s float32.

    Args, Raises: as :func:`read_image`.

    Returns:
        ``uint8``, ``float16`` or ``float32`` array shaped [H, W, C].
    """
    return _read(path, data, channels, layer, "read_texels", keep=True)


def _read(path, data: bool, channels, layer, func: str, keep: bool) -> np.ndarray:
    """``read_image`` (``keep=False``) or ``read_texels`` (``keep=True``)."""
    path = _checked_input_path(path, func)
    with open(path, "rb") as f:
        head = f.read(26)
    if head[:4] == EXR_MAGIC:
        return _read_exr(path, channels, layer, func, keep_half=keep)[0]
    if layer is not None:
        raise ValueError(f"{func}(): layer={layer!r} names an EXR layer, but '{path}' is not an OpenEXR file")
    if channels is not None:
        channels = _channel_count(channels, func)
    if _is_sixteen_bit_colour_png(head):
        image, has_alpha = _read_sixteen_bit_png(path, data, func)
        return image if channels is None else _convert_channels(image, has_alpha, channels)
    from warptex._output import check_memory  # here: _output imports this module

    limit = Image.MAX_IMAGE_PIXELS
    try:
        # Pillow refuses images past ~179 Mpixels as possible decompression bombs (a 16384² texture
        # is 268): the check of the memory the decoded image needs stands for its guess.
        Image.MAX_IMAGE_PIXELS = None
        with Image.open(path) as im:
            check_memory(func, f"'{path}' ({im.width}x{im.height} pixels)", _DECODED_BYTES_PER_PIXEL * im.width * im.height, hint="use a smaller image")
            im.load()
            codes, maxval = _pil_codes(im)
    except MemoryError:
        raise
    except Exception as exc:
        raise ValueError(f"{func}(): cannot decode '{path}' as an image: {exc}") from exc
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    has_alpha = codes.dtype != np.float32 and codes.shape[-1] in (2, 4)
    if keep and codes.dtype == np.uint8 and (channels is None or _codes_convertible(codes.shape[-1], has_alpha, channels)):
        return codes if channels is None else _convert_channels(codes, has_alpha, channels)
    image = codes if codes.dtype == np.float32 else _codes_to_linear(codes, maxval, data)[0]
    return image if channels is None else _convert_channels(image, has_alpha, channels)


def _codes_convertible(count: int, has_alpha: bool, channels: int) -> bool:
    """Whether :func:`_convert_channels` to ``channels`` takes no luminance of ``count`` channels
    (the one conversion that needs decoded values)."""
    return not ((count - has_alpha) == 3 and channels < 3)


# Bytes a decoded PNG/JPG takes per pixel at most while it is read: Pillow's 8-bit RGBA and the
# float32 RGBA made of it.
_DECODED_BYTES_PER_PIXEL = 4 + 16


def write_png(path, image, *, data: bool = False, bits: int = 8) -> None:
    """Write an image as PNG, atomically, creating missing parent directories.

    Values are clipped to [0, 1] (so +-inf become 1 and 0), colour channels
    are sRGB-encoded unless ``data=True`` (alpha never is), then rounded to
    the nearest 8- or 16-bit code. Channel counts 1-4 are gray, gray+alpha,
    RGB and RGBA. NaN has no colour and is an error.

    Args:
        path: ``str`` or ``os.PathLike`` of the file to write.
        image: Array-like of real numbers shaped [H, W] or [H, W, C], C in
            1..4, nominally in [0, 1] (also for integer dtypes).
        data: If True, write values as-is instead of sRGB-encoding colour.
        bits: 8 or 16 per channel. Encoded by :class:`warptex.png.PngWriter`, which
            also writes images band by band.

    Raises:
        ValueError: On a wrong rank or channel count, an empty image, NaN
            values or a bad ``bits`` value.
        TypeError: If ``image`` is not numeric.
    """
    path = _checked_output_path(path, "write_png")
    image = _as_image(image, "write_png")
    n = image.shape[-1]
    if n > 4:
        raise ValueError(f"write_png(): image must have 1-4 channels, got {n}")
    if bits not in (8, 16) or isinstance(bits, bool):
        raise ValueError(f"write_png(): bits must be 8 or 16, got {bits!r}")
    nans = int(np.isnan(image).sum())
    if nans:
        raise ValueError(f"write_png(): image has {nans} NaN value(s) of {image.size}; a PNG has no NaN "
                         "(replace them, e.g. np.nan_to_num, or write_exr() to keep them)")
    with PngWriter(path, image.shape[0], image.shape[1], n, bits=bits, data=data) as writer:
        writer.write_codes(codes(image, data=data, bits=bits))


def _is_sixteen_bit_colour_png(head: bytes) -> bool:
    """Whether a file starting with ``head`` (26 bytes) is a PNG of 16-bit gray+alpha, RGB or RGBA:
    the signature, then the IHDR chunk's bit depth (byte 24) and colour type (byte 25)."""
    return len(head) == 26 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and head[24] == 16 and head[25] in (2, 4, 6)


def _read_sixteen_bit_png(path: str, data: bool, func: str) -> tuple[np.ndarray, bool]:
    import imagecodecs

    try:
        with open(path, "rb") as f:
            codes = imagecodecs.png_decode(f.read())
    except Exception as exc:
        raise ValueError(f"{func}(): cannot decode '{path}' as an image: {exc}") from exc
    codes = codes.reshape(codes.shape[0], codes.shape[1], -1)
    if codes.dtype != np.uint16 or codes.shape[-1] not in (2, 3, 4) or codes.size == 0:
        raise ValueError(f"{func}(): cannot decode '{path}' as a 16-bit PNG: got {codes.dtype} {codes.shape}")
    return _codes_to_linear(codes, 65535, data)


def code_values(maxval: int) -> tuple[np.ndarray, np.ndarray]:
    """The float32 value of every integer code ``0..maxval``: ``(code / maxval, srgb_to_linear(code /
    maxval))``, each rounded to float32 once. What files decode to, and 8-bit textures too."""
    scale = np.arange(maxval + 1, dtype=np.float64) / maxval
    return scale.astype(np.float32), srgb_to_linear(scale)


def _codes_to_linear(codes: np.ndarray, maxval: int, data: bool) -> tuple[np.ndarray, bool]:
    """Integer codes ``[H, W, C]`` to float32 in [0, 1], colour sRGB-decoded unless ``data``; also
    whether the last channel is alpha (2 or 4 channels)."""
    has_alpha = codes.shape[-1] in (2, 4)
    linear_lut, srgb_lut = code_values(maxval)
    image = (linear_lut if data else srgb_lut)[codes]
    if has_alpha:
        image[..., -1] = linear_lut[codes[..., -1]]
    return image, has_alpha


def _pil_codes(im: Image.Image) -> tuple[np.ndarray, int]:
    """A loaded Pillow image's integer codes ``[H, W, C]`` and the code of 1 (float32 values and 1
    for mode ``F``)."""
    if im.mode == "F":
        return np.asarray(im, dtype=np.float32)[..., None], 1
    if im.mode in _SIXTEEN_BIT_MODES:
        return np.clip(np.asarray(im), 0, 65535).astype(np.uint16)[..., None], 65535
    target = _PIL_MODE_MAP.get(im.mode, "RGB")
    if im.mode == "P":
        target = "RGBA" if "transparency" in im.info else "RGB"
    if im.mode != target:
        im = im.convert(target)
    return np.asarray(im).reshape(im.height, im.width, -1), 255


def _channel_count(channels, func: str) -> int:
    if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)):
        raise TypeError(f"{func}(): channels for a non-EXR image must be an int 1-4, "
                        f"got {type(channels).__name__}")
    if not 1 <= channels <= 4:
        raise ValueError(f"{func}(): channels must be 1-4, got {channels}")
    return int(channels)


def _convert_channels(image: np.ndarray, has_alpha: bool, channels: int) -> np.ndarray:
    colour = image[..., :-1] if has_alpha else image
    if colour.shape[-1] == 3 and channels < 3:
        colour = (colour @ _REC709_LUMA)[..., None]
    elif colour.shape[-1] == 1 and channels >= 3:
        colour = np.repeat(colour, 3, axis=-1)
    if channels in (1, 3):
        return np.ascontiguousarray(colour)
    alpha = image[..., -1:] if has_alpha else np.full_like(colour[..., :1], 255 if image.dtype == np.uint8 else 1)
    return np.concatenate([colour, alpha], axis=-1)


