"""Jobs in tiles (warptex.tiles, issue 52): bands of rows give the whole image's pixels bit for bit,
whatever their height, from the G-buffer through every technique to the files of render and bake."""

import functools
import sys

import numpy as np
import pytest
import trimesh

import warptex as wt
from warptex.apps.render import run_render
from warptex.bake import texture_gbuffer_tiles
from warptex.tiles import SAMPLE_BYTES, tile_rows


def _same(a: dict, b: dict, rows: slice, what: str) -> None:
    for name in a:
        assert a[name].tobytes() == b[name][rows].tobytes(), f"{what}: {name} differs"


@pytest.fixture(scope="module")
def duck(request):
    from conftest import SHARED_DATA

    if not SHARED_DATA.is_dir():
        pytest.skip(f"../shared/data not found at {SHARED_DATA}: real-data tests need the shared folder")
    mesh = wt.load_mesh(SHARED_DATA / "meshes" / "Duck.glb")
    return mesh, wt.look_at((150, 120, 200), mesh.bounds.mean(0), resolution=(29, 41))


@pytest.mark.parametrize("samples", [1, 4, 9])
def test_bands_of_rows_rasterise_as_the_whole_image(duck, samples):
    mesh, camera = duck
    whole = wt.rasterize(mesh, camera, samples=samples).numpy()
    s = int(np.sqrt(samples))
    for rows in [(0, 1), (0, 13), (13, 29), (28, 29), (7, 8)]:
        band = wt.rasterize(mesh, camera, samples=samples, rows=rows).numpy()
        _same(band, whole, slice(rows[0] * s, rows[1] * s), f"rows {rows}")


def test_tiles_cover_the_image_in_equal_bands_within_the_budget():
    assert tile_rows(10, 1.0, 1 << 20) == [(0, 10)]
    assert tile_rows(10, float(1 << 20), 1 << 20) == [(k, k + 1) for k in range(10)]  # a row over budget: one a band
    bands = tile_rows(1000, 7000.0, 1 << 20)  # 149 rows fit: 7 bands of 143 or 142
    assert bands[0] == (0, 143) and bands[-1][1] == 1000 and len(bands) == 7
    assert all(b[0] == a[1] for a, b in zip(bands, bands[1:]))
    assert max(b - a for a, b in bands) - min(b - a for a, b in bands) <= 1
    for bad in (0, 2.5e6, True):
        with pytest.raises(ValueError, match=r"tile_rows\(\): memory must be a number of bytes >= 1"):
            tile_rows(10, 1.0, bad)


def test_gbuffer_tiles_are_the_whole_gbuffer_and_rasterise_again(duck):
    mesh, camera = duck
    whole = wt.rasterize(mesh, camera, samples=4).numpy()
    centre = wt.rasterize(mesh, camera).numpy()
    # 5.5 rows of 41 pixels of 4 samples a MiB: 6 tiles of 5, 5, 5, 5, 5 and 4 rows
    tiles = list(wt.gbuffer_tiles(mesh, camera, samples=4, memory=1 << 20, sample_bytes=(1 << 20) / (4 * 41 * 5.5)))
    assert [(t.rows.start, t.rows.stop) for t in tiles] == [(0, 5), (5, 10), (10, 15), (15, 20), (20, 25), (25, 29)]
    assert [(t.index, t.count) for t in tiles] == [(k, 6) for k in range(6)]
    for t in tiles:
        _same(t.gbuffer.numpy(), whole, slice(t.rows.start * 2, t.rows.stop * 2), f"tile {t.index}")
        _same(t.rasterize(1).numpy(), centre, t.rows, f"tile {t.index} at 1 sample")
    with pytest.raises(TypeError, match=r"gbuffer_tiles\(\): camera must be one warptex Camera"):
        wt.gbuffer_tiles(mesh, [camera, camera])
    with pytest.raises(ValueError, match=r"gbuffer_tiles\(\): memory must be"):
        wt.gbuffer_tiles(mesh, camera, memory=100)
    with pytest.raises(ValueError, match=r"gbuffer_tiles\(\): samples must be a square number"):
        wt.gbuffer_tiles(mesh, camera, samples=3)


@pytest.fixture(scope="module")
def terrain_scene():
    from warptex.apps.render import terrain_material
    from warptex.scenes import TERRAIN_GRID, terrain_camera
    from warptex.scenes.terrain import terrain

    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    camera = terrain_camera((23, 37), 45.0)
    material = terrain_material(mesh, None, 0, wt.Sampler(filter="anisotropic"), None)
    return mesh, camera, material


