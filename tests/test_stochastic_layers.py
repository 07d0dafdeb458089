"""Stochastic sampling inside triplanar, biplanar, triplanar normal mapping and splat layers: one
building block, composed; plain tiling unchanged; gradients; bad input."""

import functools

import numpy as np
import pytest
import trimesh
import warp as wp

import reference as ref
import reference_stochastic as rs
import reference_triplanar as rt
import warptex as wt
from fd import check_parameter_gradient
from warptex import Stochastic, prepare_histogram


def _periodic(h, w, c, seed):
    """A random periodic texture, smoothed a little so that trilinear reads are well conditioned."""
    img = np.random.default_rng(seed).random((h, w, c))
    img = (img + np.roll(img, 1, 0) + np.roll(img, 1, 1) + np.roll(img, (1, 1), (0, 1))) / 4
    return img.astype(np.float32)


@functools.lru_cache(maxsize=None)
def _sphere():
    cam = wt.orthographic((0, 0, 5), (0, 0, 0), height=2.2, resolution=(48, 48))
    g = wt.rasterize(trimesh.creation.icosphere(subdivisions=4), cam)
    return g, g.numpy()


def _stochastic_reference(method, chain, uv, lod, opts):
    if method == "hash4":
        return rs.hash4(chain, uv, lod=lod, filt="trilinear", **opts)
    return rs.cheap2(chain, uv, lod=lod, filt="trilinear", **opts)


@pytest.mark.parametrize("method, opts", [("hash4", {}), ("hash4", {"seed": 7, "mirror": True}), ("cheap2", {"seed": 3})])
@pytest.mark.parametrize("func", ["triplanar", "biplanar"])
def test_triplanar_stochastic_matches_numpy_reference(method, opts, func):
    """Every projection sampled with the technique at its own unperturbed LOD, then blended."""
    g, gn = _sphere()
    img = _periodic(32, 32, 4, seed=1)
    tiling = 3.0
    out = getattr(wt, func)(g, wt.Texture(img), tiling=tiling, stochastic=Stochastic(method=method, **opts)).numpy()

    covered, p, n, dx, dy = rt._inputs(gn, None)
    chain = ref.mip_chain(img.astype(np.float64))
    w = (rt.biplanar_weights if func == "biplanar" else rt.triplanar_weights)(n, 8.0 if func == "biplanar" else 4.0)
    uvs = rt.projection_uvs(p, n, tiling)
    lods = rt.projection_lods(dx, dy, tiling, [chain[0].shape[:2]] * 3)
    colour = sum(np.where(w[:, a, None] > 0, w[:, a, None] * _stochastic_reference(method, chain, uvs[a], lods[a], opts), 0.0) for a in range(3))
    np.testing.assert_allclose(out.reshape(-1, 4)[covered], colour, atol=1e-5)
    assert np.all(out.reshape(-1, 4)[~covered] == 0)


@pytest.mark.parametrize("stochastic", [None, "none"])
def test_plain_tiling_is_bit_identical_to_method_none(stochastic):
    """``stochastic=None`` and ``"none"`` run the plain trilinear path: identical to the reference."""
    g, gn = _sphere()
    img = _periodic(32, 32, 3, seed=2)
    out = wt.triplanar(g, wt.Texture(img), tiling=2.0, stochastic=stochastic).numpy()
    np.testing.assert_allclose(out, rt.triplanar(gn, [img] * 3, tiling=2.0), atol=1e-5)
    np.testing.assert_array_equal(out, wt.triplanar(g, wt.Texture(img), tiling=2.0).numpy())


def _ground(count=400, seed=0):
    """A ``(1, N)`` G-buffer of points on a ground plane (normal +Y): triplanar reads only its top projection."""
    rng = np.random.default_rng(seed)
    g = wt.GBuffer.empty((1, count), uv_sets=("uv0",))
    pos = np.stack([rng.uniform(-3, 3, count), np.zeros(count), rng.uniform(-3, 3, count)], -1)
    g.position.assign(pos.reshape(1, count, 3).astype(np.float32))
    g.normal.assign(np.broadcast_to(np.float32([0, 1, 0]), (1, count, 3)).copy())
    g.position_dx.assign(np.broadcast_to(np.float32([0.004, 0, 0.001]), (1, count, 3)).copy())
    g.position_dy.assign(np.broadcast_to(np.float32([0, 0, -0.006]), (1, count, 3)).copy())
    g.mask.assign(np.ones((1, count), np.float32))
    uv = g.uv_sets["uv0"]
    uv["uv"].assign(rng.uniform(0, 1, (1, count, 2)).astype(np.float32))
    uv["uv_dx"].assign(np.broadcast_to(np.float32([0.002, 0.0005]), (1, count, 2)).copy())
    uv["uv_dy"].assign(np.broadcast_to(np.float32([0.0, -0.003]), (1, count, 2)).copy())
    return g, pos


