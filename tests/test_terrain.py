"""Procedural terrain: grid layout, UVs, winding, determinism, steepness, the slope helper, bad input.

The layout checked here is the one documented in :mod:`warptex.terrain`: vertex ``r * cols + c`` at
``x = -sx/2 + c·sx/(cols-1)``, ``z = -sz/2 + r·sz/(rows-1)``; ``u`` along +X, ``v`` along -Z.
"""

import math
import time

import numpy as np
import pytest
import trimesh

from warptex.scenes.terrain import terrain, terrain_slope_height


@pytest.fixture(scope="module")
def default_mesh():
    return terrain()


def _face_slopes(mesh):
    return np.degrees(np.arccos(np.clip(mesh.face_normals[:, 1], -1.0, 1.0)))


def _grid(rows, cols, sx, sz):
    """Independent reference of the documented vertex positions (x, z) as ``[rows, cols]`` arrays."""
    r, c = np.mgrid[0:rows, 0:cols]
    return -sx / 2 + c * sx / (cols - 1), -sz / 2 + r * sz / (rows - 1)


# -- layout -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("rows, cols", [(129, 129), (5, 9), (2, 2), (17, 3)])
def test_counts(rows, cols):
    mesh = terrain(resolution=(rows, cols))
    assert mesh.vertices.shape == (rows * cols, 3)
    assert mesh.faces.shape == (2 * (rows - 1) * (cols - 1), 3)
    assert mesh.faces.min() == 0 and mesh.faces.max() == rows * cols - 1
    assert len(np.unique(mesh.faces)) == rows * cols  # every vertex used


def test_extent_centred_and_grid_order():
    sx, sz, rows, cols = 40.0, 25.0, 11, 17
    mesh = terrain((sx, sz), (rows, cols), height=5.0)
    np.testing.assert_allclose(mesh.bounds[:, [0, 2]], [[-sx / 2, -sz / 2], [sx / 2, sz / 2]], atol=1e-12)
    np.testing.assert_allclose(mesh.extents[[0, 2]], [sx, sz], atol=1e-12)
    x, z = _grid(rows, cols, sx, sz)
    grid = mesh.vertices.reshape(rows, cols, 3)
    np.testing.assert_allclose(grid[..., 0], x, atol=1e-12)
    np.testing.assert_allclose(grid[..., 2], z, atol=1e-12)


def test_scalar_size_and_resolution():
    mesh = terrain(10.0, 9)
    assert mesh.vertices.shape == (81, 3)
    np.testing.assert_allclose(mesh.extents[[0, 2]], [10.0, 10.0])
    assert mesh.metadata["terrain"]["size"] == (10.0, 10.0)
    assert mesh.metadata["terrain"]["resolution"] == (9, 9)


def test_heights_span_zero_to_height(default_mesh):
    y = default_mesh.vertices[:, 1]
    assert np.all(np.isfinite(default_mesh.vertices))
    assert y.min() == 0.0
    assert y.max() == pytest.approx(14.0, abs=1e-9)
    y = terrain(resolution=33, height=3.5, seed=7).vertices[:, 1]
    assert y.min() == 0.0 and y.max() == pytest.approx(3.5, abs=1e-9)
    assert np.std(y) > 0.1  # not a flat plane


def test_zero_height_is_flat_plane():
    mesh = terrain(resolution=9, height=0.0)
    assert np.all(mesh.vertices[:, 1] == 0.0)
    np.testing.assert_allclose(mesh.vertex_normals, np.tile([0.0, 1.0, 0.0], (81, 1)), atol=1e-12)


# -- winding, normals, faces --------------------------------------------------------------------------


@pytest.mark.parametrize("kw", [{}, {"cliffs": 3.0, "height": 40.0}, {"seed": 5, "resolution": (40, 70)}])
def test_faces_wound_counter_clockwise_from_above(kw):
    mesh = terrain(**kw)
    assert np.all(mesh.face_normals[:, 1] > 0.0)
    assert np.all(mesh.vertex_normals[:, 1] > 0.0)
    assert np.all(mesh.area_faces > 0.0)  # no degenerate triangles


def test_vertex_normals_match_trimesh():
    # trimesh's own (angle-weighted) vertex normals on a fresh mesh with no cached normals
    mesh = terrain(resolution=(21, 25), seed=3)
    fresh = trimesh.Trimesh(mesh.vertices.copy(), mesh.faces.copy(), process=False)
    np.testing.assert_allclose(mesh.vertex_normals, fresh.vertex_normals, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(mesh.vertex_normals, axis=1), 1.0, atol=1e-12)


# -- UVs ----------------------------------------------------------------------------------------------


