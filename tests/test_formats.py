"""Texel formats: float16, unorm8 and srgb8 textures sample as the float32 texture of their decoded
texels does, bit for bit, through the lane kernels and the one-pixel kernels, in every filter,
address mode and technique; their mips are linear-space box filters re-encoded; their texel
gradients land in float32 and match finite differences; files keep their precision."""

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex import io
from warptex._op import force_generated_adjoint, one_pixel_kernels
from warptex.scenes import terrain_camera
from warptex.scenes.terrain import terrain
from warptex.formats import decode_table, encode

import reference as ref

COMPACT = ["srgb8", "unorm8", "float16"]
ADDRESSES = ["wrap", "clamp", "mirror", "border"]


def _values(rng, shape, fmt):
    """Texels for ``fmt``: uint8 codes for the 8-bit formats, floats (some past 1) for float16."""
    if fmt == "float16":
        return rng.uniform(-0.5, 3.0, shape).astype(np.float32)
    return rng.integers(0, 256, shape, dtype=np.uint8)


def float_twin(tex):
    """A float32 texture holding ``tex``'s decoded texels on every level (its own mips replaced)."""
    cls = wt.Texture if isinstance(tex, wt.Texture) else wt.TextureArray
    twin = cls(tex.numpy(0), mipmaps=tex.num_levels)
    for k in range(1, tex.num_levels):
        level = np.zeros(tex.numpy(k).shape[:-1] + (4,), np.float32)
        level[..., : tex.channels] = tex.numpy(k)
        twin.level(k).assign(level)
    return twin


def _same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    same = (a.view(np.uint32) == b.view(np.uint32)) | (np.isnan(a) & np.isnan(b))
    assert same.all(), f"{int((~same).sum())} of {a.size} differ, first at {np.argwhere(~same)[0]}: {a[~same][0]!r} vs {b[~same][0]!r}"


def test_srgb8_codes_by_table_are_the_curves_codes():
    """``png.codes`` encodes 8-bit sRGB by a table on the float's bits (``png._srgb8``); it gives the
    codes of the curve (``io.linear_to_srgb``, rounded) for every float32 in [0, 1] (checked
    exhaustively once, 1,065,353,217 values: 44 s); here at each step of the codes, the floats
    either side of it, the ends, -0.0, and a million values from the whole range."""
    from warptex import png

    _, threshold = png._srgb8_lookup()
    steps = threshold[:-1].view(np.uint32)
    bits = np.concatenate([steps - 1, steps, steps + 1, np.random.default_rng(0).integers(0, 0x3F800001, 1_000_000, dtype=np.uint32), [0, 1, 0x3F800000]])
    values = np.append(bits.astype(np.uint32).view(np.float32), np.float32(-0.0))
    want = np.rint(io.linear_to_srgb(values) * np.float32(255)).astype(np.uint8)
    got = png._srgb8(values)
    assert np.array_equal(got, want), f"{int((got != want).sum())} codes differ"
    assert np.array_equal(png._srgb8(threshold[:-1]), np.arange(1, 256)), "each threshold is the first float of its code"
    rgba = np.random.default_rng(1).random((64, 3, 4), dtype=np.float32)
    alpha_linear = np.rint(rgba[..., 3] * 255).astype(np.uint8)
    coded = png.codes(rgba)
    assert np.array_equal(coded[..., :3], np.rint(io.linear_to_srgb(rgba[..., :3]) * np.float32(255)).astype(np.uint8)) and np.array_equal(coded[..., 3], alpha_linear)


def test_the_decode_tables_are_read_images_values():
    codes = np.arange(256, dtype=np.float64) / 255
    srgb, unorm = decode_table(wt.Format.SRGB8, 4).reshape(4, 256), decode_table(wt.Format.UNORM8, 4).reshape(4, 256)
    for c in range(3):
        _same_bits(srgb[c], io.srgb_to_linear(codes))
    _same_bits(srgb[3], codes.astype(np.float32))  # alpha is linear
    _same_bits(unorm, np.tile(codes.astype(np.float32), (4, 1)))
    two = decode_table(wt.Format.SRGB8, 2).reshape(4, 256)  # gray + alpha
    _same_bits(two[0], io.srgb_to_linear(codes))
    _same_bits(two[1], codes.astype(np.float32))
    assert np.all(np.diff(srgb[0]) > 0), "codes decode to distinct, increasing values"


