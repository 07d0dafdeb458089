"""Per-pixel kernel launches, split over CPU threads.

Warp runs a CPU launch on the calling thread, one kernel instance after another, and releases
the GIL while it runs. :func:`launch` therefore cuts the range of a per-pixel kernel into
contiguous chunks and launches them from a small thread pool at once, one chunk per thread, each
on views (slices) of the per-pixel arrays. Every pixel is computed by the same code from the same
inputs, so the result is bit-identical to a single launch.

Under a ``wp.Tape`` the split launch is recorded as one backward step that runs the chunks'
adjoint launches concurrently too. Warp's CPU atomics are plain read-modify-writes, so two
adjoints must never accumulate into one array: every chunk but the first gets private, zeroed
gradient arrays for the arrays it shares with the others (texels, tiling, ...; per-pixel arrays
are disjoint slices already), and those are added into the real gradients once all chunks are
done. Gradients are therefore summed in a different order than for one launch: equal to float
rounding.

CUDA launches are never split: one launch fills the device.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np
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
    for out in outputs:
        if out.shape[0] != count:
            raise RuntimeError(f"warptex internal error: an output has {out.shape[0]} rows for {count} pixels")
    bounds = [count * k // chunks for k in range(chunks + 1)]
    tape = _active_tape()
    track = tape is not None and any(o.requires_grad for o in outputs)
    private: list[tuple[wp.array, wp.array]] = []  # (real gradient, a chunk's private one)
    parts = []
    for k, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        ins = [_chunk(a, lo, hi, count) if isinstance(a, PerPixel) or not (track and k) else _with_private_grads(a, private) for a in inputs]
        parts.append((ins, [o[lo:hi] for o in outputs], hi - lo))

    def forward(part) -> None:
        ins, outs, dim = part
        wp.launch(kernel, dim=dim, inputs=ins, outputs=outs, device=device, record_tape=False)

    _run_all(forward, parts)
    if track:
        originals = [a.array if isinstance(a, PerPixel) else a for a in inputs]
        tape.record_func(lambda: _backward(tape, kernel, device, parts, originals, private), arrays=[o for o in outputs if o.requires_grad])


def _run_all(work, parts) -> None:
    """``work(part)`` for every part, the first on the calling thread, the others in the pool."""
    futures = [_executor(len(parts) - 1).submit(work, p) for p in parts[1:]]
    work(parts[0])
    for f in futures:
        f.result()  # re-raises a worker's exception here


def _active_tape():
    return wp._src.context.runtime.tape


def _with_private_grads(a, private: list):
    """``a`` with every array that has a gradient (also inside structs) replaced by a view of the
    same data whose gradient is a fresh zeroed array, recorded in ``private``.

    Adjoint kernels accumulate into the ``grad`` of the *forward* arrays of struct fields (Warp
    ignores the adjoint struct there), so private accumulators must sit in the forward arguments.
    """
    if wp._src.types.is_array(a):
        if not a.grad:
            return a
        mine = wp.zeros_like(a.grad)
        private.append((a.grad, mine))
        return wp.array(ptr=a.ptr, dtype=a.dtype, shape=a.shape, strides=a.strides, device=a.device, grad=mine)
    if wp._src.types.is_struct(a):
        copy = a._cls()
        for name, _ in a._cls.ctype._fields_:
            if not name.startswith("_"):
                setattr(copy, name, _with_private_grads(getattr(a, name), private))
        return copy
    return a


def _backward(tape, kernel, device, parts, originals, private) -> None:
    """The adjoints of a split launch, run concurrently; the private gradients of chunks 1... are
    then added into the real ones and zeroed (so a second ``tape.backward()`` adds them again)."""
    for a in originals:  # registers the real gradients with the tape (for tape.zero()), as a recorded launch does
        tape.get_adjoint(a)
    adjoints = [[tape.get_adjoint(a) for a in ins] for ins, _, _ in parts]

    def backward(k: int) -> None:
        ins, outs, dim = parts[k]
        wp.launch(kernel, dim=dim, inputs=ins, outputs=outs, adj_inputs=adjoints[k], adj_outputs=[o.grad for o in outs], device=device, adjoint=True)

    _run_all(backward, list(range(len(parts))))
    for grad, mine in private:
        target = grad.numpy()  # CPU arrays: views of the same memory
        target += mine.numpy()
        mine.zero_()
