"""Private gradient copies: how threads that run a backward pass side by side add into shared gradients.

Warp's CPU atomics are plain read-modify-writes, so two threads must never accumulate into one array
at once: every worker but the first gets private, zeroed gradient arrays for the arrays that chunks
share (texels, tiling, ...; per-pixel arrays are disjoint slices already), added into the real
gradients once all chunks are done (:func:`add_private`). Gradients are therefore summed in a
different order than for one launch: equal to float rounding. The order is fixed for a given thread
count (each worker takes the same chunks in the same order every time), so a run is reproducible bit
for bit: only a different thread count changes the rounding.

The private arrays are kept while their real gradient lives, and zeroed as they are added in, ready
for the next backward pass: allocating them afresh cost more than the whole backward of a small image
(page faults, ~0.5 ms per MB here, against ~0.07 ms per MB to zero an array in place), at the price
of one extra copy of every shared gradient per extra thread, held as long as the gradient itself.
From :data:`TRACK_TILES_FROM` threads on, the copies of texel gradients also mark the tiles they add
into (:class:`~warptex.kernels.texels.TexelGrad`), and only those are summed: threads whose pixels
read a part of a texture no longer each pay for all of it.
"""

from __future__ import annotations

import bisect
import weakref
from typing import NamedTuple

import numpy as np
import warp as wp

from warptex._threads import PARALLEL_SUM_BYTES, Split, side_by_side
from warptex._warp import map_arrays
from warptex.kernels.texels import TILE_SHIFT

# Private copies of texel gradients (``TexelGrad`` fields) mark the tiles they add into from this
# many workers on, and only those tiles are summed: marking costs the kernel one load per bilinear
# footprint (10% of a bilinear backward), which the sum repays from 3 workers (at 2 a copy still
# holds half the texture).
TRACK_TILES_FROM = 3
# Elements an accumulator is added and zeroed in at a time (256 KB of floats: in cache between the two).
SUM_BLOCK = 1 << 16

# Each real gradient array's private accumulators, by worker (see the module docstring).
_private_arrays: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class Copy(NamedTuple):
    """A worker's private accumulator for a gradient array: ``array``, zero outside the tiles
    marked in ``tiles`` (one flag per ``2**TILE_SHIFT`` entries; ``None``: not tracked, summed whole)."""

    array: wp.array
    tiles: wp.array | None


