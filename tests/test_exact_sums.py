"""The deterministic CUDA backward (issue 51), checked on the CPU.

On CUDA a backward pass is one launch whose threads add texel gradients in an order that changes
from run to run. warptex sums them in fixed point there instead (``warptex._accumulate.exact_sums``),
an integer sum that no order can change. These tests run that path on the CPU (the same scalar
kernels, one launch) and check what a GPU run would need: the gradients are the same bits
whatever order the pixels come in (the pixels reversed), where float atomics' sums are not; they
equal the float sums to rounding; and non-finite gradients still reach the texels they would."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import _accumulate, _launch, _op
from warptex.atlas import export_index_maps, pack_atlas, splat_atlas
from warptex._warp import paused_tape
from warptex.gbuffer import FIELDS

N = 20000
UV = np.random.default_rng(1).uniform(-3, 3, (N, 2)).astype(np.float32)
LOD = np.random.default_rng(2).uniform(0, 5, N).astype(np.float32)
DX = (np.random.default_rng(3).normal(size=(N, 2)) * 0.03).astype(np.float32)
DY = (np.random.default_rng(4).normal(size=(N, 2)) * 0.01).astype(np.float32)
MAPS = np.random.default_rng(5).random((1, 8, 8, 4)).astype(np.float32)


@pytest.fixture
def exact_on_cpu(monkeypatch):
    """The fixed-point sums on the CPU too, counting the texel gradients they finish."""
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda", "cpu"})
    finished = []
    add_sums = _accumulate.add_sums
    monkeypatch.setattr(_launch, "add_sums", lambda sums: (finished.extend(s.grad for s in sums.values()), add_sums(sums)))
    return finished


@functools.lru_cache(maxsize=None)
def _sphere(reverse: bool) -> wt.GBuffer:
    """A 160² view of a sphere, its pixels in reverse order where ``reverse`` (each pixel's data
    unchanged: only the order in which the backward pass meets them)."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, :2] * 0.5 + 0.5)
    g = wt.rasterize(mesh, wt.look_at((1.6, 1.2, 2.4), (0, 0, 0), fov_y=40.0, resolution=(160, 160)))
    if not reverse:
        return g

    def flip(a: wp.array) -> wp.array:
        return wp.array(np.ascontiguousarray(a.numpy()[::-1, ::-1]), dtype=a.dtype)

    sets = {s: {f: flip(a) for f, a in fields.items()} for s, fields in g.uv_sets.items()}
    return wt.GBuffer(**{name: flip(getattr(g, name)) for name in FIELDS}, uv_sets=sets, camera=g.camera, samples=g.samples, origin=g.origin)


def _image(seed: int, shape=(64, 64, 4)) -> np.ndarray:
    return np.random.default_rng(seed).random(shape).astype(np.float32)


def _tex(seed=0):
    return wt.Texture(_image(seed), requires_grad=True)


def _layers(seed=10, count=4):
    return wt.TextureArray(_image(seed, (count, 32, 32, 4)), requires_grad=True)


