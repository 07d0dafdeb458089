"""The anisotropic filter: NumPy-reference agreement, the picture it exists for, every technique that
samples, gradients against finite differences, and bad input.

The reference (``reference.anisotropic``) takes the footprint's axes from an SVD of the UV Jacobian,
not from the kernels' closed form, and reads its taps with the reference trilinear filter.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
import warp as wp

import reference as ref
import reference_triplanar as rt
import warptex as wt
from backward_paths import assert_same_gradients, texel_gradients_both_ways
from fd import check_parameter_gradient
from test_gradients import _check_per_sample
from test_triplanar_gradients import smooth_texture
from warptex.apps.demo import checker_texture, ground_plane
from warptex.atlas import export_index_maps, pack_atlas, splat_atlas
from warptex.splat import splat

ANISO = wt.Sampler(filter="anisotropic")
TRILINEAR = wt.Sampler(filter="trilinear")


def _footprints(rng, n: int, size: tuple[int, int], *, elongation=(1.0, 40.0), texels=(0.05, 30.0)):
    """Random UV derivatives: ellipses of random orientation, minor axis ``texels`` long (level-0
    texels of a ``size = (h, w)`` image) and ``elongation`` times as long a major axis, given as
    two derivative vectors that are not the axes themselves (a random shear)."""
    h, w = size
    angle = rng.uniform(0, np.pi, n)
    minor = np.exp(rng.uniform(*np.log(texels), n))
    major = minor * rng.uniform(*elongation, n)
    e1 = np.stack([np.cos(angle), np.sin(angle)], -1)
    e2 = np.stack([-np.sin(angle), np.cos(angle)], -1)
    twist = rng.uniform(0, 2 * np.pi, n)[:, None]  # J = U S R: any rotation R of the screen axes
    dx = e1 * (major * np.cos(twist[:, 0]))[:, None] - e2 * (minor * np.sin(twist[:, 0]))[:, None]
    dy = e1 * (major * np.sin(twist[:, 0]))[:, None] + e2 * (minor * np.cos(twist[:, 0]))[:, None]
    scale = np.array([w, h], np.float64)
    return (dx / scale).astype(np.float32), (dy / scale).astype(np.float32)


# -- the filter -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("max_aniso", [1, 4, 16])
@pytest.mark.parametrize("mode", ["wrap", "clamp", "mirror"])
def test_matches_the_numpy_reference(rng, mode, max_aniso):
    h, w = 48, 40
    img = rng.random((h, w, 3), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (3000, 2)).astype(np.float32)
    dx, dy = _footprints(rng, 3000, (h, w))
    out = wt.sample(wt.Texture(img), uv, uv_dx=dx, uv_dy=dy, sampler=wt.Sampler(filter="anisotropic", address=mode, max_aniso=max_aniso)).numpy()
    want = ref.anisotropic(ref.mip_chain(img), uv, dx, dy, mode, max_aniso)
    np.testing.assert_allclose(out, want, atol=2e-5, rtol=0)
    taps = ref.anisotropic_footprint(dx, dy, h, w, max_aniso)[2]
    assert taps.max() == max_aniso and (max_aniso == 1 or (taps > 1).mean() > 0.5)  # the cases cover the taps


def test_a_round_footprint_is_one_trilinear_tap(rng):
    """Derivatives that are a rotation of a circle: the footprint is round, one tap at the LOD of its
    radius, which is trilinear's LOD: the two filters agree."""
    h, w = 64, 64
    img = rng.random((h, w, 2), dtype=np.float32)
    uv = rng.uniform(0, 1, (2000, 2)).astype(np.float32)
    dx, dy = _footprints(rng, 2000, (h, w), elongation=(1.0, 1.0))
    assert (ref.anisotropic_footprint(dx, dy, h, w)[2] == 1).all()
    tex = wt.Texture(img)
    aniso = wt.sample(tex, uv, uv_dx=dx, uv_dy=dy, sampler=ANISO).numpy()
    tri = wt.sample(tex, uv, uv_dx=dx, uv_dy=dy, sampler=TRILINEAR).numpy()
    np.testing.assert_allclose(aniso, tri, atol=2e-5, rtol=0)


