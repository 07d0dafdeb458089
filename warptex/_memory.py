"""Host memory for per-pixel arrays, kept for the next array of the same size once freed.

A lookup of a million pixels writes a 16 MB output. Where that memory comes fresh from the system,
the first write to each 4 KB page is a page fault, and on this VM the 4096 faults of 16 MB cost
4-5 ms: more than half of a two-thread bilinear lookup at random UVs. glibc's ``malloc`` gives a
freed block of that size back to the system, or places the next one past it, often enough that 5
to 10 calls in 40 of a plain loop of lookups and gradient passes paid them (measured).

So on the CPU, :func:`empty` makes outputs and other per-call arrays of :data:`MIN_BYTES` or more
from blocks kept here: a Warp array over a block hands it back when it is freed (its ``deleter``),
and the next array of that exact byte size takes it, with no page faults. Blocks are kept newest
first, up to :data:`SPARE_BYTES` together; an older one past that goes back to the system. Dr.Jit's
allocator keeps its own blocks the same way. The memory holds whatever its last array held, as
``wp.empty``'s does. Smaller arrays, and arrays on a GPU (Warp's memory pool), are Warp's own.
"""

from __future__ import annotations

import math
import os
import threading

import warp as wp

MIN_BYTES = 1 << 20
"""Arrays this size or larger are made from kept blocks (smaller ones cost no faults worth it)."""

SPARE_BYTES = 256 << 20
"""The most bytes kept in freed blocks together."""

_spares: list[tuple[int, int]] = []  # (bytes, address) of each freed block, oldest first
_lock = threading.Lock()


def empty(shape, dtype, device) -> wp.array:
    """An uninitialised array of ``shape`` (an int or a tuple of ints) and ``dtype`` on ``device``,
    on a kept block of its size where there is one (CPU, :data:`MIN_BYTES` or more)."""
    nbytes = (math.prod(shape) if isinstance(shape, (tuple, list)) else shape) * wp.types.type_size_in_bytes(dtype)
    if nbytes < MIN_BYTES:  # first: a small lookup's call pays for nothing more
        return wp.empty(shape, dtype=dtype, device=device)
    device = wp.get_device(device)
    if not device.is_cpu:
        return wp.empty(shape, dtype=dtype, device=device)
    address = _take(nbytes)
    if address is None:
        address = device.get_allocator().allocate(nbytes)
    return wp.array(ptr=address, dtype=dtype, shape=shape, capacity=nbytes, device=device, deleter=_give_back)


def spare_bytes() -> int:
    """The bytes kept in freed blocks now."""
    with _lock:
        return sum(n for n, _ in _spares)


def release() -> None:
    """Give every kept block back to the system."""
    with _lock:
        blocks = _spares[:]
        _spares.clear()
    for nbytes, address in blocks:
        _free(address, nbytes)


def _take(nbytes: int) -> int | None:
    with _lock:
        for k in range(len(_spares) - 1, -1, -1):  # the newest first: likelier still in the caches
            if _spares[k][0] == nbytes:
                return _spares.pop(k)[1]
    return None


def _give_back(address: int, nbytes: int) -> None:
    """The ``deleter`` of :func:`empty`'s arrays (Warp passes the array's address and capacity)."""
    try:
        with _lock:
            _spares.append((nbytes, address))
            gone = []
            while sum(n for n, _ in _spares) > SPARE_BYTES:
                gone.append(_spares.pop(0))
        for n, a in gone:
            _free(a, n)
    except Exception:  # noqa: BLE001 (at interpreter exit the module may be gone: the system takes the memory back)
        pass


def _free(address: int, nbytes: int) -> None:
    wp.get_device("cpu").get_allocator().deallocate(address, nbytes)


def trim() -> None:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim``; nothing elsewhere).

    A tiled job frees a tile's NumPy arrays before it makes the next one's. glibc serves blocks
    below its mmap threshold from the heap, raises that threshold each time it frees a larger
    mapped block, and returns freed heap memory only from the heap's top, so without this a job's
    resident memory grew by a third of a tile's over its first tiles (measured: 464 MB between
    tiles with it, 600-700 MB without, ``warptex render`` at 2048²)."""
    if _malloc_trim is not None:
        _malloc_trim(0)


def _libc_malloc_trim():
    try:
        import ctypes

        return ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):  # not glibc
        return None


_malloc_trim = _libc_malloc_trim()


def _after_fork() -> None:  # a lock held by another thread at the fork would never be released in the child
    global _lock
    _lock = threading.Lock()


os.register_at_fork(after_in_child=_after_fork)
