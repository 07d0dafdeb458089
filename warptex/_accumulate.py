"""Gradient sums that do not depend on the thread count.

Warp's CPU atomics are plain read-modify-writes, so two threads must never add into one array at
once. A backward pass over the pixels is therefore cut into chunks fixed by the pixels and the size
of the gradients they share (:func:`~warptex._threads.grad_bounds`), never by how many threads run
them:

- chunk 0 adds into the real gradients of the arrays that all pixels share (texels, tiling, ...;
  per-pixel gradients are disjoint slices already);
- chunk ``k >= 1`` adds into a zeroed private accumulator (a *slot*), which is added into the real
  gradients once chunk ``k - 1``'s has been (:func:`run_ordered`), then zeroed for the next chunk.

Every shared gradient is thus ``((real + chunk 0, pixel by pixel) + P1) + P2 ...``, in that order,
whichever thread ran which chunk and however many ran: the same bits at 1, 2, 3 or 16 threads.

Memory does not grow with the thread count: there are at most :func:`slot_count` slots (one per
core at most), kept while their real gradient lives and zeroed as they are added in, ready for the
next pass (allocating them afresh cost more than the whole backward of a small image: page faults,
~0.5 ms per MB here, against ~0.07 ms per MB to zero an array in place). Texel-gradient slots mark
the tiles they add into (:class:`~warptex.kernels.texels.TexelGrad`), and only those are added in
and zeroed: a chunk whose pixels read a part of a texture pays for that part only.

On CUDA a backward pass is one launch, whose threads add with atomics in an order that changes
from run to run. There texel gradients are summed in fixed point instead (:func:`exact_sums`, the
kernels in :mod:`warptex.kernels.scatter`), an order-free integer sum: the same bits every run,
unless :func:`set_deterministic_gradients` turned it off. The hand-written gradients add through
their ``TexelGrad`` structs; Warp's generated adjoints read the textures through
:func:`exact_views`, whose texel reads add in fixed point too.
"""

from __future__ import annotations

import threading
import weakref
from typing import NamedTuple

import numpy as np
import warp as wp

from warptex._threads import cpu_count, side_by_side
from warptex._warp import map_arrays, replay, struct_fields, struct_like
from warptex.kernels.scatter import add_exact, exact_exponents
from warptex.kernels.texels import FORMAT_FLOAT32, FORMAT_FLOAT32_PACKED, TILE_SHIFT, TextureView

# Elements an accumulator is added and zeroed in at a time (256 KB of floats: in cache between the two).
SUM_BLOCK = 1 << 16

# Each real gradient array's private accumulators, by slot (see the module docstring).
_private_arrays: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class Copy(NamedTuple):
    """A slot's private accumulator for a gradient array: ``array``, zero outside the tiles
    marked in ``tiles`` (one flag per ``2**TILE_SHIFT`` entries; ``None``: not tracked, added whole)."""

    array: wp.array
    tiles: wp.array | None


