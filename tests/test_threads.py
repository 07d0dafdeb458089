"""Per-pixel launches split over CPU threads: identical results, gradients through private
accumulators added tile by tile, validation. That gradients are the same bits at any thread count is
``test_same_bits.py``'s."""

import ctypes
import functools
import gc
import multiprocessing
import os
import subprocess
import sys
import threading
import weakref

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from conftest import triplanar_backward
from warptex import _accumulate, _launch, _op, _threads
from warptex.kernels.lanes import LANES
from warptex.kernels.texels import TILE_SHIFT


@pytest.fixture
def threads():
    """Run with the given thread count, then restore the default."""
    yield wt.set_num_threads
    wt.set_num_threads(None)


@pytest.fixture
def chunks(monkeypatch):
    """``chunks(pixels)``: cut backward passes into chunks of ``pixels`` (``GRAD_CHUNK_PIXELS``)."""
    return lambda pixels: (monkeypatch.setattr(_threads, "GRAD_CHUNK_PIXELS", pixels), monkeypatch.setattr(_threads, "MIN_GRAD_CHUNK_PIXELS", pixels))


@functools.lru_cache(maxsize=None)
def _sphere():
    """A 256² sphere G-buffer with UVs (65 536 pixels: four chunks of the minimum size)."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, :2] * 0.5 + 0.5)
    return wt.rasterize(mesh, wt.orthographic((0, 0, 5), (0, 0, 0), height=2.2, resolution=(256, 256)))


def _texture(seed=0, requires_grad=False):
    return wt.Texture(np.random.default_rng(seed).random((64, 64, 4)).astype(np.float32), requires_grad=requires_grad)


def _uv(n=70000):
    return np.random.default_rng(1).uniform(-3, 3, (n, 2)).astype(np.float32)


TECHNIQUES = {
    "sample": lambda tex, g: wt.sample(tex, _uv(), lod=1.3),
    "stochastic": lambda tex, g: wt.stochastic(tex, _uv(), "hex", lod=0.7),
    "triplanar": lambda tex, g: wt.triplanar(g, tex, tiling=3.0),
    "splat": lambda tex, g: wt.splat(g, wt.TextureArray(np.stack([tex.numpy()] * 4) * np.float32([1, 0.5, 0.25, 2])[:, None, None, None]), np.random.default_rng(2).random((8, 8, 4)).astype(np.float32), tiling=2.0),
}


@pytest.mark.parametrize("technique", TECHNIQUES)
def test_threaded_launch_is_bit_identical(technique, threads):
    run = TECHNIQUES[technique]
    g, tex = _sphere(), _texture()
    threads(1)
    single = run(tex, g).numpy()
    threads(4)
    split = run(tex, g).numpy()
    np.testing.assert_array_equal(split, single)
    assert np.abs(single).sum() > 0


def test_threaded_launch_gives_the_same_gradients(threads):
    g = _sphere()
    weights = np.random.default_rng(3).random((256, 256, 4)).astype(np.float32)
    grads = []
    for n in (1, 4):
        threads(n)
        tex = _texture(requires_grad=True)
        tiling = wp.array([3.0], dtype=float, requires_grad=True)
        tape = triplanar_backward(g, tex, tiling, weights)
        split = [launch for launch in tape.launches if callable(launch) and launch.__qualname__ != "carry_mip_gradients.<locals>.backward"]  # (the mips' step)
        assert len(split) == 1  # one recorded step runs the adjoints of the chunks (4 of 16 384 pixels: a small texture)
        grads.append((tex.grad(), tiling.grad.numpy()))
    np.testing.assert_array_equal(grads[1][0], grads[0][0])
    np.testing.assert_array_equal(grads[1][1], grads[0][1])
    assert np.abs(grads[0][0]).sum() > 0 and grads[0][1][0] != 0


@wp.struct
class _Nothing:
    unused: wp.int32


@wp.struct
class _Values:
    x: wp.array(dtype=float)


def _values(x: wp.array):
    pixels = _Values()
    pixels.x = x
    return pixels


@wp.kernel
def _add_one(args: _Nothing, pixels: _Values, first: wp.int32, y: wp.array2d(dtype=float)):
    i = first + wp.tid()
    y[i, 0] = pixels.x[i] + 1.0


def test_small_launches_are_not_split():
    out = wp.zeros((100, 1), dtype=float)
    calls = []

    x = wp.array(np.arange(100, dtype=np.float32))
    original = _launch.replay  # an unsplit launch runs through a kept wp.Launch
    try:
        _launch.replay = lambda kernel, dim, *a: (kernel is _add_one and calls.append(dim), original(kernel, dim, *a))  # only ours: any other launch meanwhile is not this test's
        _launch.launch(_add_one, 100, args=_Nothing(), pixels=_values(x), out=out, device="cpu", threads=4)
    finally:
        _launch.replay = original
    assert calls == [100]
    np.testing.assert_array_equal(out.numpy()[:, 0], np.arange(100) + 1)


def test_bad_thread_counts_and_per_pixel_arrays_raise():
    with pytest.raises(ValueError, match=r"set_num_threads\(\): threads must be an int >= 1 or None, got 0"):
        wt.set_num_threads(0)
    with pytest.raises(ValueError, match=r"set_num_threads\(\): threads must be an int >= 1 or None, got 2.5"):
        wt.set_num_threads(2.5)
    with pytest.raises(RuntimeError, match=r"a per-pixel array has 10 rows for 40000 pixels"):
        _launch.launch(_add_one, 40000, args=_Nothing(), pixels=_values(wp.zeros(10, dtype=float)), out=wp.zeros((40000, 1), dtype=float), device="cpu", threads=2)


def test_thread_count_from_the_environment(monkeypatch):
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "3")
    assert wt.get_num_threads() == 3
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "many")
    with pytest.raises(ValueError, match=r"WARPTEX_NUM_THREADS must be an int >= 1, got 'many'"):
        wt.get_num_threads()
    monkeypatch.delenv("WARPTEX_NUM_THREADS")
    assert wt.get_num_threads() == _threads.cpu_count()


def test_threaded_backward_gives_per_pixel_and_struct_gradients(threads):
    """Per-pixel gradients (UVs, LODs) are disjoint slices: bit-identical. Splat-map texels and
    tiling (arrays inside structs) are summed from private copies: equal to rounding."""
    g = _sphere()
    uv_np, lod_np = _uv(), np.random.default_rng(4).uniform(0, 5, 70000).astype(np.float32)
    layers_np = np.random.default_rng(5).random((4, 16, 16, 4)).astype(np.float32)
    maps_np = np.random.default_rng(6).random((8, 8, 4)).astype(np.float32)
    results = []
    for n in (1, 4):
        threads(n)
        tex = _texture(requires_grad=True)
        uv = wp.array(uv_np, dtype=wp.vec2, requires_grad=True)
        lod = wp.array(lod_np, dtype=float, requires_grad=True)
        maps = wt.TextureArray(maps_np[None], mipmaps=False, requires_grad=True)
        tiling = wp.array([2.0, 1.5, 3.0, 0.5], dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            a = wt.sample(tex, uv, lod=lod)
            b = wt.splat(g, wt.TextureArray(layers_np), maps, tiling=tiling)
        a.grad.fill_(1.0)
        b.grad.fill_(1.0)
        tape.backward()
        results.append([uv.grad.numpy(), lod.grad.numpy(), tex.grad(), maps.grad(), tiling.grad.numpy()])
    single, split = results
    np.testing.assert_array_equal(split[0], single[0])
    np.testing.assert_array_equal(split[1], single[1])
    for got, want in zip(split[2:], single[2:]):
        scale = np.abs(want).max()
        assert scale > 0
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6 * scale)  # sums of cancelling terms, in another order


def test_a_second_backward_matches_a_single_launch(threads):
    """The private accumulators are emptied after each backward pass, so repeating
    ``tape.backward()`` and ``tape.zero()`` behave as they do for one Warp launch."""
    g = _sphere()
    results = []
    for n in (1, 4):
        threads(n)
        tex = _texture(requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = wt.triplanar(g, tex, tiling=3.0)
        out.grad.fill_(1.0)
        tape.backward()
        tape.backward()
        results.append(tex.grad().copy())
        tape.zero()
        assert not np.any(tex.grad())
    np.testing.assert_allclose(results[1], results[0], rtol=1e-5, atol=1e-6 * np.abs(results[0]).max())


def test_private_accumulators_are_kept_with_their_gradient(threads, chunks):
    """A backward pass of several chunks reuses the last one's private accumulators, zeroed (fresh
    ones cost page faults), through the hand-written scatter and the generated adjoint alike, and
    lets them go with the gradient they serve."""
    g = _sphere()
    chunks(8192)  # 8 chunks
    threads(1)
    want = []
    for generated in (False, True):  # hand-written texel gradient, then Warp's generated adjoint
        tex = _texture(requires_grad=True)
        tape = wp.Tape()
        with tape, _op.force_generated_adjoint(generated):
            out = wt.triplanar(g, tex, tiling=3.0)
        out.grad.fill_(1.0)
        tape.backward()
        want.append(tex.grad().copy())

    threads(4)
    tex = _texture(requires_grad=True)
    real = tex.view.texels.grad
    kept = []
    for k, generated in enumerate((False, False, True, True)):
        tape = wp.Tape()
        with tape, _op.force_generated_adjoint(generated):
            out = wt.triplanar(g, tex, tiling=3.0)
        out.grad.fill_(1.0)
        tape.backward()
        np.testing.assert_allclose(tex.grad(), want[k // 2], rtol=1e-5, atol=1e-6 * np.abs(want[k // 2]).max())
        kept.append(dict(_accumulate._private_arrays[real]))
        tex.zero_grad()
    slots = range(_accumulate.slot_count(8, min(4, _threads.cpu_count())))  # a backward pass runs on the cores at most
    assert set(kept[0]) == set(slots)
    assert all(kept[k][w].array is kept[0][w].array for k in range(4) for w in slots)

    gone = weakref.ref(kept[0][0].array)
    del tex, real, kept, tape, out
    gc.collect()
    assert gone() is None


@wp.kernel
def _first_column_only(args: _Nothing, pixels: _Values, first: wp.int32, out: wp.array2d(dtype=float)):
    out[first + wp.tid(), 0] = 1.0


@pytest.mark.parametrize("n", [1, 4])
def test_a_launch_zeroes_its_new_outputs_and_their_gradients(n, threads):
    """Outputs from ``_launch.output`` hold whatever memory they got (here NaN); the launch zeroes
    them and their gradients chunk by chunk, so what a kernel leaves alone reads 0."""
    threads(n)
    out = _launch.output((70000, 2), float, "cpu", requires_grad=True)
    out.fill_(np.nan)
    out.grad.fill_(np.nan)
    _launch.launch(_first_column_only, 70000, args=_Nothing(), pixels=_values(wp.empty(0, dtype=float)), out=out, device="cpu")
    np.testing.assert_array_equal(out.numpy(), np.float32([1, 0]) * np.ones((70000, 1), np.float32))
    np.testing.assert_array_equal(out.grad.numpy(), 0)


def test_chunks_hold_equal_costs_of_covered_pixels():
    """Over a G-buffer, chunks are cut at equal estimated costs (a pixel the mask leaves out costs
    UNCOVERED_COST), not equal pixel counts: a view whose top half is sky would otherwise give the
    threads that take its first chunks almost nothing to do. Deterministic, never an empty chunk."""
    count, chunks = 1 << 17, 8
    mask = np.zeros(count, np.float32)
    mask[count // 2 :] = 1.0
    mask[count // 2 : count // 2 + 5000 : 7] = 0.0  # a ragged edge
    bounds = _threads.bounds(count, chunks, wp.array(mask))
    assert bounds == _threads.bounds(count, chunks, wp.array(mask))
    assert bounds[0] == 0 and bounds[-1] == count and len(bounds) == chunks + 1 and (np.diff(bounds) > 0).all()
    shaded = np.float64(mask != 0)
    cost = shaded + _threads.UNCOVERED_COST * (1 - shaded)
    costs = np.array([cost[a:b].sum() for a, b in zip(bounds[:-1], bounds[1:])])
    assert np.abs(costs - cost.sum() / chunks).max() <= _threads.COVERAGE_BLOCK  # cut at whole blocks
    assert bounds[1] > count // 4  # the sky's pixels go to few chunks
    even = [count * k // chunks for k in range(chunks + 1)]
    assert _threads.bounds(count, chunks, None) == even
    assert _threads.bounds(count, chunks, wp.array(np.ones(count, np.float32))) == even
    assert _threads.bounds(count, chunks, wp.zeros(count, dtype=float)) == even  # all sky: all alike
    assert _threads.bounds(count, chunks, wp.array(np.full(count, np.nan, np.float32))) == even  # never NaN bounds
    odd = _threads.bounds(count, chunks, wp.array(mask * 5.0 - 1.0))  # not a 0/1 mask: still a valid cut
    assert odd[0] == 0 and odd[-1] == count and (np.diff(odd) > 0).all()


@pytest.mark.parametrize("failing_call", [1, 3, 6])  # chunk 0's launch; later chunks'
def test_private_copies_are_left_zero_and_dropped_after_a_failure(failing_call, threads, chunks, monkeypatch):
    """A backward pass leaves its private gradient copies zeroed for the next (they are zeroed as
    they are added in). A pass that fails part way (threads waiting for a slot meanwhile) leaves
    them holding part of a sum: the failure is raised, they are dropped, and the next pass, with new
    ones, gives the right gradient."""
    threads(8)
    chunks(8192)
    monkeypatch.setattr(_launch, "cpu_count", lambda: 8)  # 8 threads on this machine's slots
    g = _sphere()
    tex = _texture(requires_grad=True)

    def gradient():
        tape = wp.Tape()
        with tape:
            out = wt.triplanar(g, tex, tiling=3.0)
        out.grad.fill_(1.0)
        tape.backward()
        grad = tex.grad().copy()
        tex.zero_grad()
        return grad

    want = gradient()
    real = tex.view.texels.grad
    copies = _accumulate._private_arrays[real]
    assert set(copies) == set(range(_accumulate.slot_count(8, 8)))
    assert all((c.array.numpy() == 0).all() and (c.tiles.numpy() == 0).all() for c in copies.values())

    calls, original = [], wp.launch

    def failing(kernel, *args, **kwargs):
        calls.append(kernel)
        if len(calls) == failing_call:
            raise RuntimeError("a chunk failed")
        return original(kernel, *args, **kwargs)

    tape = wp.Tape()
    with tape:
        out = wt.triplanar(g, tex, tiling=3.0)
    out.grad.fill_(1.0)
    wp.launch = failing
    try:
        with pytest.raises(RuntimeError, match="a chunk failed"):
            tape.backward()
    finally:
        wp.launch = original
    assert real not in _accumulate._private_arrays
    tex.zero_grad()
    np.testing.assert_array_equal(gradient(), want)


def test_zero_grad_clears_a_large_gradient_on_the_threads(threads, monkeypatch):
    """``zero_grad`` of a gradient past PARALLEL_ZERO_BYTES is cleared in a range per thread (3
    cuts of a size that no cut divides evenly); every level is zeroed, and nothing past it."""
    threads(3)
    tex = wt.Texture(np.random.default_rng(6).random((1023, 1025, 4)).astype(np.float32), requires_grad=True)
    grad = tex.view.texels.grad
    assert grad.size * 16 >= _threads.PARALLEL_ZERO_BYTES
    grad.fill_(wp.vec4(1.0, 2.0, 3.0, 4.0))
    cleared, memset = [], ctypes.memset
    monkeypatch.setattr(ctypes, "memset", lambda ptr, value, size: (cleared.append((ptr, size)), memset(ptr, value, size))[1])
    tex.zero_grad()
    cleared.sort()
    assert len(cleared) == 3, "a range per thread"
    assert cleared[0][0] == grad.ptr and all(a + n == b for (a, n), (b, _) in zip(cleared, cleared[1:])), "ranges that meet"
    assert cleared[-1][0] + cleared[-1][1] == grad.ptr + grad.size * 16, "and end where the gradient ends"
    np.testing.assert_array_equal(grad.numpy(), 0)


def test_zero_grad_of_a_small_gradient_stays_on_one_thread(threads, monkeypatch):
    threads(2)
    tex = wt.Texture(np.random.default_rng(6).random((64, 64, 4)).astype(np.float32), requires_grad=True)
    tex.view.texels.grad.fill_(wp.vec4(1.0, 2.0, 3.0, 4.0))
    monkeypatch.setattr(_threads, "side_by_side", lambda work, parts: pytest.fail("a small clear is handed out"))
    tex.zero_grad()
    np.testing.assert_array_equal(tex.view.texels.grad.numpy(), 0)


@pytest.mark.parametrize("workers", [2, 3, 4, 16])
def test_chunks_shrink_towards_the_end(workers):
    """A forward launch is cut into at least a chunk a worker, ever smaller chunks (guided), and a
    tail of equal chunks, a whole number a worker, each at most ``1 / (GUIDED_TAIL · workers)`` of
    the whole or ``MIN_PIXELS_PER_THREAD`` pixels, and none under half of those (a 192 x 256 view
    in 3 chunks on 2 workers gave one twice the other's work)."""
    for count in (workers * _threads.MIN_PIXELS_PER_THREAD, 192 * 256, 5 * _threads.MIN_PIXELS_PER_THREAD + 7, 1 << 20):
        if count < workers * _threads.MIN_PIXELS_PER_THREAD:
            continue
        sizes = np.diff(_threads.Split(count, workers).bounds)
        assert len(sizes) >= workers and sizes.sum() == count
        assert np.all(sizes[1:] <= sizes[:-1] + LANES), sizes  # never growing (but for a lane's rounding)
        assert sizes.min() >= _threads.MIN_PIXELS_PER_THREAD // 2, sizes
        tail = sizes[np.abs(sizes - sizes[-1]) <= LANES]
        assert len(tail) % workers == 0, sizes
        assert sizes[-1] <= max(count / (_threads.GUIDED_TAIL * workers), _threads.MIN_PIXELS_PER_THREAD) + LANES, sizes


def _makespan(sizes, speeds):
    """When the last of workers of ``speeds`` (work a second) ends, taking chunks ``sizes`` in turn."""
    free = [0.0] * len(speeds)
    for size in sizes:
        w = min(range(len(speeds)), key=lambda k: (free[k], k))
        free[w] += size / speeds[w]
    return max(free)


@pytest.mark.parametrize("speeds", [(1.0, 1.0), (1.0, 0.55), (1.0, 1.0, 1.0, 0.5)])
def test_guided_chunks_even_out_unequal_workers(speeds):
    """Workers that run at unequal paces (a shared host's second vCPU ran whole calls at 0.55x the
    first's) end close together, as a split of the work by their speeds would: the last chunks are
    small. Four equal chunks on (1, 0.55) end at 1.40x that ideal."""
    count = 1 << 20
    sizes = np.diff(_threads.Split(count, len(speeds)).bounds).astype(float)
    ideal = count / sum(speeds)
    assert _makespan(sizes, speeds) <= 1.1 * ideal
    equal = np.full(2 * len(speeds), count / (2 * len(speeds)))
    if speeds == (1.0, 0.55):
        assert _makespan(equal, speeds) > 1.3 * ideal  # what the guided cut removes


def test_chunk_cuts_fall_between_lanes(rng):
    """Every cut between two chunks is a multiple of ``LANES``: a lane kernel computes pixels
    ``first .. first + LANES - 1`` per launch index, so a lane straddling a cut would be computed
    (and its gradient added) by two chunks. Equal counts, equal costs over a mask, and counts too
    small for as many chunks (fewer, never empty)."""
    mask = (rng.random(300_001) > 0.3).astype(np.float32)
    mask[:90_000] = 0.0  # sky
    for count, chunks, covered in ((1 << 20, 8, None), (300_001, 7, wp.array(mask)), (300_001, 7, None), (4 * LANES + 3, 16, None), (50, 3, None)):
        bounds = _threads.bounds(count, chunks, covered)
        assert bounds[0] == 0 and bounds[-1] == count and (np.diff(bounds) > 0).all() and len(bounds) <= chunks + 1
        assert all(b % LANES == 0 for b in bounds[:-1]), bounds
    # each whole lane a chunk of its own, the tail with the last one or alone (as the integer cuts fall)
    assert 4 <= len(_threads.bounds(4 * LANES + 3, 16, None)) - 1 <= 5


def _watch_sums(monkeypatch) -> tuple[list, list]:
    """``(seen, entries)``: filled as ``add_copies`` runs, with ``_marked_tiles`` of every tracked
    copy it adds in and the ``entries`` it is given."""
    seen, entries_seen = [], []
    real_add = _accumulate.add_copies

    def add(copies, entries=None):
        seen.extend(_marked_tiles(c) for _, c in copies if c.tiles is not None)
        entries_seen.append(dict(entries or {}))
        real_add(copies, entries)

    monkeypatch.setattr(_accumulate, "add_copies", add)
    return seen, entries_seen


def _marked_tiles(copy) -> tuple[np.ndarray, np.ndarray]:
    """``(marked, written)``: a private copy's tile flags, and which of its tiles hold non-zero entries."""
    tile = 1 << TILE_SHIFT
    values = np.abs(copy.array.numpy()).reshape(copy.array.shape[0], -1).sum(axis=1)
    written = np.add.reduceat(values, np.arange(0, len(values), tile)) > 0
    return _accumulate.tiles_reached(copy.tiles.numpy()), written


def _sample_backward(threads, count, image, uv, out_grad, make=wt.Texture, **kw):
    """A new texture of ``image`` that requires gradients, after ``wt.sample(tex, uv, **kw)``'s backward
    pass on ``count`` threads with the output gradient ``out_grad`` (an array, or a value for all)."""
    threads(count)
    tex = make(image, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = wt.sample(tex, uv, **kw)
    if np.ndim(out_grad):
        out.grad.assign(out_grad)
    else:
        out.grad.fill_(out_grad)
    tape.backward()
    return tex


@pytest.mark.parametrize("filter_, lod, levels", [("bilinear", None, (0, 0)), ("trilinear", 1.3, (1, 2)), ("nearest", 2.7, (3, 3))])
def test_private_copies_sum_only_the_tiles_they_marked(filter_, lod, levels, threads, chunks, monkeypatch):
    """A private gradient copy marks the tiles its pixels add into: every tile it wrote is marked,
    none outside the mip levels the lookup reads (one LOD for all UVs reads one or two; a mark
    covers two rows, so the last row's reaches one row past), and only the marked tiles of those
    levels' entries are added in. The gradient of every level is one thread's, and the copies and
    their marks are left clear."""
    chunks(16384)  # 4 chunks: 3 added in per pass
    uv = _uv(70000)
    image = np.random.default_rng(8).random((128, 128, 4)).astype(np.float32)
    weights = np.random.default_rng(9).random((70000, 4)).astype(np.float32)
    seen, entries = _watch_sums(monkeypatch)
    grads = []
    for n in (1, 2, 3):
        tex = _sample_backward(threads, n, image, uv, weights, lod=lod, sampler=wt.Sampler(filter=filter_, address="wrap"))
        grads.append([tex.grad(level) for level in range(tex.num_levels)])
    real = tex.view.texels.grad
    tile = 1 << TILE_SHIFT
    width = 128 >> levels[1]
    first = tex._offsets[levels[0]] // tile
    last = (tex._offsets[levels[1]] + width * width - 1 + width) // tile  # a mark covers two rows: may reach one row past the level
    assert len(seen) == 9  # 3 chunks past the first, on each thread count
    for marked, written in seen:
        assert written.any() and not (written & ~marked).any()
        assert marked[first : last + 1].any() and not marked[:first].any() and not marked[last + 1 :].any()
    assert [list(e.values()) for e in entries] == [[tex.level_entries(*levels)]] * 9
    assert all((c.array.numpy() == 0).all() and (c.tiles.numpy() == 0).all() for c in _accumulate._private_arrays[real].values())
    for level, (one, *more) in enumerate(zip(*grads)):
        for other in more:
            np.testing.assert_array_equal(other, one)
        assert (np.abs(one).sum() > 0) == (levels[0] <= level <= levels[1])


def test_coherent_pixels_mark_a_part_of_the_texture(threads, chunks, monkeypatch):
    """Pixels whose UVs follow the image (a sphere's) give each chunk a band of the texture: a
    private copy marks only part of the tiles, so less than the whole copy is added in, and the
    gradient is one thread's."""
    chunks(16384)  # 4 chunks
    g = _sphere()
    image = np.random.default_rng(10).random((256, 256, 4)).astype(np.float32)
    seen, _ = _watch_sums(monkeypatch)
    grads = [_sample_backward(threads, n, image, g.uv()["uv"], 1.0, sampler=wt.Sampler(filter="bilinear", address="wrap")).grad() for n in (1, 3)]
    level0 = 256 * 256 // (1 << TILE_SHIFT)
    assert len(seen) == 6  # chunks 1 to 3, on 1 and 3 threads
    for marked, written in seen:
        assert not (written & ~marked).any()
        assert 0 < marked[:level0].sum() < 0.5 * level0
    np.testing.assert_array_equal(grads[1], grads[0])


def test_add_copies_adds_marked_tiles():
    """``add_copies`` on hand-made copies, one after another: marked tiles are added (bit for bit
    as ``real += copy``) and zeroed, unmarked ones left alone, untracked copies added whole; past
    ``SUM_BLOCK`` alike."""
    rng = np.random.default_rng(11)
    tile = 1 << TILE_SHIFT
    for entries in (5 * tile + 7, 70 * tile + 3):  # within one block; several blocks
        tiles = -(-entries // tile)
        real = wp.array(rng.random((entries, 4)).astype(np.float32), dtype=wp.vec4)
        start = real.numpy().copy()
        private, want = [], start.copy()
        for worker in range(3):
            marks = rng.random(tiles) < 0.5 if worker < 2 else None
            values = rng.random((entries, 4)).astype(np.float32)
            if marks is not None:
                values[~np.repeat(marks, tile)[:entries]] = 0
            copy = _accumulate.Copy(wp.array(values, dtype=wp.vec4), None if marks is None else wp.array(marks.astype(np.int32), dtype=wp.int32))
            private.append((real, copy))
            want += values
        for pair in private:
            _accumulate.add_copies([pair])
        np.testing.assert_array_equal(real.numpy(), want)
        assert all((c.array.numpy() == 0).all() and (c.tiles is None or (c.tiles.numpy() == 0).all()) for _, c in private)


@pytest.mark.parametrize("address", ["wrap", "clamp", "mirror", "border"])
@pytest.mark.parametrize("filter_", ["nearest", "bilinear", "trilinear", "anisotropic"])
@pytest.mark.parametrize("size", [(300, 37), (3, 2100)])  # rows not aligned with tiles (27.7 a tile); rows wider than one
def test_tile_marks_cover_every_texel_written(size, filter_, address, threads, chunks, monkeypatch):
    """Whatever the filter and address mode (edges, wrapped rows, border texels), every tile a
    chunk's private copy adds into is marked, and the threaded gradient is one thread's."""
    chunks(8192)  # 7 chunks
    h, w = size
    rng = np.random.default_rng(12)
    image = rng.random((2, h, w, 4)).astype(np.float32)
    n = 60000
    uv = rng.uniform(-1.5, 2.5, (n, 2)).astype(np.float32)
    uv[: n // 4] = np.round(uv[: n // 4] * 4) / 4  # on texel and texture edges
    layer = rng.integers(0, 2, n).astype(np.int32)
    dx = np.stack([rng.uniform(0.001, 0.05, n), rng.uniform(-0.01, 0.01, n)], axis=1).astype(np.float32)
    dy = np.stack([rng.uniform(-0.01, 0.01, n), rng.uniform(0.001, 0.2, n)], axis=1).astype(np.float32)
    weights = rng.random((n, 4)).astype(np.float32)
    seen, _ = _watch_sums(monkeypatch)
    # Each chunk's pixels in a band of rows, so that a missed mark is not covered by the others'; in
    # both orders, so that a wrapping footprint falls to a chunk with a private copy either way.
    for order in (np.argsort(uv[:, 1] % 1.0), np.argsort(-(uv[:, 1] % 1.0))):
        sampler = wt.Sampler(filter=filter_, address=address)
        texs = [_sample_backward(threads, n, image, uv[order], weights, wt.TextureArray, layer=layer[order], uv_dx=dx[order], uv_dy=dy[order], sampler=sampler) for n in (1, 3)]
        grads = [tex.view.texels.grad.numpy() for tex in texs]
        np.testing.assert_array_equal(grads[1], grads[0])
        assert seen and all(not (written & ~marked).any() for marked, written in seen)
        seen.clear()


def test_add_copies_adds_only_the_entries_given():
    """``entries`` (the mip levels a constant-LOD lookup reads) limits the sum of an untracked copy
    to the tiles of that range: what lies outside (here planted against the contract) is not
    added, and the range is left zero."""
    tile = 1 << TILE_SHIFT
    rng = np.random.default_rng(13)
    real = wp.zeros(20 * tile, dtype=wp.vec4)
    values = np.zeros((20 * tile, 4), np.float32)
    values[5 * tile + 3 : 9 * tile - 7] = rng.random((4 * tile - 10, 4))
    values[[0, 5 * tile - 1, 9 * tile, -1]] = 7.0  # outside the range's tiles
    copy = _accumulate.Copy(wp.array(values, dtype=wp.vec4), None)
    _accumulate.add_copies([(real, copy)], entries={id(real): (5 * tile + 3, 9 * tile - 7)})
    inside = np.zeros(20 * tile, bool)
    inside[5 * tile : 9 * tile] = True
    np.testing.assert_array_equal(real.numpy()[inside], values[inside])
    assert not real.numpy()[~inside].any() and not copy.array.numpy()[inside].any()
    np.testing.assert_array_equal(copy.array.numpy()[~inside], values[~inside])


def test_side_by_side_runs_every_part_waits_for_all_and_re_raises():
    """Parts 1.. run on pool threads, part 0 here; a failing part does not stop the others, and its
    error is raised on this thread once all are done."""
    ran, main = [], threading.get_ident()

    def work(part):
        ran.append((part, threading.get_ident() == main))
        if part == 2:
            raise KeyError("part 2")

    with pytest.raises(KeyError, match="part 2"):
        _threads.side_by_side(work, 4)
    assert sorted(ran) == [(0, True), (1, False), (2, False), (3, False)]
    ran.clear()
    _threads.side_by_side(lambda part: ran.append(part), 3)  # the pool goes on after a failure
    assert sorted(ran) == [0, 1, 2]


def _threaded_sum_in_child() -> float:
    tex = wt.Texture(np.ones((64, 64, 4), np.float32))
    wt.set_num_threads(2)
    uv = np.random.default_rng(0).random((4 * _threads.MIN_PIXELS_PER_THREAD, 2)).astype(np.float32)
    return float(wt.sample(tex, uv).numpy().sum())


@pytest.mark.skipif(not hasattr(os, "register_at_fork"), reason="no fork on this platform")
def test_a_forked_child_starts_its_own_pool_threads(threads):
    """A child forked after the pool started (a fork-based DataLoader) has none of its threads: it
    must start its own rather than wait for parts nobody takes."""
    threads(2)
    _threads.side_by_side(lambda part: None, 2)  # the parent's pool is running
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply_async(_threaded_sum_in_child).get(timeout=120) == 4.0 * 4 * _threads.MIN_PIXELS_PER_THREAD


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or _threads._getcpu is None or _threads.cpu_count() < 2, reason="needs Linux's sched_getcpu and 2 CPUs")
def test_pool_threads_keep_off_the_callers_cpu():
    """A hand-out keeps the pool threads off the CPU the caller runs on (Linux would otherwise wake
    a worker that slept a while onto the caller's core, and both share it for the whole call)."""
    seen = {}

    def work(part):
        if part:
            seen[part] = _threads._getcpu()

    for parts in (2, 3, 3, 5):  # more parts than threads so far: the new threads are kept off too
        seen.clear()
        _threads.side_by_side(work, parts)
        caller = _threads._kept_off
        assert caller in os.sched_getaffinity(0) and len(_threads._worker_ids) >= parts - 1
        assert all(os.sched_getaffinity(worker) == os.sched_getaffinity(0) - {caller} for worker in _threads._worker_ids)
        assert sorted(seen) == list(range(1, parts)) and caller not in seen.values()


FIRST_CALLS = """
import numpy as np, trimesh, warptex as wt
wt.set_num_threads(2)
wt.rasterize(trimesh.creation.box(), wt.orthographic((0, 0, 3), (0, 0, 0), height=2.0, resolution=(128, 128)))
uv = np.random.default_rng(0).random((4 * 16384, 2)).astype(np.float32)
wt.sample(wt.Texture(np.ones((16, 16, 4), np.float32), mipmaps=False), uv)
"""


def test_a_first_threaded_call_compiles_each_module_once(tmp_path):
    """Warp loads a module at the first launch of one of its kernels, on whichever thread launches
    it: split over 2 threads, a first call compiled its module twice, side by side, unless warptex
    loads it before the threads start (``warptex._compile.load_first``). A fresh kernel cache, so that
    the process compiles; Warp reports each compile on its output."""
    env = {**os.environ, "WARP_CACHE_PATH": str(tmp_path / "cache")}
    done = subprocess.run([sys.executable, "-c", FIRST_CALLS], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    compiled = [line.split()[1] for line in done.stdout.splitlines() if line.startswith("Module ") and line.endswith("(compiled)")]
    assert "warptex.raster" in compiled and "warptex.sample.lanes" in compiled, done.stdout
    assert len(compiled) == len(set(compiled)), done.stdout