def test_uv_corners_and_orientation():
    sx, sz, rows, cols = 30.0, 20.0, 7, 11
    mesh = terrain((sx, sz), (rows, cols))
    assert isinstance(mesh.visual, trimesh.visual.TextureVisuals)
    uv = mesh.visual.uv
    assert uv.shape == (rows * cols, 2)
    assert uv.min() >= 0.0 and uv.max() <= 1.0
    corners = {  # (x, z) -> (u, v)
        (-sx / 2, +sz / 2): (0.0, 0.0),  # near-left: UV origin
        (+sx / 2, +sz / 2): (1.0, 0.0),
        (-sx / 2, -sz / 2): (0.0, 1.0),  # far-left: top of the image
        (+sx / 2, -sz / 2): (1.0, 1.0),
    }
    for (x, z), expected in corners.items():
        i = np.flatnonzero((mesh.vertices[:, 0] == x) & (mesh.vertices[:, 2] == z))
        assert len(i) == 1
        assert tuple(uv[i[0]]) == expected
    # u, v are affine in x, z everywhere
    np.testing.assert_allclose(uv[:, 0], (mesh.vertices[:, 0] + sx / 2) / sx, atol=1e-12)
    np.testing.assert_allclose(uv[:, 1], (sz / 2 - mesh.vertices[:, 2]) / sz, atol=1e-12)


def test_uv_image_layout_matches_height_image():
    # heights reshaped to [rows, cols] are an image whose row 0 is the top (v = 1)
    rows, cols = 9, 13
    uv = terrain(resolution=(rows, cols)).visual.uv.reshape(rows, cols, 2)
    np.testing.assert_allclose(uv[0, :, 1], 1.0)
    np.testing.assert_allclose(uv[-1, :, 1], 0.0)
    np.testing.assert_allclose(uv[:, 0, 0], 0.0)
    np.testing.assert_allclose(uv[:, -1, 0], 1.0)


# -- determinism and variety --------------------------------------------------------------------------


def test_same_seed_is_bit_identical():
    a = terrain(resolution=65, seed=11)
    b = terrain(resolution=65, seed=11)
    assert a.vertices.tobytes() == b.vertices.tobytes()
    assert a.faces.tobytes() == b.faces.tobytes()


def test_different_seeds_differ():
    ys = [terrain(resolution=65, seed=s).vertices[:, 1] for s in (0, 1, 2)]
    for i in range(3):
        for j in range(i + 1, 3):
            assert np.mean(np.abs(ys[i] - ys[j])) > 0.5  # world units, out of 14


def test_parameters_change_the_shape():
    base = terrain(resolution=65).vertices[:, 1]
    for kw in ({"ridge": 0.0}, {"octaves": 2}, {"gain": 0.8}, {"feature_size": 10.0}, {"terraces": 2}):
        assert not np.allclose(terrain(resolution=65, **kw).vertices[:, 1], base), kw


# -- steepness ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_default_terrain_has_cliffs(seed):
    slopes = _face_slopes(terrain(seed=seed))
    assert slopes.max() > 60.0
    assert np.mean(slopes > 60.0) > 0.005  # cliff faces, not one stray triangle
    assert np.mean(slopes < 20.0) > 0.2  # and flat ground for grass


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cliffs_zero_is_gentler(seed):
    steep = np.percentile(_face_slopes(terrain(seed=seed)), 99)
    gentle = np.percentile(_face_slopes(terrain(seed=seed, cliffs=0.0)), 99)
    assert gentle < steep - 2.0


def test_more_cliffs_is_steeper():
    p99 = [np.percentile(_face_slopes(terrain(cliffs=c)), 99) for c in (0.0, 1.0, 3.0)]
    assert p99[0] < p99[1] < p99[2]


# -- metadata and speed -------------------------------------------------------------------------------


def test_metadata(default_mesh):
    meta = default_mesh.metadata["terrain"]
    assert meta == {
        "size": (64.0, 64.0),
        "resolution": (129, 129),
        "seed": 0,
        "height": 14.0,
        "octaves": 6,
        "lacunarity": 2.0,
        "gain": 0.5,
        "ridge": 0.6,
        "cliffs": 1.0,
        "terraces": 5,
        "feature_size": 24.0,
    }
    meta2 = terrain((8, 6), (3, 4), 9, height=2, ridge=0.25).metadata["terrain"]
    assert meta2["size"] == (8.0, 6.0) and meta2["resolution"] == (3, 4) and meta2["seed"] == 9
    assert meta2["height"] == 2.0 and meta2["ridge"] == 0.25


def test_build_is_fast():
    terrain(resolution=33)  # warm-up
    t0 = time.perf_counter()
    terrain()
    assert time.perf_counter() - t0 < 2.0  # typically well under 0.2 s


# -- slope / height helper ----------------------------------------------------------------------------


