"""Per-pixel arrays on the CPU are made from blocks kept once freed (``warptex._memory``): the next
array of a freed block's byte size takes it, the kept bytes stay within their budget, and a lookup's
output on a kept block costs no page faults."""

import multiprocessing
import os
import threading

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex import _memory

MB = 1 << 20


@pytest.fixture
def kept(monkeypatch):
    """An empty set of kept blocks for the test (the blocks it frees are given back after it), and
    the blocks given back to the system, as ``(bytes, address)``."""
    freed = []
    free = _memory._free
    monkeypatch.setattr(_memory, "_spares", [])
    monkeypatch.setattr(_memory, "_free", lambda address, nbytes: (freed.append((nbytes, address)), free(address, nbytes)))
    yield freed
    _memory.release()


def test_a_freed_block_is_taken_by_the_next_array_of_its_byte_size(kept):
    a = _memory.empty((MB, 2), float, "cpu")  # 8 MB
    a.fill_(3.0)
    address = a.ptr
    del a
    assert _memory._spares == [(8 * MB, address)] and _memory.spare_bytes() == 8 * MB
    other = _memory.empty((MB,), float, "cpu")  # 4 MB: not that block
    assert other.ptr != address and _memory._spares == [(8 * MB, address)]
    b = _memory.empty((MB // 2,), wp.vec4, "cpu")  # 8 MB again, of another dtype and shape
    assert b.ptr == address and _memory._spares == [] and b.shape == (MB // 2,) and b.dtype == wp.vec4
    assert b.numpy()[0, 0] == 3.0  # uninitialised, as wp.empty: what the block last held
    c = _memory.empty((MB // 2,), wp.vec4, "cpu")  # none kept while b lives: a block of its own
    assert c.ptr != address
    del b, c, other
    assert sorted(n for n, _ in _memory._spares) == [4 * MB, 8 * MB, 8 * MB] and kept == []


def test_small_arrays_and_gpu_arrays_are_warps_own(kept):
    small = _memory.empty((_memory.MIN_BYTES // 4 - 1,), float, "cpu")
    assert small.deleter is not _memory._give_back
    del small
    assert _memory._spares == []
    big = _memory.empty((_memory.MIN_BYTES // 4,), float, "cpu")
    assert big.deleter is _memory._give_back


def test_kept_blocks_stay_within_their_budget_newest_kept(kept, monkeypatch):
    monkeypatch.setattr(_memory, "SPARE_BYTES", 12 * MB)
    arrays = [_memory.empty((MB * k,), float, "cpu") for k in (1, 2, 1)]  # 4, 8, 4 MB
    addresses = [a.ptr for a in arrays]
    while arrays:
        a = arrays.pop(0)
        del a
    assert _memory._spares == [(8 * MB, addresses[1]), (4 * MB, addresses[2])]  # 16 MB: the oldest went
    assert kept == [(4 * MB, addresses[0])]
    huge = _memory.empty((4 * MB,), float, "cpu")  # 16 MB: more than the budget alone
    address = huge.ptr
    del huge
    assert _memory._spares == [] and kept == [(4 * MB, addresses[0]), (8 * MB, addresses[1]), (4 * MB, addresses[2]), (16 * MB, address)]
    a = _memory.empty((MB,), float, "cpu")
    address = a.ptr
    del a
    _memory.release()
    assert _memory._spares == [] and kept[-1] == (4 * MB, address)


def test_the_newest_block_of_a_size_is_taken_first(kept):
    first, second = _memory.empty((MB,), float, "cpu"), _memory.empty((MB,), float, "cpu")
    newer = second.ptr
    del first
    del second
    assert _memory.empty((MB,), float, "cpu").ptr == newer


@pytest.mark.skipif(not hasattr(os, "register_at_fork"), reason="no fork on this platform")
def test_a_child_forked_while_the_lock_was_held_can_allocate():
    held, release = threading.Event(), threading.Event()

    def hold():
        with _memory._lock:
            held.set()
            release.wait(30)

    holder = threading.Thread(target=hold)
    holder.start()
    held.wait(30)
    try:
        with multiprocessing.get_context("fork").Pool(1) as pool:
            assert pool.apply_async(_allocate_in_child).get(timeout=120)  # hung on the parent's held lock before
    finally:
        release.set()
        holder.join()


def _allocate_in_child() -> bool:
    a = _memory.empty((MB // 2,), float, "cpu")
    del a
    return _memory.spare_bytes() >= 0


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="page-fault counts need Linux")
def test_a_lookup_on_a_kept_block_costs_no_page_faults(kept):
    """The reason for the blocks: a 16 MB output on fresh memory costs 4096 page faults (4-5 ms on
    a VM), on a kept block none; and the output is the same."""
    import resource

    rng = np.random.default_rng(0)
    tex = wt.Texture(rng.random((64, 64, 4), dtype=np.float32), mipmaps=False)
    uv = wp.array(rng.uniform(-2, 3, (1 << 20, 2)).astype(np.float32), dtype=wp.vec2)
    first = wt.sample(tex, uv)
    want, address = first.numpy().copy(), first.ptr
    del first
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    again = wt.sample(tex, uv)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
    assert again.ptr == address and np.array_equal(again.numpy(), want)
    assert faults < 256, faults  # 16 MB on fresh pages: 4096