def test_round_footprint_gradients_split_between_both_derivatives(rng):
    """A round footprint takes a shortcut (``round_footprint``). Its minor axis has a kink there (the
    two axes cross), and the derivatives' gradients must be the kink's central difference: half
    along each derivative, as the ellipse's formulas have it at a circle, not trilinear's (all
    along the longer one). Zero, tiny and huge round footprints keep finite (zero) gradients."""
    h, w = 64, 64
    img = smooth_texture(h, w, seed=3)[..., :2]
    chain = ref.mip_chain(img)
    n = 300
    uv = rng.uniform(0, 1, (n, 2)).astype(np.float32)
    dx, dy = _footprints(rng, n, (h, w), elongation=(1.0, 1.0), texels=(1.2, 1.8))  # LOD 0.26-0.85: no level switch
    a, b = dx * (w, h), dy * (w, h)
    aa, bb, ab = (a * a).sum(-1), (b * b).sum(-1), (a * b).sum(-1)
    assert (((aa - bb) / 2) ** 2 + ab**2 < (1e-7 * (aa + bb)) ** 2).all()  # round to float32 rounding
    weights = rng.normal(size=(n, 2))
    arrays = [wp.array(x, dtype=wp.vec2, requires_grad=True) for x in (dx, dy)]
    tape = wp.Tape()
    with tape:
        out = wt.sample(wt.Texture(img), uv, uv_dx=arrays[0], uv_dy=arrays[1], sampler=ANISO)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grads = [x.grad.numpy().astype(np.float64) for x in arrays]
    assert all(np.abs(g).max() > 0 for g in grads)
    loss_dx = lambda x: (ref.anisotropic(chain, uv, x, dy) * weights).sum(-1)  # noqa: E731
    loss_dy = lambda x: (ref.anisotropic(chain, uv, dx, x) * weights).sum(-1)  # noqa: E731
    _check_per_sample(loss_dx, dx, grads[0], 1e-5, kink=np.inf)  # every sample is at the kink: keep all
    _check_per_sample(loss_dy, dy, grads[1], 1e-5, kink=np.inf)

    extreme = np.float32([0.0, 1e-30, 1e-8, 1e25, 1e30])[:, None]
    dx = wp.array(extreme * (1, 0), dtype=wp.vec2, requires_grad=True)
    dy = wp.array(extreme * (0, 1), dtype=wp.vec2, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = wt.sample(wt.Texture(img), np.full((5, 2), 0.3, np.float32), uv_dx=dx, uv_dy=dy, sampler=ANISO)
    out.grad.fill_(1.0)
    tape.backward()
    assert np.isfinite(out.numpy()).all()
    assert (dx.grad.numpy() == 0).all() and (dy.grad.numpy() == 0).all()


def test_degenerate_and_non_finite_footprints():
    """Zero derivatives read level 0 exactly (one tap); a footprint along one line only (zero minor
    axis) takes max_aniso taps at the LOD of major / max_aniso; huge derivatives read the coarsest
    level; NaN derivatives give NaN, as trilinear does."""
    img = np.random.default_rng(0).random((32, 32, 1), dtype=np.float32)
    tex = wt.Texture(img)
    uv = np.float32([[0.3, 0.6]] * 4)
    dx = np.float32([[0, 0], [16 / 32, 0], [1e25, 3e25], [np.nan, 0]])
    dy = np.float32([[0, 0], [8 / 32, 0], [2e25, -1e25], [0, 0]])
    out = wt.sample(tex, uv, uv_dx=dx, uv_dy=dy, sampler=ANISO).numpy()[:, 0]
    chain = ref.mip_chain(img)
    assert out[0] == pytest.approx(ref.bilinear(img, uv[:1])[0, 0], abs=1e-6)
    np.testing.assert_allclose(out[1], ref.anisotropic(chain, uv[1:2], dx[1:2], dy[1:2])[0, 0], atol=1e-6)
    assert out[2] == pytest.approx(chain[-1][0, 0, 0], abs=1e-6)
    assert np.isnan(out[3])


def test_sharper_than_trilinear_towards_the_horizon():
    """The picture the filter exists for: a checkerboard ground plane to the horizon, against the
    same view supersampled 8 × 8 per pixel and box-filtered. Anisotropic filtering must halve
    trilinear's RMSE at least (it is about a seventh here); max_aniso = 1 is no better than trilinear."""
    res, s = (90, 120), 8
    tex = wt.Texture(checker_texture())
    uv, dx, dy, mask = ground_plane((res[0] * s, res[1] * s))
    fine = wt.sample(tex, uv, uv_dx=dx, uv_dy=dy).numpy()
    covered = mask.reshape(res[0], s, res[1], s).all(axis=(1, 3))
    reference = fine.reshape(res[0], s, res[1], s, -1).mean(axis=(1, 3))
    uv, dx, dy, _ = ground_plane(res)

    def rmse(sampler):
        out = wt.sample(tex, uv, uv_dx=dx, uv_dy=dy, sampler=sampler).numpy()
        return float(np.sqrt(((out - reference)[covered] ** 2).mean()))

    trilinear, aniso = rmse(TRILINEAR), rmse(ANISO)
    assert aniso <= 0.5 * trilinear, (aniso, trilinear)
    assert rmse(wt.Sampler(filter="anisotropic", max_aniso=1)) >= 0.9 * trilinear


# -- gradients ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("threads", [1, 2])
def test_hand_written_texel_gradients_equal_the_generated_adjoint(rng, monkeypatch, threads):
    n = 70000
    layers = rng.random((2, 37, 29, 3), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (n, 2)).astype(np.float32)
    dx, dy = _footprints(rng, n, (37, 29))

    def forward(derivative_grads):  # UV derivatives needing gradients take the generated adjoint (the UVs' own, the hand-written one)
        tex = wt.TextureArray(layers, requires_grad=True)
        return wt.sample(tex, uv, layer=1, uv_dx=wp.array(dx, dtype=wp.vec2, requires_grad=derivative_grads), uv_dy=dy, sampler=ANISO), [tex]

    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, threads, forward, rng.normal(size=(n, 3)).astype(np.float32))
    assert scatters == 1
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


