"""Per-pixel launches split over CPU threads: identical results, identical gradients (to float
rounding), validation."""

import functools

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import _launch


@pytest.fixture
def threads():
    """Run with the given thread count, then restore the default."""
    yield wt.set_num_threads
    wt.set_num_threads(None)


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
    "stochastic": lambda tex, g: wt.stochastic(tex, _uv(), method="hex", lod=0.7),
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
        tape = wp.Tape()
        with tape:
            tex.update()
            out = wt.triplanar(g, tex, tiling=tiling)
        out.grad.assign(weights)
        tape.backward()
        if n == 4:
            assert len([launch for launch in tape.launches if getattr(launch[0], "key", "").startswith("triplanar_kernel")]) == 4
        grads.append((tex.grad(), tiling.grad.numpy()))
    np.testing.assert_allclose(grads[1][0], grads[0][0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(grads[1][1], grads[0][1], rtol=1e-5)
    assert np.abs(grads[0][0]).sum() > 0 and grads[0][1][0] != 0


def test_small_launches_are_not_split():
    out = wp.zeros((100, 1), dtype=float)
    calls = []

    @wp.kernel
    def count_kernel(x: wp.array(dtype=float), y: wp.array2d(dtype=float)):
        i = wp.tid()
        y[i, 0] = x[i] + 1.0

    x = wp.array(np.arange(100, dtype=np.float32))
    original = wp.launch
    try:
        wp.launch = lambda *a, **k: (calls.append(k["dim"]), original(*a, **k))
        _launch.launch(count_kernel, 100, inputs=_launch.per_pixel(x), outputs=[out], device="cpu", threads=4)
    finally:
        wp.launch = original
    assert calls == [100]
    np.testing.assert_array_equal(out.numpy()[:, 0], np.arange(100) + 1)


def test_bad_thread_counts_and_per_pixel_arrays_raise():
    with pytest.raises(ValueError, match=r"set_num_threads\(\): threads must be an int >= 1 or None, got 0"):
        wt.set_num_threads(0)
    with pytest.raises(ValueError, match=r"set_num_threads\(\): threads must be an int >= 1 or None, got 2.5"):
        wt.set_num_threads(2.5)
    with pytest.raises(RuntimeError, match=r"a per-pixel argument has 10 rows for 40000 pixels"):
        _launch.launch(None, 40000, inputs=_launch.per_pixel(wp.zeros(10, dtype=float)), outputs=[wp.zeros(40000, dtype=float)], device="cpu", threads=2)


def test_thread_count_from_the_environment(monkeypatch):
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "3")
    assert wt.get_num_threads() == 3
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "many")
    with pytest.raises(ValueError, match=r"WARPTEX_NUM_THREADS must be an int >= 1, got 'many'"):
        wt.get_num_threads()
    monkeypatch.delenv("WARPTEX_NUM_THREADS")
    assert wt.get_num_threads() == _launch.cpu_count()