# Each technique, where only textures want gradients (warptex's hand-written texel gradients):
# order -> (output, textures); the order is an index array over the N UVs, or, for the G-buffer
# techniques, whether the G-buffer's pixels are reversed.
CASES = {
    "sample, bilinear": lambda o: (lambda t: (wt.sample(t, UV[o]), [t]))(_tex()),
    "sample, trilinear, per-sample LOD": lambda o: (lambda t: (wt.sample(t, UV[o], lod=LOD[o], sampler=wt.Sampler(filter="trilinear")), [t]))(_tex()),
    "sample, anisotropic": lambda o: (lambda t: (wt.sample(t, UV[o], uv_dx=DX[o], uv_dy=DY[o], sampler=wt.Sampler(filter="anisotropic")), [t]))(_tex()),
    "stochastic hash4": lambda o: (lambda t: (wt.stochastic(t, UV[o], "hash4", lod=LOD[o]), [t]))(_tex()),
    "stochastic hex": lambda o: (lambda t: (wt.stochastic(t, UV[o], "hex", lod=LOD[o]), [t]))(_tex()),
    "triplanar": lambda r: (lambda t: (wt.triplanar(_sphere(r), t, tiling=3.0), [t]))(_tex()),
    "biplanar hash4": lambda r: (lambda t: (wt.biplanar(_sphere(r), t, tiling=3.0, stochastic="hash4"), [t]))(_tex()),
    "triplanar per face": lambda r: (lambda ts: (wt.triplanar(_sphere(r), textures_per_face=ts, tiling=3.0), ts))([_tex(k) for k in range(6)]),
    "triplanar_normal": lambda r: (lambda t: (wt.triplanar_normal(_sphere(r), t, tiling=3.0), [t]))(wt.Texture(_image(7, (64, 64, 3)), requires_grad=True)),
    "splat, triplanar, height blend": lambda r: (lambda ls, m: (wt.splat(_sphere(r), ls, m, tiling=2.0, projection="triplanar", height_blend=0.3), [ls, m]))(
        _layers(), wt.TextureArray(MAPS, mipmaps=False, requires_grad=True)
    ),
    "splat, uv, hash4": lambda r: (lambda ls, m: (wt.splat(_sphere(r), ls, m, tiling=3.0, stochastic="hash4"), [ls, m]))(
        _layers(), wt.TextureArray(MAPS, mipmaps=False, requires_grad=True)
    ),
    "stochastic cheap2": lambda o: (lambda t: (wt.stochastic(t, UV[o], "cheap2", lod=1.2), [t]))(_tex()),
    "biplanar_normal hash4": lambda r: (lambda t: (wt.biplanar_normal(_sphere(r), t, tiling=3.0, stochastic="hash4"), [t]))(wt.Texture(_image(6, (64, 64, 3)), requires_grad=True)),
}


def _histogram(order):
    texture = wt.Texture(_image(8))
    hist = wt.prepare_histogram(texture, requires_grad=True)
    return wt.stochastic(texture, UV[order], wt.Stochastic("hex", histogram=hist), lod=LOD[order]), [hist.texture]


def _atlas(reverse):
    idx, w = export_index_maps(np.random.default_rng(9).random((2, 5, 4, 4)).astype(np.float32), 3, num_layers=5)
    with paused_tape():  # packed off the tape, so that the atlas keeps its texel gradients
        atlas = pack_atlas(_image(12, (5, 16, 16, 4)), gutter=2, requires_grad=True)
    return splat_atlas(_sphere(reverse), atlas, idx, w, tiling=2.0, sampler=wt.Sampler(filter="trilinear")), [atlas.texture]


# The same, where Warp's generated adjoint records the backward pass: another input than texels
# wants a gradient (UVs, tiling), the blend is not linear in the texels (histogram-preserving), or
# the technique has no hand-written gradient (the atlas). Their texel reads add in fixed point
# (warptex._accumulate.exact_views); ``OTHERS`` are their other differentiable inputs.
OTHERS: dict[str, list] = {}
GENERATED = {
    "sample, trilinear, UV gradients": lambda o: (lambda t, uv: (OTHERS.update(case=[uv]), (wt.sample(t, uv, lod=LOD[o], sampler=wt.Sampler(filter="trilinear")), [t]))[1])(
        _tex(), wp.array(UV[o], dtype=wp.vec2, requires_grad=True)
    ),
    "triplanar, tiling gradient": lambda r: (lambda t, tiling: (OTHERS.update(case=[tiling]), (wt.triplanar(_sphere(r), t, tiling=tiling), [t]))[1])(
        _tex(), wp.array([3.0, 2.0, 2.5], dtype=float, requires_grad=True)
    ),
    "stochastic hex, histogram-preserving": _histogram,
    "splat_atlas": _atlas,
    "splat, generated adjoint": lambda r: (lambda ls: (_generated(lambda: wt.splat(_sphere(r), ls, wt.TextureArray(MAPS, mipmaps=False), tiling=3.0)), [ls]))(_layers()),
}


def _generated(call):
    """``call()`` with its backward pass forced onto Warp's generated adjoint (whose output is a
    struct for ``splat``: the samples its hand-written blend reads)."""
    with _op.force_generated_adjoint():
        return call()
