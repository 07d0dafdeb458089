"""Stochastic sampling: reference agreement, continuity, broken repetition, histograms,
gradients, determinism and bad input.

Measured figures (autocorrelation peaks at the tile period, histogram moments) are printed; run
``pytest -s tests/test_stochastic.py`` to see them.
"""

import dataclasses

import numpy as np
import pytest
import warp as wp

import reference as ref
import reference_stochastic as rs
import warptex as wt
from backward_paths import assert_same_gradients, texel_gradients_both_ways
from conftest import with_sampler
from warptex import Method, Sampler, Stochastic, hex_taps, prepare_histogram
from warptex import _pack
from warptex._pack import stochastic_args

STOCHASTIC_FIELDS = tuple(f.name for f in dataclasses.fields(Stochastic))


def stochastic(tex, uv, **kw):
    """``wt.stochastic`` with the :class:`Stochastic` and :class:`Sampler` fields among ``kw``
    gathered into their objects (the cases below list them as keywords)."""
    kw = dict(kw)
    options = {k: kw.pop(k) for k in STOCHASTIC_FIELDS if k in kw}
    return wt.stochastic(tex, uv, Stochastic(**options), **with_sampler(kw))

TEXTURES = ("brick", "grass", "gravel")


def smooth_texture(h=32, w=32, channels=3, seed=0) -> np.ndarray:
    """A periodic texture of a few low-frequency sinusoids per channel, in [0.1, 0.9]: small neighbour steps."""
    rng = np.random.default_rng(seed)
    y, x = np.meshgrid(np.arange(h) / h, np.arange(w) / w, indexing="ij")
    img = np.zeros((h, w, channels))
    for c in range(channels):
        for _ in range(4):
            kx, ky = rng.integers(-3, 4, 2)
            img[..., c] += rng.uniform(0.5, 1) * np.sin(2 * np.pi * (kx * x + ky * y) + rng.uniform(0, 2 * np.pi))
    img -= img.min(axis=(0, 1))
    return (0.1 + 0.8 * img / img.max(axis=(0, 1))).astype(np.float32)


def _chain(tex):
    return ref.mip_chain(tex.numpy(0))


# -- agreement with the NumPy reference ---------------------------------------------------------------


@pytest.mark.parametrize("mirror", [False, True])
@pytest.mark.parametrize("lod", [None, 1.6])
def test_hash4_matches_reference(rng, mirror, lod):
    tex = wt.Texture(rng.random((16, 12, 3), dtype=np.float32))
    uv = rng.uniform(-40, 40, (3000, 2)).astype(np.float32)
    kw = {"lod": lod} if lod is not None else {}
    for seed, blend in ((0, None), (7, (0.1, 0.6)), (2**32 - 1, (0.0, 1.0))):
        out = stochastic(tex, uv, method="hash4", seed=seed, blend=blend, mirror=mirror, **kw).numpy()
        expect = rs.hash4(
            _chain(tex), uv, seed=seed, blend=blend or (0.25, 0.75), mirror=mirror,
            lod=lod or 0.0, filt="trilinear" if lod else "bilinear",
        )  # fmt: skip
        np.testing.assert_allclose(out, expect, atol=1e-5, rtol=0)


@pytest.mark.parametrize("mirror", [False, True])
def test_cheap2_matches_reference(rng, mirror):
    tex = wt.Texture(rng.random((10, 16, 2), dtype=np.float32))
    uv = rng.uniform(-30, 30, (3000, 2)).astype(np.float32)
    for seed, freq, levels, lod in ((0, 0.5, 8.0, None), (3, 1.7, 5.5, 2.3)):
        kw = {"lod": lod} if lod is not None else {}
        out = stochastic(tex, uv, method="cheap2", seed=seed, mirror=mirror, noise_frequency=freq, noise_levels=levels, **kw).numpy()
        expect = rs.cheap2(
            _chain(tex), uv, seed=seed, mirror=mirror, frequency=freq, levels=levels,
            lod=lod or 0.0, filt="trilinear" if lod else "bilinear",
        )  # fmt: skip
        np.testing.assert_allclose(out, expect, atol=1e-5, rtol=0)


@pytest.mark.parametrize("contrast, rotation", [(1.0, 0.0), (4.0, 1.0), (2.5, 0.3)])
def test_hex_matches_reference(rng, contrast, rotation):
    tex = wt.Texture(rng.random((16, 16, 3), dtype=np.float32))
    uv = rng.uniform(-20, 20, (3000, 2)).astype(np.float32)
    out = stochastic(tex, uv, method="hex", seed=11, contrast=contrast, rotation=rotation).numpy()
    expect = rs.hex_sample(_chain(tex), uv, seed=11, contrast=contrast, rotation=rotation)
    np.testing.assert_allclose(out, expect, atol=1e-5, rtol=0)


