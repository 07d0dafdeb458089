"""Splat-map layer blending: NumPy-reference agreement, weight rules, gradients, bad input."""

import numpy as np
import pytest
import warp as wp

import warptex as wt
from conftest import with_sampler
from warptex.scenes.terrain import terrain
from backward_paths import assert_same_gradients, splat_inputs, texel_gradients_both_ways
from fd import check_parameter_gradient
from reference_layers import splat_reference
from warptex.splat import splat
from warptex.scenes import terrain_camera


@pytest.fixture(scope="module")
def terrain_gbuffer():
    """The default terrain (coarse mesh) seen by the default camera at 48 × 64: flat valleys and cliffs."""
    mesh = terrain(resolution=(65, 65))
    return wt.rasterize(mesh, terrain_camera((48, 64)))


def _flat(g, uv_set="uv0"):
    """Covered pixels' G-buffer arrays, float64, flattened: ``(dict, mask)``."""
    arrays = g.numpy()
    mask = arrays["mask"] > 0
    names = {"position": "position", "normal": "normal", "position_dx": "position_dx", "position_dy": "position_dy"}
    flat = {k: arrays[v][mask].astype(np.float64) for k, v in names.items()}
    for k in ("uv", "uv_dx", "uv_dy"):
        flat[k] = arrays[f"{uv_set}.{k}"][mask].astype(np.float64)
    return flat, mask


def _layers(rng, count, channels=4, size=(24, 20)):
    return rng.random((count, *size, channels)).astype(np.float32)


def _maps(rng, count, size=(9, 7)):
    return rng.random((count, *size, 4)).astype(np.float32)


