"""Per-pixel kernel launches, split over CPU threads.

Warp runs a CPU launch on the calling thread, one kernel instance after another, and releases
the GIL while it runs. :func:`launch` therefore cuts the range of a per-pixel kernel into
contiguous chunks and launches them from a small thread pool at once, one chunk per thread, each
on views (slices) of the per-pixel arrays. Every pixel is computed by the same code from the same
inputs, so the result is bit-identical to a single launch.

Under a ``wp.Tape`` the chunks are recorded as separate launches; ``tape.backward()`` replays their
adjoints one after another on the calling thread (Warp's CPU atomics are not thread-safe, so
backward passes must not run concurrently). Gradients into shared arrays (texels, tiling) are
then summed in a different order than for one launch: equal to float rounding.

CUDA launches are never split: one launch fills the device.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import warp as wp

# Below this many pixels per thread, handing work to a thread costs more than it saves.
MIN_PIXELS_PER_THREAD = 16384

_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_num_threads: int | None = None


class PerPixel(NamedTuple):
    """A kernel argument indexed by the launch index along its first axis (sliced per chunk)."""

    array: wp.array | None


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


def launch(kernel, count: int, *, inputs: list, outputs: list, device, threads: int | None = None) -> None:
    """Launch a per-pixel ``kernel`` over ``count`` pixels, split over CPU threads.

    Args:
        kernel: a Warp kernel whose thread ``i`` reads and writes only entry ``i`` of its per-pixel
            arrays (and reads anything else).
        count: pixels to launch.
        inputs: the kernel's inputs; per-pixel arrays wrapped with :func:`per_pixel`.
        outputs: the kernel's outputs, all per-pixel arrays (first axis ``count``).
        device: the Warp device.
        threads: threads to use (default :func:`get_num_threads`); CUDA always uses one launch.
    """
    if count <= 0:
        return
    device = wp.get_device(device)
    threads = 1 if device.is_cuda else get_num_threads() if threads is None else threads
    chunks = max(1, min(threads, count // MIN_PIXELS_PER_THREAD))
    if chunks == 1:
        wp.launch(kernel, dim=count, inputs=[_chunk(a, 0, count, count) for a in inputs], outputs=outputs, device=device)
        return
    bounds = [count * k // chunks for k in range(chunks + 1)]
    for out in outputs:
        if out.shape[0] != count:
            raise RuntimeError(f"warptex internal error: an output has {out.shape[0]} rows for {count} pixels")

    def run(k: int) -> None:
        lo, hi = bounds[k], bounds[k + 1]
        wp.launch(kernel, dim=hi - lo, inputs=[_chunk(a, lo, hi, count) for a in inputs], outputs=[o[lo:hi] for o in outputs], device=device)

    futures = [_executor(chunks - 1).submit(run, k) for k in range(1, chunks)]
    run(0)
    for f in futures:
        f.result()  # re-raises a worker's exception here