@pytest.mark.parametrize("decorrelate, lod", [(False, None), (True, None), (False, 1.4), (True, 2.0)])
def test_hex_histogram_blend_matches_reference(rng, decorrelate, lod):
    img = rng.random((16, 16, 3), dtype=np.float32)
    img[..., 1] = 0.5 * img[..., 0] + 0.5 * img[..., 1] ** 2  # correlated, non-uniform histogram
    tex = wt.Texture(img)
    hist = prepare_histogram(tex, decorrelate=decorrelate)
    uv = rng.uniform(-20, 20, (3000, 2)).astype(np.float32)
    kw = {"lod": lod} if lod is not None else {}
    out = stochastic(tex, uv, method="hex", seed=5, contrast=2.0, histogram=hist, **kw).numpy()
    basis = centre = None
    if decorrelate:
        basis, centre = hist.basis.numpy()[0], hist.centre.numpy()[0]
    expect = rs.hex_sample(
        _chain(hist.texture), uv, seed=5, contrast=2.0, lut=hist.lut_numpy()[0], basis=basis, centre=centre,
        lod=lod or 0.0, filt="trilinear" if lod else "bilinear",
    )  # fmt: skip
    np.testing.assert_allclose(out, expect, atol=1e-5, rtol=0)


def test_histogram_transform_is_gaussian_and_inverts(rng):
    img = rng.random((32, 32, 2), dtype=np.float32) ** 3  # skewed
    for lut_size, error in ((4096, 2e-3), (16384, 1e-3)):  # the round trip converges with the LUT size
        hist = prepare_histogram(wt.Texture(img), lut_size=lut_size)
        g = hist.texture.numpy(0).astype(np.float64)
        np.testing.assert_allclose(g.mean(axis=(0, 1)), 0.5, atol=2e-3)
        np.testing.assert_allclose(g.std(axis=(0, 1)), 1 / 6, rtol=2e-2)
        lut = hist.lut_numpy()[0, 0]
        grid = -0.5 + (np.arange(lut_size) + 0.5) / lut_size * 2.0
        back = np.stack([np.interp(g[..., c], grid, lut[c]) for c in range(2)], axis=-1)
        np.testing.assert_allclose(back, img, atol=error)  # extremes included
        assert (np.diff(lut, axis=1) >= 0).all()


def test_method_none_is_plain_sampling(rng):
    tex = wt.Texture(rng.random((8, 8, 4), dtype=np.float32))
    uv = rng.uniform(-3, 3, (500, 2)).astype(np.float32)
    for kw in ({}, {"lod": 1.2}, {"filter": "nearest"}):
        np.testing.assert_array_equal(stochastic(tex, uv, method="none", **kw).numpy(), wt.sample(tex, uv, **with_sampler(kw)).numpy())


def test_options_on_one_texture_each_read_their_own(rng):
    # stochastic() packs a texture's arguments once per set of options (warptex._pack.packed):
    # calls on one texture that alternate method, seed, blend, LOD and sampler must each compute
    # what a fresh texture does, and a histogram (never kept) what its own texture does.
    image = rng.random((32, 32, 4), dtype=np.float32)
    shared = wt.Texture(image)
    uv = rng.uniform(-2, 6, (400, 2)).astype(np.float32)
    cases = [
        (Stochastic("hash4"), {}), (Stochastic("hash4"), {"lod": 1.5}), (Stochastic("hash4"), {"lod": 2.5}), (Stochastic("hash4"), {"address": "mirror"}),
        (Stochastic("hash4", seed=3), {}), (Stochastic("hash4", seed=3, mirror=True), {"lod": 1.5}),
        (Stochastic("cheap2"), {"lod": 1.5}), (Stochastic("hex", contrast=2.0), {}), (Stochastic("hex", rotation=0.5), {"address": "mirror"}),
        (Stochastic("hash4", blend=(0.3, 0.7)), {"filter": "nearest"}), (Stochastic("cheap2", noise_frequency=0.25), {}),
    ]
    for rounds in range(2):
        for option, kw in cases:
            fresh = wt.stochastic(wt.Texture(image), uv, option, **with_sampler(kw)).numpy()
            np.testing.assert_array_equal(wt.stochastic(shared, uv, option, **with_sampler(kw)).numpy(), fresh, err_msg=f"round {rounds}: {option} {kw}")
    fresh = wt.Texture(image)
    want = wt.stochastic(fresh, uv, Stochastic("hex", histogram=prepare_histogram(fresh))).numpy()
    kept = len(_pack._packed[shared])
    for k in range(2):
        np.testing.assert_array_equal(wt.stochastic(shared, uv, Stochastic("hex", histogram=prepare_histogram(shared))).numpy(), want)
    assert len(_pack._packed[shared]) == kept  # a histogram's option is not kept


