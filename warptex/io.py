"""Image file I/O: PNG/JPG (and other Pillow formats) and OpenEXR.

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

import os
import re
import secrets
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager

import numpy as np
import OpenEXR
from PIL import Image

__all__ = [
    "srgb_to_linear",
    "linear_to_srgb",
    "read_image",
    "read_exr",
    "exr_channel_names",
    "write_png",
    "write_exr",
]

_EXR_MAGIC = b"\x76\x2f\x31\x01"
_REC709_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
_SIXTEEN_BIT_MODES = ("I;16", "I;16L", "I;16B", "I;16N", "I")
# Pillow modes that need converting before use; everything not listed here
# (and not 16-bit or float) is converted to RGB (CMYK, YCbCr, LAB, HSV, RGBX...).
_PIL_MODE_MAP = {"L": "L", "LA": "LA", "RGB": "RGB", "RGBA": "RGBA",
                 "1": "L", "La": "LA", "PA": "RGBA", "RGBa": "RGBA"}
_DEFAULT_EXR_NAMES = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


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


def read_image(path, *, data: bool = False, channels=None) -> np.ndarray:
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

    Returns:
        float32 array shaped [H, W, C].

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        ValueError: If ``path`` is a directory, cannot be decoded, or
            ``channels`` is invalid.
        TypeError: If ``channels`` has the wrong type for the file format.
    """
    path = _checked_input_path(path, "read_image")
    with open(path, "rb") as f:
        head = f.read(26)
    if head[:4] == _EXR_MAGIC:
        return _read_exr(path, channels, "read_image")[0]
    if channels is not None:
        channels = _channel_count(channels)
    if _is_sixteen_bit_colour_png(head):
        image, has_alpha = _read_sixteen_bit_png(path, data)
        return image if channels is None else _convert_channels(image, has_alpha, channels)
    try:
        with Image.open(path) as im:
            im.load()
            image, has_alpha = _pil_to_array(im, data)
    except Exception as exc:
        raise ValueError(f"read_image(): cannot decode '{path}' as an image: {exc}") from exc
    return image if channels is None else _convert_channels(image, has_alpha, channels)


def read_exr(path, channels: Sequence[str] | None = None) -> tuple[np.ndarray, tuple[str, ...]]:
    """Read channels of an OpenEXR file.

    Pixels of the data window are returned (the display window is ignored);
    half and uint channels are converted to float32 (uint values above 2**24
    lose precision).

    Args:
        path: ``str`` or ``os.PathLike`` of the file.
        channels: Channel names to read, in that order (any number >= 1).
            Names may come from any part of a multi-part file whose size
            matches the first part's; the first part wins for duplicate
            names. If None, channels of the first part are chosen: R,G,B (+A)
            if present, else Y (+A) if present, else all channels in sorted
            order provided there are at most 4.

    Returns:
        ``(image, names)``: float32 array shaped [H, W, C] and the C channel
        names in order.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        ValueError: If the file cannot be decoded, requested channels are
            missing or differ in size, or the default choice would exceed 4
            channels.
        TypeError: If ``channels`` is not a sequence of str.
    """
    return _read_exr(_checked_input_path(path, "read_exr"), channels, "read_exr")


def exr_channel_names(path) -> tuple[str, ...]:
    """Names of the channels in an EXR file's first part, read from its header only.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if it is not a readable OpenEXR file.
    """
    path = _checked_input_path(path, "exr_channel_names")
    try:
        with OpenEXR.File(path, header_only=True) as exr:
            return tuple(channel.name for channel in exr.header()["channels"])
    except (RuntimeError, UnicodeDecodeError) as exc:  # a corrupt header may hold a name that is not UTF-8
        raise ValueError(f"exr_channel_names(): cannot decode '{path}' as an OpenEXR image: {exc}") from None


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
        bits: 8 or 16 per channel (16-bit colour is encoded with libpng
            through ``imagecodecs``, as Pillow cannot).

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
    values = np.clip(image, 0.0, 1.0)
    if not data:
        n_colour = n - 1 if n in (2, 4) else n
        values[..., :n_colour] = linear_to_srgb(values[..., :n_colour])
    maxval, dtype = (255, np.uint8) if bits == 8 else (65535, np.uint16)
    codes = np.rint(values * maxval).astype(dtype)
    if bits == 16 and n > 1:
        import imagecodecs

        encoded = imagecodecs.png_encode(codes)
        with _atomic_output(path) as tmp, open(tmp, "wb") as f:
            f.write(encoded)
        return
    pil_image = Image.fromarray(codes[..., 0] if n == 1 else codes)
    with _atomic_output(path) as tmp:
        pil_image.save(tmp, format="PNG")


