"""Scenes far from the world origin (issue 34 item 4): terrain in map coordinates (UTM metres are in
the millions) is rasterised relative to a float64 origin (camera-relative rendering), and the
plane UVs of triplanar and world-space layers add that origin in float64, less whole texture
periods, before anything becomes float32."""

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from fd import check_parameter_gradient
from warptex import _op
from warptex.scenes import TERRAIN_GRID, terrain_camera
from warptex.scenes.material import terrain_layers, terrain_splat_maps
from warptex.scenes.terrain import terrain

RES = (72, 96)
TILING = 1.0 / 6.0  # the default terrain's
PERIOD = 1.0 / np.float64(np.float32(TILING))  # one repeat of the texture at the float32 tiling the kernels use


@pytest.fixture(scope="module")
def scene():
    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    maps = wt.TextureArray(terrain_splat_maps(mesh, TERRAIN_GRID)[None], mipmaps=False)
    return mesh, maps, terrain_layers(seed=0)


def _moved(mesh: trimesh.Trimesh, shift) -> trimesh.Trimesh:
    moved = mesh.copy()
    moved.apply_translation(shift)
    moved.vertex_normals = mesh.vertex_normals  # the same normals (the copy would recompute them otherwise)
    return moved


def _render(scene, shift, origin=None, samples=4):
    mesh, maps, layers = scene
    camera = terrain_camera(RES)
    camera = wt.look_at(camera.eye + shift, camera.eye + camera.forward + shift, resolution=RES)
    g = wt.rasterize(_moved(mesh, shift), camera, samples=samples, origin=origin)
    splat = wt.splat(g, layers, maps, tiling=TILING, projection="triplanar", height_blend=0.2)
    xz = wt.splat(g, layers, maps, tiling=TILING, projection="world_xz")
    tri = wt.triplanar(g, layers, tiling=TILING, sampler=wt.Sampler(address="mirror"))
    return g, [wt.resolve(a, g).numpy() for a in (splat, xz, tri, g.mask)]


def test_a_scene_moved_by_a_million_periods_renders_the_same(scene):
    """The terrain and its camera moved by 10^6 whole texture periods along x and z (6 000 km at
    the default tiling) and 10^3 up: every technique that projects the position gives the same
    picture (< 0.02 per channel; measured 6e-5); float32 world positions gave 0.43."""
    g0, near = _render(scene, np.zeros(3))
    shift = np.array([1e6, 1e3, -1e6]) * PERIOD
    g1, far = _render(scene, shift)
    assert not g0.origin.any() and np.abs(g1.origin - (terrain_camera(RES).eye + shift)).max() < 1e-6
    for name, a, b in zip(("splat triplanar", "splat world_xz", "triplanar (mirror)", "coverage"), near, far):
        assert np.abs(a - b).max() < 0.02, (name, np.abs(a - b).max())
    # Without the origin (float32 world positions) the same scene breaks: the check can fail.
    _, naive = _render(scene, shift, origin=(0.0, 0.0, 0.0))
    assert np.abs(near[0] - naive[0]).max() > 0.1


def test_world_positions_are_the_origin_plus_the_relative_ones(scene):
    mesh = scene[0]
    shift = np.array([3e6, 0.0, 2e6])
    camera = terrain_camera((24, 32))
    far = wt.rasterize(_moved(mesh, shift), wt.look_at(camera.eye + shift, camera.eye + camera.forward + shift, resolution=(24, 32)))
    near = wt.rasterize(mesh, camera)
    covered = near.mask.numpy() > 0
    np.testing.assert_array_equal(covered, far.mask.numpy() > 0)
    np.testing.assert_allclose(far.world_position()[covered] - shift, near.position.numpy()[covered], atol=1e-3)
    np.testing.assert_allclose(far.depth.numpy()[covered], near.depth.numpy()[covered], rtol=1e-5)
    assert np.abs(far.position.numpy()[covered]).max() < 100  # relative to the eye: small, precise


def test_the_origin_survives_a_gbuffer_file(tmp_path):
    g = wt.rasterize(trimesh.creation.icosphere(), wt.look_at((0, 0, 3), (0, 0, 0), resolution=(8, 8)), samples=9, origin=(1e6 + 0.125, 2.0, -3.5))
    wt.save_gbuffer(tmp_path / "g.exr", g)
    back = wt.load_gbuffer(tmp_path / "g.exr")
    assert back.samples == 9 and back.resolution == (24, 24)
    np.testing.assert_array_equal(back.origin, [1e6 + 0.125, 2.0, -3.5])