@pytest.mark.parametrize("angle, axis", [(0.0, 0), (30.0, 0), (55.0, 2), (75.0, 2)])
def test_slope_height_of_analytic_plane(angle, axis):
    # a plane y = tan(angle) * x (or * z), built directly with trimesh: slope is `angle` everywhere
    x, z = np.meshgrid(np.linspace(-2, 3, 6), np.linspace(-1, 4, 5))
    y = math.tan(math.radians(angle)) * (x if axis == 0 else z)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    idx = np.arange(30).reshape(5, 6)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)])
    h01, slope = terrain_slope_height(trimesh.Trimesh(verts, faces, process=False))
    assert h01.shape == slope.shape == (30,)
    np.testing.assert_allclose(slope, angle, atol=1e-6)
    if angle == 0.0:
        np.testing.assert_array_equal(h01, 0.0)
    else:
        np.testing.assert_allclose(h01, (y.ravel() - y.min()) / (y.max() - y.min()), atol=1e-12)


def test_slope_height_of_terrain(default_mesh):
    h01, slope = terrain_slope_height(default_mesh)
    y = default_mesh.vertices[:, 1]
    np.testing.assert_allclose(h01, y / 14.0, atol=1e-12)
    assert h01.min() == 0.0 and h01.max() == pytest.approx(1.0)
    n = default_mesh.vertex_normals
    expected = np.degrees(np.arctan2(np.hypot(n[:, 0], n[:, 2]), n[:, 1]))
    np.testing.assert_allclose(slope, expected, atol=1e-6)
    assert 0.0 <= slope.min() and slope.max() < 90.0
    assert slope.max() > 55.0


def test_slope_height_rejects_non_mesh():
    with pytest.raises(TypeError, match=r"^terrain_slope_height\(\): mesh must be a trimesh.Trimesh"):
        terrain_slope_height(np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"^terrain_slope_height\(\): mesh has no vertices"):
        terrain_slope_height(trimesh.Trimesh())


# -- bad input ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kw, exc, msg",
    [
        ({"size": (0.0, 5.0)}, ValueError, r"size\[0\] must be positive, got 0.0"),
        ({"size": (5.0, -1.0)}, ValueError, r"size\[1\] must be positive, got -1.0"),
        ({"size": (math.inf, 5.0)}, ValueError, r"size\[0\] must be finite"),
        ({"size": (math.nan, 5.0)}, ValueError, r"size\[0\] must be finite"),
        ({"size": (1.0, 2.0, 3.0)}, ValueError, r"size must be a number or a pair, got 3 values"),
        ({"size": "big"}, TypeError, r"size\[0\] must be a number, got str"),
        ({"resolution": (1, 5)}, ValueError, r"resolution\[0\] must be at least 2, got 1"),
        ({"resolution": (5, 0)}, ValueError, r"resolution\[1\] must be at least 2, got 0"),
        ({"resolution": (64.0, 64)}, TypeError, r"resolution\[0\] must be an int, got float"),
        ({"resolution": (True, 64)}, TypeError, r"resolution\[0\] must be an int, got bool"),
        ({"resolution": (4, 5, 6)}, ValueError, r"resolution must be a number or a pair, got 3 values"),
        ({"seed": -1}, ValueError, r"seed must be at least 0, got -1"),
        ({"seed": 1.5}, TypeError, r"seed must be an int, got float"),
        ({"height": -1.0}, ValueError, r"height must be >= 0, got -1.0"),
        ({"height": math.inf}, ValueError, r"height must be finite"),
        ({"octaves": 0}, ValueError, r"octaves must be in \[1, 16\], got 0"),
        ({"octaves": 17}, ValueError, r"octaves must be in \[1, 16\], got 17"),
        ({"octaves": 2.0}, TypeError, r"octaves must be an int, got float"),
        ({"lacunarity": 0.5}, ValueError, r"lacunarity must be >= 1, got 0.5"),
        ({"gain": 0.0}, ValueError, r"gain must be in \(0, 1\], got 0.0"),
        ({"gain": 1.5}, ValueError, r"gain must be in \(0, 1\], got 1.5"),
        ({"ridge": -0.1}, ValueError, r"ridge must be in \[0, 1\], got -0.1"),
        ({"ridge": 1.1}, ValueError, r"ridge must be in \[0, 1\], got 1.1"),
        ({"ridge": "0.5"}, TypeError, r"ridge must be a number, got str"),
        ({"cliffs": -0.5}, ValueError, r"cliffs must be >= 0, got -0.5"),
        ({"cliffs": math.nan}, ValueError, r"cliffs must be finite"),
        ({"terraces": 0}, ValueError, r"terraces must be at least 1, got 0"),
        ({"feature_size": 0.0}, ValueError, r"feature_size must be positive, got 0.0"),
        ({"feature_size": None}, TypeError, r"feature_size must be a number, got NoneType"),
    ],
)
def test_bad_input(kw, exc, msg):
    with pytest.raises(exc, match=r"^terrain\(\): " + msg):
        terrain(**kw)


def test_options_are_keyword_only():
    with pytest.raises(TypeError):
        terrain((8.0, 8.0), (5, 5), 0, 14.0)  # height is keyword-only