@pytest.mark.parametrize("fmt", COMPACT)
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_encode_then_decode_keeps_the_stored_values(rng, fmt, channels):
    tex = wt.Texture(_values(rng, (9, 7, channels), fmt), format=fmt, mipmaps=False)
    again = wt.Texture(tex.numpy(0), format=fmt, mipmaps=False)  # its decoded floats, encoded again
    _same_bits(again.numpy(0), tex.numpy(0))


@pytest.mark.parametrize("fmt", ["srgb8", "unorm8"])
def test_codes_are_stored_as_given(rng, fmt):
    codes = rng.integers(0, 256, (6, 5, 4), dtype=np.uint8)
    tex = wt.Texture(codes, format=fmt, mipmaps=False)
    table = decode_table(wt.Format(fmt), 4).reshape(4, 256)
    _same_bits(tex.numpy(0), np.stack([table[c][codes[..., c]] for c in range(4)], axis=-1))


@pytest.mark.parametrize("fmt", ["srgb8", "unorm8"])
def test_every_code_is_read_as_its_tables_value(fmt):
    """Bilinear reads at texel centres (weights exactly 1 and 0) return the texel itself: a 16 x 16
    texture whose every channel holds each of the 256 codes once, read through the lanes (unorm8
    decodes arithmetically there) and the one-pixel kernels (by the table)."""
    codes = np.stack([(np.arange(256) + 64 * c) % 256 for c in range(4)], axis=-1).astype(np.uint8).reshape(16, 16, 4)
    tex = wt.Texture(codes, format=fmt, mipmaps=False)
    j, i = np.mgrid[0:16, 0:16]
    uv = np.stack([(i + 0.5) / 16, 1 - (j + 0.5) / 16], axis=-1).reshape(-1, 2).astype(np.float32)
    table = decode_table(wt.Format(fmt), 4).reshape(4, 256)
    want = np.stack([table[c][codes[..., c]] for c in range(4)], axis=-1).reshape(-1, 4)
    for one_pixel in (False, True):
        with one_pixel_kernels(one_pixel):
            _same_bits(wt.sample(tex, uv, sampler=wt.Sampler(filter="bilinear")).numpy(), want)


@pytest.mark.parametrize("fmt", COMPACT)
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
@pytest.mark.parametrize("address", ADDRESSES)
def test_a_compact_texture_samples_as_its_decoded_float_twin(rng, fmt, filter, address):
    tex = wt.TextureArray(_values(rng, (2, 21, 34, 4), fmt), format=fmt)
    twin = float_twin(tex)
    n = 700
    uv = rng.uniform(-1.5, 2.5, (n, 2)).astype(np.float32)
    layer = rng.integers(0, 2, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address=address, border=(0.1, 0.2, 0.3, 0.4), max_aniso=4)
    lod = {}
    if filter == "trilinear":
        lod = {"lod": rng.uniform(-0.5, 5.5, n).astype(np.float32)}
    elif filter == "anisotropic":
        lod = {"uv_dx": rng.normal(0, 0.05, (n, 2)).astype(np.float32), "uv_dy": rng.normal(0, 0.02, (n, 2)).astype(np.float32)}
    for layers in (layer, 1):  # a layer per UV, and one for all (the lanes' next-lane hints read either)
        got = {}
        for one_pixel in (False, True):
            with one_pixel_kernels(one_pixel):
                got[one_pixel] = wt.sample(tex, uv, layer=layers, sampler=smp, **lod).numpy()
                want = wt.sample(twin, uv, layer=layers, sampler=smp, **lod).numpy()
            _same_bits(got[one_pixel], want)
        _same_bits(got[False], got[True])  # lanes = one-pixel