def _loss(img, uv, dx, dy, weights, sampler=ANISO) -> np.ndarray:
    out = wt.sample(wt.Texture(img), uv, uv_dx=dx, uv_dy=dy, sampler=sampler).numpy()
    return (out.astype(np.float64) * weights).sum(axis=-1)


def test_texel_gradients_match_finite_differences(rng):
    img = rng.random((16, 24, 3), dtype=np.float32)
    uv = rng.uniform(-1, 2, (400, 2)).astype(np.float32)
    dx, dy = _footprints(rng, 400, (16, 24), texels=(0.2, 4.0))
    weights = rng.normal(size=(400, 3))
    tex = wt.Texture(img, requires_grad=True)
    tape = wp.Tape()
    with tape:
        tex.update()
        out = wt.sample(tex, uv, uv_dx=dx, uv_dy=dy, sampler=ANISO)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grad = tex.grad(0).astype(np.float64)
    assert np.abs(grad).sum() > 0
    for _ in range(3):
        d = rng.normal(size=img.shape)
        fd = (_loss((img + 0.05 * d).astype(np.float32), uv, dx, dy, weights).sum() - _loss((img - 0.05 * d).astype(np.float32), uv, dx, dy, weights).sum()) / 0.1
        np.testing.assert_allclose((grad * d).sum(), fd, rtol=1e-4, atol=1e-4)


def test_uv_and_derivative_gradients_match_finite_differences(rng):
    """Gradients to the UVs and to both derivative vectors (the footprint's LOD and the taps' spread)
    against central differences of the float64 reference (float32 outputs are too coarse for steps
    this small). The tap count is a step function and bilinear filtering has kinks, so samples whose
    one-sided differences disagree are left out."""
    img = smooth_texture(64, 64, seed=2)[..., :2]
    chain = ref.mip_chain(img)
    n = 400
    uv = rng.uniform(0, 1, (n, 2)).astype(np.float32)
    dx, dy = _footprints(rng, n, (64, 64), elongation=(1.5, 12.0), texels=(0.5, 3.0))
    weights = rng.normal(size=(n, 2))
    arrays = [wp.array(a, dtype=wp.vec2, requires_grad=True) for a in (uv, dx, dy)]
    tape = wp.Tape()
    with tape:
        out = wt.sample(wt.Texture(img), arrays[0], uv_dx=arrays[1], uv_dy=arrays[2], sampler=ANISO)
    out.grad.assign(weights.astype(np.float32))
    tape.backward()
    grads = [a.grad.numpy().astype(np.float64) for a in arrays]
    assert all(np.abs(g).max() > 0 for g in grads)

    def loss(x, k):
        inputs = [uv, dx, dy]
        inputs[k] = x
        return (ref.anisotropic(chain, *inputs) * weights).sum(-1)

    # A kink of one tap of N is diluted N-fold: differences of the float64 reference resolve 1e-4.
    _check_per_sample(lambda x: loss(x, 0), uv, grads[0], 1e-5, kink=1e-4)
    _check_per_sample(lambda x: loss(x, 1), dx, grads[1], 1e-5, min_kept=0.8, kink=1e-4)
    _check_per_sample(lambda x: loss(x, 2), dy, grads[2], 1e-5, min_kept=0.8, kink=1e-4)


