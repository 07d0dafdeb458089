"""Batches of views: ``rasterize`` with several cameras (one launch, one BVH) gives ``(V, H, W)``
G-buffers that every technique and ``fit_splat`` take, equal view by view to one call per view."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

import warptex as wt
from conftest import triplanar_backward
from warptex.scenes import terrain_cameras
from warptex.scenes import TERRAIN_GRID
from warptex.scenes.terrain import terrain
from warptex.scenes.material import terrain_layers, terrain_splat_maps
from warptex.gbuffer import FIELDS, UV_FIELDS


@pytest.fixture(scope="module")
def scene():
    mesh = terrain(resolution=TERRAIN_GRID)
    cameras = terrain_cameras((24, 32), 3)
    return {
        "mesh": mesh,
        "cameras": cameras,
        "batch": wt.rasterize(mesh, cameras),
        "singles": [wt.rasterize(mesh, c) for c in cameras],
        "layers": terrain_layers(size=32),
        "maps": terrain_splat_maps(mesh, TERRAIN_GRID),
    }


def test_a_batch_rasterises_as_its_views_do(scene):
    batch = scene["batch"]
    assert batch.resolution == (3, 24, 32) and batch.num_views == 3 and batch.pixel_count == 3 * 24 * 32
    assert batch.camera == tuple(scene["cameras"])
    for k, single in enumerate(scene["singles"]):
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(batch, name).numpy()[k], getattr(single, name).numpy(), err_msg=name)
        for name in UV_FIELDS:
            np.testing.assert_array_equal(batch.uv_sets["uv0"][name].numpy()[k], single.uv_sets["uv0"][name].numpy(), err_msg=name)
        view = batch.view(k)
        assert view.resolution == (24, 32) and view.camera is scene["cameras"][k] and view.num_views is None
        np.testing.assert_array_equal(view.position.numpy(), single.position.numpy())
    assert scene["singles"][0].num_views is None and scene["singles"][0].pixel_count == 24 * 32


TECHNIQUES = {
    "triplanar": lambda g, s, t: wt.triplanar(g, t, tiling=0.2, offsets=[[0, 0.3], [0.1, 0], [0.3, 0.2]]),
    "biplanar": lambda g, s, t: wt.biplanar(g, t, tiling=0.2),
    "triplanar_normal": lambda g, s, t: wt.triplanar_normal(g, t, tiling=0.2),
    "triplanar_stochastic": lambda g, s, t: wt.triplanar(g, t, tiling=0.2, stochastic="hash4"),
    "splat_uv": lambda g, s, t: wt.splat(g, s["layers"], s["maps"], tiling=4.0),
    "splat_triplanar": lambda g, s, t: wt.splat(g, s["layers"], s["maps"], projection="triplanar", height_blend=0.2, tiling=0.2, sampler=wt.Sampler(filter="anisotropic")),
    "splat_atlas": lambda g, s, t: wt.splat_atlas(g, wt.pack_atlas(s["layers"]), *wt.export_index_maps(s["maps"], 2), tiling=3.0),
}


@pytest.mark.parametrize("technique", list(TECHNIQUES))
def test_every_technique_renders_a_batch_as_its_views(technique, scene, rng):
    texture = wt.Texture(rng.uniform(0, 1, (16, 16, 3)).astype(np.float32))
    batched = TECHNIQUES[technique](scene["batch"], scene, texture).numpy()
    assert batched.shape[:3] == (3, 24, 32)
    for k, single in enumerate(scene["singles"]):
        np.testing.assert_array_equal(batched[k], TECHNIQUES[technique](single, scene, texture).numpy(), err_msg=f"view {k}")


def test_batch_gradients_are_the_sum_of_the_views(scene, rng):
    image = rng.uniform(0, 1, (16, 16, 3)).astype(np.float32)
    r = rng.standard_normal((3, 24, 32, 3)).astype(np.float32)

    def gradients(g, weights):
        texture = wt.Texture(image, requires_grad=True)
        tiling = wp.array([0.2, 0.25, 0.3], dtype=float, requires_grad=True)
        triplanar_backward(g, texture, tiling, weights)
        return texture.grad(0), tiling.grad.numpy()

    batch = gradients(scene["batch"], r)
    views = [gradients(g, r[k]) for k, g in enumerate(scene["singles"])]
    np.testing.assert_allclose(batch[0], sum(v[0] for v in views), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(batch[1], sum(v[1] for v in views), rtol=1e-4, atol=1e-4)


def test_fit_splat_takes_a_batch_as_its_views(scene):
    """One batched FitView fits as the same views given one by one (sums in another order: float rounding)."""
    layers = scene["layers"]
    truth = wt.TextureArray(scene["maps"][None], mipmaps=False)
    options = {"projection": "triplanar", "height_blend": 0.2}
    targets = wt.splat(scene["batch"], layers, truth, tiling=1 / 6, **options).numpy()[..., :3]

    def fit(views):
        params = wt.fit.SplatParameters(4, TERRAIN_GRID, tiling=0.2)
        result = wt.fit.fit_splat(views, layers, params, iters=8, splat_options=options, report_every=0, progress=False)
        return result, params

    batched, p1 = fit([wt.fit.FitView(scene["batch"], targets)])
    single, p2 = fit([wt.fit.FitView(g, targets[k]) for k, g in enumerate(scene["singles"])])
    np.testing.assert_allclose(batched.history["loss"], single.history["loss"], rtol=1e-4)
    np.testing.assert_allclose(p1.weights(), p2.weights(), atol=1e-4)
    np.testing.assert_allclose(p1.tiling_values(), p2.tiling_values(), rtol=1e-5)
    assert batched.history["loss"][-1] < batched.history["loss"][0]
    renders = wt.fit.render_views(wt.fit.FitView(scene["batch"], targets), layers, p1, splat_options=options)
    assert renders[0].shape == (3, 24, 32, 4)


def test_batch_errors(scene, tmp_path):
    small = wt.look_at((30.0, 30.0, 30.0), (0.0, 0.0, 0.0), resolution=(8, 8))
    with pytest.raises(ValueError, match=r"share one resolution; camera 0 has \(24, 32\), camera 1 \(8, 8\)"):
        wt.rasterize(scene["mesh"], [scene["cameras"][0], small])
    with pytest.raises(TypeError, match="a warptex Camera or a non-empty sequence of them"):
        wt.rasterize(scene["mesh"], [])
    with pytest.raises(ValueError, match=r"batch of 3 views; save one at a time \(gbuffer.view\(k\)\)"):
        wt.save_gbuffer(tmp_path / "g.exr", scene["batch"])
    with pytest.raises(ValueError, match=r"k must be an int in \[0, 2\], got 3"):
        scene["batch"].view(3)
    with pytest.raises(ValueError, match="one \\(H, W\\) view, not a batch"):
        scene["singles"][0].view(0)
    layers = scene["layers"]
    params = wt.fit.SplatParameters(4, TERRAIN_GRID)
    with pytest.raises(ValueError, match=r"view 0 is a batch of 3 views: its target must be \[V, H, W, C\] with V = 3, got shape \(24, 32, 3\)"):
        wt.fit.fit_splat([wt.fit.FitView(scene["batch"], np.zeros((24, 32, 3)))], layers, params, iters=1, progress=False)
    bad = np.zeros((3, 24, 32, 3))
    bad[1, 5, 5, 0] = np.nan
    covered = scene["batch"].mask.numpy()[1] > 0
    bad[1][covered] = np.nan
    with pytest.raises(ValueError, match=r"view 0\[1\]: the target has .* non-finite"):
        wt.fit.fit_splat([wt.fit.FitView(scene["batch"], bad)], layers, params, iters=1, progress=False)