@pytest.mark.parametrize("address", ADDRESSES)
def test_srgb8_is_decoded_then_filtered_as_an_independent_reference_says(rng, address):
    codes = rng.integers(0, 256, (16, 24, 4), dtype=np.uint8)
    tex = wt.Texture(codes, format="srgb8")
    decoded = [tex.numpy(k).astype(np.float64) for k in range(tex.num_levels)]
    uv = rng.uniform(-1.0, 2.0, (500, 2)).astype(np.float32)
    got = wt.sample(tex, uv, sampler=wt.Sampler(filter="bilinear", address=address)).numpy()
    np.testing.assert_allclose(got, ref.bilinear(decoded[0], uv, address), atol=1e-5, rtol=0)  # float64 UV arithmetic, as test_sampling
    if address == "wrap":
        lod = rng.uniform(0, 4, 500).astype(np.float32)
        got = wt.sample(tex, uv, lod=lod, sampler=wt.Sampler(filter="trilinear")).numpy()
        np.testing.assert_allclose(got, ref.trilinear(decoded, uv, lod), atol=1e-5, rtol=0)
    # decode, then filter (not the reverse): halfway between black and white is linear 0.5
    midway = wt.sample(wt.Texture(np.array([[[0, 0, 0, 255], [255, 255, 255, 255]]], np.uint8), format="srgb8", mipmaps=False), np.array([[0.5, 0.5]], np.float32), sampler=wt.Sampler(filter="bilinear", address="clamp")).numpy()
    np.testing.assert_allclose(midway[0, :3], 0.5, atol=1e-6)  # linear 0.5, not srgb_to_linear(0.5) = 0.214


@pytest.mark.parametrize("fmt", COMPACT)
@pytest.mark.parametrize("size", [(64, 64), (37, 23)])
def test_mips_are_a_linear_box_filter_re_encoded(rng, fmt, size):
    channels = 4
    tex = wt.Texture(_values(rng, size + (channels,), fmt), format=fmt)
    for k in range(1, tex.num_levels):
        finer = tex.numpy(k - 1).astype(np.float64)
        want = encode(ref.box_downsample(finer).astype(np.float32), wt.Format(fmt))[..., :channels]
        got = encode(tex.numpy(k), wt.Format(fmt))[..., :channels]
        if fmt == "float16":
            np.testing.assert_allclose(got.astype(np.float32), want.astype(np.float32), rtol=2e-3, atol=0)
        else:
            assert np.abs(got.astype(int) - want.astype(int)).max() <= 1, f"level {k}"
    if fmt == "srgb8":  # against the float chain of level 0 (no rounding between levels): within 1 code
        chain = ref.mip_chain(tex.numpy(0).astype(np.float64))
        for k in range(1, tex.num_levels):
            want = encode(chain[k].astype(np.float32), wt.Format.SRGB8)
            got = encode(tex.numpy(k), wt.Format.SRGB8)
            assert np.abs(got.astype(int) - want.astype(int)).max() <= 1, f"level {k}"


def test_srgb8_mips_average_light_not_codes():
    """A checker of black and white halves to linear 0.5 (code 188), where averaging codes gives 128."""
    checker = np.zeros((4, 4, 3), np.uint8)
    checker[::2, ::2] = checker[1::2, 1::2] = 255
    tex = wt.Texture(checker, format="srgb8")
    assert encode(tex.numpy(1), wt.Format.SRGB8)[0, 0, 0] == 188
    np.testing.assert_allclose(tex.numpy(1), io.srgb_to_linear(np.full((2, 2, 3), 188 / 255)), atol=0)


@pytest.mark.parametrize("fmt", COMPACT)
@pytest.mark.parametrize("filter", ["bilinear", "trilinear"])
def test_texel_gradients_land_in_float32_as_the_float_twins_do(rng, fmt, filter):
    tex = wt.Texture(_values(rng, (12, 10, 3), fmt), format=fmt, requires_grad=True)
    twin = float_twin(tex)
    twin_grad = wt.Texture(twin.numpy(0), mipmaps=tex.num_levels, requires_grad=True)
    for k in range(1, tex.num_levels):
        twin_grad.level(k).assign(twin.level(k))
    uv = rng.uniform(-1, 2, (300, 2)).astype(np.float32)
    lod = {"lod": rng.uniform(0, 3, 300).astype(np.float32)} if filter == "trilinear" else {}
    weights = rng.normal(size=(300, 3)).astype(np.float32)
    grads = []
    for t in (tex, twin_grad):
        tape = wp.Tape()
        with tape:
            out = wt.sample(t, uv, sampler=wt.Sampler(filter=filter), **lod)
        tape.backward(grads={out: wp.array(weights, dtype=float)})
        grads.append([t.grad(k) for k in range(t.num_levels)])
    for a, b in zip(*grads):
        assert a.dtype == np.float32
        _same_bits(a, b)
    assert np.abs(grads[0][0]).sum() > 0

    # finite differences on a float32 master copy of level 0 (bilinear: level 0 alone is read)
    if filter == "bilinear":
        master = tex.numpy(0).astype(np.float64)
        for row, col, c in [(3, 4, 0), (7, 2, 2), (0, 9, 1)]:
            def loss(delta):
                m = master.copy()
                m[row, col, c] += delta
                t = wt.Texture(m.astype(np.float32), mipmaps=False)
                return float((wt.sample(t, uv, sampler=wt.Sampler(filter="bilinear")).numpy().astype(np.float64) * weights).sum())
            fd = (loss(1e-2) - loss(-1e-2)) / 2e-2
            np.testing.assert_allclose(grads[0][0][row, col, c], fd, rtol=2e-3, atol=2e-4)