@pytest.mark.parametrize("technique", ["splat", "triplanar", "biplanar", "stochastic triplanar", "triplanar_normal", "sample"])
def test_every_technique_gives_a_tiles_rows_of_the_whole_image(terrain_scene, technique):
    """Techniques compute each pixel from its own G-buffer entries, on lanes of 8 or 16 pixels that
    start anywhere in a tile: a band's output is the whole image's rows, bit for bit."""
    mesh, camera, material = terrain_scene
    rng = np.random.default_rng(3)
    texture = wt.Texture(rng.random((64, 64, 4)).astype(np.float32))
    normal_map = wt.Texture((0.5 + 0.3 * (rng.random((32, 32, 3)) - 0.5)).astype(np.float32))
    aniso = wt.Sampler(filter="anisotropic")
    run = {
        "splat": material,
        "triplanar": functools.partial(wt.triplanar, texture=texture, tiling=0.3, sampler=aniso),
        "biplanar": functools.partial(wt.biplanar, texture=texture, tiling=0.3),
        "stochastic triplanar": functools.partial(wt.triplanar, texture=texture, tiling=0.3, stochastic="hex"),
        "triplanar_normal": functools.partial(wt.triplanar_normal, normal_map=normal_map, tiling=0.3),
        "sample": lambda g: wt.sample(texture, np.ascontiguousarray(g.position.numpy()[..., [0, 2]] * 0.3), uv_dx=np.ascontiguousarray(g.position_dx.numpy()[..., [0, 2]] * 0.3), uv_dy=np.ascontiguousarray(g.position_dy.numpy()[..., [0, 2]] * 0.3), sampler=aniso),
    }[technique]
    whole = run(wt.rasterize(mesh, camera, samples=4)).numpy()
    for rows in [(0, 3), (3, 11), (11, 23)]:
        band = run(wt.rasterize(mesh, camera, samples=4, rows=rows)).numpy()
        assert band.tobytes() == whole[rows[0] * 2 : rows[1] * 2].tobytes(), f"{technique}, rows {rows}"


def test_render_files_are_the_same_bytes_at_every_tile_height(tmp_path):
    """warptex render at three budgets: one band (the whole image), bands of one row (1 MiB for
    rows of 640 KB of work), and bands that do not divide the image (6, 6, 6 and 5 rows): the
    same bytes in all five files."""
    row = SAMPLE_BYTES * 4 * 640
    files = []
    for memory in (None, 1 << 20, int(6.5 * row)):
        out = tmp_path / f"m{memory}"
        run_render(out, resolution=(23, 640), memory=memory, progress=False)
        files.append({p.name: p.read_bytes() for p in out.iterdir()})
    assert sorted(files[0]) == ["albedo.png", "gbuffer.exr", "normals.png", "render.exr", "render.png"]
    assert files[1] == files[0] and files[2] == files[0]


