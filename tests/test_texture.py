"""Texture and TextureArray: bad input, mip-chain properties, loading from files, real photos.

Sampling formulas are tested in ``test_sampling.py`` and file formats in ``test_io.py``; here the
texture objects themselves are checked: what they accept and refuse, what their properties report,
that ``texels``/``update()`` keep the chain consistent, and that files (synthetic ones and the
512 × 512 photos in ``../shared/data/textures``) load into textures that sample back to the file.
"""

import re
import warnings

import numpy as np
import pytest
import warp as wp
from PIL import Image

import reference as ref
import warptex as wt
from conftest import with_sampler
from warptex.io import read_image, srgb_to_linear, write_exr, write_png

PHOTOS = ("brick.png", "grass.png", "gravel.png")


def _image(rng, h, w, c=1):
    return rng.random((h, w, c), dtype=np.float32)


def _sample(tex, uv, **kw):
    return wt.sample(tex, uv, **with_sampler(kw)).numpy()


def _centres(h, w):
    return ref.texel_centres(h, w).reshape(-1, 2)


def _vec4(img):
    """``[h, w, C]`` padded to ``[h, w, 4]`` for ``wp.array(vec4).assign``."""
    return np.pad(img, [(0, 0)] * (img.ndim - 1) + [(0, 4 - img.shape[-1])]).astype(np.float32)


# -- bad input ---------------------------------------------------------------------------------------

NAN_IMAGE = np.array([[0.0, 1.0, 0.5], [0.0, 0.0, np.nan]])


@pytest.mark.parametrize(
    "image, error, match",
    [
        (np.zeros(4), ValueError, r"Texture\(\): image must have shape \(H, W, C\) or \(H, W\), got \(4,\)"),
        (np.zeros((2, 2, 2, 2, 2)), ValueError, r"Texture\(\): image must have shape .*got \(2, 2, 2, 2, 2\)"),
        (np.zeros((4, 4, 0)), ValueError, r"Texture\(\): image must have 1 to 4 channels, got 0"),
        (np.zeros((4, 4, 5)), ValueError, r"Texture\(\): image must have 1 to 4 channels, got 5"),
        (np.zeros((0, 4)), ValueError, r"Texture\(\): image must not be empty, got shape \(0, 4"),
        (np.zeros((4, 0, 3)), ValueError, r"Texture\(\): image must not be empty, got shape \(4, 0, 3\)"),
        (np.zeros((2, 2), object), TypeError, r"Texture\(\): image must hold real numbers, got dtype object"),
        (np.array([["a", "b"]]), TypeError, r"Texture\(\): image must hold real numbers, got dtype <U1"),
        (np.zeros((2, 2), bool), TypeError, r"Texture\(\): image must hold real numbers, got dtype bool"),
        (NAN_IMAGE, ValueError, r"Texture\(\): image contains non-finite texels, first -?(nan|inf)"),
        (np.array([[0.0, -np.inf]]), ValueError, r"Texture\(\): image contains non-finite texels, first -?(nan|inf)"),
    ],
)
def test_texture_refuses_bad_images(image, error, match):
    with pytest.raises(error, match=match):
        wt.Texture(image)


@pytest.mark.parametrize("value, name", [(np.nan, r"\bnan\b"), (np.inf, r"\binf\b"), (-np.inf, r"-inf\b")])
def test_non_finite_message_names_the_value_and_texel(value, name):
    image = np.zeros((3, 4, 2), np.float32)
    image[1, 2, 1] = value
    with pytest.raises(ValueError, match=rf"Texture\(\): image .*{name}.*\(1, 2, 1\)"):
        wt.Texture(image)


