"""Backward passes of the sampling core against central finite differences.

The loss is ``L = Σ w · sample(...)`` with random weights ``w``, evaluated in float64 from the
float32 outputs. Texel gradients are checked along random directions over all texels (sampling is
linear in the texels, so central differences are exact up to rounding). UV, LOD and derivative
gradients are checked per sample, where the function is smooth: bilinear filtering has kinks on
texel-centre lines, so samples whose one-sided differences disagree are left out (and at least 90%
of the samples must remain, so the check cannot pass by leaving everything out).
"""

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex import _op
from conftest import with_sampler
from backward_paths import assert_same_gradients, launches, texel_gradients_both_ways

FILTERS = {"nearest": {"filter": "nearest"}, "bilinear": {"filter": "bilinear"}, "trilinear": {"lod": 1.4}}
MODES = ("wrap", "clamp", "mirror", "border")
BORDER = (0.3, 0.6, 0.9, 1.0)


def _forward(img, uv, weights, *, mipmaps=True, **kw) -> np.ndarray:
    """Per-sample loss ``Σ_c w · out`` (float64, shape ``[N]``) for a fresh texture of ``img``."""
    out = wt.sample(wt.Texture(img, mipmaps=mipmaps), uv, **with_sampler(kw)).numpy()
    return (out.astype(np.float64) * weights).sum(axis=-1)


def _backward(img, uv, weights, *, build_on_tape=True, uv_grad=True, backward="hand-written", **kw):
    """Analytic gradients: ``(texture, uv_array)`` after the backward pass, the texels' and (with
    ``uv_grad``) the UVs', by ``backward``: the hand-written gradient, or Warp's generated adjoint
    (forced: the hand-written one serves texels and UVs alike)."""
    tex = wt.Texture(img, requires_grad=True)
    uv_wp = wp.array(uv, dtype=wp.vec2, requires_grad=uv_grad)
    tape = wp.Tape()
    with tape, _op.force_generated_adjoint(backward == "generated"):
        if build_on_tape:
            tex.update()
        out = wt.sample(tex, uv_wp, **with_sampler(kw))
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    return tex, uv_wp


def _directional_fd(loss, x, direction, h):
    return (loss(x + h * direction) - loss(x - h * direction)) / (2 * h)


def _check_texel_gradient(rng, grad, img, uv, weights, **kw):
    """``grad`` (level 0) against central differences along three random directions over all texels."""
    assert np.abs(grad).sum() > 0
    for _ in range(3):
        direction = rng.normal(size=img.shape)
        fd = _directional_fd(lambda x: _forward(x.astype(np.float32), uv, weights, **kw).sum(), img, direction, 0.05)
        np.testing.assert_allclose((grad.astype(np.float64) * direction).sum(), fd, rtol=1e-4, atol=1e-4)


def _check_per_sample(loss_of, x, grad, rel_step, *, min_kept=0.9, kink=1e-2):
    """Compare ``grad`` (``[N, D]``) with central differences of the per-sample ``loss_of(x)``,
    leaving out samples whose one-sided differences disagree by more than ``kink`` (relative)."""
    x = np.asarray(x, np.float32)
    f0 = loss_of(x)
    kept_total = 0
    for axis in range(x.shape[1]):
        plus, minus = x.copy(), x.copy()
        plus[:, axis] += rel_step
        minus[:, axis] -= rel_step
        # The step actually taken, after float32 rounding of x ± step.
        up = plus[:, axis].astype(np.float64) - x[:, axis]
        down = x[:, axis].astype(np.float64) - minus[:, axis]
        fp, fm = loss_of(plus), loss_of(minus)
        central = (fp - fm) / (up + down)
        forward, backward = (fp - f0) / up, (f0 - fm) / down
        smooth = np.abs(forward - backward) <= kink * (1 + np.abs(central))
        np.testing.assert_allclose(grad[smooth, axis], central[smooth], rtol=2e-3, atol=2e-3)
        kept_total += smooth.mean()
    assert kept_total / x.shape[1] >= min_kept, "too few smooth samples to check the gradient"


BACKWARDS = ("generated", "hand-written")


@pytest.mark.parametrize("backward", BACKWARDS)
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("filt", list(FILTERS))
def test_texel_gradients_match_finite_differences(rng, filt, mode, backward):
    img = rng.random((12, 10, 3), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (300, 2)).astype(np.float32)
    weights = rng.normal(size=(300, 3))
    kw = {**FILTERS[filt], "address": mode, "border": BORDER}
    tex, _ = _backward(img, uv, weights, uv_grad=backward == "generated", backward=backward, **kw)
    _check_texel_gradient(rng, tex.grad(0), img, uv, weights, **kw)


@pytest.mark.parametrize("backward", BACKWARDS)
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("filt", list(FILTERS))
def test_uv_gradients_match_finite_differences(rng, filt, mode, backward):
    img = rng.random((16, 12, 4), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (400, 2)).astype(np.float32)
    weights = rng.normal(size=(400, 4))
    kw = {**FILTERS[filt], "address": mode, "border": BORDER}
    _, uv_wp = _backward(img, uv, weights, backward=backward, **kw)
    grad = uv_wp.grad.numpy().astype(np.float64)
    if filt == "nearest":
        np.testing.assert_array_equal(grad, 0.0)
    _check_per_sample(lambda x: _forward(img, x, weights, **kw), uv, grad, 2e-3 / 16)