# -- every technique that samples ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def sphere():
    camera = wt.orthographic((3.0, 2.0, 4.0), (0.0, 0.0, 0.0), height=2.2, resolution=(48, 48))
    return wt.rasterize(trimesh.creation.icosphere(subdivisions=4), camera)


def _plane_derivatives(dp, n, axis, tiling):
    """Projection ``axis``' UV derivative along the position derivatives ``dp`` (the mirror fix flips u)."""
    c = dp[:, rt.PLANES[axis]] * tiling
    return np.stack([c[:, 0] * rt.MIRROR[axis] * rt.sign_or_one(n[:, axis]), c[:, 1]], -1)


@pytest.mark.parametrize("technique", ["triplanar", "biplanar"])
def test_triplanar_filters_each_projection_along_its_own_footprint(rng, sphere, technique):
    """Triplanar (biplanar) with the anisotropic filter is the blend of the three projections, each
    read by ``sample`` with the filter at that projection's UVs and UV derivatives."""
    img = rng.random((32, 24, 3), dtype=np.float32)
    tiling = np.float32([3.0, 2.0, 5.0])
    func = wt.triplanar if technique == "triplanar" else wt.biplanar
    out = func(sphere, wt.Texture(img), tiling=tiling, sampler=ANISO).numpy().reshape(-1, 3)
    g = sphere.numpy()
    covered = g["mask"].reshape(-1) != 0
    p, n, dpdx, dpdy = (g[k].reshape(-1, 3)[covered].astype(np.float64) for k in ("position", "normal", "position_dx", "position_dy"))
    uvs = rt.projection_uvs(p, n, tiling)
    weights = rt.biplanar_weights(n, 8.0) if technique == "biplanar" else rt.triplanar_weights(n, 4.0)
    want = np.zeros((len(p), 3))
    elongated = 0
    for axis in range(3):
        ax, ay = (_plane_derivatives(d, n, axis, tiling[axis]).astype(np.float32) for d in (dpdx, dpdy))
        want += weights[:, axis : axis + 1] * wt.sample(wt.Texture(img), uvs[axis].astype(np.float32), uv_dx=ax, uv_dy=ay, sampler=ANISO).numpy()
        elongated += (ref.anisotropic_footprint(ax, ay, 32, 24)[2] > 1)[weights[:, axis] > 0.1].sum()
    np.testing.assert_allclose(out[covered], want, atol=2e-5)
    assert elongated > 100  # the sphere's rim is seen at grazing angles


def test_splat_reads_every_layer_along_its_footprint(rng):
    """``splat(projection="uv")`` with the filter: the splat-weighted layers, each read by ``sample``
    with the filter at the layer's tiling; the atlas variant agrees with it."""
    h, w = 6, 5
    layers = rng.random((4, 16, 16, 4)).astype(np.float32)
    maps = rng.random((1, h, w, 4)).astype(np.float32)
    uv = ref.texel_centres(h, w).astype(np.float32)
    dx, dy = (a.reshape(h, w, 2) for a in _footprints(rng, h * w, (16, 16), texels=(0.2, 2.0), elongation=(2.0, 10.0)))
    g = wt.GBuffer.from_arrays(position=np.zeros((h, w, 3)), normal=np.tile(np.float32([0, 1, 0]), (h, w, 1)), uv=uv, uv_dx=dx, uv_dy=dy)
    tiling = np.float32([1.7, 2.3, 3.1, 0.9])
    sampler = wt.Sampler(filter="anisotropic", max_lod=2.0)
    got = splat(g, wt.TextureArray(layers), maps, tiling=tiling, projection="uv", sampler=sampler).numpy()
    weights = maps[0] / maps[0].sum(-1, keepdims=True)
    want = sum(
        weights[..., j : j + 1] * wt.sample(wt.TextureArray(layers), uv * tiling[j], layer=j, uv_dx=dx * tiling[j], uv_dy=dy * tiling[j], sampler=sampler).numpy()
        for j in range(4)
    )
    np.testing.assert_allclose(got, want, atol=2e-5)
    atlas = pack_atlas(layers, gutter=4)
    idx, wmap = export_index_maps(maps, 4)
    np.testing.assert_allclose(splat_atlas(g, atlas, idx, wmap, tiling=tiling, sampler=sampler).numpy(), got, atol=2e-5)