@pytest.mark.parametrize("fmt", COMPACT)
def test_update_on_the_tape_carries_coarse_gradients_to_level_0_as_float32_does(rng, fmt):
    """A compact texture's mips are built on the host; ``update()`` inside the tape records their
    backward pass, which carries every level's gradient to level 0 (and clears it), bit for bit as
    a float32 texture's recorded box-filter launches do."""
    tex = wt.Texture(_values(rng, (13, 10, 3), fmt), format=fmt, requires_grad=True)
    twin = wt.Texture(tex.numpy(0), requires_grad=True)
    uv = rng.uniform(-1, 2, (400, 2)).astype(np.float32)
    lod = rng.uniform(0, 3.5, 400).astype(np.float32)
    weights = rng.normal(size=(400, 3)).astype(np.float32)
    grads = []
    for t in (tex, twin):
        tape = wp.Tape()
        with tape:
            t.update()
            out = wt.sample(t, uv, lod=lod, sampler=wt.Sampler(filter="trilinear"))
        tape.backward(grads={out: wp.array(weights, dtype=float)})
        grads.append([t.grad(k) for k in range(t.num_levels)])
        assert all(not g.any() for g in grads[-1][1:]), "the coarse levels' gradients were carried down"
        tape.zero()
        assert not t.grad(0).any()
    _same_bits(grads[0][0], grads[1][0])
    assert tex.num_levels == 4 and np.abs(grads[0][0]).sum() > 0

    # outside a tape (or without update() on it) each level keeps its own gradient, as before
    tape = wp.Tape()
    with tape:
        out = wt.sample(tex, uv, lod=lod, sampler=wt.Sampler(filter="trilinear"))
    tape.backward(grads={out: wp.array(weights, dtype=float)})
    assert tex.grad(2).any()


@pytest.mark.parametrize("fmt", COMPACT)
def test_uv_and_lod_gradients_of_a_compact_texture_are_its_float_twins(rng, fmt):
    """``sample``'s own gradient serves UVs and a LOD per sample, so a compact texture takes them
    (with its texels' gradient too): those of its float32 twin (every level's decoded texels), to
    rounding."""
    tex = wt.Texture(_values(rng, (24, 20, 4), fmt), format=fmt, requires_grad=True)
    twin = wt.Texture(tex.numpy(0), requires_grad=True)
    for k in range(1, tex.num_levels):  # the compact chain's own levels, decoded (not float32's own mips)
        twin.level(k).assign(tex.numpy(k))
    uv = rng.uniform(-1.0, 2.0, (500, 2)).astype(np.float32)
    lod = rng.uniform(0.0, 4.0, 500).astype(np.float32)
    weights = rng.normal(size=(500, 4)).astype(np.float32)
    grads = []
    for t in (tex, twin):
        inputs = [wp.array(uv, dtype=wp.vec2, requires_grad=True), wp.array(lod, dtype=float, requires_grad=True)]
        tape = wp.Tape()
        with tape:
            out = wt.sample(t, inputs[0], lod=inputs[1], sampler=wt.Sampler(filter="trilinear"))
        tape.backward(grads={out: wp.array(weights, dtype=float)})
        grads.append([a.grad.numpy() for a in inputs] + [t.grad(0)])
    for got, want in zip(*grads):
        assert np.abs(want).max() > 0
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())


