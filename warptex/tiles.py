"""Jobs that outgrow memory, in tiles: an image cut into bands of whole rows, sized from a budget.

A render holds every sample of its G-buffer, every technique's outputs and their intermediates at
once: about 250 bytes a sample, so a 4096² image of 16 samples would need 70 GB. Cut into bands of
rows, each rasterised, textured, resolved and written before the next, a job holds one band: its
memory is the textures and one tile, whatever the picture's size, and its time still grows with
pixels × samples. Production renderers and bakers work in buckets for the same reason.

A tile's pixels are those of the whole image, bit for bit: every pixel's rays, derivatives and
samples are computed from its image row and column (``rasterize(rows=...)``), and every technique
computes each pixel from its own G-buffer entries. A band of whole rows is a contiguous slice of
every row-major array, so a tile's outputs go straight into the image's rows.

:func:`gbuffer_tiles` yields the G-buffers of a camera's image, band by band; :func:`tile_rows`
says how an image is cut.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
import warp as wp

from warptex.camera import Camera
from warptex.gbuffer import GBuffer
from warptex.raster import prepare

__all__ = ["DEFAULT_MEMORY", "SAMPLE_BYTES", "Tile", "checked_memory", "gbuffer_tiles", "tile_rows"]

DEFAULT_MEMORY = 256 << 20
"""The default budget of a tile's per-sample work, in bytes (256 MiB): about a million samples,
which keeps a 2-thread launch efficient (per-launch costs are a few hundred microseconds) while a
whole job stays near what a 512² preview takes."""

SAMPLE_BYTES = 250
"""What a render takes per sample of a tile, measured (peak RSS, ``warptex render``, the default
terrain's four splat layers, 4 samples a pixel): the supersampled G-buffer (112 bytes and 40 a UV
set), the technique's outputs and intermediates, the shading and the resolve."""


def checked_memory(func: str, memory) -> int:
    """``memory`` as a whole number of bytes >= 1 MiB (``None``: :data:`DEFAULT_MEMORY`), or a
    ``ValueError`` naming ``func``."""
    if memory is None:
        return DEFAULT_MEMORY
    if isinstance(memory, bool) or not isinstance(memory, (int, np.integer)) or memory < 1 << 20:
        raise ValueError(f"{func}(): memory must be a number of bytes >= 1 MiB (1048576), got {memory!r}")
    return int(memory)


def tile_rows(height: int, row_bytes: float, memory: int | None = None) -> list[tuple[int, int]]:
    """The bands ``(start, stop)`` an image of ``height`` rows is cut into when each row's work
    takes ``row_bytes`` and a band may take ``memory`` (default :data:`DEFAULT_MEMORY`): as few
    bands as fit, of equal heights (the first ones one row taller where they cannot all be
    equal), at least one row each."""
    memory = DEFAULT_MEMORY if memory is None else memory
    if isinstance(memory, bool) or not isinstance(memory, (int, np.integer)) or memory < 1:
        raise ValueError(f"tile_rows(): memory must be a number of bytes >= 1, got {memory!r}")
    if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or height < 1:
        raise ValueError(f"tile_rows(): height must be an int >= 1, got {height!r}")
    most = max(1, int(memory // max(float(row_bytes), 1.0)))
    count = math.ceil(height / most)
    base, extra = divmod(int(height), count)
    bounds = np.cumsum([0] + [base + (k < extra) for k in range(count)])
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


@dataclass(frozen=True)
class Tile:
    """One band of an image's rows (:func:`gbuffer_tiles`, :func:`~warptex.texture_gbuffer_tiles`).

    Attributes:
        rows: the image rows it covers, ``slice(start, stop)``: ``image[tile.rows] = pixels``.
        gbuffer: their G-buffer, ``(stop - start)·s × W·s`` for ``s²`` samples a pixel.
        index, count: this tile's place among the image's tiles (``index`` from 0).
        coverage: a texture-space tile's chart coverage (``(stop - start, W)`` float32, 0 in
            gutters: :func:`~warptex.texture_gbuffer`'s), else ``None``.
    """

    rows: slice
    gbuffer: GBuffer
    index: int
    count: int
    coverage: wp.array | None = None
    _again: Callable[[int], GBuffer] | None = field(default=None, repr=False, compare=False)

    def rasterize(self, samples: int = 1) -> GBuffer:
        """The same rows rasterised at ``samples`` per pixel (e.g. 1, for a G-buffer file of one
        sample a pixel beside a supersampled render), with the tile's BVH."""
        if self._again is None:
            raise ValueError("Tile.rasterize(): only the tiles of gbuffer_tiles() are rasterised; this one is texture space")
        return self._again(samples)


def gbuffer_tiles(mesh, camera: Camera, *, samples: int = 1, memory: int | None = None, sample_bytes: float = SAMPLE_BYTES, origin=None, device=None) -> Iterator[Tile]:
    """The G-buffers of ``camera``'s image in bands of rows, each sized so that its samples take
    at most ``memory`` bytes of work: rasterise, texture, resolve and write one before the next,
    and a job of any size holds one band (module docstring).

    Every argument is checked, and the mesh's BVH built, before the first tile is yielded.

    Args:
        mesh, samples, origin, device: as for :func:`~warptex.rasterize` (one camera).
        camera: the image's camera (not supersampled).
        memory: the bytes one tile's per-sample work may take (default :data:`DEFAULT_MEMORY`);
            the tile height is ``memory / (sample_bytes × samples a row)``, at least one row.
        sample_bytes: what the caller's work takes per sample (default :data:`SAMPLE_BYTES`, a
            render's).

    Yields:
        :class:`Tile`\\ s, top to bottom. Their pixels are the whole image's, bit for bit: a
        technique's output of each tile, resolved, is that image's rows.

    Example::

        image = np.zeros((h, w, 3), np.float32)
        for tile in wt.gbuffer_tiles(mesh, camera, samples=4):
            image[tile.rows] = wt.resolve(wt.triplanar(tile.gbuffer, texture, tiling=8.0), 4).numpy()
    """
    func = "gbuffer_tiles"
    if not isinstance(camera, Camera):
        raise TypeError(f"{func}(): camera must be one warptex Camera, got {type(camera).__name__}")
    memory = checked_memory(func, memory)
    scene, cameras, _ = prepare(func, mesh, camera, samples=samples, origin=origin, device=device)
    strata = cameras[0].strata
    height, width = camera.resolution
    bands = tile_rows(height, sample_bytes * strata * strata * width, memory)

    def again(rows: tuple[int, int]) -> Callable[[int], GBuffer]:
        return lambda s: scene.rasterize([camera.supersampled(s) if s != 1 else camera], rows)

    return (Tile(slice(*rows), scene.rasterize(cameras, rows), k, len(bands), _again=again(rows)) for k, rows in enumerate(bands))