def test_lod_comes_from_the_unperturbed_derivatives(rng):
    tex = wt.Texture(rng.random((32, 32, 3), dtype=np.float32))
    uv = rng.uniform(-5, 5, (800, 2)).astype(np.float32)
    dx = rng.uniform(0.01, 0.2, (800, 2)).astype(np.float32)
    dy = rng.uniform(-0.05, 0.05, (800, 2)).astype(np.float32)
    lod = ref.lod_from_derivatives(dx, dy, 32, 32).astype(np.float32)
    for method in ("hash4", "cheap2", "hex"):
        a = stochastic(tex, uv, method=method, uv_dx=dx, uv_dy=dy, mirror=method != "hex", rotation=0.5 * (method == "hex")).numpy()
        b = stochastic(tex, uv, method=method, lod=lod, mirror=method != "hex", rotation=0.5 * (method == "hex")).numpy()
        np.testing.assert_allclose(a, b, atol=2e-6)


# -- hex grid -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("rotation", [0.0, 1.0])
def test_hex_weights_sum_to_one_and_offsets_are_constant_per_tile(rotation):
    g = (np.arange(160) + 0.5) / 160 * 2.0 - 0.5  # a 2.0 x 2.0 UV window: dozens of tiles
    uv = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2).astype(np.float32)
    w, verts, taps = hex_taps(uv, seed=3, contrast=3.0, rotation=rotation)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-6)
    assert (w >= 0).all()
    ref_w, ref_v, ref_taps = rs.hex_taps(uv, seed=3, contrast=3.0, rotation=rotation)
    np.testing.assert_allclose(w, ref_w, atol=1e-5)
    used = w > 1e-4  # the zero-weight vertex of an edge may be either neighbour
    assert (verts[used] == ref_v[used]).all()
    d = taps - ref_taps  # kernel taps are reduced by an even integer: same texels
    np.testing.assert_allclose(d - np.round(d / 2) * 2, 0.0, atol=2e-5)

    # Within each vertex's tile (where its weight is > 0) the tap is one rigid motion of uv:
    # tap = R uv + t with a single rotation R and offset t, R = I without rotation.
    # The kernel reduced uv by 2 floor(uv / 2) (same texels); undo it to see the motion.
    full = taps.astype(np.float64) + 2.0 * np.floor(uv / 2.0)[:, None, :]
    keys, inverse = np.unique(verts.reshape(-1, 2)[w.reshape(-1) > 0], axis=0, return_inverse=True)
    x = np.repeat(uv, 3, axis=0)[w.reshape(-1) > 0].astype(np.float64)
    y = full.reshape(-1, 2)[w.reshape(-1) > 0]
    checked = 0
    for t in range(len(keys)):
        sel = inverse.ravel() == t
        if sel.sum() < 20:
            continue
        a = np.c_[x[sel], np.ones(sel.sum())]
        fit, *_ = np.linalg.lstsq(a, y[sel], rcond=None)
        r = fit[:2].T
        assert np.abs(a @ fit - y[sel]).max() < 1e-4, f"tile {keys[t]}: taps are not one rigid motion"
        np.testing.assert_allclose(r @ r.T, np.eye(2), atol=1e-4)
        if rotation == 0.0:
            np.testing.assert_allclose(r, np.eye(2), atol=1e-5)
        checked += 1
    assert checked >= 20


# -- continuity -------------------------------------------------------------------------------------


def _max_step(tex, uv, **kw):
    out = stochastic(tex, uv, **kw).numpy().astype(np.float64)
    return np.abs(np.diff(out, axis=0)).max()


CONTINUITY_CASES = {
    "hash4": {"method": "hash4"},
    "hash4-mirror-trilinear": {"method": "hash4", "mirror": True, "lod": 1.3},
    "cheap2": {"method": "cheap2", "noise_frequency": 1.0},
    "hex": {"method": "hex", "contrast": 4.0, "rotation": 1.0},
    "hex-histogram-trilinear": {"method": "hex", "histogram": True, "lod": 0.7},
}


@pytest.mark.parametrize("case", list(CONTINUITY_CASES))
def test_output_is_continuous_across_cell_borders(case):
    img = smooth_texture()
    tex = wt.Texture(img)
    kw = dict(CONTINUITY_CASES[case])
    if kw.pop("histogram", False):
        kw["histogram"] = prepare_histogram(tex)
    neighbour = max(np.abs(np.diff(img, axis=a)).max() for a in (0, 1))
    start, end = np.array([0.13, 0.37]), np.array([6.91, 4.18])  # crosses many cells, tiles and noise steps
    step = 0.25 / 32  # a quarter texel
    n = int(np.linalg.norm(end - start) / step)
    line = lambda k: (start + np.linspace(0, 1, k * n + 1)[:, None] * (end - start)).astype(np.float32)  # noqa: E731
    coarse, fine = _max_step(tex, line(1), **kw), _max_step(tex, line(4), **kw)
    print(f"\ncontinuity {case}: max step {coarse:.4f} (quarter texel), {fine:.4f} (1/16 texel); neighbour texel diff {neighbour:.4f}")
    assert coarse <= neighbour
    assert fine <= 0.5 * coarse  # steps shrink with the step size: no jump anywhere on the line
    if case == "cheap2":  # the line must actually switch offsets
        l = rs.value_noise(line(1).astype(np.float64) * 1.0, 0) * 8.0
        assert len(np.unique(np.floor(l))) >= 3