def test_triplanar_hex_with_histogram_on_the_ground_is_the_standalone_technique():
    """On the ground only the top projection is read, at (-x, z) · tiling: it must equal
    :func:`warptex.stochastic` there, histogram blend and LUTs included."""
    g, pos = _ground()
    tex = wt.Texture(_periodic(32, 32, 3, seed=4))
    hist = prepare_histogram(tex)
    option = Stochastic(method="hex", seed=5, contrast=2.0, histogram=hist)
    t = 0.7
    out = wt.triplanar(g, tex, tiling=t, stochastic=option).numpy()[0]
    dpdx, dpdy = g.position_dx.numpy()[0], g.position_dy.numpy()[0]
    uv = np.stack([-pos[:, 0], pos[:, 2]], -1) * t
    alone = wt.stochastic(
        tex, uv.astype(np.float32), Stochastic("hex", seed=5, contrast=2.0, histogram=hist),
        uv_dx=(np.stack([-dpdx[:, 0], dpdx[:, 2]], -1) * t).astype(np.float32),
        uv_dy=(np.stack([-dpdy[:, 0], dpdy[:, 2]], -1) * t).astype(np.float32),
    ).numpy()  # fmt: skip
    np.testing.assert_allclose(out, alone, atol=2e-5)  # UVs rounded apart in float32 (kernel) and float64 (here)


def _layers(count=4, size=16, channels=4):
    return wt.TextureArray(np.stack([_periodic(size, size, channels, seed=10 + j) for j in range(count)]))


@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("projection", ["uv", "world_xz"])
def test_splat_layers_are_each_sampled_like_the_standalone_technique(method, projection):
    """With constant weights, the splat is Σ w_j · stochastic(layer j at its tiling)."""
    g, pos = _ground()
    layers = _layers()
    weights = np.float32([0.1, 0.2, 0.3, 0.4])
    tiling = np.float32([1.5, 2.0, 0.75, 3.0])
    option = Stochastic(method=method, seed=11)
    out = wt.splat(g, layers, weights.reshape(1, 1, 4), tiling=tiling, projection=projection, stochastic=option).numpy()[0]

    if projection == "uv":
        uv0 = g.uv_sets["uv0"]
        uv, dx, dy = (uv0[k].numpy()[0] for k in ("uv", "uv_dx", "uv_dy"))
    else:
        flat = lambda v: np.stack([-v[:, 0], v[:, 2]], -1)  # noqa: E731 - the top projection
        uv, dx, dy = flat(pos), flat(g.position_dx.numpy()[0]), flat(g.position_dy.numpy()[0])
    expected = sum(
        w * wt.stochastic(layers, (uv * t).astype(np.float32), Stochastic(method, seed=11), layer=j, uv_dx=(dx * t).astype(np.float32), uv_dy=(dy * t).astype(np.float32)).numpy()
        for j, (w, t) in enumerate(zip(weights, tiling))
    )
    np.testing.assert_allclose(out, expected, atol=2e-6)


def test_splat_with_height_array_reads_heights_at_the_same_taps():
    """Heights from a separate array follow the colour taps: with equal colour and height layers
    (heights = channel 0), the channel and array height modes agree."""
    g, _ = _ground()
    layers = _layers(channels=1)
    maps = np.random.default_rng(3).random((4, 4, 4)).astype(np.float32)
    option = Stochastic(method="hash4", seed=2)
    by_channel = wt.splat(g, layers, maps, tiling=2.0, height_blend=0.3, height_channel=0, stochastic=option).numpy()
    by_array = wt.splat(g, layers, maps, tiling=2.0, height_blend=0.3, heights=layers, stochastic=option).numpy()
    np.testing.assert_allclose(by_array, by_channel, atol=1e-6)


def test_stochastic_changes_the_terrain_but_keeps_its_colours(shared_data):
    """On the real terrain layers, hex + histogram changes the texture arrangement but keeps each
    channel's mean and contrast within a few percent of plain tiling's."""
    from warptex.scenes import TERRAIN_GRID, terrain_camera
    from warptex.scenes.terrain import terrain
    from warptex.scenes.material import terrain_layers, terrain_splat_maps

    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    g = wt.rasterize(mesh, terrain_camera((96, 144)))
    layers = terrain_layers()
    maps = terrain_splat_maps(mesh, TERRAIN_GRID)
    kw = dict(tiling=1 / 6, projection="triplanar", height_blend=0.2)
    plain = wt.splat(g, layers, maps, **kw).numpy()
    hexed = wt.splat(g, layers, maps, stochastic=Stochastic(method="hex", histogram=prepare_histogram(layers)), **kw).numpy()
    covered = g.mask.numpy() > 0
    assert np.isfinite(hexed).all()
    difference = np.abs(hexed - plain)[covered].mean()
    assert difference > 0.01, difference  # the taps moved (the layers' texels differ by ~0.1)
    np.testing.assert_allclose(hexed[covered].mean(0)[:3], plain[covered].mean(0)[:3], rtol=0.03)
    np.testing.assert_allclose(hexed[covered].std(0)[:3], plain[covered].std(0)[:3], rtol=0.1)