@pytest.mark.parametrize(
    "layers, error, match",
    [
        ([np.zeros((4, 4)), np.zeros((4, 4, 1)), np.zeros((4, 5))], ValueError,
         r"TextureArray\(\): all layers must have the same \(H, W, C\); layer 0 is \(4, 4, 1\) but layer 2 is \(4, 5, 1\)"),
        ([np.zeros((4, 4, 1)), np.zeros((4, 4, 3))], ValueError, r"layer 0 is \(4, 4, 1\) but layer 1 is \(4, 4, 3\)"),
        ([], ValueError, r"TextureArray\(\): needs at least one layer, got an empty sequence"),
        ((), ValueError, r"TextureArray\(\): needs at least one layer, got an empty sequence"),
        (np.zeros((0, 4, 4, 1)), ValueError, r"TextureArray\(\): needs at least one layer, got shape \(0, 4, 4, 1\)"),
        (np.zeros((4, 4)), ValueError, r"TextureArray\(\): layers must have shape \(L, H, W, C\) or \(L, H, W\), got \(4, 4\)"),
        (np.zeros((1, 2, 2, 2, 2)), ValueError, r"TextureArray\(\): layers must have shape .*got \(1, 2, 2, 2, 2\)"),
        (np.zeros((2, 4, 4, 7)), ValueError, r"TextureArray\(\): layer 0 must have 1 to 4 channels, got 7"),
        ([np.zeros((4, 4)), np.full((4, 4), np.inf)], ValueError, r"TextureArray\(\): layer 1 contains non-finite texels, first inf"),
        ([np.zeros((4, 4)), np.array([["a"]])], TypeError, r"TextureArray\(\): layer 1 must hold real numbers, got dtype <U1"),
        (np.zeros((2, 2, 2), object), TypeError, r"TextureArray\(\): layers must hold real numbers, got dtype object"),
    ],
)
def test_texture_array_refuses_bad_layers(layers, error, match):
    with pytest.raises(error, match=match):
        wt.TextureArray(layers)


@pytest.mark.parametrize("cls", [wt.Texture, wt.TextureArray])
@pytest.mark.parametrize("mipmaps", [0, -1])
def test_bad_mipmaps_counts(cls, mipmaps):
    data = np.zeros((4, 4) if cls is wt.Texture else (1, 4, 4))
    with pytest.raises(ValueError, match=rf"{cls.__name__}\(\): mipmaps must be a bool or a positive int, got {mipmaps}"):
        cls(data, mipmaps=mipmaps)


@pytest.mark.parametrize("mipmaps", ["yes", None])
def test_mipmaps_of_the_wrong_type_is_a_type_error(mipmaps):
    with pytest.raises(TypeError, match=rf"Texture\(\): mipmaps must be a bool or a positive int, got {mipmaps!r}"):
        wt.Texture(np.zeros((4, 4)), mipmaps=mipmaps)


@pytest.mark.parametrize("method", ["level", "numpy", "grad"])
@pytest.mark.parametrize("level", [3, -1, 1.0, "1"])
def test_level_out_of_range(method, level):
    tex = wt.Texture(np.zeros((4, 4, 2)), requires_grad=True)  # levels 0..2
    with pytest.raises(ValueError, match=rf"Texture\b.*level must be an int in \[0, 2\], got {re.escape(repr(level))}"):
        getattr(tex, method)(level)
    arr = wt.TextureArray(np.zeros((2, 8, 8)), mipmaps=2, requires_grad=True)
    with pytest.raises(ValueError, match=r"TextureArray\b.*level must be an int in \[0, 1\], got 2"):
        getattr(arr, method)(2)


def test_grad_level_out_of_range_without_gradients():
    with pytest.raises(ValueError, match=r"Texture\b.*level must be an int in \[0, 2\], got 7"):
        wt.Texture(np.zeros((4, 4))).grad(7)