@pytest.mark.parametrize("backward", BACKWARDS)
def test_lod_gradients_match_finite_differences(rng, backward):
    img = rng.random((32, 32, 2), dtype=np.float32)
    uv = rng.uniform(0, 1, (300, 2)).astype(np.float32)
    lod = rng.uniform(0.1, 4.9, (300, 1)).astype(np.float32)
    weights = rng.normal(size=(300, 2))
    tex = wt.Texture(img)
    lod_wp = wp.array(lod[:, 0], dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape, _op.force_generated_adjoint(backward == "generated"):
        out = wt.sample(tex, uv, lod=lod_wp)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grad = lod_wp.grad.numpy()[:, None].astype(np.float64)
    _check_per_sample(lambda x: _forward(img, uv, weights, lod=x[:, 0]), lod, grad, 1e-3)


def test_derivative_gradients_match_finite_differences(rng):
    img = rng.random((64, 64, 1), dtype=np.float32)
    uv = rng.uniform(0, 1, (300, 2)).astype(np.float32)
    dx = rng.uniform(0.02, 0.1, (300, 2)).astype(np.float32)
    dy = rng.uniform(-0.01, 0.01, (300, 2)).astype(np.float32)
    weights = rng.normal(size=(300, 1))
    dx_wp = wp.array(dx, dtype=wp.vec2, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = wt.sample(wt.Texture(img), uv, uv_dx=dx_wp, uv_dy=dy)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grad = dx_wp.grad.numpy().astype(np.float64)
    assert np.abs(grad).max() > 0
    _check_per_sample(lambda x: _forward(img, uv, weights, uv_dx=x, uv_dy=dy), dx, grad, 1e-4)


@pytest.mark.parametrize("backward", BACKWARDS)
def test_coarse_level_gradients_flow_to_level_zero_through_the_chain(rng, backward):
    img = rng.random((24, 20, 3), dtype=np.float32)
    uv = rng.uniform(-1, 2, (300, 2)).astype(np.float32)
    weights = rng.normal(size=(300, 3))
    kw = {"lod": 2.6}  # levels 2 and 3 only: level 0 is reached only through the box filter
    tex, _ = _backward(img, uv, weights, build_on_tape=True, uv_grad=backward == "generated", backward=backward, **kw)
    _check_texel_gradient(rng, tex.grad(0), img, uv, weights, **kw)


def test_each_level_receives_its_own_gradient(rng):
    # Without the chain on the tape, gradients stay on the level that was sampled.
    img = rng.random((16, 16, 2), dtype=np.float32)
    uv = rng.uniform(0, 1, (200, 2)).astype(np.float32)
    weights = rng.normal(size=(200, 2))
    tex, _ = _backward(img, uv, weights, build_on_tape=False, lod=1.5)
    assert np.abs(tex.grad(0)).sum() == 0.0
    for k in (1, 2):
        grad = tex.grad(k).astype(np.float64)
        direction = rng.normal(size=grad.shape)

        def loss(values):
            probe = wt.Texture(img)
            level = probe.numpy(k)
            level_vec4 = np.zeros((*level.shape[:2], 4), np.float32)
            level_vec4[..., :2] = values
            probe.level(k).assign(level_vec4)
            return (wt.sample(probe, uv, lod=1.5).numpy().astype(np.float64) * weights).sum()

        fd = _directional_fd(loss, tex.numpy(k).astype(np.float64), direction, 0.05)
        np.testing.assert_allclose((grad * direction).sum(), fd, rtol=1e-4, atol=1e-4)


def test_texture_array_gradients_go_to_the_sampled_layer(rng):
    layers = rng.random((3, 8, 8, 1), dtype=np.float32)
    arr = wt.TextureArray(layers, requires_grad=True)
    uv = rng.uniform(0, 1, (100, 2)).astype(np.float32)
    tape = wp.Tape()
    with tape:
        out = wt.sample(arr, uv, layer=1)
    out.grad.fill_(1.0)
    tape.backward()
    grad = arr.grad(0)
    assert np.abs(grad[[0, 2]]).sum() == 0.0
    np.testing.assert_allclose(grad[1].sum(), 100.0, rtol=1e-5)  # bilinear weights sum to 1 per sample


@pytest.mark.parametrize("backward", BACKWARDS)
def test_non_finite_uvs_give_zero_gradients(rng, backward):
    img = rng.random((8, 8, 1), dtype=np.float32)
    uv = np.array([[np.nan, 0.5], [0.25, 0.75], [np.inf, 0.1]], np.float32)
    tex, uv_wp = _backward(img, uv, np.ones((3, 1)), backward=backward)
    assert np.isfinite(tex.grad(0)).all()
    np.testing.assert_allclose(tex.grad(0).sum(), 1.0, rtol=1e-6)
    assert np.isfinite(uv_wp.grad.numpy()).all()
    assert (uv_wp.grad.numpy()[[0, 2]] == 0).all()
    assert (uv_wp.grad.numpy()[1] != 0).any()


LOOKUPS = {  # sample() keywords, each a way of choosing the levels
    "nearest": {"filter": "nearest", "address": "border", "border": BORDER},
    "bilinear lod 2.6": {"filter": "bilinear", "lod": 2.6, "address": "clamp"},
    "trilinear lod 1.4": {"lod": 1.4, "address": "mirror"},
    "trilinear per-sample lods": {"lod": "array"},
    "trilinear derivatives": {"uv_dx": "array", "uv_dy": "array"},
    "per-sample layers": {"layer": "array", "lod": 0.5},
}


@pytest.mark.parametrize("threads", [1, 2, 3])  # 3: private copies track tiles
@pytest.mark.parametrize("lookup", LOOKUPS)
def test_hand_written_texel_gradients_equal_the_generated_adjoint(rng, monkeypatch, lookup, threads):
    """The hand-written gradient runs where only texels need gradients and where the UVs need them
    too (the one input besides texels it serves with ``sample``'s LODs), and gives the texel
    gradients the generated adjoint gives, over every level read, on one thread and split over two
    (70 000 samples: more than one chunk)."""
    n = 70000
    layers = rng.random((3, 37, 29, 3), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (n, 2)).astype(np.float32)
    arrays = {"lod": rng.uniform(-0.5, 6.0, n).astype(np.float32), "uv_dx": rng.uniform(-0.2, 0.2, (n, 2)).astype(np.float32),
              "uv_dy": rng.uniform(-0.05, 0.05, (n, 2)).astype(np.float32), "layer": rng.integers(-1, 4, n)}  # fmt: skip
    kw = {"layer": 1, **{k: arrays[k] if v == "array" else v for k, v in LOOKUPS[lookup].items()}}

    def forward(uv_grad):
        tex = wt.TextureArray(layers, requires_grad=True)
        return wt.sample(tex, wp.array(uv, dtype=wp.vec2, requires_grad=uv_grad), **with_sampler(kw)), [tex]

    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, threads, forward, rng.normal(size=(n, 3)).astype(np.float32))
    assert scatters == 2
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("lookup", LOOKUPS)
def test_hand_written_uv_and_lod_gradients_equal_the_generated_adjoint(rng, monkeypatch, lookup, threads):
    """UVs (and a LOD per sample) needing gradients, with the texels or without: the hand-written
    gradient (one launch of it, and no generated adjoint) gives each sample's UV and LOD gradient
    as the generated adjoint does, to float rounding (they differentiate the same bilinear blends in
    another order), NaN nowhere, and zero where the UV is not finite (everywhere for nearest)."""
    n = 20000
    layers = rng.random((3, 37, 29, 3), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (n, 2)).astype(np.float32)
    uv[:3] = [(np.nan, 0.5), (0.5, np.inf), (1e30, 0.25)]
    arrays = {"lod": rng.uniform(-0.5, 6.0, n).astype(np.float32), "uv_dx": rng.uniform(-0.2, 0.2, (n, 2)).astype(np.float32),
              "uv_dy": rng.uniform(-0.05, 0.05, (n, 2)).astype(np.float32), "layer": rng.integers(-1, 4, n)}  # fmt: skip
    weights = rng.normal(size=(n, 3)).astype(np.float32)
    launched = launches(monkeypatch)
    wt.set_num_threads(threads)
    try:
        for texels in (True, False):
            results = []
            for generated in (False, True):
                launched.clear()
                kw = {"layer": 1, **{k: arrays[k] if v == "array" else v for k, v in LOOKUPS[lookup].items()}}
                inputs = [wp.array(uv, dtype=wp.vec2, requires_grad=True)]
                if isinstance(kw.get("lod"), np.ndarray):
                    kw["lod"] = wp.array(kw["lod"], dtype=float, requires_grad=True)
                    inputs.append(kw["lod"])
                tex = wt.TextureArray(layers, requires_grad=texels)
                tape = wp.Tape()
                with tape, _op.force_generated_adjoint(generated):
                    out = wt.sample(tex, inputs[0], **with_sampler(kw))
                out.grad.assign(weights)
                tape.backward()
                results.append([a.grad.numpy().reshape(n, -1) for a in inputs] + ([np.concatenate([tex.grad(k).reshape(-1, 1) for k in range(tex.num_levels)])] if texels else []))
                adjoint = [k for k in launched if k.endswith("_adjoint")]
                assert len(adjoint) == generated and len([k for k in launched if "texel_grad" in k]) == (not generated), launched
            for k, (hand, gen) in enumerate(zip(*results)):
                assert np.isfinite(hand).all() and (np.abs(hand).max() > 0) == (lookup != "nearest" or k == len(inputs))  # nearest: zero UV gradients
                np.testing.assert_allclose(hand, gen, rtol=1e-4, atol=1e-5 * np.abs(gen).max())
            np.testing.assert_array_equal(results[0][0][:2], 0.0)
    finally:
        wt.set_num_threads(None)
