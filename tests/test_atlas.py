"""Atlas + index-map splatting: export, packing, agreement with ``splat``, no bleeding,
gradients, bad input.

G-buffers here are built by hand (``GBuffer.empty`` + ``assign``): the splat path reads weights
bilinearly between splat texels while the index-map path reads one texel (nearest), so comparisons
with :func:`warptex.splat` put every pixel's UV0 on a splat-texel centre, where the bilinear
read returns that texel exactly and the two paths must agree to rounding.
"""

import numpy as np
import pytest
import warp as wp

import warptex as wt
from fd import check_parameter_gradient
from reference import texel_centres
from warptex.atlas import Atlas, export_index_maps, pack_atlas, splat_atlas
from warptex.splat import splat


def _gbuffer(uv, uv_dx=None, uv_dy=None):
    """A fully covered ``(h, w)`` G-buffer with UV set ``uv0`` (``uv``: ``[h, w, 2]``)."""
    uv = np.asarray(uv, np.float32)
    h, w = uv.shape[:2]
    g = wt.GBuffer.empty((h, w), uv_sets=("uv0",))
    g.mask.fill_(1.0)
    g.normal.assign(np.tile(np.float32([0, 1, 0]), (h, w, 1)))
    s = g.uv_sets["uv0"]
    s["uv"].assign(uv)
    s["uv_dx"].assign(np.zeros_like(uv) if uv_dx is None else np.asarray(uv_dx, np.float32))
    s["uv_dy"].assign(np.zeros_like(uv) if uv_dy is None else np.asarray(uv_dy, np.float32))
    return g


def _cell(img, g):
    """``img`` (``[h, w, C]``) framed by ``g`` texels of its own wrapped content."""
    h, w = img.shape[:2]
    return img[np.arange(-g, h + g) % h][:, np.arange(-g, w + g) % w]


def _reference_top_k(layer_w, k):
    """Top-k by (weight descending, index ascending) with np.lexsort, per texel."""
    idx = np.broadcast_to(np.arange(layer_w.shape[-1]), layer_w.shape)
    return np.lexsort((idx, -layer_w), axis=-1)[..., :k]