# -- properties ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "size, max_levels, expected",
    [
        ((8, 8), None, [(8, 8), (4, 4), (2, 2), (1, 1)]),
        ((16, 4), None, [(16, 4), (8, 2), (4, 1), (2, 1), (1, 1)]),
        ((5, 3), None, [(5, 3), (2, 1), (1, 1)]),
        ((13, 17), None, [(13, 17), (6, 8), (3, 4), (1, 2), (1, 1)]),
        ((1, 8), None, [(1, 8), (1, 4), (1, 2), (1, 1)]),
        ((6, 1), None, [(6, 1), (3, 1), (1, 1)]),
        ((1, 1), None, [(1, 1)]),
        ((64, 16), 3, [(64, 16), (32, 8), (16, 4)]),
        ((64, 16), 1, [(64, 16)]),
        ((5, 3), 100, [(5, 3), (2, 1), (1, 1)]),
    ],
)
def test_mip_sizes(size, max_levels, expected):
    assert wt.mip_sizes(*size, max_levels=max_levels) == expected
    assert wt.mip_sizes(512, 512)[-1] == (1, 1) and len(wt.mip_sizes(512, 512)) == 10


@pytest.mark.parametrize("args, match", [((0, 4), r"height .*got 0"), ((4, -2), r"width .*got -2"), ((4, 4, 0), r"max_levels .*got 0")])
def test_mip_sizes_refuses_bad_sizes(args, match):
    with pytest.raises(ValueError, match=rf"mip_sizes\(\): {match}"):
        wt.mip_sizes(*args)


def test_texture_properties(rng):
    img = _image(rng, 12, 20, 3)
    tex = wt.Texture(img)
    sizes = [(12, 20), (6, 10), (3, 5), (1, 2), (1, 1)]
    assert (tex.height, tex.width, tex.channels, tex.num_layers, tex.num_levels) == (12, 20, 3, 1, 5)
    assert tex.level_sizes == sizes and not tex.requires_grad
    assert repr(tex) == f"Texture(layers=1, size=12x20, channels=3, format=float32, levels=5, device={tex.device})"
    assert tex.texels.shape == (12, 20) and tex.texels.dtype == wp.vec4
    for k, (h, w) in enumerate(sizes):
        assert tex.level(k).shape == (h, w) and tex.numpy(k).shape == (h, w, 3)
    np.testing.assert_array_equal(tex.numpy(), img)
    img[0, 0] = 7.0  # the texture holds a copy
    assert tex.numpy()[0, 0, 0] != 7.0
    assert [wt.Texture(img, mipmaps=m).num_levels for m in (False, True, 1, 3, np.int64(2), 99)] == [1, 5, 1, 3, 2, 5]
    assert wt.Texture(img, mipmaps=3).level_sizes == sizes[:3]


def test_texture_accepts_2d_images():
    tex = wt.Texture(np.arange(12, dtype=np.float64).reshape(3, 4))
    assert tex.channels == 1 and tex.numpy().dtype == np.float32
    np.testing.assert_array_equal(tex.numpy()[..., 0], np.arange(12).reshape(3, 4))  # float values as given


@pytest.mark.parametrize("dtype, maxval", [(np.uint8, 255), (np.uint16, 65535)])
@pytest.mark.parametrize("cls", [wt.Texture, wt.TextureArray])
def test_uint8_and_uint16_texels_are_scaled_to_unit_range_as_read_image_does(tmp_path, cls, dtype, maxval):
    codes = np.linspace(0, maxval, 12).astype(dtype).reshape(3, 4)
    tex = cls(codes if cls is wt.Texture else codes[None])
    got = tex.numpy() if cls is wt.Texture else tex.numpy()[0]
    assert got.dtype == np.float32 and got.min() == 0.0 and got.max() == 1.0
    write_png(tmp_path / "codes.png", codes / maxval, data=True, bits=8 if dtype is np.uint8 else 16)
    np.testing.assert_array_equal(got, read_image(tmp_path / "codes.png", data=True))  # the same floats as the file
    arr = wt.TextureArray([codes, codes.astype(np.float32) / maxval])  # a list of layers, mixed dtypes
    np.testing.assert_array_equal(arr.numpy()[0], arr.numpy()[1])