def private(real: wp.array, slot: int, tracked: bool = False) -> Copy:
    """Slot ``slot``'s private accumulator for the gradient array ``real``, zero: the one kept from
    the last backward pass when there is one (:func:`add_copies` zeroed it), else a new one (kept
    while ``real`` lives); with tile flags when ``tracked`` (a ``TexelGrad`` field)."""
    copies = _private_arrays.setdefault(real, {})
    mine = copies.get(slot)
    if mine is None:  # keyed by the array itself, whose shape and dtype never change
        mine = copies[slot] = Copy(wp.zeros_like(real), None)
    if not tracked:  # added whole (its tiles, if any, stay clear: nothing marks them)
        return Copy(mine.array, None)
    if mine.tiles is None:
        tiles = wp.zeros(-(-real.shape[0] // (1 << TILE_SHIFT)), dtype=wp.int32, device=real.device)
        mine = copies[slot] = Copy(mine.array, tiles)
    return mine


def slot_count(chunks: int, workers: int) -> int:
    """Slots a backward pass of ``chunks`` chunks on ``workers`` threads uses: one per worker that
    can run a chunk ``k >= 1`` at once, at most one more than the cores (threads beyond the
    cores wait for a slot rather than each holding a copy of every shared gradient)."""
    return max(1, min(chunks - 1, workers, cpu_count() + 1))


def with_private_grads(value, copies: list, slot: int):
    """``value`` (an array or a struct) with every array that has a gradient replaced by a view of
    the same data whose gradient is slot ``slot``'s zeroed private accumulator, recorded in ``copies``.

    Adjoint kernels accumulate into the ``grad`` of the *forward* arrays of struct fields (Warp
    ignores the adjoint struct there), so private accumulators must sit in the forward arguments.
    """

    def private_view(a: wp.array) -> wp.array:
        if not a.grad:
            return a
        mine = private(a.grad, slot)
        copies.append((a.grad, mine))
        return wp.array(ptr=a.ptr, dtype=a.dtype, shape=a.shape, strides=a.strides, device=a.device, grad=mine.array)

    return map_arrays(value, private_view)


def tiles_reached(marks: np.ndarray) -> np.ndarray:
    """Which tiles a copy's ``TexelGrad.tiles`` marks reach: ``marks[t] = k`` reaches tiles ``t``
    to ``t + k - 1``."""
    index = np.arange(len(marks))
    return np.maximum.accumulate(np.where(marks > 0, index + marks, 0)) > index


def add_copies(copies: list[tuple[wp.array, Copy]], entries: dict | None = None) -> None:
    """``real += mine; mine = 0`` for every distinct ``(real, mine)`` pair of gradient arrays (CPU:
    NumPy views), on this thread; a gradient that several arguments share has one accumulator per
    slot, added once. Where ``mine`` tracks tiles, only the tiles it marked are added and zeroed
    (the rest is still zero), and the marks are cleared; where ``entries`` gives ``real`` a
    ``(start, stop)`` range, only the tiles of that range (the kernel added nowhere else). Blocks of
    :data:`SUM_BLOCK` elements are zeroed while still in cache from the addition."""
    for real, mine in {id(mine.array): (real, mine) for real, mine in copies}.values():
        target, source = real.numpy(), mine.array.numpy()  # CPU arrays: views of the same memory
        marked = None if mine.tiles is None else tiles_reached(mine.tiles.numpy())
        if mine.tiles is not None:
            mine.tiles.zero_()
        if real.size == 0:
            continue
        if not (target.flags.c_contiguous and source.flags.c_contiguous):  # a strided gradient: added whole
            target += source
            source[...] = 0
            continue
        target, source = target.reshape(-1), source.reshape(-1)
        tile = (source.size // real.size) << TILE_SHIFT  # scalars per tile
        if marked is None:
            marked = np.ones(-(-source.size // tile), dtype=bool)
        if entries and id(real) in entries:
            start, stop = entries[id(real)]
            marked[: start >> TILE_SHIFT] = False
            marked[-(-stop >> TILE_SHIFT) :] = False
        edges = np.flatnonzero(np.diff(marked, prepend=False, append=False)).tolist()  # starts and stops of runs, alternating
        for first, last in zip(edges[0::2], edges[1::2]):
            for start in range(first * tile, min(last * tile, target.size), SUM_BLOCK):
                block = slice(start, min(start + SUM_BLOCK, last * tile, target.size))
                target[block] += source[block]
                source[block] = 0


class _Order:
    """The shared state of :func:`run_ordered`: the next chunk to hand out, the free slots, the
    finished chunks waiting to be added in, and the next one to add."""

    def __init__(self, slots: int):
        self.cond = threading.Condition()
        self.taken = 0  # chunks handed out
        self.first_done = False  # chunk 0 (which adds into the real gradients) has finished
        self.next_add = 1  # the next chunk whose slot is added in
        self.waiting: dict[int, int] = {}  # finished chunk -> its slot
        self.free = list(range(slots - 1, -1, -1))
        self.adding = False  # a thread is adding slots in
        self.failed = False


def run_ordered(chunks: int, workers: int, work, copies_of, entries: dict | None = None) -> None:
    """``work(k, slot)`` for every chunk ``k`` on ``workers`` threads (worker 0 the calling one),
    ``slot`` ``None`` for chunk 0 (it adds into the real gradients) and a free slot for the others,
    whose accumulators ``copies_of(slot)`` (``(real gradient, copy)`` pairs) are added into the real
    gradients in chunk order (:func:`add_copies`; see :func:`private` for ``entries``), by whichever
    thread finds the next one finished, while the others go on with their chunks.

    A failure stops the other workers after their current chunk and is re-raised here; the slots,
    holding part of a pass, are dropped (the next pass makes new ones)."""
    order = _Order(slot_count(chunks, workers))
    cond = order.cond

    def add_in() -> None:
        while True:
            with cond:
                if order.adding or order.failed or not order.first_done or order.next_add not in order.waiting:
                    return
                order.adding = True
                slot = order.waiting.pop(order.next_add)
            add_copies(copies_of(slot), entries)  # a failure: run by loop(), which stops the others
            with cond:
                order.adding = False
                order.next_add += 1
                order.free.append(slot)
                cond.notify_all()

    def loop(worker: int) -> None:
        try:
            while True:
                with cond:  # a chunk is taken with its slot, so slots go to chunks in order
                    while order.taken > 0 and not order.free and not order.failed and order.taken < chunks:
                        cond.wait()
                    k = order.taken
                    if k >= chunks or order.failed:
                        return
                    order.taken += 1
                    slot = None if k == 0 else order.free.pop()
                work(k, slot)
                with cond:
                    if slot is None:
                        order.first_done = True
                    else:
                        order.waiting[k] = slot
                add_in()
        except BaseException:
            with cond:
                order.failed = True
                cond.notify_all()
            raise

    try:
        side_by_side(loop, workers)  # waits for every worker; re-raises a failure here
    except BaseException:
        for slot in range(slot_count(chunks, workers)):
            for real, _ in copies_of(slot):
                _private_arrays.pop(real, None)
        raise
    assert order.next_add == chunks, "warptex internal error: a chunk's gradient was not added in"


# Whether CUDA's hand-written texel gradients are summed in fixed point (see the module docstring).
_deterministic = True

# The devices those sums run on: CUDA. Tests add the CPU, where one launch runs the same kernels.
EXACT_DEVICES = {"cuda"}


def set_deterministic_gradients(enabled: bool) -> None:
    """Whether texel gradients on CUDA are the same bits every run (the default, ``True``), summed
    in fixed point by two passes of the gradient kernel, or added with float atomics (``False``:
    one pass, whose last bits change from run to run). On the CPU gradients are the same bits at
    any thread count either way. Gradients of other inputs than texels on CUDA (UVs are per pixel
    and keep their bits; the scalar tiling, sharpness, offset and transition gradients are added
    with float atomics) are not covered (docs/performance.md says how and what it costs)."""
    global _deterministic
    if not isinstance(enabled, bool):
        raise TypeError(f"set_deterministic_gradients() takes True or False, not {enabled!r}")
    _deterministic = enabled


def get_deterministic_gradients() -> bool:
    """Whether texel gradients on CUDA are summed deterministically (:func:`set_deterministic_gradients`)."""
    return _deterministic


class Exact(NamedTuple):
    """A texel gradient ``grad``'s fixed-point sum: two int32 per texel (its largest contribution's
    float bits, then its exponent; how many contributions it has) and four int64 (the sum)."""

    grad: wp.array
    exponents: wp.array
    fixed: wp.array


def exact_sums(device, texel_grads: list[wp.array]) -> dict[int, Exact] | None:
    """Zeroed fixed-point sums for the texel gradients ``texel_grads`` (by id), where a backward
    pass on ``device`` sums them exactly (CUDA, unless turned off); ``None`` where it adds with
    float atomics or in fixed chunks (the CPU)."""
    if not _deterministic or not texel_grads or ("cuda" if device.is_cuda else "cpu") not in EXACT_DEVICES:
        return None
    return {id(g): Exact(g, wp.zeros(2 * g.shape[0], dtype=wp.int32, device=device), wp.zeros(4 * g.shape[0], dtype=wp.int64, device=device)) for g in texel_grads}


def set_exponents(sums: dict[int, Exact]) -> None:
    """Between the two passes: each texel's exponent, from its contributions' count and largest
    magnitude (the first pass)."""
    for s in sums.values():
        replay(exact_exponents, s.grad.shape[0], (s.exponents,), s.grad.device)


def add_sums(sums: dict[int, Exact]) -> None:
    """After the second pass: each fixed-point sum added into its gradient."""
    for s in sums.values():
        replay(add_exact, s.grad.shape[0], (s.grad, s.exponents, s.fixed), s.grad.device)


class ExactViews(NamedTuple):
    """A generated adjoint's arguments whose texel gradients are summed in fixed point: ``first``
    and ``second``, the launch's ``args`` for each pass (see :func:`exact_views`), ``sums`` by
    gradient id, and what the passes' views point at (kept alive while they run)."""

    first: object
    second: object
    sums: dict[int, Exact]
    held: list


def exact_texel_grads(args, device) -> list[wp.array]:
    """The gradients of the float32 textures in ``args`` that Warp's generated adjoint of a launch
    on ``device`` sums in fixed point (:func:`exact_views`): those that want one, where texel
    gradients are summed so there (:func:`exact_sums`); else none."""
    if not _deterministic or ("cuda" if device.is_cuda else "cpu") not in EXACT_DEVICES:
        return []
    views = _texture_views(args)
    return list({id(v.texels.grad): v.texels.grad for v in views if v.texel_format == FORMAT_FLOAT32 and v.texels.shape[0] > 0 and v.texels.requires_grad}.values())


def exact_views(args, device) -> ExactViews | None:
    """For Warp's generated adjoint of a launch with ``args`` on ``device``: ``args`` as each of
    its two passes reads it, with new zeroed sums, where it sums texel gradients in fixed point
    (:func:`exact_texel_grads`), else ``None``.

    Each such :class:`~warptex.kernels.texels.TextureView` reads its texels from their address
    (``FORMAT_FLOAT32_PACKED``, ``texels`` empty): the adjoint of that read adds its texel's
    gradient in fixed point (``exact``: the sum's arrays; the first pass without the int64 sums),
    where Warp's adjoint of an array read would add with float atomics."""
    sums = exact_sums(device, exact_texel_grads(args, device))
    if sums is None:
        return None
    empty = wp.empty(1, dtype=wp.vec4, device=device)
    headers = {key: [wp.array([s.exponents.ptr, ptr], dtype=wp.uint64, device=device) for ptr in (0, s.fixed.ptr)] for key, s in sums.items()}

    def rewired(value, second: bool):
        copy = struct_like(value)
        for name, field in struct_fields(value).items():
            if wp.types.is_struct(field):
                key = id(field.texels.grad) if field._cls is TextureView and field.texels is not None else None
                field = _packed_view(field, empty, headers[key][second]) if key in headers else rewired(field, second)
            setattr(copy, name, field)
        return copy

    return ExactViews(rewired(args, False), rewired(args, True), sums, [empty, headers])


def _texture_views(value) -> list:
    """Every :class:`~warptex.kernels.texels.TextureView` in the struct ``value`` (nested ones included)."""
    views = []
    for field in struct_fields(value).values():
        if wp.types.is_struct(field):
            views += [field] if field._cls is TextureView else _texture_views(field)
    return views


def _packed_view(view, empty: wp.array, header: wp.array):
    """``view`` reading its float32 texels from their address, its gradient summed at ``header``."""
    copy = struct_like(view)
    for name, field in struct_fields(view).items():
        setattr(copy, name, field)
    copy.texels = empty
    copy.texel_format = FORMAT_FLOAT32_PACKED
    copy.packed = wp.uint64(view.texels.ptr)
    copy.exact = wp.uint64(header.ptr)
    return copy