def test_bad_origins_are_refused():
    ball, camera = trimesh.creation.icosphere(), wt.look_at((0, 0, 3), (0, 0, 0), resolution=(8, 8))
    with pytest.raises(ValueError, match=r"rasterize\(\): origin must be None or 3 finite numbers"):
        wt.rasterize(ball, camera, origin=(0, np.nan, 0))
    with pytest.raises(ValueError, match=r"GBuffer: origin must be 3 finite numbers"):
        wt.GBuffer.empty((2, 2), origin=(1, 2))


# -- the tiling's gradient takes the origin into account -------------------------------------------

ORIGIN = np.array([3.75, -1.5, 2.25])  # small enough for finite differences of the tiling


def _sphere_views(origin):
    """A bumpy ball seen from one camera, rasterised with its positions relative to ``origin``."""
    ball = trimesh.creation.icosphere(subdivisions=3)
    ball.vertices *= 1 + 0.05 * np.sin(5 * ball.vertices[:, :1])
    ball.visual = trimesh.visual.TextureVisuals(uv=ball.vertices[:, [0, 2]] * 0.5 + 0.5)  # UV0 for a splat map
    return wt.rasterize(ball, wt.look_at((0.6, 0.9, 2.6), (0, 0, 0), resolution=(40, 40)), origin=origin)


def _tiling_gradient(g, run, t, r):
    tiling = wp.array(np.asarray(t, np.float32).reshape(-1), dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = run(g, tiling)
    out.grad.assign(np.asarray(r, np.float32).reshape(out.shape))
    tape.backward()
    return tiling.grad.numpy().astype(np.float64)


def _generated(technique, *args, **kw):
    """``technique(*args, **kw)``, its backward Warp's generated adjoint (``warptex._op.force_generated_adjoint``)."""
    with _op.force_generated_adjoint():
        return technique(*args, **kw)


TECHNIQUES = {
    # the hand-written slopes (plane_sample_slope, layer_read_slopes) ...
    "triplanar": lambda tex: lambda g, t: wt.triplanar(g, tex, tiling=t, sharpness=4.0),
    "splat triplanar": lambda tex: lambda g, t: wt.splat(g, tex, wt.TextureArray(np.full((1, 4, 4, 2), 0.5, np.float32), mipmaps=False), tiling=t, projection="triplanar"),
    # ... and Warp's generated adjoint through the float64 origin term (forced)
    "triplanar, generated adjoint": lambda tex: lambda g, t: _generated(wt.triplanar, g, tex, tiling=t, sharpness=4.0),
    # stochastic: cells are hashed where the folded UVs fall, so the pattern differs from the
    # world origin's (as any translation changes it); the gradient still matches differences
    "triplanar hash4": lambda tex: lambda g, t: wt.triplanar(g, tex, tiling=t, stochastic="hash4"),
}


@pytest.mark.parametrize("name", list(TECHNIQUES))
def test_tiling_gradients_with_an_origin_match_finite_differences(name):
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:32, 0:32] * (2 * np.pi / 32)
    smooth = np.stack([0.5 + 0.4 * np.sin(x + k) * np.cos(2 * y - k) for k in range(3)], -1)  # tileable, smooth
    tex = wt.TextureArray(np.stack([smooth, smooth[::-1]]).astype(np.float32))
    run = TECHNIQUES[name](tex)
    relative, world = _sphere_views(ORIGIN), _sphere_views((0.0, 0.0, 0.0))
    assert np.abs(relative.origin - ORIGIN).max() == 0
    r = rng.random((40, 40, 3))
    t = np.array([1.3])
    # The same scene with or without an origin: the same gradient (the origin's plane coordinates
    # are part of d uv / d tiling), and it matches finite differences.
    grad = _tiling_gradient(relative, run, t, r)
    assert np.abs(grad).max() > 0.1
    if "hash4" not in name:
        np.testing.assert_allclose(grad, _tiling_gradient(world, run, t, r), rtol=2e-3)
    check_parameter_gradient(lambda v: run(relative, wp.array(v.astype(np.float32), dtype=float)).numpy(),
                             lambda v, w: _tiling_gradient(relative, run, v, w), t, r, 1e-3, rtol=2e-2, atol=2e-2, label=name)