# -- export ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [2, 3, 4])
def test_export_matches_sort_reference_with_deterministic_ties(rng, k):
    maps = (rng.integers(-1, 4, (2, 6, 5, 4)) / 4).astype(np.float32)  # many ties, some negatives
    maps[:, 0, 0] = 0.0  # an all-zero texel
    idx, w = export_index_maps(maps, k, num_layers=7)
    assert idx.dtype == np.int32 and w.dtype == np.float32 and idx.shape == w.shape == (6, 5, k)
    layer_w = np.clip(maps.transpose(1, 2, 0, 3).reshape(6, 5, 8)[..., :7], 0, None)
    np.testing.assert_array_equal(idx, _reference_top_k(layer_w, k))
    kept = np.take_along_axis(layer_w, idx, -1)
    total = kept.sum(-1, keepdims=True)
    np.testing.assert_allclose(w, np.where(total > 0, kept / np.maximum(total, 1e-30), 0), atol=1e-7)
    np.testing.assert_allclose(w[total[..., 0] > 0].sum(-1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(idx[0, 0], np.arange(k))
    np.testing.assert_array_equal(w[0, 0], 0.0)
    raw_idx, raw = export_index_maps(maps, k, num_layers=7, normalize=False)
    np.testing.assert_array_equal(raw_idx, idx)
    np.testing.assert_allclose(raw, kept)

    # Explicit ties: equal weights go to the lower layer index.
    tie = np.float32([[[0.1, 0.3, 0.3, 0.3]], [[0.25, 0.25, 0.25, 0.25]]])
    np.testing.assert_array_equal(export_index_maps(tie, 2)[0][:, 0], [[1, 2], [0, 1]])


# -- packing --------------------------------------------------------------------------------------


def test_pack_places_tiles_with_wrapped_gutters_for_odd_npot_layers(rng):
    layers = rng.random((5, 6, 10, 3)).astype(np.float32)  # L = 5, 6 × 10 tiles, gutter 3: all NPOT
    atlas = pack_atlas(layers, gutter=3)
    assert (atlas.columns, atlas.rows, atlas.tile_size, atlas.gutter, atlas.max_lod) == (3, 2, (6, 10), 3, 0)
    tex = atlas.texture.numpy(0)
    assert tex.shape == (2 * 12, 3 * 16, 3)
    for j in range(5):
        r, c = divmod(j, 3)
        np.testing.assert_array_equal(tex[r * 12 : (r + 1) * 12, c * 16 : (c + 1) * 16], _cell(layers[j], 3))
        assert atlas.cell_origin(j) == (r * 12 + 3, c * 16 + 3)
    np.testing.assert_array_equal(tex[12:, 32:], 0.0)  # the unused sixth cell
    # Atlas.uv sends every layer texel centre to that texel of the atlas.
    centres = texel_centres(6, 10).reshape(-1, 2) + rng.integers(-3, 4, (60, 2))  # any period
    for j in range(5):
        got = wt.sample(atlas.texture, atlas.uv(j, centres).astype(np.float32), sampler=wt.Sampler(filter="nearest")).numpy()
        np.testing.assert_array_equal(got, layers[j].reshape(-1, 3))

    one_column = pack_atlas(layers, gutter=1, columns=1)
    assert one_column.texture.numpy(0).shape == (5 * 8, 12, 3) and one_column.rows == 5


@pytest.mark.parametrize("tile, gutter, max_lod", [((16, 16), 4, 2), ((12, 8), 8, 2), ((16, 32), 2, 1), ((8, 8), 6, 1)])
def test_safe_mips_are_each_layers_own_mip_with_a_gutter(rng, tile, gutter, max_lod):
    """Up to ``max_lod``, atlas level ℓ is every layer's own level ℓ with ``gutter / 2^ℓ`` wrapped texels."""
    layers = rng.random((3, *tile, 2)).astype(np.float32)
    atlas = pack_atlas(wt.TextureArray(layers), gutter=gutter)
    assert atlas.max_lod == max_lod
    own = wt.TextureArray(layers)
    for level in range(max_lod + 1):
        s, gl = 2**level, gutter // 2**level
        tex = atlas.texture.numpy(level)
        for j in range(3):
            r, c = divmod(j, atlas.columns)
            ch, cw = (tile[0] + 2 * gutter) // s, (tile[1] + 2 * gutter) // s
            np.testing.assert_allclose(tex[r * ch : (r + 1) * ch, c * cw : (c + 1) * cw], _cell(own.numpy(level)[j], gl), atol=1e-6)


# -- agreement with splat -------------------------------------------------------------------------


def _splat_scene(rng, size=(16, 16)):
    """4 layers, one RGBA splat map of 6 × 5 texels, and a 6 × 5 G-buffer on its texel centres."""
    layers = rng.random((4, *size, 4)).astype(np.float32)
    maps = rng.random((1, 6, 5, 4)).astype(np.float32)
    uv = texel_centres(6, 5)
    dx = rng.uniform(0.005, 0.1, (6, 5, 2)) * rng.choice([-1, 1], (6, 5, 2))
    dy = rng.uniform(0.005, 0.1, (6, 5, 2))
    return layers, maps, _gbuffer(uv, dx, dy)


@pytest.mark.parametrize("mips", ["off", "trilinear"])
def test_all_layers_reproduce_the_splat_path(rng, mips):
    """k = L = 4 on splat-texel centres: the atlas path equals ``splat(projection="uv")``, with mips off
    (bilinear, level 0) and with trilinear mips limited to the atlas' safe levels (LODs here span
    about -3 to 2.6, so both the clamp at 0 and at ``max_lod = 2`` are exercised)."""
    layers, maps, g = _splat_scene(rng)
    tiling = np.float32([1.7, 2.3, 3.1, 0.9])
    atlas = pack_atlas(layers, gutter=4)
    assert atlas.max_lod == 2
    sampler = wt.Sampler(filter="bilinear", max_lod=0.0) if mips == "off" else wt.Sampler(filter="trilinear", max_lod=float(atlas.max_lod))
    idx, w = export_index_maps(maps, 4)
    got = splat_atlas(g, atlas, idx, w, tiling=tiling, sampler=sampler).numpy()
    want = splat(g, wt.TextureArray(layers), maps, tiling=tiling, projection="uv", sampler=sampler).numpy()
    np.testing.assert_allclose(got, want, atol=1e-5)
    assert np.abs(want).max() > 0.1


def test_top_two_error_is_bounded_by_the_dropped_weight(rng):
    """|atlas(k) - splat| <= dropped · (max - min layer value) per pixel and channel (layers >= 0, so
    also <= dropped · max|layer|), where dropped = 1 - Σ kept / Σ all weights of the texel."""
    layers, maps, g = _splat_scene(rng)
    atlas = pack_atlas(layers, gutter=4)
    want = splat(g, wt.TextureArray(layers), maps, tiling=2.0, projection="uv").numpy()
    layer_w = maps[0]
    spread = (layers.max(axis=(0, 1, 2)) - layers.min(axis=(0, 1, 2)))
    for k in (2, 3):
        idx, w = export_index_maps(maps, k)
        got = splat_atlas(g, atlas, idx, w, tiling=2.0).numpy()
        dropped = 1.0 - np.take_along_axis(layer_w, idx, -1).sum(-1) / layer_w.sum(-1)
        err = np.abs(got - want)
        assert (err <= dropped[..., None] * spread + 1e-5).all()
        assert (err <= dropped[..., None] * np.abs(layers).max() + 1e-5).all()
        assert err.max() > 1e-3  # dropping layers did change the result


# -- no bleeding ----------------------------------------------------------------------------------


BORDER_UV = np.float32([[0.0, 0.0], [0.999, 0.999], [0.0, 0.999], [0.999, 0.0], [0.5, 0.0], [0.0, 0.5], [1.0, 1.0], [-0.0005, 0.5]])


def test_tile_borders_never_bleed_at_coarse_lod_but_would_without_the_clamp(rng):
    """Layers of distinct constant colours, tile-border UVs, derivatives asking for LOD 5."""
    colours = np.float32([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]])
    layers = np.broadcast_to(colours[:, None, None], (4, 16, 16, 3)).copy()
    atlas = pack_atlas(layers, gutter=4)  # 2 × 2 cells of 24 texels; max_lod = 2
    n = len(BORDER_UV)
    dx = np.tile(np.float32([2.0, 0.0]), (1, n, 1))  # 2 tile widths per pixel: 32 texels, LOD 5
    g = _gbuffer(BORDER_UV[None], dx, np.zeros_like(dx))
    for j in range(4):
        out = splat_atlas(g, atlas, np.full((1, 1, 1), j), np.ones((1, 1, 1)), sampler=wt.Sampler(filter="trilinear")).numpy()
        np.testing.assert_allclose(out[0], np.broadcast_to(colours[j], (n, 3)), atol=1e-6)
        # The same reads at an unclamped LOD 4 (cells of 1.5 texels) or 5 (the 1 × 1 level) mix tiles.
        for lod in (4.0, 5.0):
            raw = wt.sample(atlas.texture, atlas.uv(j, BORDER_UV).astype(np.float32), lod=lod).numpy()
            assert np.abs(raw - colours[j]).max() > 0.2, (j, lod)

    # Textured layers: the clamped read is the layer's own wrapped mip at max_lod. Unclamped, even
    # LOD 3, whose cells still fall on texel edges, is wrong: half a texel of gutter is too little.
    layers = rng.random((4, 16, 16, 3)).astype(np.float32)
    atlas = pack_atlas(layers, gutter=4)
    own = wt.TextureArray(layers)
    for j in range(4):
        out = splat_atlas(g, atlas, np.full((1, 1, 1), j), np.ones((1, 1, 1))).numpy()[0]
        want = wt.sample(own, BORDER_UV, layer=j, lod=float(atlas.max_lod)).numpy()
        np.testing.assert_allclose(out, want, atol=1e-5)
        raw = wt.sample(atlas.texture, atlas.uv(j, BORDER_UV).astype(np.float32), lod=3.0).numpy()
        assert np.abs(raw - wt.sample(own, BORDER_UV, layer=j, lod=3.0).numpy()).max() > 0.02


# -- gradients ------------------------------------------------------------------------------------


def _grad_scene(rng):
    uv = rng.uniform(-0.2, 1.2, (8, 8, 2)).astype(np.float32)
    dx = rng.uniform(0.01, 0.08, (8, 8, 2)).astype(np.float32)  # LODs about -1.5 to 2: several levels
    g = _gbuffer(uv, dx, rng.uniform(0.01, 0.08, (8, 8, 2)))
    idx, w = export_index_maps(rng.random((2, 5, 4, 4)).astype(np.float32), 3, num_layers=5)
    return g, idx, w, rng.normal(size=(8, 8, 2)).astype(np.float32)


def _loss(out, r):
    return float((out.numpy().astype(np.float64) * r).sum())


def test_texel_gradients_match_finite_differences(rng):
    """To the source layers (packed on the tape) and to the atlas texels (mips built on the tape)."""
    g, idx, w, r = _grad_scene(rng)
    layers = rng.random((5, 8, 8, 2)).astype(np.float32)
    tiling = np.float32([1.0, 2.0, 1.5, 3.0, 0.7])

    def render(lay):
        return splat_atlas(g, pack_atlas(lay, gutter=2), idx, w, tiling=tiling)

    lt = wt.TextureArray(layers, mipmaps=False, requires_grad=True)
    tape = wp.Tape()
    with tape:
        atlas = pack_atlas(lt, gutter=2)
        out = splat_atlas(g, atlas, idx, w, tiling=tiling)
    out.grad.assign(r)
    tape.backward()
    grad = lt.grad(0).astype(np.float64)
    assert np.abs(grad).sum() > 0
    for _ in range(2):
        d = rng.normal(size=layers.shape).astype(np.float32)
        fd = (_loss(render(layers + 0.05 * d), r) - _loss(render(layers - 0.05 * d), r)) / 0.1
        np.testing.assert_allclose((grad * d).sum(), fd, rtol=1e-3, atol=1e-3)

    atlas = pack_atlas(layers, gutter=2, requires_grad=True)
    base = atlas.texture.numpy(0)
    tape = wp.Tape()
    with tape:
        atlas.texture.update()
        out = splat_atlas(g, atlas, idx, w, tiling=tiling)
    out.grad.assign(r)
    tape.backward()
    grad = atlas.texture.grad(0).astype(np.float64)

    def render_atlas(texels):
        atlas.texture.texels.assign(np.concatenate([texels, np.zeros((*texels.shape[:2], 2), np.float32)], -1))
        atlas.texture.update()
        return splat_atlas(g, atlas, idx, w, tiling=tiling)

    for _ in range(2):
        d = rng.normal(size=base.shape).astype(np.float32)
        fd = (_loss(render_atlas(base + 0.05 * d), r) - _loss(render_atlas(base - 0.05 * d), r)) / 0.1
        np.testing.assert_allclose((grad * d).sum(), fd, rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("normalize", [False, True])
def test_weight_gradients_match_finite_differences(rng, normalize):
    g, idx, w, r = _grad_scene(rng)
    atlas = pack_atlas(rng.random((5, 8, 8, 2)).astype(np.float32), gutter=2)
    w = w + 0.05  # away from the clamp at 0, so the normalised blend is smooth

    weights = wp.array(w, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = splat_atlas(g, atlas, idx, weights, normalize=normalize, tiling=2.0)
    out.grad.assign(r)
    tape.backward()
    grad = weights.grad.numpy().astype(np.float64)
    assert np.abs(grad).sum() > 0
    for _ in range(3):
        d = rng.normal(size=w.shape).astype(np.float32)
        step = 3e-3  # the normalised blend is curved: a small step keeps the truncation error low
        plus, minus = (splat_atlas(g, atlas, idx, w + s * d, normalize=normalize, tiling=2.0) for s in (step, -step))
        fd = (_loss(plus, r) - _loss(minus, r)) / (2 * step)
        np.testing.assert_allclose((grad * d).sum(), fd, rtol=2e-3, atol=2e-3)


def test_tiling_gradient_matches_finite_differences(rng):
    g, idx, w, _ = _grad_scene(rng)
    y, x = np.meshgrid(np.arange(16) / 16, np.arange(16) / 16, indexing="ij")
    layers = np.stack([np.stack([0.5 + 0.3 * np.sin(2 * np.pi * (x + y * (j % 2 + 1)) + c + j) for c in range(2)], -1) for j in range(5)])
    atlas = pack_atlas(layers.astype(np.float32), gutter=4)
    r = rng.normal(size=(8, 8, 2)).astype(np.float32)

    def gradient(v, weights):
        arr = wp.array(v.astype(np.float32), dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = splat_atlas(g, atlas, idx, w, tiling=arr)
        out.grad.assign(weights)
        tape.backward()
        return arr.grad.numpy()

    render = lambda v: splat_atlas(g, atlas, idx, w, tiling=v).numpy()  # noqa: E731
    check_parameter_gradient(render, gradient, np.array([1.0, 2.0, 1.5, 3.0, 0.7]), r, 1e-3, rtol=1e-2, atol=1e-2, label="tiling")


# -- bad input ------------------------------------------------------------------------------------


def test_bad_input_raises_clear_errors(rng):
    maps = rng.random((6, 5, 4)).astype(np.float32)
    for k in (0, 5, True, 2.0):
        with pytest.raises(ValueError, match=r"export_index_maps\(\): k must be an int in \[1, 4\]"):
            export_index_maps(maps, k)
    with pytest.raises(ValueError, match=r"export_index_maps\(\): k must be an int in \[1, 3\]"):
        export_index_maps(maps, 4, num_layers=3)
    with pytest.raises(ValueError, match=r"export_index_maps\(\): 1 splat map\(s\) of 4 channel\(s\)"):
        export_index_maps(maps, 2, num_layers=6)
    with pytest.raises(ValueError, match=r"export_index_maps\(\): splat_maps must have shape"):
        export_index_maps(maps[0], 2)
    with pytest.raises(ValueError, match=r"export_index_maps\(\): splat_maps must be finite"):
        export_index_maps(np.full((2, 2, 4), np.nan), 2)

    layers = rng.random((4, 8, 8, 3)).astype(np.float32)
    for gutter in (-1, 0, 2.5, True):
        with pytest.raises(ValueError, match=r"pack_atlas\(\): gutter must be an int >= 1"):
            pack_atlas(layers, gutter=gutter)
    with pytest.raises(ValueError, match=r"pack_atlas\(\): layers must all have one size; layer 0 is \(8, 8, 3\) but layer 1 is \(4, 8, 3\)"):
        pack_atlas([layers[0], layers[1, :4]])
    with pytest.raises(ValueError, match=r"pack_atlas\(\): layers must have shape"):
        pack_atlas(layers[0, 0])
    with pytest.raises(ValueError, match=r"pack_atlas\(\): layers must have 1 to 4 channels"):
        pack_atlas(np.zeros((2, 4, 4, 5)))
    with pytest.raises(ValueError, match=r"pack_atlas\(\): layers must be finite"):
        pack_atlas(np.full((2, 4, 4, 3), np.inf))
    with pytest.raises(TypeError, match=r"pack_atlas\(\): pass layers as a TextureArray"):
        pack_atlas(wp.zeros((4, 8, 8), dtype=wp.vec4))
    with pytest.raises(ValueError, match=r"pack_atlas\(\): columns must be a positive int"):
        pack_atlas(layers, columns=0)

    atlas = pack_atlas(layers, gutter=2)
    g = _gbuffer(texel_centres(4, 4))
    idx, w = np.zeros((5, 5, 2), np.int32), np.full((5, 5, 2), 0.5, np.float32)
    with pytest.raises(ValueError, match=r"splat_atlas\(\): weights must have shape \(5, 5, 2\), the shape of indices, got \(5, 4, 2\)"):
        splat_atlas(g, atlas, idx, w[:, :4])
    with pytest.raises(ValueError, match=r"splat_atlas\(\): weights must have shape \(5, 5, 2\)"):
        splat_atlas(g, atlas, idx, w[..., :1])
    with pytest.raises(ValueError, match=r"splat_atlas\(\): indices must have shape \(h, w, k\) with h, w >= 1 and 1 <= k <= 4"):
        splat_atlas(g, atlas, np.zeros((5, 5, 5), np.int32), np.zeros((5, 5, 5)))
    with pytest.raises(ValueError, match=r"splat_atlas\(\): indices must be layers of the atlas, in \[0, 3\], got values in \[0, 4\]"):
        splat_atlas(g, atlas, idx + np.int32([0, 4]), w)
    with pytest.raises(TypeError, match=r"splat_atlas\(\): indices must hold integers"):
        splat_atlas(g, atlas, idx.astype(np.float32), w)
    with pytest.raises(ValueError, match=r"splat_atlas\(\): indices must have shape \(H, W, k\)"):
        splat_atlas(g, atlas, idx[..., 0], w)
    with pytest.raises(ValueError, match=r"splat_atlas\(\): weights must be a wp.array of float32"):
        splat_atlas(g, atlas, idx, wp.array(w[:, :, :1], dtype=float))
    with pytest.raises(TypeError, match=r"splat_atlas\(\): atlas must be an Atlas"):
        splat_atlas(g, atlas.texture, idx, w)
    with pytest.raises(ValueError, match=r"splat_atlas\(\): tiling must have shape \(1,\) or \(4,\)"):
        splat_atlas(g, atlas, idx, w, tiling=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"splat_atlas\(\): sampler.min_lod \(2.0\) must not exceed the atlas' max_lod \(1\)"):
        splat_atlas(g, atlas, idx, w, sampler=wt.Sampler(min_lod=2.0))
    with pytest.raises(ValueError, match=r"splat_atlas\(\): the G-buffer has no UV set 'uv1'"):
        splat_atlas(g, atlas, idx, w, uv_set="uv1")
    assert isinstance(atlas, Atlas) and "max_lod=1" in repr(atlas)


def test_masked_and_non_finite_pixels(rng):
    atlas = pack_atlas(rng.random((2, 4, 4, 1)).astype(np.float32), gutter=1)
    g = _gbuffer(np.float32([[[0.3, 0.3], [np.nan, 0.5], [0.2, 0.7]]]))
    g.mask.assign(np.float32([[1, 1, 0]]))
    out = splat_atlas(g, atlas, np.zeros((2, 2, 1), np.int32), np.ones((2, 2, 1))).numpy()
    assert np.isfinite(out[0, 0]).all() and np.isnan(out[0, 1]).all() and (out[0, 2] == 0).all()