@pytest.mark.parametrize("dtype", [np.int8, np.int16, np.int32, np.int64, np.uint32, np.uint64])
def test_other_integer_texels_are_refused(dtype):
    with pytest.raises(TypeError, match=rf"Texture\(\): image has integer dtype {np.dtype(dtype)}; pass floats .*uint8 / uint16"):
        wt.Texture(np.zeros((2, 2), dtype))
    with pytest.raises(TypeError, match=rf"TextureArray\(\): layers has integer dtype {np.dtype(dtype)}"):
        wt.TextureArray(np.zeros((1, 2, 2), dtype))
    with pytest.raises(TypeError, match=rf"TextureArray\(\): layer 1 has integer dtype {np.dtype(dtype)}"):
        wt.TextureArray([np.zeros((2, 2)), np.zeros((2, 2), dtype)])
    with pytest.raises(TypeError, match=r"Texture\(\): image has integer dtype int64"):
        wt.Texture([[0, 1], [1, 0]])  # Python ints: no scale can be guessed


def test_ragged_nesting_is_a_clear_error():
    with pytest.raises(ValueError, match=r"Texture\(\): image must be a rectangular array of numbers, got list"):
        wt.Texture([[0.0, 1.0], [0.5]])
    with pytest.raises(ValueError, match=r"TextureArray\(\): layer 1 must be a rectangular array of numbers"):
        wt.TextureArray([np.zeros((2, 2)), [[0.0, 1.0], [0.5]]])


def test_texture_array_from_textures_copies_their_level_0(rng):
    images = [_image(rng, 8, 6, 4) for _ in range(3)]
    textures = [wt.Texture(img, requires_grad=True) for img in images]
    arr = wt.TextureArray(textures, mipmaps=2)
    assert (arr.num_layers, arr.height, arr.width, arr.channels, arr.num_levels) == (3, 8, 6, 4, 2)
    np.testing.assert_array_equal(arr.numpy(), np.stack(images))
    for k, img in enumerate(images):
        np.testing.assert_allclose(arr.numpy(1)[k], ref.mip_chain(img)[1], rtol=1e-6, atol=1e-7)
    textures[0].texels.zero_()  # a copy: later changes to the Textures do not reach the array
    np.testing.assert_array_equal(arr.numpy()[0], images[0])
    mixed = wt.TextureArray([textures[1], images[2]])  # Textures and arrays together
    np.testing.assert_array_equal(mixed.numpy(), np.stack(images[1:]))
    np.testing.assert_array_equal(wt.TextureArray(arr).numpy(), arr.numpy())  # a TextureArray is copied
    np.testing.assert_array_equal(wt.Texture(textures[1]).numpy(), images[1])  # and so is a Texture


def test_texture_array_from_textures_refuses_mismatches(rng):
    a, b = wt.Texture(_image(rng, 8, 8, 3)), wt.Texture(_image(rng, 8, 4, 3))
    with pytest.raises(ValueError, match=r"TextureArray\(\): all layers must have the same \(H, W, C\); layer 0 is \(8, 8, 3\) but layer 1 is \(8, 4, 3\)"):
        wt.TextureArray([a, b])
    with pytest.raises(ValueError, match=r"layer 0 is \(8, 8, 3\) but layer 1 is \(8, 8, 1\)"):
        wt.TextureArray([a, wt.Texture(_image(rng, 8, 8, 1))])
    with pytest.raises(TypeError, match=r"TextureArray\(\): layer 1 is a TextureArray of 2 layers; pass Textures or \[H, W, C\] arrays"):
        wt.TextureArray([a, wt.TextureArray(_image(rng, 2, 8, 8)[None].repeat(2, 0)[..., 0])])


def test_texture_array_properties(rng):
    layers = rng.random((2, 8, 4, 2), dtype=np.float32)
    arr = wt.TextureArray(layers, requires_grad=True)
    assert (arr.num_layers, arr.height, arr.width, arr.channels, arr.num_levels) == (2, 8, 4, 2, 4)
    assert arr.level_sizes == [(8, 4), (4, 2), (2, 1), (1, 1)] and arr.requires_grad
    assert repr(arr) == f"TextureArray(layers=2, size=8x4, channels=2, format=float32, levels=4, device={arr.device})"
    assert arr.texels.shape == (2, 8, 4) and arr.numpy(1).shape == (2, 4, 2, 2)
    np.testing.assert_array_equal(arr.numpy(), layers)
    assert wt.TextureArray(list(layers[..., 0])).channels == 1  # a list of [H, W] layers


