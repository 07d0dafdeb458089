"""PNG files written band by band: :class:`PngWriter`, which :func:`warptex.io.write_png` uses too.

A tiled job (:mod:`warptex.tiles`) makes its image a band of rows at a time. Pillow and libpng's
Python bindings encode only a whole image held in memory (a 16384² RGBA image is 1 GiB in 8 bits);
a PNG is a stream of filtered rows through one zlib stream, so this writer takes each band as it
comes and keeps only the previous row and zlib's window (ISO/IEC 15948, PNG 2nd edition):

- values are encoded as :func:`warptex.io.write_png` documents (clipped to [0, 1], colour
  sRGB-encoded unless ``data``, rounded to 8- or 16-bit codes), by :func:`codes`;
- each row gets the filter (None, Sub, Up, Average or Paeth) whose residuals have the least sum of
  absolute values as signed bytes, the heuristic the PNG specification recommends (§12.8) and
  libpng and Pillow use; the rows of a band are filtered at once in NumPy;
- the filtered bytes go through one ``zlib`` stream (level 6, as Pillow's default) into IDAT
  chunks of up to 1 MiB.

The file is written under a temporary name beside the target and renamed onto it only when the
last row is in (:func:`warptex._files._atomic_output`); an error or a missing row removes it.
"""

from __future__ import annotations

import functools
import struct
import zlib

import numpy as np

from warptex._files import _RowFile

__all__ = ["PngWriter", "codes"]

SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOUR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}  # channels -> gray, gray+alpha, RGB, RGBA
_CHUNK = 1 << 20  # IDAT data per chunk
_FILTER_BYTES = 1 << 20  # row bytes filtered at once (their temporaries take ~25 times as much)


def codes(values: np.ndarray, *, data: bool = False, bits: int = 8) -> np.ndarray:
    """``[..., C]`` float values as PNG codes: clipped to [0, 1], colour channels sRGB-encoded
    unless ``data`` (alpha never: channel 2 of 2 and 4 of 4), rounded to ``uint8``/``uint16``.
    NaN must be refused before (it has no code)."""
    values = np.clip(np.asarray(values, np.float32), 0.0, 1.0)
    colour = 0 if data else colour_channels(values.shape[-1])
    maxval, dtype = (255, np.uint8) if bits == 8 else (65535, np.uint16)
    if bits == 8 and colour:
        out = np.empty(values.shape, dtype)
        out[..., :colour] = _srgb8(values[..., :colour])
        out[..., colour:] = np.rint(values[..., colour:] * maxval)
        return out
    if colour:
        values[..., :colour] = _srgb(values[..., :colour])
    return np.rint(values * maxval).astype(dtype)


def colour_channels(channels: int) -> int:
    """How many of ``channels`` are colour (the rest, of 2 or 4, is alpha)."""
    return channels - 1 if channels in (2, 4) else channels


def _srgb(values: np.ndarray) -> np.ndarray:
    """sRGB-encoded ``values`` (float32 in [0, 1]): the exact curve (``io.linear_to_srgb``)."""
    from warptex.io import linear_to_srgb

    return linear_to_srgb(values)


_SHIFT = 12  # a bucket of the lookup: 2^12 consecutive float32 values


@functools.cache
def _srgb8_lookup() -> tuple[np.ndarray, np.ndarray]:
    """``(first, threshold)`` of :func:`_srgb8`: the 8-bit sRGB code of the smallest float32 of
    each bucket (its bits shifted right by ``_SHIFT``), and ``threshold[k]``, the smallest float32
    whose code is above ``k`` (``inf`` for 255), both found with :func:`_srgb8_exact` itself.
    Within a bucket the code rises at most once (checked): the codes' steps are wider than one."""
    top = int(np.float32(1.0).view(np.uint32)) >> _SHIFT
    starts = (np.arange(top + 1, dtype=np.uint32) << _SHIFT).view(np.float32)
    first = _srgb8_exact(starts)
    ends = np.minimum(np.arange(1, top + 2, dtype=np.uint32) << _SHIFT, np.uint32(np.float32(1.0).view(np.uint32)) + 1) - 1
    if np.any(_srgb8_exact(ends.view(np.float32)).astype(np.int32) > first.astype(np.int32) + 1):
        raise AssertionError("an sRGB code bucket holds two steps")
    # Bisection on the float32 bits (monotonic in the value for x >= 0): the first of code > k.
    lo = np.zeros(255, np.int64)
    hi = np.full(255, int(np.float32(1.0).view(np.uint32)), np.int64)
    k = np.arange(255)
    while np.any(lo < hi):
        mid = (lo + hi) // 2
        above = _srgb8_exact(mid.astype(np.uint32).view(np.float32)) > k
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid + 1)
    threshold = np.append(lo.astype(np.uint32).view(np.float32), np.float32(np.inf))
    return first, threshold