@pytest.mark.parametrize("method", ["hash4", "hex"])
def test_stochastic_is_filtered_along_the_footprint(rng, method):
    """Each anisotropic tap is sampled with the stochastic technique (every tap at the footprint's
    LOD), then averaged: the filter integrates the stochastic texture along the footprint."""
    h, w = 32, 32
    img = rng.random((h, w, 3), dtype=np.float32)
    tex = wt.Texture(img)
    n = 500
    uv = rng.uniform(-3, 3, (n, 2)).astype(np.float32)
    dx, dy = _footprints(rng, n, (h, w), texels=(0.3, 3.0), elongation=(1.0, 8.0))
    option = wt.Stochastic(method=method, seed=3)
    got = wt.stochastic(tex, uv, option, uv_dx=dx, uv_dy=dy, sampler=ANISO).numpy()
    lod, step, taps = ref.anisotropic_footprint(dx, dy, h, w)
    want = np.zeros((n, 3))
    for k in range(taps.max()):
        live = k < taps
        at = (uv + step * (k + 0.5 - 0.5 * taps)[:, None]).astype(np.float32)
        want[live] += wt.stochastic(tex, at, option, lod=lod.astype(np.float32), sampler=TRILINEAR).numpy()[live]
    np.testing.assert_allclose(got, want / taps[:, None], atol=5e-5)
    assert (taps > 1).mean() > 0.5


@pytest.mark.parametrize("technique", ["triplanar", "splat_triplanar"])
def test_tiling_gradients_match_the_generated_adjoint_and_finite_differences(sphere, technique):
    """The hand-written tiling gradient moves the anisotropic taps with the tiling (their spread, as
    well as the UV and the LOD): it equals the generated adjoint's, and central differences."""
    rng = np.random.default_rng(4)
    img = np.stack([smooth_texture(24, 24, seed=5), smooth_texture(24, 24, seed=6)])
    r = rng.normal(size=(*sphere.resolution, 3)).astype(np.float32)
    maps = np.full((1, 4, 4, 4), [0.6, 0.4, 0.0, 0.0], np.float32)
    g = sphere.numpy()
    zero = np.zeros((*sphere.resolution, 2), np.float32)  # splat maps read at UV0 = 0: the weights are constant
    surface = wt.GBuffer.from_arrays(g["position"], g["normal"], g["mask"], position_dx=g["position_dx"], position_dy=g["position_dy"], uv=zero, uv_dx=zero, uv_dy=zero)

    def render(tiling, layers=None):
        textures = wt.TextureArray(img) if layers is None else layers
        if technique == "triplanar":
            return wt.triplanar(sphere, textures, tiling=tiling, sampler=ANISO)
        return splat(surface, textures, maps, tiling=tiling, projection="triplanar", sampler=ANISO)

    def gradient(value, weights, other_grads=False):
        tiling = wp.array(np.asarray(value, np.float32), dtype=float, requires_grad=True)
        layers = wt.TextureArray(img, requires_grad=other_grads)
        tape = wp.Tape()
        with tape:
            out = render(tiling, layers)
        out.grad.assign(weights.reshape(out.shape))
        tape.backward()
        return tiling.grad.numpy().astype(np.float64)

    value = np.array([2.3, 1.7, 3.1]) if technique == "triplanar" else np.array([2.3, 1.7])
    hand = gradient(value, r)
    with wt._op.force_generated_adjoint():
        generated = gradient(value, r)
    np.testing.assert_allclose(hand, generated, rtol=2e-3, atol=2e-3 * np.abs(generated).max())
    check_parameter_gradient(lambda v: render(v).numpy(), gradient, value, r, 1e-3, rtol=2e-2, atol=2e-2, min_kept=0.8, label=technique)


# -- bad input ------------------------------------------------------------------------------------------


def test_bad_input_raises_clear_errors(rng):
    tex = wt.Texture(rng.random((8, 8, 3), dtype=np.float32))
    uv = rng.random((4, 2), dtype=np.float32)
    with pytest.raises(ValueError, match=r"sample\(\): filter='anisotropic' needs uv_dx=/uv_dy="):
        wt.sample(tex, uv, lod=1.0, sampler=ANISO)
    with pytest.raises(ValueError, match=r"stochastic\(\): filter='anisotropic' needs uv_dx=/uv_dy="):
        wt.stochastic(tex, uv, "hash4", sampler=ANISO)
    for bad in (0, 65, 2.5, True, "16"):
        with pytest.raises(ValueError, match=r"Sampler\(\): max_aniso must be an int in \[1, 64\]"):
            wt.Sampler(filter="anisotropic", max_aniso=bad)