@pytest.mark.parametrize("fmt", COMPACT)
def test_triplanar_parameter_gradients_of_a_compact_texture_are_its_float_twins(rng, fmt):
    """Plain triplanar's own gradient serves the tiling, offsets and sharpness, so a compact
    texture takes them (with its texels' gradient, on the lanes): its float32 twin's, to rounding."""
    gbuffer = wt.rasterize(terrain(resolution=(65, 65)), terrain_camera((48, 64)))
    tex = wt.Texture(_values(rng, (32, 32, 4), fmt), format=fmt, requires_grad=True)
    twin = wt.Texture(tex.numpy(0), requires_grad=True)
    for k in range(1, tex.num_levels):  # the compact chain's own levels, decoded
        twin.level(k).assign(tex.numpy(k))
    weights = rng.normal(size=(48, 64, 4)).astype(np.float32)
    grads = []
    for t in (tex, twin):
        tiling = wp.array([0.3, 0.25, 0.35], dtype=float, requires_grad=True)
        offsets = wp.array(np.float32([[0.1, 0.3], [0.0, 0.25], [0.5, 0.2]]), dtype=float, requires_grad=True)
        sharpness = wp.array([3.5], dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = wt.triplanar(gbuffer, t, tiling=tiling, offsets=offsets, sharpness=sharpness, sampler=wt.Sampler(filter="anisotropic"))
        tape.backward(grads={out: wp.array(weights, dtype=float)})
        grads.append([tiling.grad.numpy(), offsets.grad.numpy(), sharpness.grad.numpy(), t.grad(0)])
    for got, want in zip(*grads):
        assert np.abs(want).max() > 0
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * np.abs(want).max())


def test_a_gradient_only_warps_generated_adjoint_gives_is_refused_for_a_compact_texture(rng):
    tex = wt.Texture(rng.integers(0, 256, (8, 8, 4), dtype=np.uint8), format="srgb8", requires_grad=True)
    uv = rng.uniform(0, 1, (10, 2)).astype(np.float32)
    with force_generated_adjoint(), wp.Tape():
        with pytest.raises(ValueError, match="compact format"):
            wt.sample(tex, uv)


@pytest.mark.parametrize("fmt", COMPACT)
def test_every_technique_reads_a_compact_texture_as_its_float_twin(rng, fmt):
    gbuffer = wt.rasterize(terrain(resolution=(65, 65)), terrain_camera((48, 64)))  # UVs, slopes and cliffs
    tex = wt.Texture(_values(rng, (32, 32, 4), fmt), format=fmt)
    layers = wt.TextureArray(_values(rng, (3, 32, 32, 4), fmt), format=fmt)
    maps = wt.Texture(rng.uniform(0, 1, (16, 16, 3)).astype(np.float32))
    runs = {
        "triplanar": lambda t, a: wt.triplanar(gbuffer, t, tiling=2.0),
        "biplanar": lambda t, a: wt.biplanar(gbuffer, t, tiling=2.0),
        "triplanar_normal": lambda t, a: wt.triplanar_normal(gbuffer, t, tiling=2.0),
        "triplanar stochastic": lambda t, a: wt.triplanar(gbuffer, t, tiling=2.0, stochastic=wt.Stochastic(method="hex")),
        "stochastic": lambda t, a: wt.stochastic(t, rng_uv, "hash4"),
        "splat": lambda t, a: wt.splat(gbuffer, a, maps, projection="uv"),
        "splat stochastic": lambda t, a: wt.splat(gbuffer, a, maps, projection="uv", stochastic=wt.Stochastic(method="cheap2")),
    }
    rng_uv = rng.uniform(-3, 3, (500, 2)).astype(np.float32)
    twins = float_twin(tex), float_twin(layers)
    for name, run in runs.items():
        for one_pixel in (False, True):
            with one_pixel_kernels(one_pixel):
                _same_bits(run(tex, layers).numpy(), run(*twins).numpy())


def test_nbytes_of_a_compact_texture(rng):
    image = rng.integers(0, 256, (1024, 1024, 4), dtype=np.uint8)
    srgb, full = wt.Texture(image, format="srgb8"), wt.Texture(image)
    assert full.nbytes == 16 * sum(h * w for h, w in full.level_sizes)
    assert srgb.nbytes == 4 * sum(h * w for h, w in srgb.level_sizes) + 4 * 1024  # texels and the decode table
    assert srgb.nbytes <= 0.26 * full.nbytes
    assert wt.Texture(image, format="float16").nbytes == full.nbytes // 2


def test_assign_stores_a_float_master_copy(rng):
    master = rng.uniform(0, 1, (10, 12, 3)).astype(np.float32)
    tex = wt.Texture(np.zeros((10, 12, 3), np.float32), format="srgb8")
    tex.assign(master)
    _same_bits(tex.numpy(0), wt.Texture(master, format="srgb8").numpy(0))
    _same_bits(tex.numpy(2), wt.Texture(master, format="srgb8").numpy(2))
    assert np.abs(tex.numpy(0) - master).max() < 0.01  # 8-bit sRGB steps are at most ~0.9% of white
    with pytest.raises(ValueError, match="shaped"):
        tex.assign(master[:5])


