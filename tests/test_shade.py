"""The preview helpers: Lambert lighting with optional normals, normal maps from height, panels."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex.apps.shade import SKY, height_to_normal_map, lambert, side_by_side


def _flat_gbuffer(normal=(0.0, 1.0, 0.0)):
    g = wt.GBuffer.empty((1, 3))
    g.normal.assign(np.tile(np.asarray(normal, np.float32), (1, 3, 1)))
    g.mask.assign(np.array([[1.0, 1.0, 0.0]], np.float32))
    return g


def test_lambert_uses_given_normals_and_accepts_warp_arrays():
    g = _flat_gbuffer()
    albedo = wp.array(np.full((1, 3, 3), 0.5, np.float32), dtype=float)
    tilted = np.zeros((1, 3, 3), np.float32)
    tilted[..., 0] = 1.0  # facing +X: half lit by a light along +X, unlit by one along +Y
    up = lambert(g, albedo, light_dir=(0, 1, 0), ambient=0.2)
    side = lambert(g, albedo, normals=tilted, light_dir=(0, 1, 0), ambient=0.2)
    np.testing.assert_allclose(up[0, :2], 0.5)
    np.testing.assert_allclose(side[0, :2], 0.5 * 0.2)
    np.testing.assert_allclose(up[0, 2], SKY)


def test_lambert_rejects_bad_input():
    g = _flat_gbuffer()
    with pytest.raises(ValueError, match=r"lambert\(\): normals must have shape \(1, 3, 3\)"):
        lambert(g, np.zeros((1, 3, 3)), normals=np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"lambert\(\): albedo must have shape"):
        lambert(g, np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match=r"lambert\(\): ambient must be in \[0, 1\]"):
        lambert(g, np.zeros((1, 3, 3)), ambient=1.5)


def test_height_to_normal_map_slopes_and_orientation():
    """A ramp rising to the right tilts normals to -x; rising up the image (towards row 0) to -y."""
    cols = np.tile(np.arange(8, dtype=np.float32), (8, 1))
    rows = cols.T.copy()
    right = height_to_normal_map(cols, strength=1.0) * 2 - 1
    up = height_to_normal_map(-rows, strength=1.0) * 2 - 1  # height grows towards row 0
    inner = (slice(2, -2), slice(2, -2))  # away from the wrap-around seam
    np.testing.assert_allclose(right[inner], np.broadcast_to([-1, 0, 1] / np.sqrt(2), (4, 4, 3)), atol=1e-6)
    np.testing.assert_allclose(up[inner], np.broadcast_to([0, -1, 1] / np.sqrt(2), (4, 4, 3)), atol=1e-6)
    flat = height_to_normal_map(np.ones((4, 4, 3)))
    np.testing.assert_allclose(flat, np.broadcast_to([0.5, 0.5, 1.0], (4, 4, 3)))
    with pytest.raises(ValueError, match=r"height_to_normal_map\(\): height must be finite"):
        height_to_normal_map(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match=r"height_to_normal_map\(\): height must be \[H, W\]"):
        height_to_normal_map(np.zeros(5))


def test_side_by_side_lays_out_a_grid():
    panels = {f"p{i}": np.full((10, 12, 3), i / 4, np.float32) for i in range(5)}
    sheet = side_by_side(panels, columns=3)
    assert sheet.shape == (20, 36, 3)
    assert sheet.dtype == np.float32 and 0.0 <= sheet.min() and sheet.max() <= 1.0
    np.testing.assert_array_equal(sheet[10:, 24:], 0.0)  # the empty sixth cell
    with pytest.raises(ValueError, match="one size"):
        side_by_side({"a": np.zeros((4, 4, 3)), "b": np.zeros((5, 4, 3))})


def test_triplanar_bunny_example_writes_its_picture(shared_data, tmp_path):
    """The issue's picture: the example runs on the shared bunny and brick and writes the PNG."""
    path = Path(__file__).resolve().parents[1] / "examples" / "triplanar_bunny.py"
    spec = importlib.util.spec_from_file_location("triplanar_bunny", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    png = example.render_bunny(tmp_path, resolution=(96, 96))
    image = wt.io.read_image(png, data=True)
    assert image.shape == (192, 288, 3)
    weights = image[96 + 20 : 96 + 76, 96 + 20 : 96 + 76]  # the blend-weight panel's centre
    assert (weights.max(axis=-1) > 0.2).mean() > 0.5  # the bunny is in view and has weights
