"""The procedural terrain: layout, UVs, determinism, steep cliffs, validation."""

import numpy as np
import pytest
import trimesh

from warptex.terrain import terrain, terrain_slope_height


@pytest.fixture(scope="module")
def default_terrain():
    return terrain()


def _face_slopes(mesh):
    n = mesh.face_normals
    return np.degrees(np.arccos(np.clip(n[:, 1], -1, 1)))


def test_grid_layout_extent_and_winding(default_terrain):
    mesh = terrain(size=(40.0, 20.0), resolution=(11, 21), height=5.0)
    assert len(mesh.vertices) == 11 * 21 and len(mesh.faces) == 2 * 10 * 20
    np.testing.assert_allclose(mesh.bounds[:, [0, 2]], [[-20, -10], [20, 10]], atol=1e-9)
    np.testing.assert_allclose([mesh.vertices[:, 1].min(), mesh.vertices[:, 1].max()], [0.0, 5.0], atol=1e-9)
    assert (mesh.face_normals[:, 1] > 0).all(), "faces wind counter-clockwise seen from above"
    assert (mesh.area_faces > 0).all()
    assert np.isfinite(default_terrain.vertices).all()


def test_uv0_spans_the_terrain_like_a_map():
    mesh = terrain(size=(10.0, 10.0), resolution=(5, 7))
    uv, v = np.asarray(mesh.visual.uv), np.asarray(mesh.vertices)
    assert uv.min() >= 0 and uv.max() <= 1
    np.testing.assert_allclose(uv[:, 0], (v[:, 0] + 5) / 10, atol=1e-7)  # u along +X
    np.testing.assert_allclose(uv[:, 1], (5 - v[:, 2]) / 10, atol=1e-7)  # v along -Z


def test_seed_determinism(default_terrain):
    np.testing.assert_array_equal(terrain().vertices, default_terrain.vertices)
    assert not np.array_equal(terrain(seed=1).vertices, default_terrain.vertices)


def test_default_terrain_has_cliffs_that_triplanar_must_fix(default_terrain):
    slopes = _face_slopes(default_terrain)
    assert slopes.max() > 60.0
    gentle = _face_slopes(terrain(cliffs=0.0))
    assert np.percentile(gentle, 99) < np.percentile(slopes, 99)


def test_parameters_are_recorded(default_terrain):
    meta = default_terrain.metadata["terrain"]
    assert meta["seed"] == 0 and meta["cliffs"] == 1.0


def test_slope_height_helper_on_a_known_ramp():
    # A ramp rising 1 in y per 1 in x: 45 degrees everywhere, heights spanning [0, 1].
    x, z = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4))
    vertices = np.stack([x.ravel(), x.ravel(), z.ravel()], axis=1)
    faces = []
    for r in range(3):
        for c in range(3):
            a, b, d, e = r * 4 + c, r * 4 + c + 1, (r + 1) * 4 + c, (r + 1) * 4 + c + 1
            faces += [[a, d, b], [b, d, e]]
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    height01, slope = terrain_slope_height(mesh)
    np.testing.assert_allclose(height01, x.ravel(), atol=1e-12)
    np.testing.assert_allclose(slope, 45.0, atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        ({"size": (0.0, 10.0)}, ValueError, r"terrain\(\): size"),
        ({"size": (np.nan, 10.0)}, ValueError, r"terrain\(\): size"),
        ({"resolution": (1, 10)}, ValueError, r"terrain\(\): resolution"),
        ({"resolution": (2.5, 10)}, (TypeError, ValueError), r"terrain\(\): resolution"),
        ({"octaves": 0}, ValueError, r"terrain\(\): octaves"),
        ({"ridge": 1.5}, ValueError, r"terrain\(\): ridge"),
        ({"cliffs": -1.0}, ValueError, r"terrain\(\): cliffs"),
        ({"height": -2.0}, ValueError, r"terrain\(\): height"),
    ],
)
def test_bad_arguments_raise(kwargs, error, match):
    with pytest.raises(error, match=match):
        terrain(**kwargs)