def _srgb8_exact(values: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes of ``values`` (float32 in [0, 1]) by the curve: the reference of :func:`_srgb8`."""
    return np.rint(_srgb(values) * np.float32(255)).astype(np.uint8)


def _srgb8(values: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes of ``values`` (float32 in [0, 1]), the same as :func:`_srgb8_exact` for every
    float32, by a table on the value's bits and one comparison: the curve's ``pow`` in float64 was
    most of building an 8-bit texture (4 s of 5.5 for a 4096² RGBA one)."""
    first, threshold = _srgb8_lookup()
    code = first[(values.view(np.uint32) & np.uint32(0x7FFFFFFF)) >> _SHIFT]  # -0.0 as 0.0
    code += values >= threshold[code]
    return code


def _chunk(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(payload, zlib.crc32(kind)))


class PngWriter(_RowFile):
    """Write a ``height × width`` PNG of ``channels`` (1-4: gray, gray+alpha, RGB, RGBA) band by
    band: :meth:`write` takes float values, :meth:`write_codes` codes; use it as a context
    manager, which renames the file onto ``path`` on success (every row written) and removes it
    on any error.

    Args:
        path: the ``.png`` to write (parent folders are created).
        height, width: the image's size in pixels.
        channels: 1-4.
        bits: 8 or 16 per channel.
        data: values are data, written as they are (no sRGB encoding).
    """

    def __init__(self, path, height: int, width: int, channels: int, *, bits: int = 8, data: bool = False):
        from warptex._files import _checked_output_path

        func = "PngWriter"
        for name, value, low in (("height", height, 1), ("width", width, 1), ("channels", channels, 1)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f"{func}(): {name} must be an int >= {low}, got {value!r}")
        if channels > 4:
            raise ValueError(f"{func}(): a PNG has 1-4 channels, got {channels}")
        if bits not in (8, 16) or isinstance(bits, bool):
            raise ValueError(f"{func}(): bits must be 8 or 16, got {bits!r}")
        if width >= 2**31 or height >= 2**31:
            raise ValueError(f"{func}(): a PNG is at most 2^31 - 1 pixels a side, got {height}x{width}")
        self.path = _checked_output_path(path, func)
        self.height, self.width, self.channels, self.bits, self.data = int(height), int(width), int(channels), bits, bool(data)
        self._pixel = channels * bits // 8  # bytes a pixel
        self._rows = 0
        self._previous = np.zeros(self.width * self._pixel, np.uint8)  # the row above the first is zero
        self._zlib = zlib.compressobj(6)
        self._pending = bytearray()
        header = struct.pack(">IIBBBBB", self.width, self.height, bits, _COLOUR_TYPES[channels], 0, 0, 0)
        self._open().write(SIGNATURE + _chunk(b"IHDR", header))

    def write(self, values) -> None:
        """Append rows of float values, ``[n, width, channels]`` (``[n, width]`` for one channel),
        encoded as :func:`codes` says. NaN is an error."""
        values = np.asarray(values, np.float32)
        if values.ndim == 2 and self.channels == 1:
            values = values[..., None]
        self._check_shape(values)
        nans = int(np.isnan(values).sum())
        if nans:
            raise ValueError(f"PngWriter.write(): {nans} NaN value(s) in rows {self._rows}..{self._rows + len(values) - 1}; a PNG has no NaN")
        self.write_codes(codes(values, data=self.data, bits=self.bits))

    def write_codes(self, band: np.ndarray) -> None:
        """Append rows of codes, ``[n, width, channels]`` ``uint8`` (8 bits) or ``uint16`` (16)."""
        band = np.asarray(band)
        if band.ndim == 2 and self.channels == 1:
            band = band[..., None]
        self._check_shape(band)
        want = np.uint8 if self.bits == 8 else np.uint16
        if band.dtype != want:
            raise TypeError(f"PngWriter.write_codes(): a {self.bits}-bit PNG takes {np.dtype(want).name} codes, got {band.dtype}")
        raw = np.ascontiguousarray(band.astype(">u2") if self.bits == 16 else band).view(np.uint8).reshape(len(band), -1)
        step = max(1, _FILTER_BYTES // raw.shape[1])  # rows filtered at once: bounded temporaries
        for start in range(0, len(raw), step):
            rows = raw[start : start + step]
            filtered = _filter_rows(rows, self._previous, self._pixel)
            self._previous = rows[-1].copy()
            self._pending += self._zlib.compress(filtered.tobytes())
            self._flush(final=False)
        self._rows += len(band)

    def _finish(self) -> None:
        self._pending += self._zlib.flush()
        self._flush(final=True)
        self._file.write(_chunk(b"IEND", b""))

    def _check_shape(self, band: np.ndarray) -> None:
        if band.ndim != 3 or band.shape[1:] != (self.width, self.channels) or len(band) == 0:
            raise ValueError(f"PngWriter: rows must be [n >= 1, {self.width}, {self.channels}], got {band.shape}")
        if self._rows + len(band) > self.height:
            raise ValueError(f"PngWriter: {len(band)} more rows after {self._rows} would pass the image's {self.height}")

    def _flush(self, final: bool) -> None:
        while len(self._pending) >= _CHUNK or (final and self._pending):
            self._file.write(_chunk(b"IDAT", bytes(self._pending[:_CHUNK])))
            del self._pending[:_CHUNK]


def _filter_rows(raw: np.ndarray, previous: np.ndarray, pixel: int) -> np.ndarray:
    """``raw`` rows ``[n, row bytes]`` filtered for PNG, each with the filter whose residuals (as
    signed bytes) have the least sum of absolute values, its type byte first: ``[n, 1 + row bytes]``."""
    x = raw.astype(np.int16)
    up = np.concatenate([previous[None].astype(np.int16), x[:-1]])
    left = np.zeros_like(x)
    left[:, pixel:] = x[:, :-pixel]
    upleft = np.zeros_like(x)
    upleft[:, pixel:] = up[:, :-pixel]
    p = left + up - upleft  # Paeth predictor: the neighbour nearest to p, ties to left, up, upleft
    pa, pb, pc = np.abs(p - left), np.abs(p - up), np.abs(p - upleft)
    paeth = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, up, upleft))
    candidates = np.stack([x, x - left, x - up, x - ((left + up) >> 1), x - paeth]).astype(np.uint8)  # mod 256
    cost = np.abs(candidates.view(np.int8).astype(np.int16)).sum(axis=2, dtype=np.int64)  # [5, n]
    best = np.argmin(cost, axis=0)
    out = np.empty((len(raw), raw.shape[1] + 1), np.uint8)
    out[:, 0] = best
    out[:, 1:] = candidates[best, np.arange(len(raw))]
    return out