def test_render_bands_of_a_large_row(tmp_path):
    """A budget of 1 MiB against rows of 2.6 MB of work: a band is one row, and the image the same."""
    run_render(tmp_path / "a", resolution=(5, 640), samples=16, progress=False)
    run_render(tmp_path / "b", resolution=(5, 640), samples=16, memory=1 << 20, progress=False)
    for name in ("render.png", "render.exr", "gbuffer.exr"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


@pytest.mark.parametrize("gutter", [0, 3, 20])
def test_texture_space_bands_are_the_whole_atlas(gutter, monkeypatch):
    """Jump flooding reaches 2^(k+1) - 1 texels: a band, or a window of bands, flooded with that
    many rows on each side floods as the whole atlas does, so its texels are the whole atlas's,
    bit for bit."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    layout = wt.unwrap(mesh, size=96, padding=4)
    g, coverage = wt.texture_gbuffer(layout, 96, gutter=gutter)
    whole = {**g.numpy(), "coverage": coverage.numpy()}
    for rows in [(0, 1), (0, 40), (40, 41), (41, 96), (95, 96)]:
        band, cov = wt.texture_gbuffer(layout, 96, gutter=gutter, rows=rows)
        _same({**band.numpy(), "coverage": cov.numpy()}, whole, slice(*rows), f"rows {rows}")
    for flood_bytes in (12, 160):  # floods of the whole atlas, and of windows of 2 or 3 bands
        monkeypatch.setattr(sys.modules["warptex.bake"], "FLOOD_TEXEL_BYTES", flood_bytes)
        tiles = list(texture_gbuffer_tiles(layout, 96, gutter=gutter, memory=1 << 20))  # half a MiB: 13 rows of 96 texels, 8 bands of 12
        assert [(t.rows.start, t.rows.stop) for t in tiles] == [(k, k + 12) for k in range(0, 96, 12)]
        for name in ("position", "normal", "triangle", "position_dy"):
            assert np.concatenate([getattr(t.gbuffer, name).numpy() for t in tiles]).tobytes() == whole[name].tobytes(), (flood_bytes, name)
        assert np.concatenate([t.coverage.numpy() for t in tiles]).tobytes() == whole["coverage"].tobytes()
    with pytest.raises(ValueError, match=r"Tile.rasterize\(\): only the tiles of gbuffer_tiles"):
        tiles[0].rasterize()
    with pytest.raises(ValueError, match=r"texture_gbuffer\(\): rows must be \(start, stop\)"):
        wt.texture_gbuffer(layout, 96, rows=(50, 200))


def test_bake_gltf_writes_the_same_bytes_in_bands_as_export_gltf_of_bake(tmp_path, monkeypatch):
    rng = np.random.default_rng(8)
    colour = functools.partial(wt.triplanar, texture=wt.Texture(rng.random((16, 16, 4)).astype(np.float32)), tiling=1.5)
    normal = functools.partial(wt.triplanar_normal, normal_map=wt.Texture((0.5 + 0.2 * (rng.random((16, 16, 3)) - 0.5)).astype(np.float32)), tiling=1.5)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    whole = wt.export_gltf(wt.bake(mesh, colour, normal=normal, size=64), tmp_path / "whole" / "asset.glb")
    expected = {p.name: p.read_bytes() for p in whole}
    monkeypatch.setattr(sys.modules["warptex.bake"], "BAKE_TEXEL_BYTES", (1 << 20) / (64 * 7))  # 7 rows a MiB: 10 bands of 7 or 6 rows
    for memory in (1 << 20, 1 << 30):
        paths = wt.bake_gltf(mesh, tmp_path / str(memory) / "asset.glb", colour, normal=normal, size=64, memory=memory, progress=False)
        assert [p.name for p in paths] == [p.name for p in whole]
        assert {p.name: p.read_bytes() for p in paths} == expected
        assert sorted(p.name for p in paths[0].parent.iterdir()) == sorted(expected)  # no temporary left


def _fit_gradient(objective, params, sigma: float, stride: int):
    """The fit loop's gradient of one iteration: maps (and prior) on one tape, the renders' bands
    on their own (fit_splat's order): ``(loss, mse, d/dlogits, d/dlog_tiling)``."""
    import warp as wp

    params.zero_grad()
    tape = wp.Tape()
    with tape:
        params.apply()
        prior = objective.prior()
    loss, mse = objective.gradient(sigma, stride)
    tape.backward(loss=prior)
    grads = params.logits.grad.numpy().copy(), params.log_tiling.grad.numpy().copy()
    tape.zero()
    return loss, mse, *grads


@pytest.mark.parametrize("sigma, stride", [(0.0, 1), (1.5, 1), (2.0, 2)])
def test_a_fits_gradient_in_bands_is_the_whole_views_to_float_rounding(monkeypatch, sigma, stride):
    """fit_splat takes each band's gradient before rendering the next (a blurred band is rendered
    with a halo of the blur's radius): its loss and gradients equal the whole views' to float
    rounding, at band heights that divide the view and that do not, and they are the same bits
    at any thread count for one band height."""
    import importlib

    from test_fit import OPTIONS, smooth_layers
    from warptex.fit import FitView, Objective, SplatParameters, prepare_views
    from warptex.scenes import terrain_camera
    from warptex.scenes.terrain import terrain

    objective_module = importlib.import_module("warptex.fit.objective")
    mesh = terrain(resolution=(33, 33))
    g = wt.rasterize(mesh, terrain_camera((40, 48)))
    g2 = wt.rasterize(mesh, wt.look_at((20.0, 30.0, 25.0), (0.0, 3.0, 0.0), resolution=(23, 31)))
    layers = wt.TextureArray(smooth_layers(4))
    rng = np.random.default_rng(5)
    true = wt.TextureArray(rng.dirichlet(np.full(4, 0.7), size=(9, 9)).astype(np.float32)[None], mipmaps=False)
    views = [FitView(x, wt.splat(x, layers, true, tiling=0.2, **OPTIONS).numpy()[..., :3]) for x in (g, g2)]
    params = SplatParameters(4, (9, 9), tiling=0.23)
    params.logits.assign(rng.normal(size=params.logits.shape).astype(np.float32))

    def run(rows: float | None, threads: int = 2):
        if rows is not None:  # ``rows`` rows of the 48-pixel view a MiB
            monkeypatch.setattr(objective_module, "FIT_PIXEL_BYTES", (1 << 20) / (48 // stride * rows))
        wt.set_num_threads(threads)
        try:
            objective = Objective(prepare_views("t", views, layers, params, wp.get_device()), layers, params, dict(OPTIONS), wt.fit.Loss.L2, 1e-3, wp.get_device(), memory=1 << 20)
            bands = len(list(objective._bands(sigma, stride)))
            return bands, _fit_gradient(objective, params, sigma, stride)
        finally:
            wt.set_num_threads(None)
            monkeypatch.undo()

    import warp as wp

    bands, whole = run(None)
    assert bands == 2  # one band a view
    for rows in (1, 5.5, 8):  # bands of 1 row, of 5 (not dividing 40: 5 × 8 and 23 = 5+5+5+4+4), of 8
        bands, banded = run(rows)
        assert bands > 3  # more than one band in a view
        np.testing.assert_allclose(banded[0], whole[0], rtol=1e-6)  # the loss
        np.testing.assert_allclose(banded[1], whole[1], rtol=1e-6)  # the sharp MSE
        scale = np.abs(whole[2]).max()
        np.testing.assert_allclose(banded[2], whole[2], rtol=1e-4, atol=1e-6 * scale)  # d/dlogits
        np.testing.assert_allclose(banded[3], whole[3], rtol=1e-4)  # d/dlog_tiling
    one = run(5.5, threads=1)[1]
    two = run(5.5, threads=2)[1]
    for a, b in zip(one, two):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
