"""Per-pixel kernel launches, split over CPU threads.

Warp runs a CPU launch on the calling thread, one kernel instance after another, and releases
the GIL while it runs. :func:`launch` therefore cuts the range of a per-pixel kernel into
contiguous chunks (a few per thread, so that a thread whose pixels are cheap takes more of them)
and launches them from a small thread pool, each on views (slices) of the per-pixel arrays.
Every pixel is computed by the same code from the same inputs, so the result is bit-identical to
a single launch.

Under a ``wp.Tape`` the split launch is recorded as one backward step that runs the chunks'
adjoint launches on the threads too. Warp's CPU atomics are plain read-modify-writes, so two
adjoints must never accumulate into one array at once: every thread but the first gets private,
zeroed gradient arrays for the arrays that chunks share (texels, tiling, ...; per-pixel arrays are
disjoint slices already), added into the real gradients once all chunks are done. Gradients are
therefore summed in a different order than for one launch: equal to float rounding. The order is
fixed for a given thread count (each thread takes the same chunks in the same order every time),
so a run is reproducible bit for bit: only a different thread count changes the rounding. The private
arrays are kept while their real gradient lives, and zeroed as they are added in, ready for the
next backward pass: allocating them afresh cost more than the whole backward of a small image
(page faults, ~0.5 ms per MB here, against ~0.07 ms per MB to zero an array in place), at the
price of one extra copy of every shared gradient per extra thread, held as long as the gradient
itself. From :data:`TRACK_TILES_FROM` threads on, the copies of texel gradients also mark the
tiles they add into (:class:`~warptex.kernels.sampling.TexelGrad`), and only those are summed:
threads whose pixels read a part of a texture no longer each pay for all of it.

The same page faults are why a launch's outputs are made with :func:`output` (allocated, not
touched) and zeroed by :func:`launch` chunk by chunk, on the thread that then fills the chunk:
``wp.zeros`` of a 12.6 MB output and its gradient measured up to 8 ms on the calling thread where
the memory came fresh from the system, a third of a one-thread bilinear lookup of as many pixels.

CUDA launches are never split: one launch fills the device.
"""

from __future__ import annotations

import bisect
import functools
import itertools
import os
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np
import warp as wp

from warptex._warp import active_tape, struct_fields, struct_like
from warptex.kernels.sampling import TILE_SHIFT, TexelGrad

# Below this many pixels per thread, handing work to a thread costs more than it saves.
MIN_PIXELS_PER_THREAD = 16384
# Chunks per thread (when the pixels allow): costs vary across an image (sky, terrain), so
# threads take chunks from a queue rather than one fixed share each. More, smaller chunks measured
# slower (each launch costs ~0.1 ms of Python, partly under the GIL).
CHUNKS_PER_THREAD = 4
# Where a G-buffer's mask is known (``covered``), chunks are cut to equal estimated cost rather than
# equal pixel counts: a pixel it does not cover costs about this much of a covered one (the sky of
# the terrain view with triplanar mapping: 0.13) ...
UNCOVERED_COST = 0.1
# ... counted in blocks of this many pixels.
COVERAGE_BLOCK = 1024
# Private gradient copies smaller than this in all are summed on one thread (handing out the work
# costs more).
PARALLEL_SUM_BYTES = 1 << 20
# Private copies of texel gradients (``TexelGrad`` arguments) mark the tiles they add into from this
# many workers on, and only those tiles are summed: marking costs the kernel one load per bilinear
# footprint (10% of a bilinear backward), which the sum repays from 3 workers (at 2 a copy still
# holds half the texture).
TRACK_TILES_FROM = 3
# Elements an accumulator is added and zeroed in at a time (256 KB of floats: in cache between the two).
SUM_BLOCK = 1 << 16