def test_bad_formats_and_values_are_refused_clearly(rng):
    with pytest.raises(ValueError, match="format must be one of"):
        wt.Texture(np.zeros((2, 2, 3), np.float32), format="rgba8")
    with pytest.raises(ValueError, match="65504"):
        wt.Texture(np.full((2, 2, 1), 1e5, np.float32), format="float16")
    tex = wt.Texture(np.zeros((2, 2, 3), np.uint8), format="unorm8")
    with pytest.raises(TypeError, match="numpy\\(\\)"):
        tex.texels
    assert wt.Texture(np.zeros((2, 2, 3), np.uint8), format="SRGB8").format is wt.Format.SRGB8


def test_files_keep_their_precision(tmp_path, rng):
    image = rng.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    png = tmp_path / "a.png"
    from PIL import Image

    Image.fromarray(image).save(png)
    colour, data = wt.Texture.from_file(png), wt.Texture.from_file(png, data=True)
    assert (colour.format, data.format) == (wt.Format.SRGB8, wt.Format.UNORM8)
    _same_bits(colour.numpy(0), io.read_image(png))
    _same_bits(data.numpy(0), io.read_image(png, data=True))
    assert wt.Texture.from_file(png, format="float32").format is wt.Format.FLOAT32
    _same_bits(wt.Texture.from_file(png, format="float32").numpy(0), io.read_image(png))
    _same_bits(wt.Texture.from_file(png, channels=3).numpy(0), io.read_image(png, channels=3))
    luma = wt.Texture.from_file(png, channels=1)  # luminance is taken of decoded values: float32
    assert luma.format is wt.Format.FLOAT32
    _same_bits(luma.numpy(0), io.read_image(png, channels=1))

    half = tmp_path / "h.exr"
    values = rng.uniform(0, 4, (8, 6, 3)).astype(np.float32)
    io.write_exr(half, values, half=True)
    tex = wt.Texture.from_file(half)
    assert tex.format is wt.Format.FLOAT16
    _same_bits(tex.numpy(0), io.read_image(half))
    full = tmp_path / "f.exr"
    io.write_exr(full, values)
    assert wt.Texture.from_file(full).format is wt.Format.FLOAT32

    layers = wt.TextureArray.from_files([png, png])
    assert layers.format is wt.Format.SRGB8
    assert wt.TextureArray.from_files([png, png], data=True).format is wt.Format.UNORM8


def test_a_real_texture_as_srgb8_samples_as_read_image_does(shared_data, rng):
    path = next((p for p in sorted(shared_data.rglob("*.png")) + sorted(shared_data.rglob("*.jpg")) if p.stat().st_size < 8 << 20), None)
    if path is None:
        pytest.skip("no PNG or JPG texture in ../shared/data")
    tex = wt.Texture.from_file(path, mipmaps=False)
    if tex.format is not wt.Format.SRGB8:
        pytest.skip(f"{path.name} is not an 8-bit image")
    uv = rng.uniform(-1, 2, (4000, 2)).astype(np.float32)
    _same_bits(wt.sample(tex, uv).numpy(), wt.sample(wt.Texture(io.read_image(path), mipmaps=False), uv).numpy())
    assert tex.nbytes <= 0.26 * wt.Texture(io.read_image(path), mipmaps=False).nbytes


@pytest.mark.parametrize("fmt", COMPACT)
def test_a_tiling_gradient_reads_a_compact_texture_as_its_float_twin(rng, fmt):
    """The fit's path: Warp's generated adjoint differentiates the tiling through texels it only
    reads (the layers are not fitted), as the float twin's texels."""
    gbuffer = wt.rasterize(terrain(resolution=(65, 65)), terrain_camera((48, 64)))
    tex = wt.Texture(_values(rng, (32, 32, 4), fmt), format=fmt)
    weights = rng.normal(size=gbuffer.resolution + (4,)).astype(np.float32)
    grads = []
    for t in (tex, float_twin(tex)):
        tiling = wp.array([2.0], dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = wt.triplanar(gbuffer, t, tiling=tiling)
        out.grad.assign(weights)
        tape.backward()
        grads.append(tiling.grad.numpy().copy())
    _same_bits(grads[0], grads[1])
    assert grads[0][0] != 0.0
