"""Gradients that do not depend on the thread count (issue 33): a backward pass is cut into chunks
fixed by its pixels alone (``warptex._threads.grad_bounds``) and their shared gradients are added in
chunk order (``warptex._accumulate``), so texel and parameter gradients of every technique, and a
whole fit, are the same bits at 1, 2, 3 and 8 threads, whichever thread is slow."""

from __future__ import annotations

import functools
import threading
import time

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import _accumulate, _op, _threads

THREADS = (1, 2, 3, 8)


@pytest.fixture
def small_chunks(monkeypatch):
    """Chunks of 4096 pixels, and threads for launches of 1024 pixels a thread: a 256² view's
    backward pass is cut into 16 chunks, as a 2048² one's is by default. A backward pass runs on
    as many threads as asked, as on a machine with that many cores (it uses the cores at most)."""
    monkeypatch.setattr(_threads, "GRAD_CHUNK_PIXELS", 4096)
    monkeypatch.setattr(wt._launch, "cpu_count", lambda: 64)
    monkeypatch.setattr(_threads, "MIN_GRAD_CHUNK_PIXELS", 4096)
    monkeypatch.setattr(_threads, "MIN_PIXELS_PER_THREAD", 1024)
    yield
    wt.set_num_threads(None)


@functools.lru_cache(maxsize=None)
def _sphere() -> wt.GBuffer:
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, :2] * 0.5 + 0.5)
    return wt.rasterize(mesh, wt.look_at((1.6, 1.2, 2.4), (0, 0, 0), fov_y=40.0, resolution=(256, 256)))


def _image(seed: int, shape=(64, 64, 4)) -> np.ndarray:
    return np.random.default_rng(seed).random(shape).astype(np.float32)


def _grad_array(values, requires_grad=True) -> wp.array:
    return wp.array(np.asarray(values, np.float32), dtype=float, requires_grad=requires_grad)


N = 65536
UV = np.random.default_rng(1).uniform(-3, 3, (N, 2)).astype(np.float32)
LOD = np.random.default_rng(2).uniform(0, 5, N).astype(np.float32)
DX = (np.random.default_rng(3).normal(size=(N, 2)) * 0.03).astype(np.float32)
DY = (np.random.default_rng(4).normal(size=(N, 2)) * 0.01).astype(np.float32)
MAPS = np.random.default_rng(5).random((1, 8, 8, 4)).astype(np.float32)


def _tex(seed=0, **kw):
    return wt.Texture(_image(seed), requires_grad=True, **kw)


def _layers(seed=10, count=4):
    return wt.TextureArray(_image(seed, (count, 32, 32, 4)), requires_grad=True)


def _generated(technique, *args, **kw):
    with _op.force_generated_adjoint():
        return technique(*args, **kw)


# Each technique: () -> (output, [what has gradients: textures, atlases, arrays]). Every texture
# reaches every thread's chunks; "generated adjoint" forces Warp's (warptex._op.force_generated_adjoint).
CASES = {
    "sample, bilinear": lambda: (lambda t: (wt.sample(t, UV), [t]))(_tex()),
    "sample, per-sample LOD": lambda: (lambda t: (wt.sample(t, UV, lod=LOD), [t]))(_tex()),
    "sample, anisotropic": lambda: (lambda t: (wt.sample(t, UV, uv_dx=DX, uv_dy=DY, sampler=wt.Sampler(filter="anisotropic")), [t]))(_tex()),
    "sample, per-sample UVs": lambda: (lambda t, uv: (wt.sample(t, uv, lod=1.5), [t, uv]))(_tex(), wp.array(UV, dtype=wp.vec2, requires_grad=True)),
    "stochastic hash4": lambda: (lambda t: (wt.stochastic(t, UV, "hash4", lod=LOD), [t]))(_tex()),
    "stochastic cheap2": lambda: (lambda t: (wt.stochastic(t, UV, "cheap2", lod=1.2), [t]))(_tex()),
    "stochastic hex": lambda: (lambda t: (wt.stochastic(t, UV, "hex", lod=LOD), [t]))(_tex()),
    "triplanar": lambda: (lambda t: (wt.triplanar(_sphere(), t, tiling=3.0), [t]))(_tex()),
    "triplanar, tiling and sharpness": lambda: (lambda t, a, s: (wt.triplanar(_sphere(), t, tiling=a, sharpness=s), [t, a, s]))(_tex(), _grad_array([3.0]), _grad_array([4.0])),
    "triplanar, generated adjoint": lambda: (lambda t, a, s: (_generated(wt.triplanar, _sphere(), t, tiling=a, sharpness=s), [t, a, s]))(_tex(), _grad_array([3.0]), _grad_array([4.0])),
    "biplanar": lambda: (lambda t: (wt.biplanar(_sphere(), t, tiling=3.0), [t]))(_tex()),
    "triplanar per face": lambda: (lambda ts: (wt.triplanar(_sphere(), textures_per_face=ts, tiling=3.0, stochastic="hash4"), ts))([_tex(k) for k in range(6)]),
    "triplanar_normal": lambda: (lambda t: (wt.triplanar_normal(_sphere(), t, tiling=3.0), [t]))(wt.Texture(_image(7, (64, 64, 3)), requires_grad=True)),
    "splat, triplanar, height blend": lambda: (lambda ls, m, a: (wt.splat(_sphere(), ls, m, tiling=a, projection="triplanar", height_blend=0.3), [ls, m, a]))(
        _layers(), wt.TextureArray(MAPS, mipmaps=False, requires_grad=True), _grad_array([2.0, 3.0, 4.0, 5.0])
    ),
    "splat, uv": lambda: (lambda ls, m: (wt.splat(_sphere(), ls, m, tiling=3.0, projection="uv"), [ls, m]))(_layers(), wt.TextureArray(MAPS, mipmaps=False, requires_grad=True)),
    # packed on the tape: the atlas texels' gradient is carried back to the layers
    "splat_atlas": lambda: (lambda ls: (wt.splat_atlas(_sphere(), wt.pack_atlas(ls), *wt.export_index_maps(MAPS, k=2), tiling=3.0), [ls]))(_layers()),
}