_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_num_threads: int | None = None
# Each real gradient array's private accumulators, by worker (see the module docstring).
_private_arrays: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def preload(kernels, device=None) -> None:
    """Compile (or load from Warp's kernel cache) the Warp modules of ``kernels`` for ``device``,
    side by side on every core.

    Warp compiles a module the first time one of its kernels runs, one module after another. A job
    that knows which kernels it will run calls this first, so that a cold start compiles them in
    parallel (each compile is single-threaded, on the CPU and with NVRTC alike).
    """
    modules = list({id(k.module): k.module for k in kernels}.values())
    if modules:
        wp.force_load(device=wp.get_device(device), modules=modules, max_workers=min(len(modules), cpu_count()))


def precompile(device=None, *, layer_counts=(4,)) -> None:
    """Compile every warptex kernel for ``device`` now, side by side on every core, into Warp's
    kernel cache (the first run of each kernel then starts at once).

    Args:
        device: Warp device (``None``: Warp's default).
        layer_counts: the layer counts whose splat kernels to compile (they come in sizes of 8,
            16, 32... layers).
    """
    from warptex.kernels import all_kernels

    preload(all_kernels(layer_counts), device)


class PerPixel(NamedTuple):
    """A kernel argument indexed by the launch index along its first axis (sliced per chunk)."""

    array: wp.array | None


def output(shape, dtype, device, requires_grad: bool = False) -> wp.array:
    """A new per-pixel output for :func:`launch` (first axis: one row per pixel), and its gradient
    when ``requires_grad``: allocated, not zeroed; :func:`launch` zeroes both, chunk by chunk on
    the threads that fill them (module docstring)."""
    out = wp.empty(shape, dtype=dtype, device=device)
    if requires_grad:
        out.grad = wp.empty(shape, dtype=dtype, device=device)
    return out


def _zero_rows(outputs: list[wp.array]) -> None:
    """Zero ``outputs`` (a chunk's rows of per-pixel outputs) and their gradients."""
    for out in outputs:
        out.zero_()
        if out.grad is not None:
            out.grad.zero_()


def per_pixel(*arrays: wp.array | None) -> list[PerPixel]:
    """Mark ``arrays`` (first axis: one entry per launched pixel; ``None``: an unused optional
    array) for :func:`launch`."""
    return [PerPixel(a) for a in arrays]


def cpu_count() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def set_num_threads(threads: int | None) -> None:
    """Set how many CPU threads warptex's per-pixel launches use.

    Args:
        threads: an int >= 1, or ``None`` for the default: ``$WARPTEX_NUM_THREADS`` when set, else
            every core this process may use.
    """
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"set_num_threads(): threads must be an int >= 1 or None, got {threads!r}")
    global _num_threads
    _num_threads = threads


def get_num_threads() -> int:
    """The CPU threads warptex's per-pixel launches use (see :func:`set_num_threads`)."""
    if _num_threads is not None:
        return _num_threads
    env = os.environ.get("WARPTEX_NUM_THREADS", "").strip()
    if env:
        try:
            value = int(env)
        except ValueError:
            value = 0
        if value < 1:
            raise ValueError(f"WARPTEX_NUM_THREADS must be an int >= 1, got {env!r}")
        return value
    return cpu_count()