def test_triplanar_stochastic_gradients_match_finite_differences():
    g, _ = _sphere()
    img = _periodic(16, 16, 3, seed=6)
    option = Stochastic(method="hash4", seed=1)
    r = np.random.default_rng(0).random((48, 48, 3)).astype(np.float32)

    def render(t):
        return wt.triplanar(g, wt.Texture(img), tiling=float(t[0]), stochastic=option).numpy()

    def gradient(t, weights):
        tiling = wp.array(np.float32(t), dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = wt.triplanar(g, wt.Texture(img), tiling=tiling, stochastic=option)
        out.grad.assign(weights)
        tape.backward()
        return tiling.grad.numpy()

    check_parameter_gradient(render, gradient, np.array([2.3]), r, 1e-3, label="tiling")

    # Texels: a few level-0 texels through the mip chain built on the tape.
    tex = wt.Texture(img, requires_grad=True)
    tape = wp.Tape()
    with tape:
        tex.update()
        out = wt.triplanar(g, tex, tiling=2.3, stochastic=option)
    out.grad.assign(r)
    tape.backward()
    analytic = tex.grad()
    eps = 1e-2
    for y, x, c in [(3, 4, 0), (8, 1, 1), (12, 12, 2), (0, 15, 0)]:
        plus, minus = img.copy(), img.copy()
        plus[y, x, c] += eps
        minus[y, x, c] -= eps
        fd = ((wt.triplanar(g, wt.Texture(plus), tiling=2.3, stochastic=option).numpy() - wt.triplanar(g, wt.Texture(minus), tiling=2.3, stochastic=option).numpy()) * r).sum() / (2 * eps)
        np.testing.assert_allclose(analytic[y, x, c], fd, rtol=2e-3, atol=2e-3)


def test_splat_stochastic_gradients_match_finite_differences():
    g, _ = _ground(200)
    layers_np = np.stack([_periodic(8, 8, 4, seed=20 + j) for j in range(4)])
    maps = np.random.default_rng(5).random((3, 3, 4)).astype(np.float32)
    option = Stochastic(method="cheap2", seed=4)
    r = np.random.default_rng(1).random((1, 200, 4)).astype(np.float32)

    def render(t):
        return wt.splat(g, wt.TextureArray(layers_np), maps, tiling=t.astype(np.float32), stochastic=option).numpy()

    def gradient(t, weights):
        tiling = wp.array(t.astype(np.float32), dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = wt.splat(g, wt.TextureArray(layers_np), maps, tiling=tiling, stochastic=option)
        out.grad.assign(weights)
        tape.backward()
        return tiling.grad.numpy()

    check_parameter_gradient(render, gradient, np.array([1.5, 2.0, 0.75, 3.0]), r, 1e-3, label="tiling")


def test_bad_stochastic_options_raise_clear_errors():
    g, _ = _sphere()
    tex = wt.Texture(_periodic(8, 8, 3, seed=0))
    other = wt.Texture(_periodic(8, 8, 3, seed=1))
    hist = prepare_histogram(tex)
    with pytest.raises(TypeError, match=r"triplanar\(\): stochastic must be None, a method name or a warptex.Stochastic, got dict"):
        wt.triplanar(g, tex, stochastic={"method": "hex"})
    with pytest.raises(ValueError, match=r"biplanar\(\): stochastic: Stochastic\(\): method must be one of"):
        wt.biplanar(g, tex, stochastic="hexagonal")
    with pytest.raises(ValueError, match=r"triplanar\(\): stochastic sampling needs address 'wrap' or 'mirror'.*'clamp'"):
        wt.triplanar(g, tex, stochastic="hash4", sampler=wt.Sampler(address="clamp"))
    with pytest.raises(ValueError, match=r"triplanar\(\): a stochastic histogram needs one texture for every projection"):
        wt.triplanar(g, tex, textures_per_axis=(tex, other, tex), stochastic=Stochastic(method="hex", histogram=hist))
    with pytest.raises(ValueError, match=r"triplanar_normal\(\): stochastic mirror and rotation"):
        wt.triplanar_normal(g, tex, stochastic=Stochastic(method="hash4", mirror=True))
    layers, ground = _layers(channels=3, size=8), _ground(4)[0]
    with pytest.raises(ValueError, match=r"splat\(\): the stochastic histogram was built for \(layers, H, W, C\) = \(1, 8, 8, 3\), the texture is \(4, 8, 8, 3\)"):
        wt.splat(ground, layers, np.ones((2, 2, 4), np.float32), stochastic=Stochastic(method="hex", histogram=hist))
    with pytest.raises(ValueError, match=r"splat\(\): stochastic sampling needs address"):
        wt.splat(ground, layers, np.ones((2, 2, 4), np.float32), stochastic="cheap2", sampler=wt.Sampler(address="border"))