def _gradients(case, weights_seed=20) -> list[np.ndarray]:
    """The gradients of ``Σ w · out`` (random ``w``) of a fresh run of ``case``."""
    tape = wp.Tape()
    with tape:
        out, inputs = CASES[case]()
    out.grad.assign(np.random.default_rng(weights_seed).normal(size=out.shape).astype(np.float32))
    tape.backward()
    grads = [(x.grad if isinstance(x, wp.array) else x.view.texels.grad).numpy().copy() for x in inputs]
    assert all(np.abs(g).sum() > 0 for g in grads), "every input received a gradient"
    return grads


@pytest.mark.parametrize("case", CASES)
def test_gradients_of_every_technique_are_the_same_bits_at_any_thread_count(case, small_chunks):
    results = {}
    for threads in THREADS:
        wt.set_num_threads(threads)
        results[threads] = _gradients(case)
    for threads in THREADS[1:]:
        for got, want in zip(results[threads], results[1]):
            np.testing.assert_array_equal(got, want, err_msg=f"{threads} threads against 1")


def test_the_default_chunks_give_the_same_bits():
    """At the default chunk sizes (a small texture's gradient: chunks of ``MIN_GRAD_CHUNK_PIXELS``), on 1 and 3 threads."""
    count = 2 * _threads.MIN_GRAD_CHUNK_PIXELS + 12345
    uv = np.random.default_rng(6).uniform(-2, 2, (count, 2)).astype(np.float32)
    image = _image(8, (96, 80, 4))
    results = []
    try:
        for threads in (1, 3):
            wt.set_num_threads(threads)
            tex = wt.Texture(image, requires_grad=True)
            tape = wp.Tape()
            with tape:
                out = wt.sample(tex, uv, lod=0.6)
            out.grad.assign(np.random.default_rng(9).normal(size=out.shape).astype(np.float32))
            tape.backward()
            results.append(tex.view.texels.grad.numpy().copy())
    finally:
        wt.set_num_threads(None)
    np.testing.assert_array_equal(results[1], results[0])
    assert np.abs(results[0]).sum() > 0