def write_exr(path, image, *, channel_names: Sequence[str] | None = None, half: bool = False) -> None:
    """Write an OpenEXR file (ZIP compression), atomically, creating missing parent directories.

    Args:
        path: ``str`` or ``os.PathLike`` of the file to write.
        image: Array-like of real numbers shaped [H, W] or [H, W, C], or a
            dict mapping channel names to [H, W] arrays of equal size.
        channel_names: Names for the C channels of an array (any names, e.g.
            ``'Position.X'``). Defaults: 1 -> Y, 2 -> Y,A, 3 -> R,G,B,
            4 -> R,G,B,A; required for other channel counts. Not allowed
            with a dict.
        half: If True, store float16 (values beyond +-65504 become +-inf);
            otherwise float32.

    Raises:
        ValueError: On a wrong rank, empty image, mismatched channel sizes,
            or missing/duplicate/wrong-length channel names.
        TypeError: If the pixels are not numeric or names are not str.
    """
    path = _checked_output_path(path, "write_exr")
    if isinstance(image, Mapping):
        if channel_names is not None:
            raise ValueError("write_exr(): channel_names cannot be given with a dict image; "
                             "the dict keys are the channel names")
        names = _name_tuple(list(image), "write_exr", "dict keys")
        planes = [_as_image(image[name], "write_exr") for name in names]
        if any(p.shape[-1] != 1 for p in planes):
            raise ValueError("write_exr(): dict values must be [H, W] arrays")
        if len({p.shape for p in planes}) > 1:
            sizes = ", ".join(f"{k!r}: {p.shape[:2]}" for k, p in zip(names, planes))
            raise ValueError(f"write_exr(): all channels must have the same size, got {sizes}")
    else:
        pixels = _as_image(image, "write_exr")
        n = pixels.shape[-1]
        if channel_names is None:
            if n not in _DEFAULT_EXR_NAMES:
                raise ValueError(f"write_exr(): image has {n} channels; pass channel_names=")
            channel_names = _DEFAULT_EXR_NAMES[n]
        names = _name_tuple(channel_names, "write_exr", "channel_names")
        if len(names) != n:
            raise ValueError(f"write_exr(): got {len(names)} channel_names for an image with {n} channels")
        planes = [pixels[..., i : i + 1] for i in range(n)]
    if not names:
        raise ValueError("write_exr(): image has no channels")
    if len(set(names)) != len(names) or "" in names:
        raise ValueError(f"write_exr(): channel names must be unique and non-empty, got {names}")
    with np.errstate(over="ignore"):
        dtype = np.float16 if half else np.float32
        channels = {name: np.ascontiguousarray(p[..., 0], dtype=dtype) for name, p in zip(names, planes)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with _atomic_output(path) as tmp:
        OpenEXR.File(header, channels).write(tmp)


def _read_exr(path: str, channels, fn: str) -> tuple[np.ndarray, tuple[str, ...]]:
    if channels is not None:
        channels = _name_tuple(channels, fn, "channels")
        if not channels:
            raise ValueError(f"{fn}(): channels must name at least one channel")
    try:
        exr = OpenEXR.File(path, separate_channels=True)
        parts = exr.parts
        if not parts:  # OpenEXR reports a cut-short file by reading no parts
            raise RuntimeError("no readable image in it: truncated or corrupt")
        first = parts[0]
        available = dict(first.channels)
        if channels is None:
            channels = _default_exr_channels(available, path, fn)
        else:
            size = (first.height(), first.width())
            for part in parts[1:]:
                if (part.height(), part.width()) == size:
                    for name, channel in part.channels.items():
                        available.setdefault(name, channel)
    except (RuntimeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{fn}(): cannot decode '{path}' as an OpenEXR image: {exc}") from exc
    missing = [name for name in channels if name not in available]
    if missing:
        raise ValueError(f"{fn}(): channels {missing} not found in '{path}'; "
                         f"available channels: {sorted(available)}")
    planes = [available[name].pixels for name in channels]
    if any(p is None or p.ndim != 2 for p in planes):
        raise ValueError(f"{fn}(): '{path}' holds deep or non-2D channel data, which is not supported")
    if len({p.shape for p in planes}) > 1:
        sizes = ", ".join(f"{name!r}: {p.shape}" for name, p in zip(channels, planes))
        raise ValueError(f"{fn}(): channels of '{path}' differ in size (subsampled?): {sizes}")
    return np.stack([p.astype(np.float32, copy=False) for p in planes], axis=-1), channels


def _default_exr_channels(available: Mapping, path: str, fn: str) -> tuple[str, ...]:
    alpha = ("A",) if "A" in available else ()
    if {"R", "G", "B"} <= available.keys():
        return ("R", "G", "B") + alpha
    if "Y" in available:
        return ("Y",) + alpha
    names = tuple(sorted(available))
    if not names:
        raise ValueError(f"{fn}(): '{path}' has no channels")
    if len(names) > 4:
        raise ValueError(f"{fn}(): '{path}' has {len(names)} channels {list(names)} and no R,G,B or Y; "
                         "pass channels= to choose which to read")
    return names


def _is_sixteen_bit_colour_png(head: bytes) -> bool:
    """Whether a file starting with ``head`` (26 bytes) is a PNG of 16-bit gray+alpha, RGB or RGBA:
    the signature, then the IHDR chunk's bit depth (byte 24) and colour type (byte 25)."""
    return len(head) == 26 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and head[24] == 16 and head[25] in (2, 4, 6)


def _read_sixteen_bit_png(path: str, data: bool) -> tuple[np.ndarray, bool]:
    import imagecodecs

    try:
        with open(path, "rb") as f:
            codes = imagecodecs.png_decode(f.read())
    except Exception as exc:
        raise ValueError(f"read_image(): cannot decode '{path}' as an image: {exc}") from exc
    codes = codes.reshape(codes.shape[0], codes.shape[1], -1)
    if codes.dtype != np.uint16 or codes.shape[-1] not in (2, 3, 4) or codes.size == 0:
        raise ValueError(f"read_image(): cannot decode '{path}' as a 16-bit PNG: got {codes.dtype} {codes.shape}")
    return _codes_to_linear(codes, 65535, data)


def _codes_to_linear(codes: np.ndarray, maxval: int, data: bool) -> tuple[np.ndarray, bool]:
    """Integer codes ``[H, W, C]`` to float32 in [0, 1], colour sRGB-decoded unless ``data``; also
    whether the last channel is alpha (2 or 4 channels)."""
    has_alpha = codes.shape[-1] in (2, 4)
    scale = np.arange(maxval + 1, dtype=np.float64) / maxval
    linear_lut = scale.astype(np.float32)
    image = (linear_lut if data else srgb_to_linear(scale))[codes]
    if has_alpha:
        image[..., -1] = linear_lut[codes[..., -1]]
    return image, has_alpha


def _pil_to_array(im: Image.Image, data: bool) -> tuple[np.ndarray, bool]:
    """Decode a loaded Pillow image to float32 [H, W, C]; also return whether the last channel is alpha."""
    if im.mode == "F":
        return np.asarray(im, dtype=np.float32)[..., None], False
    if im.mode in _SIXTEEN_BIT_MODES:
        codes, maxval = np.clip(np.asarray(im), 0, 65535).astype(np.uint16)[..., None], 65535
    else:
        target = _PIL_MODE_MAP.get(im.mode, "RGB")
        if im.mode == "P":
            target = "RGBA" if "transparency" in im.info else "RGB"
        if im.mode != target:
            im = im.convert(target)
        codes, maxval = np.asarray(im).reshape(im.height, im.width, -1), 255
    return _codes_to_linear(codes, maxval, data)


def _channel_count(channels) -> int:
    if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)):
        raise TypeError("read_image(): channels for a non-EXR image must be an int 1-4, "
                        f"got {type(channels).__name__}")
    if not 1 <= channels <= 4:
        raise ValueError(f"read_image(): channels must be 1-4, got {channels}")
    return int(channels)