def test_continuity_check_detects_a_hard_seam():
    # A near-zero blend window makes a visible seam; the measure used above must catch it.
    tex = wt.Texture(smooth_texture())
    neighbour = max(np.abs(np.diff(smooth_texture(), axis=a)).max() for a in (0, 1))
    uv = (np.array([0.13, 0.37]) + np.linspace(0, 1, 3000)[:, None] * np.array([6.78, 3.81])).astype(np.float32)
    assert _max_step(tex, uv, method="hash4", blend=(0.4999, 0.5001)) > neighbour


# -- repetition and histograms on real textures ----------------------------------------------------


def _tiled(tex, method, tiles=16, size=512, **kw):
    """``tiles × tiles`` repeats on a ``size²`` image, LOD from the pixel footprint: grey ``[size, size]``."""
    centres = (np.arange(size) + 0.5) / size * tiles
    uv = np.stack(np.meshgrid(centres, centres[::-1], indexing="xy"), axis=-1).astype(np.float32)
    d = np.full(uv.shape, 0.0, np.float32)
    dx, dy = d.copy(), d.copy()
    dx[..., 0] = tiles / size
    dy[..., 1] = -tiles / size
    return stochastic(tex, uv, method=method, uv_dx=dx, uv_dy=dy, **kw).numpy().mean(axis=-1).astype(np.float64)


def _autocorrelation_at(image, period):
    """Normalised circular autocorrelation, its peak within ±2 px of ``period`` along x and y (mean of both)."""
    x = image - image.mean()
    spec = np.fft.rfft2(x)
    r = np.fft.irfft2(spec * np.conj(spec), s=x.shape) / (x * x).sum()
    near = range(period - 2, period + 3)
    return 0.5 * (max(r[0, k] for k in near) + max(r[k, 0] for k in near))


@pytest.mark.parametrize("name", TEXTURES)
def test_repetition_is_broken_on_real_textures(shared_data, name):
    tex = wt.Texture.from_file(shared_data / "textures" / f"{name}.png")
    hist = prepare_histogram(tex)
    tiles, size = 16, 512
    period = size // tiles
    peaks = {
        "plain": _autocorrelation_at(_tiled(tex, "none"), period),
        "hash4": _autocorrelation_at(_tiled(tex, "hash4"), period),
        "cheap2": _autocorrelation_at(_tiled(tex, "cheap2"), period),
        "hex": _autocorrelation_at(_tiled(tex, "hex", histogram=hist), period),
    }
    print(f"\n{name}: autocorrelation at the tile period ({period} px, {tiles}x tiling): " + ", ".join(f"{k} {v:.3f}" for k, v in peaks.items()))
    assert peaks["plain"] > 0.95
    for method in ("hash4", "cheap2", "hex"):
        assert peaks[method] < 0.5 * peaks["plain"], f"{name}: {method} keeps the repetition ({peaks[method]:.3f})"


@pytest.mark.parametrize("name", ["grass", "gravel"])
def test_hex_histogram_keeps_mean_and_contrast(shared_data, rng, name):
    tex = wt.Texture.from_file(shared_data / "textures" / f"{name}.png")
    src = tex.numpy(0).reshape(-1, tex.channels).astype(np.float64)
    uv = rng.uniform(-50, 50, (60000, 2)).astype(np.float32)
    kw = {"method": "hex", "filter": "nearest", "contrast": 1.0, "seed": 2}
    blended = stochastic(tex, uv, histogram=prepare_histogram(tex), **kw).numpy().astype(np.float64)
    linear = stochastic(tex, uv, **kw).numpy().astype(np.float64)
    mean, std = src.mean(0), src.std(0)
    rel = lambda out: (out.mean(0) / mean - 1, out.std(0) / std - 1)  # noqa: E731
    (m_h, s_h), (m_l, s_l) = rel(blended), rel(linear)
    print(
        f"\n{name}: input mean {mean.round(4)} std {std.round(4)}; hex+histogram mean {m_h.round(4)} std {s_h.round(4)} "
        f"(relative); linear 3-tap mean {m_l.round(4)} std {s_l.round(4)}"
    )
    assert (np.abs(m_h) < 0.03).all() and (np.abs(s_h) < 0.03).all()
    assert (s_l < -0.15).all()  # linear blending of 3 taps loses contrast


