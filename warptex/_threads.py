"""CPU threads: how many, the pool they run on, and how a launch is cut into chunks for them.

Warp runs a CPU launch on the calling thread, one kernel instance after another, and releases the
GIL while it runs. warptex therefore cuts the range of a per-pixel kernel into contiguous chunks
(:class:`Split`) and runs them from a small thread pool (``warptex._launch``). CUDA launches are
never split: one launch fills the device.
"""

from __future__ import annotations

import ctypes
import itertools
import math
import os
import queue
import threading

import numpy as np
import warp as wp

from warptex.kernels.lanes import LANES

# Below this many pixels per thread, handing work to a thread costs more than it saves.
MIN_PIXELS_PER_THREAD = 16384
# A forward launch's chunks shrink as the launch goes (guided scheduling): each holds 1 / (2 ·
# workers) of the estimated cost left, down to 1 / (GUIDED_TAIL · workers) of the whole (or
# MIN_PIXELS_PER_THREAD pixels, the larger), and the rest is cut into equal chunks no larger, a
# whole number a worker. Threads take the next chunk as they finish one, so the last chunks, small,
# even out what the estimate misses (a splat's costs vary with its layers, not with the mask) and
# a core slower than the other (a shared host's second vCPU ran whole calls at 0.55x the first's
# pace). Each launch costs ~20 us of Python, partly under the GIL: a 1024² launch is cut into 12
# chunks on 2 workers, against 4 equal ones before (2 a thread, which measured 2-4% faster than 4
# on a host with equal cores). docs/performance.md, "Threads and speed", has the guided cut's figures.
GUIDED_TAIL = 16
# Where a G-buffer's mask is known (``covered``), chunks are cut by estimated cost rather than by
# pixel counts: a pixel it does not cover costs about this much of a covered one (the lane
# kernels, which skip lanes of sky: 0.10-0.11 for triplanar and splat4 on the benchmark's sphere and
# terrain) ...
UNCOVERED_COST = 0.1
# ... counted in blocks of this many pixels (a multiple of LANES: see bounds()).
COVERAGE_BLOCK = 1024
# A backward pass's chunks (:func:`grad_bounds`). Every chunk but the first costs adding its private
# gradients into the real ones, whatever the thread count: up to the whole shared gradient (a 1024²
# texture's mip chain, 21 MB: 2 ms) where its pixels read all of it, against the pixels' own cost,
# about their bilinear footprints. So a chunk holds one footprint per GRAD_BYTES_PER_FOOTPRINT bytes
# of shared gradient, MIN_GRAD_CHUNK_PIXELS to GRAD_CHUNK_PIXELS pixels, and there are at most
# MAX_GRAD_CHUNKS. (Measured on one thread, bilinear on a sphere at 1024², one footprint a pixel:
# chunks of 65 536 pixels cost 1.22× the time of one launch, of 131 072 1.16×, of 262 144 1.11×;
# the 330 000 these constants give, 1.05×. Triplanar's six footprints a pixel on the same texture
# give 55 000-pixel chunks: 1.06×, and four chunks of a 512² terrain to spread over the threads.)
GRAD_BYTES_PER_FOOTPRINT = 64
MIN_GRAD_CHUNK_PIXELS = 16384
GRAD_CHUNK_PIXELS = 1 << 19
MAX_GRAD_CHUNKS = 16
# Zeroing arrays smaller than this stays on one thread (Warp's memset). Measured on 2 threads
# (2026-11-28, best of 30, interleaved): Warp's zero_() against a memset of each half on its own
# thread took 15 / 46-67 µs at 1 MB, 48 / 77-98 µs at 4 MB, 206-453 / 132-233 µs at 16 MB and
# 871-874 / 992-1032 µs at 64 MB (the bandwidth's limit either way). NumPy's fill of each half,
# the clear before, was the slowest at every size (82, 148, 391 and 2140 µs).
PARALLEL_ZERO_BYTES = 8 << 20