def _convert_channels(image: np.ndarray, has_alpha: bool, channels: int) -> np.ndarray:
    colour = image[..., :-1] if has_alpha else image
    if colour.shape[-1] == 3 and channels < 3:
        colour = (colour @ _REC709_LUMA)[..., None]
    elif colour.shape[-1] == 1 and channels >= 3:
        colour = np.repeat(colour, 3, axis=-1)
    if channels in (1, 3):
        return np.ascontiguousarray(colour)
    alpha = image[..., -1:] if has_alpha else np.ones_like(colour[..., :1])
    return np.concatenate([colour, alpha], axis=-1)


def _as_image(image, fn: str) -> np.ndarray:
    """Validate array-like pixels and return them as a float32 [H, W, C] array (always a new array)."""
    try:
        array = np.asarray(image)
    except ValueError as exc:  # ragged nested sequences
        raise ValueError(f"{fn}(): image must be a rectangular array of numbers: {exc}") from None
    if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
            or array.dtype == np.bool_):
        raise TypeError(f"{fn}(): image must hold real numbers, got dtype {array.dtype}")
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3:
        raise ValueError(f"{fn}(): image must be shaped [H, W] or [H, W, C], got shape {array.shape}")
    if 0 in array.shape:
        raise ValueError(f"{fn}(): image must not be empty, got shape {array.shape}")
    return array.astype(np.float32, copy=True)