CASES.update(GENERATED)
ON_UVS = {"sample, bilinear", "sample, trilinear, per-sample LOD", "sample, anisotropic", "stochastic hash4", "stochastic hex", "stochastic cheap2",
          "sample, trilinear, UV gradients", "stochastic hex, histogram-preserving"}  # fmt: skip


def test_a_generated_adjoint_backward_twice_adds_twice(exact_on_cpu):
    """Two backward passes of one tape through a generated adjoint (as torch's ``retain_graph``
    runs them) add the same gradients twice: each pass sums afresh."""
    tex, uv = _tex(), wp.array(UV, dtype=wp.vec2, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = wt.sample(tex, uv, lod=LOD, sampler=wt.Sampler(filter="trilinear"))
    weights = np.random.default_rng(4).normal(size=out.shape).astype(np.float32)
    grads = []
    for _ in range(2):
        out.grad.assign(weights)
        tape.backward()
        grads.append((tex.grad(0).copy(), uv.grad.numpy().copy()))
    assert len(exact_on_cpu) == 2
    np.testing.assert_allclose(grads[1][0], 2 * grads[0][0], rtol=1e-6, atol=1e-6 * np.abs(grads[0][0]).max())
    np.testing.assert_allclose(grads[1][1], 2 * grads[0][1], rtol=1e-6, atol=1e-6 * np.abs(grads[0][1]).max())


def _gradients(case: str, reverse: bool, weights_seed: int = 20, nan_at: int | None = None, others: bool = False) -> list[np.ndarray]:
    """Every level's texel gradients of ``Σ w · out`` (random ``w``, one per pixel and channel),
    the pixels met in reverse order where ``reverse``; ``w`` is NaN at pixel ``nan_at``. With
    ``others``, the gradients of the case's ``OTHERS`` follow."""
    OTHERS.clear()
    order = np.arange(N)[::-1].copy() if reverse else np.arange(N)
    tape = wp.Tape()
    with tape:
        out, textures = CASES[case](order if case in ON_UVS else reverse)
    weights = np.random.default_rng(weights_seed).normal(size=out.shape).astype(np.float32)
    rows = weights.reshape(-1, weights.shape[-1])
    if nan_at is not None:
        rows[nan_at] = np.nan
    if reverse:  # pixel k of the reversed run is pixel n - 1 - k of the forward one
        rows[...] = rows[::-1].copy()
    out.grad.assign(weights)
    tape.backward()
    grads = [np.concatenate([t.grad(k).ravel() for k in range(t.num_levels)]) for t in textures]
    return grads + [a.grad.numpy() for a in OTHERS.get("case", [])] if others else grads


@pytest.mark.parametrize("case", CASES)
def test_texel_gradients_are_the_same_bits_in_any_order(case, exact_on_cpu):
    forward = _gradients(case, reverse=False)
    assert exact_on_cpu, "the fixed-point sums ran"
    backward = _gradients(case, reverse=True)
    for got, want in zip(backward, forward):
        assert np.abs(want).sum() > 0
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("case", ["sample, trilinear, per-sample LOD", "triplanar", "splat, triplanar, height blend"])
def test_they_equal_the_float_sums_to_rounding(case, monkeypatch):
    floats = _gradients(case, reverse=False)
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda", "cpu"})
    exact = _gradients(case, reverse=False)
    for got, want in zip(exact, floats):
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-6 * np.abs(want).max())


@pytest.mark.parametrize("case", GENERATED)
def test_generated_adjoints_sum_in_fixed_point_and_keep_their_other_gradients(case, exact_on_cpu, monkeypatch):
    """Where Warp's generated adjoint runs, its texel reads add in fixed point (the sums ran, and
    equal the float sums to rounding), and every other gradient is the float path's: added once,
    not once per pass (UV gradients, per pixel, to the bit)."""
    exact = _gradients(case, reverse=False, others=True)
    assert exact_on_cpu, "the fixed-point sums ran"
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda"})
    floats = _gradients(case, reverse=False, others=True)
    assert len(exact) == len(floats)
    for got, want in zip(exact, floats):
        assert np.abs(want).sum() > 0
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())
    if case == "sample, trilinear, UV gradients":
        np.testing.assert_array_equal(exact[-1], floats[-1])