@pytest.mark.parametrize("cls, shape", [(wt.Texture, (24, 20, 3)), (wt.TextureArray, (2, 24, 20, 3))])
def test_writing_texels_then_update_rebuilds_the_chain(rng, cls, shape):
    tex = cls(rng.random(shape, dtype=np.float32))
    old_level1 = tex.numpy(1)
    new = rng.random(shape, dtype=np.float32)
    tex.texels.assign(_vec4(new))  # texels is level 0 of the chain, not a copy
    np.testing.assert_array_equal(tex.numpy(0), new)
    np.testing.assert_array_equal(tex.numpy(1), old_level1)  # coarse levels wait for update()
    tex.update()
    for layer, img in enumerate(new[None] if cls is wt.Texture else new):
        for k, expected in enumerate(ref.mip_chain(img)):
            got = tex.numpy(k) if cls is wt.Texture else tex.numpy(k)[layer]
            np.testing.assert_allclose(got, expected, atol=1e-6, rtol=0)


def test_grad_and_zero_grad(rng):
    assert wt.Texture(_image(rng, 4, 4)).grad() is None
    assert wt.TextureArray(rng.random((2, 4, 4))).grad(1) is None
    wt.Texture(_image(rng, 4, 4)).zero_grad()  # nothing to reset: no error
    tex = wt.Texture(_image(rng, 8, 8, 2), requires_grad=True)
    assert tex.grad(0).shape == (8, 8, 2) and not tex.grad(0).any()
    tape = wp.Tape()
    with tape:
        out = wt.sample(tex, rng.random((50, 2)), lod=0.5)
    out.grad.fill_(1.0)
    tape.backward()
    assert tex.grad(0).any() and tex.grad(1).any()
    tex.zero_grad()
    assert not any(tex.grad(k).any() for k in range(tex.num_levels))


# -- files -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("data", [True, False])
def test_from_file_png(tmp_path, rng, data):
    img = _image(rng, 16, 8, 3)
    write_png(tmp_path / "a.png", img, data=data)
    tex = wt.Texture.from_file(tmp_path / "a.png", data=data, mipmaps=2, requires_grad=True)
    assert (tex.height, tex.width, tex.channels, tex.num_levels, tex.requires_grad) == (16, 8, 3, 2, True)
    np.testing.assert_array_equal(tex.numpy(), read_image(tmp_path / "a.png", data=data))
    np.testing.assert_allclose(tex.numpy(), img, atol=0.5 / 255 if data else 5e-3, rtol=0)
    raw = wt.Texture.from_file(str(tmp_path / "a.png"), data=True).numpy()
    np.testing.assert_allclose(wt.Texture.from_file(tmp_path / "a.png").numpy(), srgb_to_linear(raw), atol=1e-6)


def test_from_file_exr_channel_selection(tmp_path, rng):
    img = _image(rng, 6, 10, 4) * 5 - 2  # EXR keeps values outside [0, 1]
    path = tmp_path / "m.exr"
    write_exr(path, img, channel_names=("albedo.R", "albedo.G", "albedo.B", "rough"))
    tex = wt.Texture.from_file(path, channels=("rough", "albedo.G"))
    assert tex.channels == 2
    np.testing.assert_array_equal(tex.numpy(), img[..., [3, 1]])
    with pytest.raises(ValueError, match=r"\['metal'\] not found in '.*m\.exr'"):
        wt.Texture.from_file(path, channels=("rough", "metal"))


def test_from_file_errors(tmp_path):
    (tmp_path / "notes.txt").write_text("not an image")
    with pytest.raises(ValueError, match=r"cannot decode '.*notes\.txt' as an image"):
        wt.Texture.from_file(tmp_path / "notes.txt")
    with pytest.raises(FileNotFoundError, match=r"missing\.png"):
        wt.Texture.from_file(tmp_path / "missing.png")
    with pytest.raises(FileNotFoundError, match=r"missing\.png"):
        wt.TextureArray.from_files([tmp_path / "missing.png"])


