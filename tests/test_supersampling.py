"""Supersampled G-buffers and their resolve (issue 34 item 3): several stratified samples per pixel,
textures filtered at one sample's footprint, coverage as a fraction."""

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt


def _plane(size=4.0):
    """A square in z = 0 facing +Z, UV0 across it."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64) * size / 2
    plane = trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)
    plane.visual = trimesh.visual.TextureVisuals(uv=v[:, :2] / size + 0.5)
    return plane


@pytest.mark.parametrize("s", [2, 3, 4])
def test_the_samples_of_a_pixel_are_stratified_n_rooks(s):
    """One sample in each of the s × s strata, and no two in one column or row of the s² × s²
    sub-grid; every pixel the same pattern; Camera.rays() and the rasteriser agree on it."""
    camera = wt.orthographic((0, 0, 5), (0, 0, 0), height=2.0, resolution=(3, 4))
    fine = camera.supersampled(s * s)
    assert fine.resolution == (3 * s, 4 * s) and fine.strata == s and fine.pixel_resolution == (3, 4)
    origins, _ = fine.rays()
    hx, hy = camera.half_extent
    px = (origins[..., 0] + hx) / (2 * hx) * 4  # pixel units, x right
    py = (hy - origins[..., 1]) / (2 * hy) * 3  # y down
    for i in range(3):
        for j in range(4):
            x = px[i * s : (i + 1) * s, j * s : (j + 1) * s] - j
            y = py[i * s : (i + 1) * s, j * s : (j + 1) * s] - i
            np.testing.assert_array_equal(np.floor(x * s), np.tile(np.arange(s), (s, 1)))  # stratum columns
            np.testing.assert_array_equal(np.floor(y * s), np.tile(np.arange(s)[:, None], (1, s)))  # stratum rows
            assert len(np.unique(np.floor(x * s * s + 1e-9))) == s * s and len(np.unique(np.floor(y * s * s + 1e-9))) == s * s
    g = wt.rasterize(_plane(), camera, samples=s * s)
    assert g.samples == s * s and g.resolution == (3 * s, 4 * s)
    np.testing.assert_allclose(g.position.numpy()[..., :2], origins[..., :2], atol=1e-6)


def test_rotated_grid_for_four_samples():
    """For 4 samples the pattern is 4× MSAA's rotated grid: (3/8, 1/8), (7/8, 3/8), (1/8, 5/8), (5/8, 7/8)."""
    camera = wt.orthographic((0, 0, 5), (0, 0, 0), height=2.0, resolution=(1, 1)).supersampled(4)
    origins, _ = camera.rays()
    x, y = (origins[..., 0] + 1) / 2, (1 - origins[..., 1]) / 2
    got = sorted(zip(x.ravel().round(6), y.ravel().round(6)))
    assert got == [(0.125, 0.625), (0.375, 0.125), (0.625, 0.875), (0.875, 0.375)]


