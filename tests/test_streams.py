"""PNG and EXR files written band by band (warptex.png.PngWriter, warptex.exr_writer.ExrWriter):
read back exactly by independent decoders, the same bytes however the rows are cut, and nothing
left behind when a job stops short."""

import os

import imagecodecs
import numpy as np
import OpenEXR
import pytest
from PIL import Image

from warptex import io
from warptex.exr_writer import ExrWriter
from warptex.png import PngWriter, codes


def _bands(height: int) -> list[list[int]]:
    """Ways to cut ``height`` rows: whole, row by row, and uneven bands."""
    cuts = [[height], [1] * height]
    if height > 16:
        cuts.append([5, 11, height - 16])
    return cuts


def _write_png(path, image, bands, bits):
    h, w, c = image.shape
    with PngWriter(path, h, w, c, bits=bits) as writer:
        start = 0
        for n in bands:
            writer.write(image[start : start + n])
            start += n
    return path.read_bytes()


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("bits", [8, 16])
def test_png_bands_decode_to_the_codes_and_give_the_same_bytes(tmp_path, rng, channels, bits):
    image = rng.random((37, 29, channels)).astype(np.float32)
    image[:10] = np.linspace(-0.1, 1.1, 29)[None, :, None]  # smooth rows, clipped ends
    image[11, 3] = np.inf
    want = codes(image, bits=bits)
    files = {tuple(b): _write_png(tmp_path / "t.png", image, b, bits) for b in _bands(37)}
    assert len(set(files.values())) == 1, "the bytes depend on how the rows were cut"
    got = imagecodecs.png_decode(next(iter(files.values())))  # libpng
    assert got.dtype == want.dtype and (got.reshape(want.shape) == want).all()
    if bits == 8:
        assert (np.asarray(Image.open(tmp_path / "t.png")).reshape(want.shape) == want).all()
    assert os.listdir(tmp_path) == ["t.png"]


def test_png_codes_are_write_pngs(tmp_path, rng):
    """write_png is PngWriter over one band: sRGB-encoded colour, linear alpha, data as it is."""
    image = rng.random((9, 7, 4)).astype(np.float32)
    io.write_png(tmp_path / "a.png", image)
    decoded = np.asarray(Image.open(tmp_path / "a.png")).astype(np.float64) / 255
    np.testing.assert_allclose(decoded[..., :3], io.linear_to_srgb(image[..., :3]), atol=0.5 / 255 + 1e-7)
    np.testing.assert_allclose(decoded[..., 3], image[..., 3], atol=0.5 / 255 + 1e-7)
    io.write_png(tmp_path / "d.png", image, data=True)
    np.testing.assert_allclose(np.asarray(Image.open(tmp_path / "d.png")) / 255.0, image, atol=0.5 / 255 + 1e-7)


def test_a_png_or_exr_missing_rows_or_stopped_leaves_nothing(tmp_path):
    with pytest.raises(ValueError, match="3 of 4 rows"):
        with PngWriter(tmp_path / "a.png", 4, 5, 3) as writer:
            writer.write(np.zeros((3, 5, 3)))
    with pytest.raises(ValueError, match="3 of 4 rows"):
        with ExrWriter(tmp_path / "a.exr", 4, 5, ["R"]) as writer:
            writer.write(np.zeros((3, 5)))
    with pytest.raises(KeyboardInterrupt):
        with ExrWriter(tmp_path / "b.exr", 40, 5, ["R"]) as writer:
            writer.write(np.zeros((20, 5)))
            raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("make, rows, message", [
    (lambda p: PngWriter(p, 4, 5, 3), np.zeros((2, 6, 3)), r"rows must be \[n >= 1, 5, 3\]"),
    (lambda p: PngWriter(p, 4, 5, 3), np.zeros((5, 5, 3)), "would pass the image's 4"),
    (lambda p: PngWriter(p, 4, 5, 3), np.full((1, 5, 3), np.nan), "NaN"),
    (lambda p: ExrWriter(p, 4, 5, ["R", "G"]), np.zeros((2, 5, 3)), r"rows must be \[n >= 1, 5, 2\]"),
    (lambda p: ExrWriter(p, 4, 5, ["R", "G"]), {"R": np.zeros((1, 5))}, "must hold the channels"),
])
def test_bad_rows_are_refused_and_leave_nothing(tmp_path, make, rows, message):
    with pytest.raises(ValueError, match=message):
        with make(tmp_path / "x") as writer:
            writer.write(rows)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("kwargs, message", [
    (dict(height=0, width=2, channels=3), "height must be an int >= 1"),
    (dict(height=2, width=2, channels=5), "1-4 channels"),
    (dict(height=2, width=2, channels=3, bits=12), "bits must be 8 or 16"),
])
def test_png_writer_checks_its_arguments(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        PngWriter(tmp_path / "x.png", **kwargs)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("half", [False, True])
def test_exr_bands_read_back_exactly_by_openexr_and_give_the_same_bytes(tmp_path, rng, half):
    names = ["b", "a", "Position.X", "zz", "a_channel_name_longer_than_31_bytes_in_all"]
    image = (rng.normal(size=(37, 23, len(names))) * 100).astype(np.float32)
    image[20:] = 0.5  # chunks that compress and chunks that do not
    image[0, 0, 0], image[-1, -1, -1], image[3, 4, 1] = np.inf, np.nan, -0.0
    attributes = {"origin": np.array([1.5, -2.0, 1e9]), "samples": 4, "scale": 0.25, "note": "hi", "v": np.array([1, 2], np.float32)}
    files = set()
    for bands in _bands(37):
        with ExrWriter(tmp_path / "t.exr", 37, 23, names, half=half, attributes=attributes) as writer:
            start = 0
            for n in bands:
                writer.write(image[start : start + n])
                start += n
        files.add((tmp_path / "t.exr").read_bytes())
    assert len(files) == 1, "the bytes depend on how the rows were cut"
    with OpenEXR.File(str(tmp_path / "t.exr"), separate_channels=True) as exr:
        channels = exr.channels()
        for k, name in enumerate(names):
            want = image[..., k].astype(np.float16 if half else np.float32)
            assert channels[name].pixels.dtype == want.dtype
            assert channels[name].pixels.tobytes() == want.tobytes(), name
    read = io.exr_attributes(tmp_path / "t.exr")
    assert read["samples"] == 4 and read["scale"] == 0.25 and read["note"] == "hi"
    assert read["origin"].dtype == np.float64 and read["origin"].tolist() == [1.5, -2.0, 1e9]
    assert read["v"].dtype == np.float32 and read["v"].tolist() == [1.0, 2.0]


def test_write_exr_refuses_attributes_it_cannot_type(tmp_path):
    for value in (True, [1, 2, 3, 4], {"a": 1}):
        with pytest.raises(ValueError, match="attribute 'x'"):
            io.write_exr(tmp_path / "x.exr", np.zeros((2, 2)), attributes={"x": value})
    assert os.listdir(tmp_path) == []