@pytest.mark.parametrize("num_layers", [4, 8])
@pytest.mark.parametrize("projection", ["uv", "world_xz", "triplanar"])
@pytest.mark.parametrize("height", [None, "channel", "array"])
def test_splat_matches_numpy_reference(terrain_gbuffer, rng, num_layers, projection, height):
    g = terrain_gbuffer
    layers = _layers(rng, num_layers)
    maps = _maps(rng, num_layers // 4)
    tiling = rng.uniform(0.05, 0.3, num_layers) if projection != "uv" else rng.uniform(2, 9, num_layers)
    kw, ref_kw = {}, {}
    if height is not None:
        kw["height_blend"] = ref_kw["transition"] = 0.15
        if height == "array":
            heights = rng.random((num_layers, 16, 16, 1)).astype(np.float32)
            kw["heights"], ref_kw["heights"] = wt.TextureArray(heights), heights
    out = splat(g, wt.TextureArray(layers), wt.TextureArray(maps), tiling=tiling, projection=projection, **kw).numpy()
    flat, mask = _flat(g)
    expected = splat_reference(flat, layers, maps, tiling=tiling, projection=projection, **ref_kw)
    np.testing.assert_allclose(out[mask], expected, atol=1e-5)
    np.testing.assert_array_equal(out[~mask], 0.0)
    if height is not None:  # the height blend changed something
        plain = splat(g, wt.TextureArray(layers), wt.TextureArray(maps), tiling=tiling, projection=projection).numpy()
        assert np.abs(plain - out).max() > 0.05


def test_one_hot_splat_reproduces_the_layer_alone(terrain_gbuffer, rng):
    g = terrain_gbuffer
    layers = _layers(rng, 4)
    uv0 = g.uv()
    for j in range(4):
        maps = np.zeros((1, 5, 5, 4), np.float32)
        maps[..., j] = 1.0
        out = splat(g, wt.TextureArray(layers), maps, tiling=3.0).numpy()
        alone = wt.sample(
            wt.Texture(layers[j]), uv0["uv"].numpy() * 3.0, uv_dx=uv0["uv_dx"].numpy() * 3.0, uv_dy=uv0["uv_dy"].numpy() * 3.0
        ).numpy()
        mask = g.mask.numpy() > 0
        np.testing.assert_allclose(out[mask], alone[mask], atol=1e-6)


def test_weights_are_normalised_clamped_and_zero_safe(terrain_gbuffer, rng):
    g = terrain_gbuffer
    layers = wt.TextureArray(_layers(rng, 4))
    maps = _maps(rng, 1)
    base = splat(g, layers, maps).numpy()
    np.testing.assert_allclose(splat(g, layers, maps * 3.7).numpy(), base, atol=1e-6)  # scale-free
    negative = maps.copy()
    negative[..., 2] = -1.0
    zeroed = maps.copy()
    zeroed[..., 2] = 0.0
    np.testing.assert_allclose(splat(g, layers, negative).numpy(), splat(g, layers, zeroed).numpy(), atol=1e-6)
    zero = splat(g, layers, np.zeros_like(maps), height_blend=0.1).numpy()
    assert np.isfinite(zero).all() and np.abs(zero).max() == 0.0
    # normalize=False blends the raw weights.
    half = splat(g, layers, np.full_like(maps, 0.125), normalize=False).numpy()
    np.testing.assert_allclose(half * 2, splat(g, layers, np.full_like(maps, 0.25)).numpy(), atol=1e-6)


def test_height_blend_tends_to_the_plain_blend_and_to_the_highest_layer(terrain_gbuffer, rng):
    g = terrain_gbuffer
    layers = _layers(rng, 4)
    maps = np.full((1, 3, 3, 4), 0.25, np.float32)  # equal weights: the highest layer wins when sharp
    plain = splat(g, wt.TextureArray(layers), maps).numpy()
    wide = splat(g, wt.TextureArray(layers), maps, height_blend=1e4).numpy()
    np.testing.assert_allclose(wide, plain, atol=1e-3)
    flat, mask = _flat(g)
    sharp = splat(g, wt.TextureArray(layers), maps, height_blend=1e-6).numpy()[mask]
    ref = splat_reference(flat, layers, maps, tiling=1.0, transition=1e-6)
    np.testing.assert_allclose(sharp, ref, atol=1e-4)


def _splat_loss(g, layers, maps, r, **kw):
    return float((splat(g, wt.TextureArray(layers), wt.TextureArray(maps), **kw).numpy().astype(np.float64) * r).sum())


@pytest.mark.parametrize("projection", ["uv", "triplanar"])
def test_texel_gradients_match_finite_differences(terrain_gbuffer, rng, projection):
    """Splat-map texels (every channel) and layer texels, along random directions."""
    g = terrain_gbuffer
    layers, maps = _layers(rng, 8, size=(8, 8)), _maps(rng, 2, size=(6, 6))
    tiling = 0.2 if projection == "triplanar" else 2.0
    r = rng.normal(size=(*g.resolution, 4)).astype(np.float32)
    lt, mt = wt.TextureArray(layers, requires_grad=True), wt.TextureArray(maps, requires_grad=True)
    tape = wp.Tape()
    with tape:
        lt.update()
        out = splat(g, lt, mt, tiling=tiling, projection=projection, height_blend=0.3)
    out.grad.assign(r)
    tape.backward()
    for name, data, grad in (("maps", maps, mt.grad(0)), ("layers", layers, lt.grad(0))):
        assert np.abs(grad).sum() > 0, name
        for _ in range(2):
            d = rng.normal(size=data.shape).astype(np.float32)
            step = 1e-3
            args = {"maps": lambda s: (layers, maps + s * d), "layers": lambda s: (layers + s * d, maps)}[name]
            fd = (_splat_loss(g, *args(step), r, tiling=tiling, projection=projection, height_blend=0.3) - _splat_loss(g, *args(-step), r, tiling=tiling, projection=projection, height_blend=0.3)) / (2 * step)
            np.testing.assert_allclose((grad.astype(np.float64) * d).sum(), fd, rtol=2e-2, atol=2e-2, err_msg=name)


def test_tiling_and_transition_gradients_match_finite_differences(terrain_gbuffer, rng):
    g = terrain_gbuffer
    maps = _maps(rng, 1, size=(6, 6))
    # Smooth layers: bilinear's curvature and slope jumps stay small against the step.
    y, x = np.meshgrid(np.arange(32) / 32, np.arange(32) / 32, indexing="ij")
    layers = np.stack([np.stack([0.5 + 0.3 * np.sin(2 * np.pi * (x * (j % 2 + 1) + y) + c + j) for c in range(4)], -1) for j in range(4)])
    r = rng.normal(size=(*g.resolution, 4)).astype(np.float32)
    base = {"tiling": np.array([2.0, 3.0, 1.5, 2.5]), "height_blend": np.array([0.2])}

    def render(name):
        return lambda v: splat(g, wt.TextureArray(layers), maps, **{**base, name: v}).numpy()

    def gradient(name):
        def run(v, weights):
            arr = wp.array(v.astype(np.float32), dtype=float, requires_grad=True)
            tape = wp.Tape()
            with tape:
                out = splat(g, wt.TextureArray(layers), maps, **{**base, name: arr})
            out.grad.assign(weights)
            tape.backward()
            return arr.grad.numpy()

        return run

    for name, step in (("tiling", 1e-3), ("height_blend", 1e-3)):
        check_parameter_gradient(render(name), gradient(name), base[name], r, step, rtol=1e-2, atol=1e-2, label=name)


BACKWARD_CASES = {
    "uv, 4 layers, mirror": dict(layers=4, projection="uv", address="mirror"),
    "world_xz, 8 layers, height channel, not normalised, bilinear": dict(layers=8, projection="world_xz", height="channel", normalize=False, filter="bilinear"),
    "triplanar, 8 layers, height array, clamp, biased": dict(layers=8, projection="triplanar", height="array", address="clamp", lod_bias=0.3, min_lod=0.5),
    "uv, 4 layers, nearest, height channel": dict(layers=4, projection="uv", height="channel", filter="nearest"),
    "uv, 4 layers, hash4, height channel": dict(layers=4, projection="uv", height="channel", stochastic=wt.Stochastic("hash4", mirror=True)),
    "triplanar, 4 layers, hex rotated, height array": dict(layers=4, projection="triplanar", height="array", stochastic=wt.Stochastic("hex", rotation=0.5, contrast=2.0)),
    "uv, 4 layers, hex histogram": dict(layers=4, projection="uv", height="channel", histogram=True),
}


@pytest.mark.parametrize("threads", [1, 2, 3])  # 3: private copies track tiles
@pytest.mark.parametrize("case", list(BACKWARD_CASES))
def test_hand_written_gradients_equal_the_generated_adjoint(monkeypatch, case, threads):
    """The hand-written gradient (texels, transition and, for plain sampling, tiling) against the
    generated adjoint (a sharpness array needs gradients too): layers (every level), separate
    heights, splat maps (negative values included, which the clamp cuts), the transition and the
    tiling, on the terrain at 192² (36 864 pixels: split over two threads; 256² over three, whose
    private copies track tiles). The histogram blend,
    not linear in the texels, always takes the generated adjoint; with a stochastic method the
    tiling is left out (its gradient needs the generated adjoint)."""
    c = dict(BACKWARD_CASES[case])
    g = wt.rasterize(terrain(resolution=(65, 65)), terrain_camera((256, 256) if threads == 3 else (192, 192)))
    rng = np.random.default_rng(11)
    count = c.pop("layers")
    layer_data = rng.random((count, 24, 20, 4)).astype(np.float32)
    map_data = rng.random((count // 4, 9, 7, 4)).astype(np.float32) - 0.2
    height_data = rng.random((count, 16, 16, 1)).astype(np.float32)
    tiling = (rng.uniform(0.05, 0.3, count) if c["projection"] != "uv" else rng.uniform(2, 9, count)).astype(np.float32)
    height, histogram = c.pop("height", None), c.pop("histogram", False)
    plain = "stochastic" not in c and not histogram

    def forward(other_grads):
        blend, heights = (0.15 if height is not None else None), (height_data if height == "array" else None)
        layers, maps, kw, textures = splat_inputs(layer_data, map_data, tiling, other_grads, plain=plain, height_blend=blend, height_data=heights, histogram=histogram)
        return splat(g, layers, maps, **with_sampler({**c, **kw})), textures

    weights = rng.normal(size=(*g.resolution, 4)).astype(np.float32)
    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, threads, forward, weights)
    assert scatters == (0 if histogram else 1)
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


def test_bad_input_raises_clear_errors(terrain_gbuffer, rng):
    g = terrain_gbuffer
    layers = wt.TextureArray(_layers(rng, 4))
    maps = _maps(rng, 1)
    with pytest.raises(ValueError, match=r"TextureArray\(\): all layers must have the same"):
        wt.TextureArray([np.zeros((8, 8, 3)), np.zeros((4, 4, 3))])
    with pytest.raises(ValueError, match=r"splat\(\): 2 splat map\(s\) of 4 channel\(s\) hold weights for 5 to 8 layers, but there are 4"):
        splat(g, layers, _maps(rng, 2))
    with pytest.raises(ValueError, match=r"splat\(\): 1 splat map\(s\) of 3 channel\(s\) hold weights for 1 to 3 layers, but there are 4"):
        splat(g, layers, np.zeros((5, 5, 3)))
    with pytest.raises(ValueError, match=r"splat\(\): height_blend \(the transition\) must be > 0"):
        splat(g, layers, maps, height_blend=0.0)
    with pytest.raises(ValueError, match=r"splat\(\): height_channel must be a channel of the layers"):
        splat(g, wt.TextureArray(_layers(rng, 4, channels=3)), maps, height_blend=0.1)
    with pytest.raises(ValueError, match=r"splat\(\): heights must have 4 one-channel layers"):
        splat(g, layers, maps, height_blend=0.1, heights=wt.TextureArray(np.zeros((3, 4, 4, 1))))
    with pytest.raises(ValueError, match=r"splat\(\): heights are only used with height_blend"):
        splat(g, layers, maps, heights=wt.TextureArray(np.zeros((4, 4, 4, 1))))
    with pytest.raises(ValueError, match=r"splat\(\): tiling must have shape \(1,\) or \(4,\)"):
        splat(g, layers, maps, tiling=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"splat\(\): projection must be one of"):
        splat(g, layers, maps, projection="cubic")
    with pytest.raises(ValueError, match=r"splat\(\): the G-buffer has no UV set 'uv7'"):
        splat(g, layers, maps, uv_set="uv7")
    with pytest.raises(TypeError, match=r"splat\(\): layers must be a TextureArray"):
        splat(g, np.zeros((4, 8, 8, 3)), maps)


def test_terrain_splat_maps_follow_height_and_slope():
    """The default terrain's rules: weights sum to 1, rock owns the cliffs, snow the high flats."""
    from warptex.scenes.terrain import terrain_slope_height
    from warptex.scenes.material import terrain_splat_maps

    mesh = terrain(resolution=(65, 65))
    maps = terrain_splat_maps(mesh, (65, 65))
    assert maps.shape == (65, 65, 4)
    np.testing.assert_allclose(maps.sum(axis=-1), 1.0, atol=1e-6)
    assert maps.min() >= 0.0
    height, slope = (a.reshape(65, 65) for a in terrain_slope_height(mesh))
    assert (maps[slope > 45][:, 2] > 0.99).all()  # rock on steep faces
    high_flat = (height > 0.85) & (slope < 20)
    assert high_flat.any() and (maps[high_flat][:, 3] > 0.99).all()  # snow on high, gentle ground
    with pytest.raises(ValueError, match=r"terrain_splat_maps\(\): the mesh has 4225 vertices, not a 64x64 grid"):
        terrain_splat_maps(mesh, (64, 64))