def _executor(size: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size < size:
            if _pool is not None:
                _pool.shutdown(wait=False)
            _pool, _pool_size = ThreadPoolExecutor(max_workers=size, thread_name_prefix="warptex"), size
        return _pool


def _chunk(value: Any, start: int, stop: int, count: int):
    if isinstance(value, PerPixel):
        if value.array is None:
            return None
        if value.array.shape[0] != count:
            raise RuntimeError(f"warptex internal error: a per-pixel argument has {value.array.shape[0]} rows for {count} pixels")
        return value.array[start:stop]
    return value


GENERATED = "generated"
"""``backward=GENERATED``: record the kernel's generated adjoint (see :func:`launch`)."""


def launch(kernel, count: int, *, inputs: list, outputs: list, device, threads: int | None = None, backward=None, covered: wp.array | None = None) -> None:
    """Launch a per-pixel ``kernel`` over ``count`` pixels, split over CPU threads.

    Args:
        kernel: a Warp kernel whose thread ``i`` reads and writes only entry ``i`` of its per-pixel
            arrays (and reads anything else).
        count: pixels to launch.
        inputs: the kernel's inputs; per-pixel arrays wrapped with :func:`per_pixel`.
        outputs: the kernel's outputs, all per-pixel arrays (first axis ``count``), new ones from
            :func:`output`: they and their gradients are zeroed here, each chunk's rows before the
            kernel runs on them.
        device: the Warp device.
        threads: threads to use (default :func:`get_num_threads`); CUDA always uses one launch.
        backward: what an active ``wp.Tape`` records for the backward pass (when an output requires
            gradients): ``None``, nothing; :data:`GENERATED`, the kernel's generated adjoint (the
            kernel must have one); or ``backward(tape)``, a hand-written gradient (see
            :func:`scatter`) that reads the outputs' ``.grad`` when the tape runs backwards.
        covered: the pixels' mask (``count`` entries, non-zero where a pixel is shaded), when the
            launch is over a G-buffer: chunks are then cut to equal estimated costs (see
            :func:`_bounds`), so that the sky's cheap pixels do not unbalance the threads.
    """
    if count <= 0:
        return
    device = wp.get_device(device)
    workers = _workers(device, count, threads)
    tape = active_tape()
    recorded = [o for o in outputs if o.requires_grad] if tape is not None and backward is not None else []
    if recorded and backward is not GENERATED:
        tape.record_func(functools.partial(backward, tape), arrays=recorded)
    generated = bool(recorded) and backward is GENERATED
    if workers == 1:
        _zero_rows(outputs)
        wp.launch(kernel, dim=count, inputs=[_chunk(a, 0, count, count) for a in inputs], outputs=outputs, device=device, record_tape=generated)
        return
    for out in outputs:
        if out.shape[0] != count:
            raise RuntimeError(f"warptex internal error: an output has {out.shape[0]} rows for {count} pixels")
    split = _Split(kernel, device, count, inputs, outputs, workers, covered)

    def forward(worker: int, k: int) -> None:
        ins, outs, dim = split.arguments(inputs, k)
        _zero_rows(outs)
        wp.launch(kernel, dim=dim, inputs=ins, outputs=outs, device=device, record_tape=False)

    split.run(forward)
    if generated:
        tape.record_func(lambda: _backward(tape, split), arrays=recorded)


def scatter(kernel, count: int, *, inputs: list, targets: list, device, threads: int | None = None, covered: wp.array | None = None, entries: dict | None = None) -> None:
    """Launch a per-pixel ``kernel`` that *adds* into ``targets``, arrays shared by every pixel
    (texel gradients), split over CPU threads as :func:`launch` splits a launch.

    Warp's CPU atomics are plain read-modify-writes, so every worker but the first adds into
    private zeroed copies of ``targets``, summed into them once all chunks are done (equal to a
    single launch up to float rounding). A kernel argument of type
    :class:`~warptex.kernels.sampling.TexelGrad` is given here as its gradient array (or ``None``:
    not needed) and passed as one; a private copy passed so marks the tiles it adds into, and only
    those are summed (a thread's pixels often read a part of a texture only). Not recorded on a
    tape: this is what a backward step runs.

    Args:
        kernel: a Warp kernel; ``targets`` appear among its ``inputs`` (by identity).
        count, inputs, device, threads, covered: as for :func:`launch` (no outputs).
        targets: the arrays the kernel adds into.
        entries: ``{id(target): (start, stop)}`` for targets the kernel adds into only there (the
            mip levels a constant-LOD lookup reads): only the tiles of those entries are summed
            from the private copies, tracked or not (the rest stays zero).
    """
    if count <= 0:
        return
    device = wp.get_device(device)
    workers = _workers(device, count, threads)
    texel_grads = {i for i, arg in enumerate(kernel.adj.args) if arg.type is TexelGrad}
    # Tiles are tracked in the copies of arrays passed only as TexelGrad arguments, from TRACK_TILES_FROM workers.
    tracked = set() if workers < TRACK_TILES_FROM else {id(a) for i, a in enumerate(inputs) if i in texel_grads} - {id(a) for i, a in enumerate(inputs) if i not in texel_grads}
    if workers == 1:
        ins = _texel_grads(inputs, texel_grads, {})
        wp.launch(kernel, dim=count, inputs=[_chunk(a, 0, count, count) for a in ins], device=device, record_tape=False)
        return
    split = _Split(kernel, device, count, inputs, [], workers, covered)
    unique = list({id(t): t for t in targets}.values())  # one texture may feed several arguments
    private: list[tuple[wp.array, _Copy]] = []
    shared = [_texel_grads(inputs, texel_grads, {})]
    for worker in range(1, workers):
        copies = {id(t): _private(t, worker, tracked=id(t) in tracked) for t in unique}
        private += [(t, copies[id(t)]) for t in unique]
        shared.append(_texel_grads(inputs, texel_grads, copies))

    def run(worker: int, k: int) -> None:
        ins, _, dim = split.arguments(shared[worker], k)
        wp.launch(kernel, dim=dim, inputs=ins, device=device, record_tape=False)

    _run_private(split, run, private, entries)


def _texel_grads(inputs: list, positions: set, copies: dict) -> list:
    """``inputs`` with each array replaced by its copy in ``copies`` (by id) where it has one, and
    those at ``positions`` (``TexelGrad`` arguments) made :class:`TexelGrad` structs: the copy and
    its tiles, the real gradient untracked, or nothing (``None``: not needed)."""
    result = []
    for i, a in enumerate(inputs):
        copy = copies.get(id(a))
        if i in positions:
            grad = TexelGrad()
            grad.texels, grad.tiles = (copy.array, copy.tiles) if copy is not None else (a, None)
            result.append(grad)
        else:
            result.append(copy.array if copy is not None else a)
    return result


def _workers(device, count: int, threads: int | None) -> int:
    """Threads a launch of ``count`` pixels is split over: 1 on CUDA and for small launches."""
    threads = 1 if device.is_cuda else get_num_threads() if threads is None else threads
    return max(1, min(threads, count // MIN_PIXELS_PER_THREAD))


class _Split:
    """A launch cut into contiguous chunks, up to :data:`CHUNKS_PER_THREAD` per worker and as many
    for each (a worker whose chunks are cheap, e.g. sky pixels, takes more of them when they are
    handed out as workers finish), run by ``workers`` threads taking the next chunk.
    With a G-buffer's mask (``covered``), the chunks hold equal estimated costs (:func:`_bounds`)."""

    def __init__(self, kernel, device, count: int, inputs: list, outputs: list, workers: int, covered: wp.array | None = None):
        self.kernel, self.device, self.count, self.inputs, self.outputs, self.workers = kernel, device, count, inputs, outputs, workers
        # A whole number of chunks per worker: the backward's fixed order (see run) then gives
        # every worker the same share (3 chunks on 2 workers left one with twice the other's work).
        chunks = workers * max(1, min(count // (MIN_PIXELS_PER_THREAD * workers), CHUNKS_PER_THREAD))
        self.bounds = _bounds(count, chunks, covered)

    @property
    def chunks(self) -> int:
        return len(self.bounds) - 1

    def arguments(self, inputs: list, k: int):
        """``(inputs, outputs, dim)`` of chunk ``k``: per-pixel arrays sliced, the rest from ``inputs``."""
        lo, hi = self.bounds[k], self.bounds[k + 1]
        ins = [_chunk(a, lo, hi, self.count) for a in inputs]
        return ins, [o[lo:hi] for o in self.outputs], hi - lo

    def run(self, work, *, fixed: bool = False) -> None:
        """``work(worker, chunk)`` for every chunk; worker 0 is the calling thread. Workers take the
        next chunk as they finish one; with ``fixed``, worker ``w`` takes chunks ``w, w + workers,
        ...`` in order instead (interleaved, so each still gets a share of cheap and costly pixels):
        what accumulates into a worker's gradient arrays, and in what order, is then the same on
        every run, and so are the summed gradients, bit for bit."""
        counter = itertools.count()

        def loop(worker: int) -> None:
            if fixed:
                for k in range(worker, self.chunks, self.workers):
                    work(worker, k)
                return
            while (k := next(counter)) < self.chunks:  # itertools.count is thread-safe in CPython
                work(worker, k)

        futures = [_executor(self.workers - 1).submit(loop, w) for w in range(1, self.workers)]
        try:
            loop(0)
        finally:
            for f in futures:
                f.result()  # waits for every worker; re-raises a worker's exception here


def _bounds(count: int, chunks: int, covered: wp.array | None) -> list[int]:
    """The ``chunks + 1`` bounds of ``count`` pixels cut into ``chunks`` contiguous chunks: equal
    pixel counts, or, given the mask ``covered``, equal costs (a covered pixel costs 1, another
    :data:`UNCOVERED_COST`), cut at whole blocks of :data:`COVERAGE_BLOCK` pixels. Deterministic, so
    the backward pass's fixed order (see :meth:`_Split.run`) stays reproducible.

    The covered pixels of a block are counted as the sum of its mask, exact for the 0/1 masks the
    rasteriser and ``GBuffer.from_arrays`` write (and 2.5× faster than counting non-zeros: 1.3 ms
    for 4M pixels); other values only skew the estimate, never the result."""
    if covered is None or count < 2 * COVERAGE_BLOCK * chunks:
        return [count * k // chunks for k in range(chunks + 1)]
    mask = covered.numpy().reshape(-1)
    full = count // COVERAGE_BLOCK * COVERAGE_BLOCK
    shaded = mask[:full].reshape(-1, COVERAGE_BLOCK).sum(axis=1)
    sizes = np.full(len(shaded), float(COVERAGE_BLOCK))
    if full < count:
        shaded = np.append(shaded, mask[full:].sum())
        sizes = np.append(sizes, count - full)
    shaded = np.clip(np.nan_to_num(shaded), 0.0, sizes)
    cost = np.cumsum(shaded + UNCOVERED_COST * (sizes - shaded))
    ends = np.minimum((np.searchsorted(cost, cost[-1] * np.arange(1, chunks) / chunks) + 1) * COVERAGE_BLOCK, count)
    return sorted({0, count, *(int(e) for e in ends)})  # a chunk never empty (bounds distinct)


class _Copy(NamedTuple):
    """A worker's private accumulator for a gradient array: ``array``, zero outside the tiles
    marked in ``tiles`` (one flag per ``2**TILE_SHIFT`` entries; ``None``: not tracked, summed whole)."""

    array: wp.array
    tiles: wp.array | None


def _private(real: wp.array, worker: int, tracked: bool = False) -> _Copy:
    """Worker ``worker``'s private accumulator for the gradient array ``real``, zero: the one kept
    from the last backward pass when there is one (:func:`_add_private` zeroed it), else a new one
    (kept while ``real`` lives); with tile flags when ``tracked`` (a ``TexelGrad`` argument)."""
    copies = _private_arrays.setdefault(real, {})
    mine = copies.get(worker)
    if mine is None:  # keyed by the array itself, whose shape and dtype never change
        mine = copies[worker] = _Copy(wp.zeros_like(real), None)
    if not tracked:  # summed whole (its tiles, if any, stay clear: nothing marks them)
        return _Copy(mine.array, None)
    if mine.tiles is None:
        tiles = wp.zeros(-(-real.shape[0] // (1 << TILE_SHIFT)), dtype=wp.int32, device=real.device)
        mine = copies[worker] = _Copy(mine.array, tiles)
    return mine


def _run_private(split: _Split, work, private: list[tuple[wp.array, _Copy]], entries: dict | None = None) -> None:
    """``work(worker, chunk)`` for every chunk, in :meth:`_Split.run`'s fixed order, then the
    private accumulators of ``private`` added into the real gradients (and zeroed again; see
    :func:`_add_private` for ``entries``). A failure leaves them holding part of a pass: they are dropped (the
    next pass makes new ones)."""
    try:
        split.run(work, fixed=True)
        _add_private(private, split.workers, entries)
    except BaseException:
        for real, _ in private:
            _private_arrays.pop(real, None)
        raise


def _with_private_grads(a, private: list, worker: int):
    """``a`` with every array that has a gradient (also inside structs) replaced by a view of the
    same data whose gradient is ``worker``'s zeroed private accumulator, recorded in ``private``.

    Adjoint kernels accumulate into the ``grad`` of the *forward* arrays of struct fields (Warp
    ignores the adjoint struct there), so private accumulators must sit in the forward arguments.
    """
    if wp.types.is_array(a):
        if not a.grad:
            return a
        mine = _private(a.grad, worker)
        private.append((a.grad, mine))
        return wp.array(ptr=a.ptr, dtype=a.dtype, shape=a.shape, strides=a.strides, device=a.device, grad=mine.array)
    if wp.types.is_struct(a):
        copy = struct_like(a)
        for name, value in struct_fields(a).items():
            setattr(copy, name, _with_private_grads(value, private, worker))
        return copy
    return a


def _backward(tape, split: _Split) -> None:
    """The adjoints of a split launch, run by the same workers: worker 0 accumulates into the real
    gradients, the others into private copies of the shared ones, added in at the end (summed
    whole: Warp's generated adjoints do not mark tiles)."""
    for a in split.inputs:  # registers the real gradients with the tape (for tape.zero()), as a recorded launch does
        tape.get_adjoint(a.array if isinstance(a, PerPixel) else a)
    private: list[tuple[wp.array, _Copy]] = []  # (real gradient, a worker's private one)
    shared = [split.inputs] + [[a if isinstance(a, PerPixel) else _with_private_grads(a, private, w) for a in split.inputs] for w in range(1, split.workers)]

    def backward(worker: int, k: int) -> None:
        ins, outs, dim = split.arguments(shared[worker], k)
        adj_ins = [tape.get_adjoint(a) for a in ins]
        wp.launch(split.kernel, dim=dim, inputs=ins, outputs=outs, adj_inputs=adj_ins, adj_outputs=[o.grad for o in outs], device=split.device, adjoint=True)

    _run_private(split, backward, private)


class _Sum(NamedTuple):
    """One real gradient (flat NumPy view) and what is added into it: each private copy (flat) with
    the runs ``(start, stop)`` of tiles where it may be non-zero, in worker order."""

    target: np.ndarray
    tile: int  # scalars per tile
    sources: list


def _tiles_reached(marks: np.ndarray) -> np.ndarray:
    """Which tiles a copy's ``TexelGrad.tiles`` marks reach: ``marks[t] = k`` reaches tiles ``t``
    to ``t + k - 1``."""
    index = np.arange(len(marks))
    return np.maximum.accumulate(np.where(marks > 0, index + marks, 0)) > index


def _add_private(private: list[tuple[wp.array, _Copy]], workers: int, entries: dict | None = None) -> None:
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
    for real, mine in {id(mine.array): (real, mine) for real, mine in private}.values():
        target, source = real.numpy(), mine.array.numpy()  # CPU arrays: views of the same memory
        marked = None if mine.tiles is None else _tiles_reached(mine.tiles.numpy())
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

    _side_by_side(add, parts)


def _side_by_side(work, parts: int) -> None:
    """``work(part)`` for ``part`` in ``0 .. parts - 1``, part 0 on this thread, the others on the
    pool; returns when all are done (re-raising the first failure)."""
    futures = [_executor(parts - 1).submit(work, part) for part in range(1, parts)]
    try:
        work(0)
    finally:
        for f in futures:
            f.result()


def zero(array: wp.array) -> None:
    """``array.zero_()``; on the CPU, a contiguous array of :data:`PARALLEL_SUM_BYTES` or more is
    zeroed in ranges on :func:`get_num_threads` threads side by side (one core does not fill the
    memory bandwidth: a 22 MB texel gradient took 1.8 ms on one thread, 1.2 ms on two here)."""
    parts = get_num_threads() if array.device.is_cpu and array.is_contiguous and array.size * wp.types.type_size_in_bytes(array.dtype) >= PARALLEL_SUM_BYTES else 1
    if parts == 1:
        array.zero_()
        return
    flat = array.numpy().reshape(-1)

    def clear(part: int) -> None:
        flat[flat.size * part // parts : flat.size * (part + 1) // parts] = 0

    _side_by_side(clear, parts)