def test_grad_chunks_depend_on_the_pixels_alone():
    """Chunks are fixed by the pixel count, the shared gradient's size and a pixel's bilinear
    footprints: one footprint per ``GRAD_BYTES_PER_FOOTPRINT`` bytes of it, within
    ``MIN_GRAD_CHUNK_PIXELS .. GRAD_CHUNK_PIXELS`` pixels (adding a chunk's private copy in costs up
    to the whole gradient; a chunk's pixels, their footprints)."""
    low, high, per = _threads.MIN_GRAD_CHUNK_PIXELS, _threads.GRAD_CHUNK_PIXELS, _threads.GRAD_BYTES_PER_FOOTPRINT
    cases = ((None, 1, high), (0, 1, low), (1 << 40, 1, high), (3 * low * per, 1, 3 * low), (3 * low * per, 3, low), (12 * low * per, 6, 2 * low))
    for shared, footprints, pixels in cases:
        for count in (1, 1000, pixels - 1, pixels * 3 + 5, 1 << 24):
            bounds = _threads.grad_bounds(count, shared_bytes=shared, footprints=footprints)
            chunks = len(bounds) - 1
            assert bounds[0] == 0 and bounds[-1] == count and (np.diff(bounds) > 0).all()
            assert chunks == max(1, min(count // pixels, _threads.MAX_GRAD_CHUNKS))
    mask = np.zeros(1 << 20, np.float32)
    mask[1 << 19 :] = 1.0  # the top half sky: chunks hold equal costs, not equal pixel counts
    bounds = _threads.grad_bounds(1 << 20, wp.array(mask))
    assert bounds[1] > (1 << 20) // (len(bounds) - 1)


@pytest.mark.parametrize("case", ["triplanar, generated adjoint", "triplanar, tiling and sharpness", "sample, bilinear", "splat, triplanar, height blend"])  # generated adjoint; hand-written scatters
def test_the_same_bits_whichever_thread_is_slow(case, small_chunks, monkeypatch):
    """Chunks finish in another order when one is held up; they are still added in chunk order."""
    real_run = _accumulate.run_ordered
    results = []
    for slow in (None, 1, 5):

        def run(chunks, workers, work, *args, slow=slow):
            def held_up(k, slot):
                if k == slow:
                    time.sleep(0.05)
                work(k, slot)

            return real_run(chunks, workers, held_up, *args)

        monkeypatch.setattr(_accumulate, "run_ordered", run)
        monkeypatch.setattr(wt._launch, "run_ordered", run)
        wt.set_num_threads(3)
        results.append(_gradients(case))
    for other in results[1:]:
        for got, want in zip(other, results[0]):
            np.testing.assert_array_equal(got, want)


def test_more_threads_than_slots_wait_for_one_and_never_hang(small_chunks):
    """16 threads share at most ``cpu_count() + 1`` slots (threads past the cores wait rather than
    each holding a copy of every shared gradient); the result is the 1-thread one, and the pass ends."""
    assert _accumulate.slot_count(16, 16) <= _threads.cpu_count() + 1
    wt.set_num_threads(1)
    want = _gradients("triplanar, generated adjoint")
    wt.set_num_threads(16)
    done: list = []
    worker = threading.Thread(target=lambda: done.append(_gradients("triplanar, generated adjoint")), daemon=True)
    worker.start()
    worker.join(timeout=120)
    assert done, "a backward pass on 16 threads did not end"
    for got, expected in zip(done[0], want):
        np.testing.assert_array_equal(got, expected)


def test_a_twenty_iteration_fit_is_the_same_bits_at_any_thread_count(small_chunks):
    from warptex.fit import FitView, SplatParameters, Stage, fit_splat
    from warptex.scenes import terrain_camera
    from warptex.scenes.terrain import terrain

    mesh = terrain(resolution=(33, 33))
    g = wt.rasterize(mesh, terrain_camera((96, 128)))  # 12 288 pixels: 3 chunks of 4096
    layers = wt.TextureArray(_image(30, (4, 32, 32, 4)))
    true = np.random.default_rng(5).dirichlet(np.full(4, 0.7), size=(9, 9)).astype(np.float32)
    options = {"projection": "triplanar", "height_blend": 0.2}
    target = wt.splat(g, layers, wt.TextureArray(true[None], mipmaps=False), tiling=0.2, **options).numpy()[..., :3]
    results = {}
    for threads in THREADS:
        wt.set_num_threads(threads)
        params = SplatParameters(4, (9, 9), tiling=0.2 * 1.1, sharpness=4.0)
        stages = [Stage(20, sigma=1.0, lr_logits=0.2, lr_tiling=0.01, lr_sharpness=0.05)]
        result = fit_splat(FitView(g, target), layers, params, stages=stages, splat_options=options, progress=False)
        results[threads] = (params.logits.numpy().copy(), params.log_tiling.numpy().copy(), params.sharpness_raw.numpy().copy(), np.array(result.history["loss"]))
    assert results[1][3][-1] < results[1][3][0]
    for threads in THREADS[1:]:
        for got, want in zip(results[threads], results[1]):
            np.testing.assert_array_equal(got, want, err_msg=f"{threads} threads against 1")


def test_a_pixels_footprints_count_its_filter_taps_and_lookups():
    from warptex._pack import footprints, sampler_args, stochastic_args

    def smp(filter_, **kw):
        return sampler_args("test", wt.Sampler(filter=filter_, **kw), has_lod=True)

    tex = wt.Texture(_image(0))
    assert footprints(smp("nearest")) == footprints(smp("bilinear")) == 1
    assert footprints(smp("trilinear")) == 2
    assert footprints(smp("anisotropic", max_aniso=8)) == 16  # trilinear taps along the major axis
    for method, taps in (("hash4", 4), ("cheap2", 2), ("hex", 3)):
        stoch, _ = stochastic_args("test", wt.Stochastic(method=method), tex, wt.Sampler())
        assert footprints(smp("trilinear"), stoch, lookups=3) == 2 * taps * 3