def private(real: wp.array, worker: int, tracked: bool = False) -> Copy:
    """Worker ``worker``'s private accumulator for the gradient array ``real``, zero: the one kept
    from the last backward pass when there is one (:func:`add_private` zeroed it), else a new one
    (kept while ``real`` lives); with tile flags when ``tracked`` (a ``TexelGrad`` field)."""
    copies = _private_arrays.setdefault(real, {})
    mine = copies.get(worker)
    if mine is None:  # keyed by the array itself, whose shape and dtype never change
        mine = copies[worker] = Copy(wp.zeros_like(real), None)
    if not tracked:  # summed whole (its tiles, if any, stay clear: nothing marks them)
        return Copy(mine.array, None)
    if mine.tiles is None:
        tiles = wp.zeros(-(-real.shape[0] // (1 << TILE_SHIFT)), dtype=wp.int32, device=real.device)
        mine = copies[worker] = Copy(mine.array, tiles)
    return mine


def run_private(split: Split, work, copies: list[tuple[wp.array, Copy]], entries: dict | None = None) -> None:
    """``work(worker, chunk)`` for every chunk, in :meth:`~warptex._threads.Split.run`'s fixed order, then the
    private accumulators ``copies`` (``(real gradient, copy)`` pairs) added into the real gradients
    (and zeroed again; see :func:`add_private` for ``entries``). A failure leaves them holding part of
    a pass: they are dropped (the next pass makes new ones)."""
    try:
        split.run(work, fixed=True)
        add_private(copies, split.workers, entries)
    except BaseException:
        for real, _ in copies:
            _private_arrays.pop(real, None)
        raise


def with_private_grads(value, copies: list, worker: int):
    """``value`` (an array or a struct) with every array that has a gradient replaced by a view of
    the same data whose gradient is ``worker``'s zeroed private accumulator, recorded in ``copies``.

    Adjoint kernels accumulate into the ``grad`` of the *forward* arrays of struct fields (Warp
    ignores the adjoint struct there), so private accumulators must sit in the forward arguments.
    """

    def private_view(a: wp.array) -> wp.array:
        if not a.grad:
            return a
        mine = private(a.grad, worker)
        copies.append((a.grad, mine))
        return wp.array(ptr=a.ptr, dtype=a.dtype, shape=a.shape, strides=a.strides, device=a.device, grad=mine.array)

    return map_arrays(value, private_view)


class _Sum(NamedTuple):
    """One real gradient (flat NumPy view) and what is added into it: each private copy (flat) with
    the runs ``(start, stop)`` of tiles where it may be non-zero, in worker order."""

    target: np.ndarray
    tile: int  # scalars per tile
    sources: list


def tiles_reached(marks: np.ndarray) -> np.ndarray:
    """Which tiles a copy's ``TexelGrad.tiles`` marks reach: ``marks[t] = k`` reaches tiles ``t``
    to ``t + k - 1``."""
    index = np.arange(len(marks))
    return np.maximum.accumulate(np.where(marks > 0, index + marks, 0)) > index


def add_private(copies: list[tuple[wp.array, Copy]], workers: int, entries: dict | None = None) -> None:
    """``real += mine; mine = 0`` for every distinct ``(real, mine)`` pair of gradient arrays (CPU:
    NumPy views); a gradient that several arguments share has one accumulator per worker, added
    once. Where ``mine`` tracks tiles, only the tiles it marked are added and zeroed (the rest is
    still zero), and the marks are cleared; where ``entries`` gives ``real`` a ``(start, stop)``
    range, only the tiles of that range (the kernel added nowhere else).

    The tiles of all real gradients are cut into ``workers`` ranges of equal work (marked tiles),
    summed on the workers side by side (NumPy releases the GIL), block by block so that each block
    of an accumulator is zeroed while it is still in cache; each element still adds the workers'
    copies in worker order, so the result is the same bit for bit as one thread adding them."""
    sums: dict[int, _Sum] = {}
    for real, mine in {id(mine.array): (real, mine) for real, mine in copies}.values():
        target, source = real.numpy(), mine.array.numpy()  # CPU arrays: views of the same memory
        marked = None if mine.tiles is None else tiles_reached(mine.tiles.numpy())
        if mine.tiles is not None:
            mine.tiles.zero_()
        if real.size == 0:
            continue
        if not (target.flags.c_contiguous and source.flags.c_contiguous):  # a strided gradient: added whole, on this thread
            target += source
            source[...] = 0
            continue
        target, source = target.reshape(-1), source.reshape(-1)
        tile = (source.size // real.size) << TILE_SHIFT
        if marked is None:
            marked = np.ones(-(-source.size // tile), dtype=bool)
        if entries and id(real) in entries:
            start, stop = entries[id(real)]
            marked[: start >> TILE_SHIFT] = False
            marked[-(-stop >> TILE_SHIFT) :] = False
        edges = np.flatnonzero(np.diff(marked, prepend=False, append=False))  # starts and stops of runs, alternating
        sums.setdefault(id(real), _Sum(target, tile, [])).sources.append((source, marked, edges[0::2].tolist(), edges[1::2].tolist()))
    if not sums:
        return
    # Work per tile (copies to add there), every gradient's tiles end to end, cut into equal parts.
    work = [np.sum([marked for _, marked, _, _ in s.sources], axis=0) for s in sums.values()]
    offsets = np.cumsum([0] + [len(w) for w in work])
    cumulative = np.cumsum(np.concatenate(work))
    nbytes = sum(int(w.sum()) * s.tile * s.target.itemsize for w, s in zip(work, sums.values()))
    parts = workers if nbytes >= PARALLEL_SUM_BYTES else 1
    cuts = [0, *(np.searchsorted(cumulative, cumulative[-1] * np.arange(1, parts) / parts) + 1).tolist(), len(cumulative)]

    def add(part: int) -> None:
        for s, offset in zip(sums.values(), offsets):
            lo, hi = max(cuts[part] - offset, 0), min(cuts[part + 1] - offset, len(s.sources[0][1]))
            for source, _, starts, stops in s.sources:  # worker order
                for k in range(bisect.bisect_right(stops, lo), len(starts)):
                    first, last = max(starts[k], lo), min(stops[k], hi)
                    if first >= last:
                        break
                    for start in range(first * s.tile, min(last * s.tile, s.target.size), SUM_BLOCK):
                        block = slice(start, min(start + SUM_BLOCK, last * s.tile, s.target.size))
                        s.target[block] += source[block]
                        source[block] = 0

    side_by_side(add, parts)