@pytest.mark.parametrize("name", TEXTURES)
def test_prefiltered_luts_keep_the_mean_at_every_distance(shared_data, rng, name):
    # Coarse mips of the Gaussianised texture have less variance; with the level-0 LUT at every
    # level the output drifts towards the median. Per-level (prefiltered) LUTs keep the mean.
    tex = wt.Texture.from_file(shared_data / "textures" / f"{name}.png")
    hist = prepare_histogram(tex)
    level0 = hist.lut_numpy()[:, :1].repeat(hist.levels, axis=1)
    unfiltered = dataclasses.replace(hist, lut=wp.array(level0.reshape(-1), dtype=float))
    mean = tex.numpy(0).astype(np.float64).mean()
    uv = rng.uniform(-50, 50, (20000, 2)).astype(np.float32)
    lods = (0.0, 1.5, 3.0, 5.0, 7.0, 9.0)
    drift = {
        label: np.array([stochastic(tex, uv, method="hex", histogram=h, lod=lod).numpy().mean() / mean - 1 for lod in lods])
        for label, h in (("prefiltered", hist), ("level-0 LUT", unfiltered))
    }
    print(f"\n{name}: relative mean drift at LOD {lods}: " + "; ".join(f"{k} {np.round(v, 4).tolist()}" for k, v in drift.items()))
    assert np.abs(drift["prefiltered"]).max() < 0.05
    assert np.abs(drift["prefiltered"][-1]) < 0.005  # the coarsest level reads the mean
    if name == "brick":  # skewed histogram: mean and median differ by a quarter
        assert np.abs(drift["level-0 LUT"][-1]) > 0.2


def test_decorrelated_histogram_keeps_colour_moments(rng):
    # Correlated colours: the decorrelated transform keeps the per-channel moments and the correlation.
    base = rng.random((64, 64), dtype=np.float32)
    img = np.stack([base, 0.7 * base + 0.3 * rng.random((64, 64)), base**2], axis=-1).astype(np.float32)
    tex = wt.Texture(img)
    uv = rng.uniform(-50, 50, (40000, 2)).astype(np.float32)
    out = stochastic(tex, uv, method="hex", filter="nearest", histogram=prepare_histogram(tex, decorrelate=True)).numpy()
    src = img.reshape(-1, 3)
    np.testing.assert_allclose(out.mean(0), src.mean(0), rtol=0.03)
    np.testing.assert_allclose(out.std(0), src.std(0), rtol=0.05)
    np.testing.assert_allclose(np.corrcoef(out.T), np.corrcoef(src.T), atol=0.05)


# -- gradients ----------------------------------------------------------------------------------------

GRAD_CASES = {
    "hash4": {"method": "hash4", "mirror": True, "lod": 1.3},
    "cheap2": {"method": "cheap2", "noise_frequency": 1.5, "lod": 0.6},
    "hex": {"method": "hex", "contrast": 3.0, "rotation": 1.0, "lod": 1.3},
}


@pytest.mark.parametrize("backward", ["hand-written", "generated"])
@pytest.mark.parametrize("case", list(GRAD_CASES))
def test_texel_gradients_match_finite_differences(rng, case, backward):
    """Only the texels need gradients: the hand-written texel gradient; the UVs too: the generated adjoint."""
    img = rng.random((16, 16, 3), dtype=np.float32)
    uv = rng.uniform(-4, 4, (400, 2)).astype(np.float32)
    weights = rng.normal(size=(400, 3))
    kw = GRAD_CASES[case]
    tex = wt.Texture(img, requires_grad=True)
    tape = wp.Tape()
    with tape:
        tex.update()
        out = stochastic(tex, wp.array(uv, dtype=wp.vec2, requires_grad=backward == "generated"), **kw)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grad = tex.grad(0).astype(np.float64)
    assert np.abs(grad).sum() > 0
    loss = lambda x: (stochastic(wt.Texture(x.astype(np.float32)), uv, **kw).numpy().astype(np.float64) * weights).sum()  # noqa: E731
    for _ in range(2):
        direction = rng.normal(size=img.shape)
        fd = (loss(img + 0.05 * direction) - loss(img - 0.05 * direction)) / 0.1
        np.testing.assert_allclose((grad * direction).sum(), fd, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("threads", [1, 2, 3])  # 3: private copies track tiles
@pytest.mark.parametrize("case", [*GRAD_CASES, "hex derivatives", "hex histogram"])
def test_hand_written_texel_gradients_equal_the_generated_adjoint(rng, monkeypatch, case, threads):
    """The hand-written texel gradient (only texels need gradients) gives what the generated adjoint
    gives when the UVs need gradients too, over every level, on one thread and split over two
    (70 000 samples). The histogram blend, not linear in the texels, always takes the generated adjoint."""
    n = 70000
    img = rng.random((37, 29, 3), dtype=np.float32)
    uv = rng.uniform(-6, 6, (n, 2)).astype(np.float32)
    kw = dict(GRAD_CASES.get(case, {"method": "hex", "rotation": 0.3}))
    if case == "hex derivatives":
        kw.update(uv_dx=rng.uniform(-0.2, 0.2, (n, 2)).astype(np.float32), uv_dy=rng.uniform(-0.05, 0.05, (n, 2)).astype(np.float32))

    def forward(uv_grad):
        tex = wt.Texture(img, requires_grad=True)
        histogram = prepare_histogram(tex, requires_grad=True) if case == "hex histogram" else None
        out = stochastic(tex, wp.array(uv, dtype=wp.vec2, requires_grad=uv_grad), histogram=histogram, **kw)
        return out, [tex if histogram is None else histogram.texture]

    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, threads, forward, rng.normal(size=(n, 3)).astype(np.float32))
    assert scatters == (0 if case == "hex histogram" else 1)
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