def test_derivatives_are_those_of_one_samples_footprint():
    camera = wt.look_at((0.3, 0.4, 3.0), (0, 0, 0), resolution=(16, 16))
    one, four = wt.rasterize(_plane(), camera), wt.rasterize(_plane(), camera, samples=4)
    covered = one.mask.numpy() > 0
    for name in ("position_dx", "position_dy"):
        blocks = getattr(four, name).numpy().reshape(16, 2, 16, 2, 3).mean(axis=(1, 3))
        np.testing.assert_allclose(blocks[covered], getattr(one, name).numpy()[covered] / 2, rtol=0.02, atol=1e-6)
    uv_dx = four.uv("uv0")["uv_dx"].numpy().reshape(16, 2, 16, 2, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(uv_dx[covered], one.uv("uv0")["uv_dx"].numpy()[covered] / 2, rtol=0.02, atol=1e-7)


def test_resolve_averages_each_pixels_block_and_passes_gradients_back():
    rng = np.random.default_rng(5)
    image = rng.random((2, 9, 12, 3)).astype(np.float32)  # a batch of 2 views, 9 samples per pixel
    reference = image.reshape(2, 3, 3, 4, 3, 3).mean(axis=(2, 4))
    np.testing.assert_allclose(wt.resolve(image, 9).numpy(), reference, rtol=1e-6)
    np.testing.assert_allclose(wt.resolve(image[0, ..., 0], 9).numpy(), reference[0, ..., 0], rtol=1e-6)
    x = wp.array(image, dtype=float, requires_grad=True)
    seed = rng.random((2, 3, 4, 3)).astype(np.float32)
    tape = wp.Tape()
    with tape:
        out = wt.resolve(x, 9)
    out.grad.assign(seed)
    tape.backward()
    # d(Σ seed · resolve(x)) / dx: every sample gets 1/9 of its pixel's seed (the map is linear,
    # so this is also what finite differences give, to rounding).
    np.testing.assert_allclose(x.grad.numpy(), np.repeat(np.repeat(seed, 3, axis=1), 3, axis=2) / 9, rtol=1e-6)
    eps = 1e-2
    bumped = image.copy()
    bumped[1, 4, 7, 2] += eps
    fd = ((wt.resolve(bumped, 9).numpy() - wt.resolve(image, 9).numpy()) * seed).sum() / eps
    np.testing.assert_allclose(x.grad.numpy()[1, 4, 7, 2], fd, rtol=1e-3)


@pytest.mark.parametrize(
    "call, error, match",
    [
        (lambda: wt.resolve(np.zeros((4, 4)), 3), ValueError, r"resolve\(\): samples must be a square number"),
        (lambda: wt.resolve(np.zeros((5, 4)), 4), ValueError, r"resolve\(\): image must be 2-times a pixel size"),
        (lambda: wt.resolve(wp.zeros((4, 4), dtype=wp.int32), 4), TypeError, r"resolve\(\): image must be a wp.array of float32"),
        (lambda: wt.rasterize(_plane(), wt.look_at((0, 0, 3), (0, 0, 0), resolution=(4, 4)), samples=8), ValueError, r"rasterize\(\): samples must be a square number"),
    ],
)
def test_bad_supersampling_input_raises(call, error, match):
    with pytest.raises(error, match=match):
        call()


def _edge_coverage(height: int, width: int, slope: float, offset: float, n: int = 64) -> np.ndarray:
    """The exact fraction of each pixel below the line ``y = slope x + offset`` (pixel units, y
    down), by brute force on an n × n grid per pixel."""
    y, x = (np.mgrid[0 : height * n, 0 : width * n] + 0.5) / n
    return (y > slope * x + offset).reshape(height, n, width, n).mean(axis=(1, 3))


def test_silhouettes_get_the_fraction_of_the_pixel_they_cover():
    """A straight silhouette at a shallow angle: 16 stratified samples give each pixel's coverage
    within 1/16 on average (one sample per pixel: a staircase of 0 and 1)."""
    h, w = 24, 32
    camera = wt.orthographic((0, 0, 5), (0, 0, 0), height=float(h), resolution=(h, w))
    slope, offset = 0.23, 6.4  # the edge y = slope x + offset (pixel units, y down)
    # A big triangle whose top edge is that line, in world units (1 per pixel, y up, centred).
    to_world = lambda x, y: [x - w / 2, h / 2 - y, 0.0]  # noqa: E731
    tri = trimesh.Trimesh([to_world(-10, offset - 10 * slope), to_world(w + 10, offset + (w + 10) * slope), to_world(w / 2, h + 40)], [[0, 2, 1]], process=False)
    exact = _edge_coverage(h, w, slope, offset)
    one = wt.rasterize(tri, camera).mask.numpy()
    g = wt.rasterize(tri, camera, samples=16)
    alpha = wt.resolve(g.mask, g).numpy()
    edge = (exact > 0) & (exact < 1)
    assert np.abs(alpha - exact)[edge].mean() < 1 / 16
    assert np.abs(one - exact)[edge].mean() > 0.2
    assert set(np.unique(alpha[edge] * 16).round(6)) - set(range(17)) == set()
