"""The main job (``warptex demo``): outputs, anti-aliasing it is meant to show, and CLI errors."""

import numpy as np

import warptex as wt
from warptex import io
from warptex.apps import demo
from warptex.apps.cli import main


def test_demo_writes_png_and_exr(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--resolution", "48x64"]) == 0
    png = io.read_image(tmp_path / "demo.png", data=True)
    assert png.shape == (48 + 64, 4 * 64, 3)  # ground-plane row (four filters), then the address-mode row
    for name in ("demo_trilinear.exr", "demo_anisotropic.exr"):
        exr = io.read_image(tmp_path / name)
        assert exr.shape == (48, 64, 3) and np.isfinite(exr).all()
    assert "wrote" in capsys.readouterr().out


def test_cli_reports_bad_input_without_a_traceback(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--texture", str(tmp_path / "missing.png")]) == 1
    assert "read_image(): file not found" in capsys.readouterr().err
    assert not (tmp_path / "demo.png").exists()


def test_ground_plane_derivatives_match_neighbouring_pixels():
    # Away from the horizon, where the 1/distance projection is close to linear over 2 pixels.
    uv, uv_dx, uv_dy, mask = demo.ground_plane((120, 160))
    both = mask[1:-1, 1:-1] & mask[2:, 1:-1] & mask[:-2, 1:-1]
    both[:60] = False
    assert both.sum() > 5000
    central_x = (uv[1:-1, 2:] - uv[1:-1, :-2]) / 2
    central_y = (uv[2:, 1:-1] - uv[:-2, 1:-1]) / 2
    np.testing.assert_allclose(uv_dx[1:-1, 1:-1][both], central_x[both], rtol=0.05, atol=1e-6)
    np.testing.assert_allclose(uv_dy[1:-1, 1:-1][both], central_y[both], rtol=0.05, atol=1e-6)


def test_trilinear_removes_the_aliasing_that_level_zero_shows():
    # Near the horizon many texels fall into each pixel: level 0 aliases into noise, trilinear
    # filtering averages them. Pixel-to-pixel differences measure the noise.
    tex = wt.Texture(demo.checker_texture())
    uv, uv_dx, uv_dy, mask = demo.ground_plane((120, 160))
    far = mask & (np.linalg.norm(uv_dy, axis=-1) * 256 > 8)  # footprints over 8 texels
    assert far.sum() > 500

    def roughness(image):
        step = np.abs(np.diff(image, axis=1)).sum(-1)
        return step[far[:, 1:] & far[:, :-1]].mean()

    aliased = roughness(wt.sample(tex, uv, sampler=wt.Sampler(filter="bilinear")).numpy())
    filtered = roughness(wt.sample(tex, uv, uv_dx=uv_dx, uv_dy=uv_dy).numpy())
    assert filtered < 0.25 * aliased