def _check_against_reference_differences(ref_loss, x, grad, *, step=1e-6, tol=1e-3, min_kept=0.9):
    """``grad`` [N, D] against float64 central differences of the NumPy reference ``ref_loss(x)`` [N].

    Differences of the float32 kernels are dominated by rounding at steps small enough to ignore
    curvature, so the differences are taken on the float64 reference (which agrees with the kernels
    to 1e-5, tested above) with a tiny step. Samples within a step of a kink (bilinear texel-centre
    lines, LUT entries) show one-sided differences that disagree and are left out; at least
    ``min_kept`` of them must remain, so the check cannot pass by leaving everything out.
    """
    x = np.asarray(x, np.float64)
    f0 = ref_loss(x)
    for axis in range(x.shape[1]):
        e = np.zeros(x.shape[1])
        e[axis] = step
        fp, fm = ref_loss(x + e), ref_loss(x - e)
        central = (fp - fm) / (2 * step)
        smooth = np.abs((fp - f0) - (f0 - fm)) / step <= 1e-4 * (1 + np.abs(central))
        assert smooth.mean() >= min_kept, f"only {smooth.mean():.0%} smooth samples on axis {axis}"
        np.testing.assert_allclose(grad[smooth, axis], central[smooth], rtol=tol, atol=tol)