# The pool: threads that take (work, part, done, failures) from _tasks (side_by_side). A plain
# queue and a lock per part, not concurrent.futures: handing out a part and waiting for it took
# ~100 us of Python on cold caches with an executor's futures, ~75 with these (the rest is the
# system waking a thread).
_lock = threading.Lock()
_tasks: queue.SimpleQueue = queue.SimpleQueue()
_started = 0
_worker_ids: list = []  # the pool threads' native ids
_kept_off = -1  # the CPU they are kept off (_keep_workers_off_this_cpu), -1 for none
_num_threads: int | None = None


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


def _worker() -> None:
    while True:
        _run_task(*_tasks.get())  # a function call: nothing of a task outlives it (its arrays)


def _run_task(work, part: int, done: threading.Lock, failures: list) -> None:
    try:
        work(part)
    except BaseException as error:  # re-raised by side_by_side() on the thread that handed it out
        failures.append(error)
    finally:
        done.release()


def _start_workers(count: int) -> None:
    """At least ``count`` pool threads (daemons: they only run work a caller waits for)."""
    global _started, _kept_off
    with _lock:
        while _started < count:
            thread = threading.Thread(target=_worker, name=f"warptex-{_started + 1}", daemon=True)
            thread.start()
            _worker_ids.append(thread.native_id)
            _started += 1
            _kept_off = -1  # the new thread is kept off the caller's CPU too (side_by_side)


def _sched_getcpu():
    """libc's ``sched_getcpu`` (the CPU the calling thread runs on), or ``None`` where there is none."""
    try:
        getcpu = ctypes.CDLL(None, use_errno=True).sched_getcpu
    except (AttributeError, OSError):
        return None
    getcpu.restype, getcpu.argtypes = ctypes.c_int, []
    return getcpu


_getcpu = _sched_getcpu() if hasattr(os, "sched_setaffinity") else None


def _keep_workers_off_this_cpu() -> None:
    """Let the pool threads run anywhere this thread may but on the CPU it runs on now.

    Linux wakes a sleeping thread on the waker's CPU when that looks cheap (wake-affine), and after
    the pool has idled a while (a fit doing other work between calls) it did so here: the worker
    then shared the caller's core for whole calls, and a 2-thread bilinear lookup on the benchmark
    sphere took 2.2-2.6 ms a call instead of 1.6-1.7 (1 thread: 3.1). Dr.Jit's pool spins between
    tasks and keeps its cores; this costs a system call only when the caller moves to another CPU."""
    global _kept_off
    cpu = _getcpu() if _getcpu is not None else -1
    if cpu < 0 or cpu == _kept_off:
        return
    try:
        others = os.sched_getaffinity(0) - {cpu}
        if others:
            for worker in _worker_ids:
                os.sched_setaffinity(worker, others)
    except OSError:  # a CPU set that changed under us: leave the threads where they are
        return
    _kept_off = cpu


def _after_fork() -> None:  # a forked child has none of the parent's threads
    global _lock, _tasks, _started, _kept_off
    _lock, _tasks, _started, _kept_off = threading.Lock(), queue.SimpleQueue(), 0, -1
    _worker_ids.clear()


os.register_at_fork(after_in_child=_after_fork)


def interruptible(name: str, call, *args, **kwargs):
    """``call(*args, **kwargs)``, run on a daemon thread ``name`` while this one waits for it: a
    Ctrl-C (or SIGTERM's :class:`~warptex.apps.distributed.Terminated`) is raised here at once,
    where a call that blocks in native code (Warp's compile pool, torch.distributed's rendezvous)
    would hold it until it returns. The call's own error is raised here; an interrupted call runs
    on in the background (the command line then ends the process)."""
    done, result = threading.Event(), []

    def run() -> None:
        try:
            result.append((True, call(*args, **kwargs)))
        except BaseException as err:  # re-raised on the waiting thread
            result.append((False, err))
        finally:
            done.set()

    threading.Thread(target=run, name=name, daemon=True).start()
    done.wait()
    ok, value = result[0]
    if not ok:
        raise value
    return value


def never_split(device, count: int) -> bool:
    """Whether a launch of ``count`` pixels runs unsplit whatever the thread settings: on CUDA,
    and a small launch on the CPU."""
    return device.is_cuda or count < 2 * MIN_PIXELS_PER_THREAD


