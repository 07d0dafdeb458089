"""OpenEXR files written band by band: :class:`ExrWriter`, and :func:`write_exr` built on it.

A tiled job (:mod:`warptex.tiles`) makes its images a band of rows at a time; the G-buffer of a
4096² render is 1.2 GiB in float32. OpenEXR's Python binding writes only whole images (``File``),
and its deprecated scanline writer (``OutputFile``) cannot write the double-precision vectors a
G-buffer's header carries. A scanline EXR is simple to stream (the OpenEXR file layout, "Technical
Introduction" and "OpenEXR File Layout"): a header, a table of the chunks' offsets, then chunks of
16 scanlines, each holding every channel's row in turn (channels sorted by name), ZIP-compressed:
bytes split into even and odd halves, delta-coded, deflated (stored raw where that is not
smaller). The table is written last, over the zeros it starts as. OpenEXR reads what this writes
(tests/test_io.py compares every channel type and attribute both ways).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from warptex._files import _as_image, _checked_output_path, _RowFile
from warptex.exr import _STANDARD_ATTRIBUTES, EXR_MAGIC, _name_tuple

__all__ = ["ExrWriter", "write_exr"]

_DEFAULT_EXR_NAMES = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}
_LINES = 16  # scanlines a ZIP chunk holds
_LEVEL = 4  # zlib level: OpenEXR's default for ZIP
_HALF, _FLOAT = 1, 2  # OpenEXR pixel types


def _attribute(name: str, value) -> tuple[str, bytes]:
    """``(type name, value bytes)`` of an extra header attribute, typed as OpenEXR's Python binding
    types it: int -> int, float -> float, str -> string, float64 (2,)/(3,) -> v2d/v3d, float32
    (2,)/(3,) -> v2f/v3f."""
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"write_exr(): attribute {name!r} is a bool; EXR has no bool attribute (use an int)")
    if isinstance(value, (int, np.integer)):
        return "int", struct.pack("<i", int(value))
    if isinstance(value, (float, np.floating)):
        return "float", struct.pack("<f", float(value))
    if isinstance(value, str):
        return "string", value.encode()
    array = np.asarray(value)
    if array.shape in ((2,), (3,)) and array.dtype in (np.float64, np.float32):
        kind = f"v{len(array)}{'d' if array.dtype == np.float64 else 'f'}"
        return kind, array.astype("<f8" if array.dtype == np.float64 else "<f4").tobytes()
    raise ValueError(f"write_exr(): attribute {name!r} must be an int, float, str or a float32/float64 vector of 2 or 3, got {value!r}")


class ExrWriter(_RowFile):
    """Write a ``height × width`` scanline OpenEXR file (ZIP) of named float channels band by
    band: :meth:`write` takes rows. Use it as a context manager, which renames the file onto
    ``path`` on success (every row written) and removes it on any error.

    Args:
        path: the ``.exr`` to write (parent folders are created).
        height, width: the image's size in pixels.
        channel_names: the channels, any names (``diffuse.R``, ``Position.X``...), unique.
        half: store float16 (values beyond ±65504 become ±inf) rather than float32.
        attributes: extra header attributes (see :func:`write_exr`).
    """

    def __init__(self, path, height: int, width: int, channel_names: Sequence[str], *, half: bool = False, attributes: Mapping | None = None):
        func = "write_exr"
        for name, value in (("height", height), ("width", width)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value < 2**31:
                raise ValueError(f"{func}(): {name} must be an int in [1, 2^31), got {value!r}")
        names = list(channel_names)
        if not names:
            raise ValueError(f"{func}(): image has no channels")
        if len(set(names)) != len(names) or "" in names or not all(isinstance(n, str) for n in names):
            raise ValueError(f"{func}(): channel names must be unique and non-empty str, got {tuple(names)}")
        extras = []
        for key, value in (attributes or {}).items():
            if not isinstance(key, str) or key in _STANDARD_ATTRIBUTES or not key:
                raise ValueError(f"{func}(): attribute names must be str and not standard ones, got {key!r}")
            extras.append((key, *_attribute(key, value)))
        self.path = _checked_output_path(path, func)
        self.height, self.width, self.names, self.half = int(height), int(width), tuple(names), bool(half)
        self._sorted = sorted(range(len(names)), key=lambda k: names[k].encode())  # the file's channel order
        self._dtype = np.dtype("<f2" if half else "<f4")
        self._rows = 0
        self._buffer: list[np.ndarray] = []  # rows not yet in a chunk (fewer than _LINES)
        self._offsets: list[int] = []
        self._pool = ThreadPoolExecutor(2)
        long_names = any(len(n.encode()) > 31 for n in names) or any(len(k.encode()) > 31 for k, _, _ in extras)
        box = struct.pack("<iiii", 0, 0, self.width - 1, self.height - 1)
        channels = b"".join(names[k].encode() + b"\0" + struct.pack("<iB3xii", _HALF if half else _FLOAT, 0, 1, 1) for k in self._sorted) + b"\0"
        header = [
            ("channels", "chlist", channels),
            ("compression", "compression", b"\x03"),
            ("dataWindow", "box2i", box),
            ("displayWindow", "box2i", box),
            ("lineOrder", "lineOrder", b"\x00"),
            ("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            ("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
            ("screenWindowWidth", "float", struct.pack("<f", 1.0)),
            *extras,
        ]
        head = EXR_MAGIC + struct.pack("<I", 2 | (0x400 if long_names else 0))
        head += b"".join(n.encode() + b"\0" + t.encode() + b"\0" + struct.pack("<i", len(v)) + v for n, t, v in sorted(header)) + b"\0"
        self._chunks = -(-self.height // _LINES)
        self._table = len(head)
        self._open().write(head + bytes(8 * self._chunks))  # the offset table, filled in by close()

    def write(self, rows) -> None:
        """Append rows: ``[n, width, C]`` for the C channels in the order named (``[n, width]``
        for one), or a dict of ``[n, width]`` arrays by channel name."""
        if isinstance(rows, Mapping):
            if set(rows) != set(self.names):
                raise ValueError(f"ExrWriter.write(): rows must hold the channels {self.names}, got {tuple(rows)}")
            band = np.stack([np.asarray(rows[n], np.float32) for n in self.names], axis=-1)
        else:
            band = np.asarray(rows, np.float32)
            if band.ndim == 2 and len(self.names) == 1:
                band = band[..., None]
        if band.ndim != 3 or band.shape[1:] != (self.width, len(self.names)) or len(band) == 0:
            raise ValueError(f"ExrWriter.write(): rows must be [n >= 1, {self.width}, {len(self.names)}], got {band.shape}")
        if self._rows + len(band) > self.height:
            raise ValueError(f"ExrWriter.write(): {len(band)} more rows after {self._rows} would pass the image's {self.height}")
        with np.errstate(over="ignore"):
            band = band[..., self._sorted].astype(self._dtype)
        self._rows += len(band)
        self._buffer.append(band)
        buffered = sum(len(b) for b in self._buffer)
        whole = buffered if self._rows == self.height else buffered - buffered % _LINES
        if whole:
            lines = np.concatenate(self._buffer) if len(self._buffer) > 1 else self._buffer[0]
            self._buffer = [lines[whole:]] if whole < buffered else []
            first = self._rows - buffered
            starts = range(0, whole, _LINES)
            blocks = self._pool.map(_compressed, (lines[s : s + _LINES] for s in starts))  # zlib frees the GIL
            for start, data in zip(starts, blocks):
                self._offsets.append(self._file.tell())
                self._file.write(struct.pack("<ii", first + start, len(data)) + data)

    def _finish(self) -> None:
        self._file.seek(self._table)
        self._file.write(struct.pack(f"<{len(self._offsets)}Q", *self._offsets))
        self._pool.shutdown()

    def abort(self, error: BaseException | None = None) -> None:
        """Stop and remove the partial file (nothing appears at ``path``)."""
        self._pool.shutdown(cancel_futures=True)
        super().abort(error)


def _compressed(lines: np.ndarray) -> bytes:
    """One chunk's pixel data (``[n <= 16, W, C]``, channels in file order), ZIP-compressed as
    OpenEXR does: each scanline's channels one after another, the bytes split into even and odd
    halves, each byte stored as its difference to the previous one plus 128, then deflated; stored
    raw where that is not smaller."""
    raw = np.ascontiguousarray(lines.transpose(0, 2, 1)).view(np.uint8).reshape(-1)
    interleaved = np.concatenate([raw[0::2], raw[1::2]])
    delta = interleaved.copy()
    np.subtract(interleaved[1:], interleaved[:-1], out=delta[1:])  # uint8: wraps modulo 256, as OpenEXR's does
    delta[1:] += 128
    packed = zlib.compress(delta.tobytes(), _LEVEL)
    return packed if len(packed) < len(raw) else raw.tobytes()


def write_exr(path, image, *, channel_names: Sequence[str] | None = None, half: bool = False, attributes: Mapping | None = None) -> None:
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
        attributes: Extra header attributes ``{name: value}``: ints, floats (stored as float32),
            strings, and float64 or float32 vectors of 2 or 3 (``v2d``, ``v3d``, ``v2f``,
            ``v3f``), read back by :func:`~warptex.io.exr_attributes`.

    Raises:
        ValueError: On a wrong rank, empty image, mismatched channel sizes,
            missing/duplicate/wrong-length channel names, or an attribute of another type.
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
        pixels = np.concatenate(planes, axis=-1) if planes else np.zeros((1, 1, 0), np.float32)
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
    with ExrWriter(path, pixels.shape[0], pixels.shape[1], names, half=half, attributes=attributes) as writer:
        writer.write(pixels)