def _uv_gradient(tex, uv, weights, **kw):
    """``dL/duv`` [N, 2] of ``L = Σ weights · stochastic(tex, uv)`` by the backward pass."""
    uv_wp = wp.array(uv, dtype=wp.vec2, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = stochastic(tex, uv_wp, **kw)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grad = uv_wp.grad.numpy().astype(np.float64)
    assert np.isfinite(grad).all() and np.abs(grad).max() > 0
    return grad


def _reference(case, chain, uv, hist=None):
    """The NumPy reference of one ``UV_GRAD_CASES`` entry at ``uv`` [N, 2]."""
    if case == "hash4":
        return rs.hash4(chain, uv, mirror=True, lod=1.3, filt="trilinear")
    if case == "cheap2":
        return rs.cheap2(chain, uv, frequency=1.5, lod=0.6, filt="trilinear")
    if case == "hex":
        return rs.hex_sample(chain, uv, contrast=3.0, rotation=1.0, lod=1.3, filt="trilinear")
    return rs.hex_sample(chain, uv, contrast=2.0, lut=hist.lut_numpy()[0])  # level 0 (no LOD)


UV_GRAD_CASES = {**GRAD_CASES, "hex-histogram": {"method": "hex", "contrast": 2.0}}


@pytest.mark.parametrize("case", list(UV_GRAD_CASES))
def test_uv_gradients_match_finite_differences(rng, case):
    tex = wt.Texture(smooth_texture(seed=1))
    kw = dict(UV_GRAD_CASES[case])
    hist = None
    if case == "hex-histogram":
        hist = kw["histogram"] = prepare_histogram(tex)
    uv = rng.uniform(-4, 4, (400, 2)).astype(np.float32)
    weights = rng.normal(size=(400, 3))
    grad = _uv_gradient(tex, uv, weights, **kw)
    chain = _chain(hist.texture if hist else tex)
    _check_against_reference_differences(lambda x: (_reference(case, chain, x, hist) * weights).sum(axis=-1), uv, grad)


@pytest.mark.parametrize("case", ["hash4", "cheap2", "hex"])
def test_tiling_scale_gradient_matches_finite_differences(rng, case):
    # uv = s * uv0, one tiling scale s per sample: dL/ds = uv0 · dL/duv against differences in s.
    tex = wt.Texture(smooth_texture(seed=2))
    uv0 = rng.uniform(0.2, 1, (400, 2))
    scale = rng.uniform(2, 6, (400, 1))
    weights = rng.normal(size=(400, 3))
    uv = (scale * uv0).astype(np.float32)
    grad = (_uv_gradient(tex, uv, weights, **GRAD_CASES[case]) * uv0).sum(axis=1, keepdims=True)
    chain = _chain(tex)
    _check_against_reference_differences(lambda s: (_reference(case, chain, s * uv0) * weights).sum(axis=-1), scale, grad)


def test_uv_gradients_match_kernel_differences_in_aggregate(rng):
    # The kernels' own differences, summed over samples and along one random direction per sample.
    tex = wt.Texture(smooth_texture(seed=3))
    uv = rng.uniform(-3, 3, (2000, 2)).astype(np.float32)
    direction = rng.normal(size=uv.shape)
    weights = rng.normal(size=(2000, 3))
    for kw in GRAD_CASES.values():
        grad = _uv_gradient(tex, uv, weights, **kw)
        loss = lambda t: (stochastic(tex, (uv + t * direction).astype(np.float32), **kw).numpy() * weights).sum()  # noqa: E731
        fd = (loss(1e-4) - loss(-1e-4)) / 2e-4
        print(f"\n{kw['method']}: directional uv derivative {(grad * direction).sum():.3f}, kernel difference {fd:.3f}")
        np.testing.assert_allclose((grad * direction).sum(), fd, rtol=1e-2)  # kinks bias the sum a little


def test_histogram_texture_receives_the_gradients(rng):
    tex = wt.Texture(rng.random((16, 16, 1), dtype=np.float32))
    hist = prepare_histogram(tex, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = stochastic(tex, rng.uniform(0, 4, (200, 2)).astype(np.float32), method="hex", histogram=hist)
    out.grad.fill_(1.0)
    tape.backward()
    assert np.abs(hist.texture.grad(0)).sum() > 0 and np.isfinite(hist.texture.grad(0)).all()


# -- determinism, layers, edge cases --------------------------------------------------------------------


def test_deterministic_per_seed(rng):
    tex = wt.Texture(rng.random((16, 16, 3), dtype=np.float32))
    uv = rng.uniform(-10, 10, (2000, 2)).astype(np.float32)
    for method in ("hash4", "cheap2", "hex"):
        a = stochastic(tex, uv, method=method, seed=42).numpy()
        np.testing.assert_array_equal(a, stochastic(tex, uv, method=method, seed=42).numpy())
        assert np.abs(a - stochastic(tex, uv, method=method, seed=43).numpy()).max() > 0.1


@pytest.mark.skipif(not wp.is_cuda_available(), reason="no CUDA device")
def test_same_result_on_cpu_and_cuda(rng):
    img = rng.random((16, 16, 3), dtype=np.float32)
    uv = rng.uniform(-100, 100, (4000, 2)).astype(np.float32)
    for method in ("hash4", "cheap2", "hex"):
        out = [stochastic(wt.Texture(img, device=d), uv, method=method, seed=9, lod=0.7).numpy() for d in ("cpu", "cuda:0")]
        np.testing.assert_allclose(out[0], out[1], atol=1e-5)
    _, v_cpu, _ = hex_taps(uv, seed=9, device="cpu")
    _, v_gpu, _ = hex_taps(uv, seed=9, device="cuda:0")
    np.testing.assert_array_equal(v_cpu, v_gpu)


def test_texture_array_layers_match_single_textures(rng):
    layers = rng.random((3, 8, 8, 2), dtype=np.float32)
    arr = wt.TextureArray(layers)
    uv = rng.uniform(-5, 5, (600, 2)).astype(np.float32)
    per = rng.integers(0, 3, 600)
    hist = prepare_histogram(arr)
    out = stochastic(arr, uv, method="hex", layer=per, histogram=hist).numpy()
    for k in range(3):
        single = wt.Texture(layers[k])
        expect = stochastic(single, uv, method="hex", histogram=prepare_histogram(single)).numpy()
        np.testing.assert_allclose(out[per == k], expect[per == k], atol=1e-6)
    np.testing.assert_allclose(
        stochastic(arr, uv, method="hash4", layer=1).numpy(), stochastic(wt.Texture(layers[1]), uv, method="hash4").numpy(), atol=1e-7
    )


def test_non_finite_uv_gives_nan_and_large_uv_stays_exact(rng):
    tex = wt.Texture(rng.random((8, 8, 1), dtype=np.float32))
    out = stochastic(tex, np.array([[np.nan, 0.5], [0.5, np.inf]], np.float32), method="hex").numpy()
    assert np.isnan(out).all()
    uv = rng.uniform(0, 1, (200, 2)).astype(np.float32)
    far = (uv + np.float32(4096)).astype(np.float32)  # exact shift by whole cells
    a = stochastic(tex, far, method="hash4", seed=1).numpy()
    np.testing.assert_allclose(a, rs.hash4([tex.numpy(0).astype(np.float64)], far, seed=1), atol=1e-5)


def test_stochastic_args_pack_the_options_for_other_techniques():
    tex = wt.Texture(np.zeros((4, 4, 3), np.float32))
    params, sampled = stochastic_args("triplanar", Stochastic(Method.HEX, seed=3, contrast=2.0, rotation=True), tex, Sampler())
    assert sampled is tex and params.method == 3 and params.seed == 3 and params.rotation == 1.0
    assert (params.blend_lo, params.blend_hi) == (0.25, 0.75)
    hist = prepare_histogram(tex)
    _, sampled = stochastic_args("triplanar", Stochastic("hex", histogram=hist), tex, Sampler())
    assert sampled is hist.texture
    with pytest.raises(ValueError, match=r"triplanar\(\): stochastic sampling needs address 'wrap' or 'mirror'"):
        stochastic_args("triplanar", Stochastic("hash4"), tex, Sampler(address="clamp"))
    cheap2 = Stochastic("hash4").replace(method="cheap2")  # an unset blend window follows the method
    assert cheap2.blend is None and cheap2.blend_window == (0.2, 0.8)


BAD_INPUTS = [
    ({"method": "quilez"}, ValueError, r"Stochastic\(\): method must be one of .*'quilez'"),
    ({"seed": -1}, ValueError, r"Stochastic\(\): seed must be in \[0, 2\*\*32\), got -1"),
    ({"seed": 1.5}, TypeError, r"Stochastic\(\): seed must be an int, got float"),
    ({"blend": (0.8, 0.2)}, ValueError, r"Stochastic\(\): blend must be two numbers .*\(0.8, 0.2\)"),
    ({"blend": (0.1, 0.2, 0.3)}, ValueError, r"Stochastic\(\): blend must be two numbers"),
    ({"mirror": 1}, TypeError, r"Stochastic\(\): mirror must be a bool, got int"),
    ({"contrast": 0.5}, ValueError, r"Stochastic\(\): contrast must be >= 1 .*got 0.5"),
    ({"rotation": 2.0}, ValueError, r"Stochastic\(\): rotation must be .*got 2.0"),
    ({"noise_frequency": 0.0}, ValueError, r"Stochastic\(\): noise_frequency and noise_levels must be positive"),
    ({"histogram": "lut"}, TypeError, r"Stochastic\(\): histogram must be a Histogram"),
    ({"address": "clamp"}, ValueError, r"stochastic\(\): stochastic sampling needs address 'wrap' or 'mirror' .*'clamp'"),
    ({"filter": "trilinear"}, ValueError, r"stochastic\(\): filter='trilinear' needs lod="),
    ({"lod": 1.0, "uv_dx": np.zeros((4, 2)), "uv_dy": np.zeros((4, 2))}, ValueError, r"stochastic\(\): pass either lod="),
    ({"uv_dx": np.zeros((4, 2))}, ValueError, r"stochastic\(\): uv_dx and uv_dy must be given together"),
    ({"uv_dx": np.zeros((3, 2)), "uv_dy": np.zeros((3, 2))}, ValueError, r"stochastic\(\): uv_dx must have the shape of uv"),
    ({"layer": 2}, ValueError, r"stochastic\(\): layer must be in \[0, 0\], got 2"),
]


@pytest.mark.parametrize("kwargs, error, message", BAD_INPUTS)
def test_bad_input_raises(kwargs, error, message):
    tex = wt.Texture(np.zeros((4, 4, 3), np.float32))
    with pytest.raises(error, match=message):
        stochastic(tex, np.zeros((4, 2), np.float32), **kwargs)


def test_bad_histogram_and_texture_raise():
    tex = wt.Texture(np.zeros((4, 4, 3), np.float32))
    uv = np.zeros((4, 2), np.float32)
    other = prepare_histogram(wt.Texture(np.zeros((8, 4, 3), np.float32)))
    with pytest.raises(ValueError, match=r"stochastic\(\): the stochastic histogram was built for .*\(1, 8, 4, 3\).*\(1, 4, 4, 3\)"):
        stochastic(tex, uv, method="hex", histogram=other)
    with pytest.raises(ValueError, match=r"Stochastic\(\): histogram= is used by method='hex' only, got method='hash4'"):
        stochastic(tex, uv, method="hash4", histogram=prepare_histogram(tex))
    with pytest.raises(TypeError, match=r"stochastic\(\): texture must be a Texture or TextureArray, got ndarray"):
        stochastic(np.zeros((4, 4, 3)), uv)
    with pytest.raises(TypeError, match=r"stochastic\(\): uv must hold real numbers"):
        stochastic(tex, np.array([["a", "b"]]))
    with pytest.raises(TypeError, match=r"stochastic\(\): stochastic must be None, a method name or a warptex.Stochastic, got dict"):
        wt.stochastic(tex, uv, {"method": "hex"})
    with pytest.raises(ValueError, match=r"stochastic\(\): stochastic: Stochastic\(\): method must be one of"):
        wt.stochastic(tex, uv, "quilez")
    with pytest.raises(ValueError, match=r"prepare_histogram\(\): decorrelate=True needs 3 or 4 channels, the texture has 1"):
        prepare_histogram(wt.Texture(np.zeros((4, 4), np.float32)), decorrelate=True)
    with pytest.raises(ValueError, match=r"prepare_histogram\(\): lut_size must be an int in \[16, 1048576\], got 3"):
        prepare_histogram(tex, lut_size=3)
    with pytest.raises(TypeError, match=r"prepare_histogram\(\): texture must be a Texture or TextureArray, got list"):
        prepare_histogram([[0.0]])


def test_a_one_texel_texture_decorrelates_to_itself():
    """Fuzz finding: one texel has no covariance (NumPy's is NaN, and its eigen-solver then failed);
    the decorrelation is the identity and the hex blend returns the texel."""
    texel = np.float32([[[0.63, 0.27, 0.04]]])
    tex = wt.Texture(texel)
    hist = prepare_histogram(tex, decorrelate=True)
    out = wt.stochastic(tex, np.float32([[0.0, 0.0], [0.3, 0.8]]), wt.Stochastic("hex", histogram=hist)).numpy()
    np.testing.assert_allclose(out, np.broadcast_to(texel[0, 0], (2, 3)), atol=1e-6)