def workers_for(device, count: int, threads: int | None) -> int:
    """Threads a launch of ``count`` pixels is split over: 1 on CUDA and for small launches
    (decided first: a small call does not pay for reading the thread settings)."""
    if never_split(device, count):
        return 1
    threads = get_num_threads() if threads is None else threads
    return max(1, min(threads, count // MIN_PIXELS_PER_THREAD))


class Split:
    """``count`` pixels cut into contiguous chunks that shrink towards the end (:data:`GUIDED_TAIL`),
    run by ``workers`` threads taking the next chunk as they finish one. With a G-buffer's mask
    (``covered``), the chunks' sizes are shares of the estimated cost (:func:`bounds`). For a
    forward launch, whose pixels are independent: a backward pass cuts its chunks by the pixels
    alone (:func:`grad_bounds`)."""

    def __init__(self, count: int, workers: int, covered: wp.array | None = None):
        self.count, self.workers = count, workers
        cuts = guided_cuts(workers, max(MIN_PIXELS_PER_THREAD / max(count, 1), 1.0 / (GUIDED_TAIL * workers)))
        self.bounds = bounds(count, len(cuts) + 1, covered, cuts)

    @property
    def chunks(self) -> int:
        return len(self.bounds) - 1

    def span(self, k: int) -> tuple[int, int]:
        """The pixels ``[lo, hi)`` of chunk ``k``."""
        return self.bounds[k], self.bounds[k + 1]

    def run(self, work) -> None:
        """``work(worker, chunk)`` for every chunk; worker 0 is the calling thread. Workers take the
        next chunk as they finish one."""
        counter = itertools.count()

        def loop(worker: int) -> None:
            while (k := next(counter)) < self.chunks:  # itertools.count is thread-safe in CPython
                work(worker, k)

        side_by_side(loop, self.workers)


def grad_bounds(count: int, covered: wp.array | None = None, shared_bytes: int | None = None, footprints: int = 1) -> list[int]:
    """The chunks of a backward pass over ``count`` pixels (see ``warptex._accumulate``): fixed by
    the pixels, the size of the gradients they share (``shared_bytes``; ``None``: large) and the
    bilinear footprints a pixel reads (``footprints``), never by the thread count, so that shared
    gradients are summed in the same order whatever runs them. A footprint per
    :data:`GRAD_BYTES_PER_FOOTPRINT` bytes of shared gradient each, :data:`MIN_GRAD_CHUNK_PIXELS`
    to :data:`GRAD_CHUNK_PIXELS` pixels, at most :data:`MAX_GRAD_CHUNKS`, cut to equal costs where
    the mask ``covered`` is known (:func:`bounds`)."""
    pixels = GRAD_CHUNK_PIXELS if shared_bytes is None else min(max(shared_bytes // (GRAD_BYTES_PER_FOOTPRINT * max(1, footprints)), MIN_GRAD_CHUNK_PIXELS), GRAD_CHUNK_PIXELS)
    return bounds(count, max(1, min(count // pixels, MAX_GRAD_CHUNKS)), covered)


def guided_cuts(workers: int, smallest: float) -> list[float]:
    """The cuts (shares of the whole, increasing, in (0, 1)) of a launch's chunks for ``workers``
    taking them in turn: each chunk ``1 / (2 · workers)`` of what is left, while that is at least
    ``smallest``; the rest in equal chunks of at most ``smallest``, as many as a whole number a
    worker allows."""
    cuts, done = [], 0.0
    while (1.0 - done) / (2 * workers) >= smallest:
        done += (1.0 - done) / (2 * workers)
        cuts.append(done)
    tail = workers * math.ceil((1.0 - done) / (smallest * workers) - 1e-9)
    cuts += [done + (1.0 - done) * k / tail for k in range(1, tail)]
    return cuts


def bounds(count: int, chunks: int, covered: wp.array | None, cuts: list[float] | None = None) -> list[int]:
    """The bounds of ``count`` pixels cut into ``chunks`` contiguous chunks of equal pixel counts,
    or, given the mask ``covered``, equal costs (a covered pixel costs 1, another
    :data:`UNCOVERED_COST`), cut at whole blocks of :data:`COVERAGE_BLOCK` pixels; given ``cuts``
    (``chunks - 1`` shares of the whole, increasing, :func:`guided_cuts`), cut there rather than
    into equal chunks. Every cut is a multiple of :data:`~warptex.kernels.lanes.LANES`, so that a lane
    kernel's lanes never straddle two chunks (fewer chunks where ``count`` is too small for that).
    Deterministic: a function of the pixels, the mask and the cuts alone.

    The covered pixels of a block are counted as the sum of its mask, exact for the 0/1 masks the
    rasteriser and ``GBuffer.from_arrays`` write (and 2.5× faster than counting non-zeros: 1.3 ms
    for 4M pixels); other values only skew the estimate, never the result."""
    if covered is None or count < 2 * COVERAGE_BLOCK * chunks:
        ends = [int(count * f) for f in cuts] if cuts is not None else [count * k // chunks for k in range(1, chunks)]
        return sorted({0, count, *(e // LANES * LANES for e in ends)})
    mask = covered.numpy().reshape(-1)
    full = count // COVERAGE_BLOCK * COVERAGE_BLOCK
    shaded = mask[:full].reshape(-1, COVERAGE_BLOCK).sum(axis=1)
    sizes = np.full(len(shaded), float(COVERAGE_BLOCK))
    if full < count:
        shaded = np.append(shaded, mask[full:].sum())
        sizes = np.append(sizes, count - full)
    shaded = np.clip(np.nan_to_num(shaded), 0.0, sizes)
    cost = np.cumsum(shaded + UNCOVERED_COST * (sizes - shaded))
    targets = cost[-1] * np.asarray(cuts, dtype=np.float64) if cuts is not None else cost[-1] * np.arange(1, chunks) / chunks
    ends = np.minimum((np.searchsorted(cost, targets) + 1) * COVERAGE_BLOCK, count)
    return sorted({0, count, *(int(e) for e in ends)})  # a chunk never empty (bounds distinct)


def side_by_side(work, parts: int) -> None:
    """``work(part)`` for ``part`` in ``0 .. parts - 1``, part 0 on this thread, the others on the
    pool; returns when all are done, re-raising a failure (this thread's first)."""
    if parts > 1:
        _start_workers(parts - 1)
        _keep_workers_off_this_cpu()
    failures: list = []
    waits = []
    for part in range(1, parts):
        done = threading.Lock()
        done.acquire()
        _tasks.put((work, part, done, failures))
        waits.append(done)
    try:
        work(0)
    finally:
        for done in waits:
            done.acquire()
    if failures:
        raise failures[0]


def rows_side_by_side(rows: int, work, device, kernels=()) -> None:
    """``work(a, b)`` over rows ``0 .. rows`` cut into one range per CPU thread, side by side: for
    the kernels that compute each pixel (or texel) on its own from its row, the rasteriser's and
    the bake's, which Warp runs on one thread a launch; the ranges give one launch's bits. One
    range on a GPU, or for fewer than 64 rows. ``kernels``: those ``work`` launches, whose modules
    are loaded first (``warptex._compile.load_first``)."""
    parts = 1 if not wp.get_device(device).is_cpu or rows < 64 else min(get_num_threads(), rows // 32)
    if parts > 1:
        from warptex._compile import load_first  # _compile imports this module

        load_first(kernels, device)
    bounds = [rows * k // parts for k in range(parts + 1)]
    side_by_side(lambda part: work(bounds[part], bounds[part + 1]), parts)


def zero(array: wp.array) -> None:
    """``array.zero_()``; on the CPU, a contiguous array of :data:`PARALLEL_ZERO_BYTES` or more is
    cleared by a ``memset`` of a range per thread (:func:`get_num_threads`), side by side (ctypes
    lets go of the GIL for the call)."""
    nbytes = array.size * wp.types.type_size_in_bytes(array.dtype)
    parts = get_num_threads() if array.device.is_cpu and array.is_contiguous and nbytes >= PARALLEL_ZERO_BYTES else 1
    if parts == 1:
        array.zero_()
        return
    bounds = [nbytes * part // parts // 64 * 64 for part in range(parts)] + [nbytes]  # cache-line aligned cuts
    side_by_side(lambda part: ctypes.memset(array.ptr + bounds[part], 0, bounds[part + 1] - bounds[part]), parts)