def _name_tuple(names, fn: str, arg: str) -> tuple[str, ...]:
    """Return channel names as a tuple of str; a lone str is rejected as ambiguous ('RGB' vs ('RGB',))."""
    try:
        result = None if isinstance(names, (str, bytes)) else tuple(names)
    except TypeError:
        result = None
    if result is None or not all(isinstance(name, str) for name in result):
        raise TypeError(f"{fn}(): {arg} must be a sequence of str channel names such as ('R', 'G'), "
                        f"got {names!r}")
    return tuple(str(name) for name in result)


def _fspath(path, fn: str) -> str:
    try:
        return os.fsdecode(path)
    except TypeError:
        raise TypeError(f"{fn}(): path must be str or os.PathLike, got {type(path).__name__}") from None


def _checked_input_path(path, fn: str) -> str:
    path = _fspath(path, fn)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{fn}(): file not found: '{path}'")
    if os.path.isdir(path):
        raise ValueError(f"{fn}(): '{path}' is a directory, not an image file")
    return path


def _checked_output_path(path, fn: str) -> str:
    path = _fspath(path, fn)
    if os.path.isdir(path):
        raise ValueError(f"{fn}(): '{path}' is a directory")
    folder = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(folder):  # the folders to create: their first existing ancestor must be a folder
        folder = os.path.dirname(folder)
    if not os.path.isdir(folder):
        raise NotADirectoryError(f"{fn}(): cannot write '{path}': '{folder}' is a file, not a folder")
    return path


@contextmanager
def _atomic_output(path: str) -> Iterator[str]:
    """Yield a temporary path next to ``path``; on success move it onto ``path``, on error remove it.

    The temporary name (``.name.<pid>-<random>.tmp.png``) keeps the real extension in case an
    encoder picks the format from it, and names the writing process: temporaries of ``path`` left
    by a process that no longer exists (killed mid-write) are removed here. It is created with
    ``os.open`` so the final file gets the usual umask-based permissions.
    """
    directory, base = os.path.split(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    _remove_stale_temporaries(directory, base)
    tmp = os.path.join(directory, f".{base}.{os.getpid()}-{secrets.token_hex(6)}.tmp{os.path.splitext(base)[1]}")
    os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.remove(tmp)
        except FileNotFoundError:
            pass
        raise


def _remove_stale_temporaries(directory: str, base: str) -> None:
    pattern = re.compile(re.escape(f".{base}.") + r"(\d+)-[0-9a-f]{12}\.tmp" + re.escape(os.path.splitext(base)[1]) + "$")
    for name in os.listdir(directory):
        match = pattern.match(name)
        if match and not process_alive(int(match.group(1)), os.path.join(directory, name)):
            try:
                os.remove(os.path.join(directory, name))
            except OSError:
                pass


def process_alive(pid: int, path: str | os.PathLike) -> bool:
    """Whether process ``pid``, which made ``path``, may still be writing it. POSIX: whether the
    process exists on this machine. Windows, where probing a process can end it: whether ``path``
    is younger than a day."""
    if pid == os.getpid():
        return True
    if os.name != "nt":
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:
            pass  # exists but is not ours (PermissionError), or we cannot tell: leave it
        return True
    try:
        return time.time() - os.stat(path).st_mtime < 86400.0
    except OSError:
        return False