def test_from_files(tmp_path, rng):
    paths = [tmp_path / f"{k}.png" for k in range(3)]
    for p in paths:
        write_png(p, _image(rng, 4, 6))
    arr = wt.TextureArray.from_files(paths, data=True, mipmaps=False)
    assert (arr.num_layers, arr.channels, arr.num_levels) == (3, 1, 1)
    np.testing.assert_array_equal(arr.numpy(), np.stack([read_image(p, data=True) for p in paths]))
    write_png(tmp_path / "odd.png", _image(rng, 4, 5))
    both = rf"'{re.escape(str(tmp_path / 'odd.png'))}' is \(4, 5, 1\).*'{re.escape(str(paths[0]))}' is \(4, 6, 1\)"
    with pytest.raises(ValueError, match=rf"TextureArray\.from_files\(\): {both}"):
        wt.TextureArray.from_files([paths[0], paths[1], tmp_path / "odd.png"])
    with pytest.raises(ValueError, match=r"TextureArray\.from_files\(\): needs at least one path"):
        wt.TextureArray.from_files([])


def test_from_files_refuses_a_single_path(tmp_path, rng):
    write_png(tmp_path / "a.png", _image(rng, 4, 4))
    with pytest.raises(TypeError, match=r"TextureArray\.from_files\(\): paths must be a sequence of paths"):
        wt.TextureArray.from_files(str(tmp_path / "a.png"))


# -- the photos in ../shared/data/textures ---------------------------------------------------------------


@pytest.fixture(params=PHOTOS)
def photo(request, shared_data):
    return shared_data / "textures" / request.param


def test_photo_texel_centres_are_exact(photo):
    img = read_image(photo)
    tex = wt.Texture.from_file(photo)
    assert (tex.height, tex.width, tex.channels, tex.num_levels) == (512, 512, 1, 10)
    np.testing.assert_allclose(tex.numpy(), srgb_to_linear(read_image(photo, data=True)), atol=1e-6)  # linear
    for filt in ("nearest", "bilinear"):
        np.testing.assert_array_equal(_sample(tex, _centres(512, 512), filter=filt), img.reshape(-1, 1))


def test_photo_trilinear_matches_reference(photo, rng):
    img = read_image(photo)
    tex = wt.Texture.from_file(photo, format="float32")  # float mips, as the reference builds them (srgb8 mips: test_formats)
    chain = ref.mip_chain(img)
    uv = rng.uniform(-0.5, 1.5, (2000, 2)).astype(np.float32)
    for k in range(4):
        np.testing.assert_allclose(tex.numpy(k), chain[k], atol=1e-6, rtol=0)
        np.testing.assert_allclose(_sample(tex, uv, lod=float(k)), ref.bilinear(chain[k], uv), atol=1e-5, rtol=0)
    lod = rng.uniform(0.0, 3.99, 2000).astype(np.float32)
    np.testing.assert_allclose(_sample(tex, uv, lod=lod), ref.trilinear(chain, uv, lod), atol=1e-5, rtol=0)


def test_photos_as_a_texture_array(shared_data, rng):
    paths = [shared_data / "textures" / name for name in PHOTOS]
    arr = wt.TextureArray.from_files(paths)
    assert (arr.num_layers, arr.height, arr.width, arr.channels) == (3, 512, 512, 1)
    uv = rng.uniform(-1, 2, (3000, 2)).astype(np.float32)
    lod = rng.uniform(0, 9, 3000).astype(np.float32)
    for k, path in enumerate(paths):
        single = wt.Texture.from_file(path)
        np.testing.assert_array_equal(arr.numpy(4)[k], single.numpy(4))
        np.testing.assert_array_equal(_sample(arr, uv, layer=k, lod=lod), _sample(single, uv, lod=lod))
        np.testing.assert_array_equal(_sample(arr, _centres(512, 512), layer=k, filter="nearest"), read_image(path).reshape(-1, 1))