def test_float_sums_depend_on_the_order_the_fixed_point_ones_do_not(exact_on_cpu, monkeypatch):
    """What the test above shows is not vacuous: the same pixels reversed change float sums."""
    exact = [_gradients("sample, bilinear", reverse=r)[0] for r in (False, True)]
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda"})
    floats = [_gradients("sample, bilinear", reverse=r)[0] for r in (False, True)]
    assert np.count_nonzero(floats[0] != floats[1]) > 100
    np.testing.assert_array_equal(exact[0], exact[1])


def test_a_non_finite_gradient_reaches_the_texels_it_would(exact_on_cpu, monkeypatch):
    """A NaN output gradient makes NaN the texel gradients it adds into, and only those, as float
    sums do (the fixed-point sum marks the texel rather than converting NaN to an integer)."""
    exact = _gradients("sample, bilinear", reverse=False, nan_at=123)[0]
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda"})
    floats = _gradients("sample, bilinear", reverse=False, nan_at=123)[0]
    assert 0 < np.isnan(floats).sum() <= 16
    np.testing.assert_array_equal(np.isnan(exact), np.isnan(floats))
    finite = ~np.isnan(floats)
    np.testing.assert_allclose(exact[finite], floats[finite], rtol=0, atol=2e-6 * np.abs(floats[finite]).max())


def test_gradients_accumulate_over_backward_passes(exact_on_cpu):
    """A second backward pass adds to the first's gradients (as ``tape.backward`` does), once."""
    tex = wt.Texture(_image(3), requires_grad=True)
    weights = np.random.default_rng(4).normal(size=(N, 4)).astype(np.float32)
    grads = []
    for _ in range(2):
        tape = wp.Tape()
        with tape:
            out = wt.sample(tex, UV, lod=0.7)
        out.grad.assign(weights)
        tape.backward()
        grads.append(tex.grad(0).copy())
    np.testing.assert_allclose(grads[1], 2 * grads[0], rtol=1e-6, atol=1e-7)


def test_the_switch(monkeypatch):
    """``set_deterministic_gradients(False)`` gives CUDA float atomics; it takes booleans only."""
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda", "cpu"})
    grad = wp.zeros(4, dtype=wp.vec4)
    assert wt.get_deterministic_gradients() is True
    assert _accumulate.exact_sums(wp.get_device("cpu"), [grad]) is not None
    try:
        wt.set_deterministic_gradients(False)
        assert wt.get_deterministic_gradients() is False
        assert _accumulate.exact_sums(wp.get_device("cpu"), [grad]) is None
        with pytest.raises(TypeError, match="takes True or False"):
            wt.set_deterministic_gradients(0)
    finally:
        wt.set_deterministic_gradients(True)


def test_the_sum_is_the_exact_sum_rounded_once(exact_on_cpu, monkeypatch):
    """65,536 contributions to one texel (a 1×1 texture, nearest: each pixel adds its output
    gradient as it is): the fixed-point sum is the float64 sum rounded to float32, within one
    step of float32, where a float32 running sum drifts by many."""
    weights = np.random.default_rng(11).normal(size=(65536, 4)).astype(np.float32)
    uv = np.random.default_rng(12).uniform(-4, 4, (65536, 2)).astype(np.float32)

    def grad() -> np.ndarray:
        tex = wt.Texture(np.full((1, 1, 4), 0.5, np.float32), mipmaps=False, requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = wt.sample(tex, uv, sampler=wt.Sampler(filter="nearest"))
        out.grad.assign(weights)
        tape.backward()
        return tex.grad(0).reshape(4)

    exact = grad()
    monkeypatch.setattr(_accumulate, "EXACT_DEVICES", {"cuda"})
    floats = grad()
    truth = weights.astype(np.float64).sum(axis=0)
    step = np.spacing(np.abs(truth).astype(np.float32)).astype(np.float64)
    assert np.all(np.abs(exact - truth) <= step)
    assert np.abs(floats - truth).max() > 4 * step.max()