def test_photo_round_trips_through_png_and_exr(photo, tmp_path):
    img = read_image(photo)
    tex = wt.Texture.from_file(photo)
    write_png(tmp_path / "copy.png", tex.numpy(), data=False)
    write_exr(tmp_path / "copy.exr", tex.numpy())
    with Image.open(photo) as a, Image.open(tmp_path / "copy.png") as b:
        np.testing.assert_array_equal(np.asarray(b), np.asarray(a))  # the same 8-bit codes
    for name in ("copy.png", "copy.exr"):
        out = _sample(wt.Texture.from_file(tmp_path / name), _centres(512, 512), filter="bilinear")
        np.testing.assert_array_equal(out.view(np.uint32), img.reshape(-1, 1).view(np.uint32))


def test_texture_errors_name_what_the_user_passed(monkeypatch):
    """Issue 50 item 14: a texture past memory raised NumPy's bare MemoryError part-way; NaN in
    splat maps was blamed on "TextureArray(): layer 0"; finite float64 UVs past float32's range
    came back NaN with only NumPy's overflow warning."""
    from warptex import _output
    from warptex import texture as texture_module

    monkeypatch.setattr(_output, "_available_memory", lambda: 1 << 20)
    monkeypatch.setattr(texture_module, "LARGE_CHAIN_BYTES", 1 << 20)  # checked from 64 MiB: small ones read nothing
    with pytest.raises(MemoryError, match=r"Texture\(\): a 1x256x256 float32 texture with 9 level\(s\) needs about 0.0 GiB of memory, but 0.0 GiB is available; use a smaller texture, a compact format, or mipmaps=False"):
        wt.Texture(np.zeros((256, 256, 4), np.float32))
    monkeypatch.undo()
    g = wt.GBuffer.empty((2, 2), uv_sets=("uv0",))
    maps = np.ones((2, 4, 4, 4), np.float32)
    maps[1, 2, 3, 0] = np.nan
    with pytest.raises(ValueError, match=r"^splat\(\): splat_maps: map 1 contains non-finite texels, first nan at \(row, col, channel\) \(2, 3, 0\)$"):
        wt.splat(g, wt.TextureArray(np.ones((8, 8, 8, 3), np.float32)), maps)
    texture = wt.Texture(np.ones((4, 4, 3), np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NumPy overflow warning either
        with pytest.raises(ValueError, match=r"^sample\(\): uv holds -1e\+39 at \(1, 0\), beyond float32's range \(about ±3.4e38\), which the kernels compute in$"):
            wt.sample(texture, np.array([[0.1, 0.5], [-1e39, 0.5]]))
    np.testing.assert_array_equal(wt.sample(texture, np.array([[0.1, 0.5]])).numpy(), 1.0)  # float64 in range: as before


def test_around_reads_a_contiguous_chain_in_place_and_refuses_a_strided_one(rng):
    """``around`` wraps another framework's buffer without a copy. The CPU lanes read a float32
    chain's texels 16 bytes apart, so a strided chain is refused before anything reads it."""
    image = rng.random((8, 8, 4)).astype(np.float32)
    tex = wt.Texture(image, mipmaps=False)
    chain = wp.array(image.reshape(-1, 4), dtype=wp.vec4)
    uv = rng.random((500, 2)).astype(np.float32)
    wrapped = wt.Texture.around(chain, 1, [(8, 8)], 4)
    smp = wt.Sampler(filter="bilinear")
    assert np.array_equal(wt.sample(wrapped, uv, sampler=smp).numpy(), wt.sample(tex, uv, sampler=smp).numpy())
    every_other = wp.array(np.repeat(image.reshape(-1, 4), 2, axis=0), dtype=wp.vec4)[::2]
    assert every_other.shape == (64,) and not every_other.is_contiguous
    with pytest.raises(ValueError, match="contiguous"):
        wt.Texture.around(every_other, 1, [(8, 8)], 4)
