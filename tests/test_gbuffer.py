"""G-buffers: rasterised real meshes against brute-force ray casting, derivatives, EXR I/O, bad input."""

import numpy as np
import OpenEXR
import pytest
import trimesh

import warptex as wt
from warptex import io
from warptex.camera import look_at, orthographic
from warptex.gbuffer import GBuffer, load_mesh
from warptex.raster import rasterize
from warptex.gbuffer_io import load_gbuffer, save_gbuffer

MESHES = ("bunny.ply", "fandisk.obj", "featuretype.ply", "Duck.glb", "monkey.glb")


def _framing_camera(mesh, resolution=(96, 96), direction=(0.3, 0.4, 1.0)):
    centre, radius = mesh.bounds.mean(axis=0), np.linalg.norm(mesh.extents)
    return look_at(centre + np.asarray(direction) * radius * 1.2, centre, fov_y=40.0, resolution=resolution)


def _brute_force_hits(mesh, origins, directions):
    """Möller–Trumbore against every triangle: (t, face, barycentric) per ray, t = inf on a miss."""
    p = np.asarray(mesh.vertices, np.float64)[mesh.faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    ts, faces, barys = [], [], []
    for o, d in zip(origins, directions):
        q = np.cross(d, e2)
        det = (e1 * q).sum(-1)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - p[:, 0]
        b1 = (s * q).sum(-1) * inv
        r = np.cross(s, e1)
        b2 = (d * r).sum(-1) * inv
        t = (e2 * r).sum(-1) * inv
        hit = ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 0)
        t = np.where(hit, t, np.inf)
        f = int(np.argmin(t))
        ts.append(t[f])
        faces.append(f if np.isfinite(t[f]) else -1)
        barys.append((1 - b1[f] - b2[f], b1[f], b2[f]))
    return np.array(ts), np.array(faces), np.array(barys)


@pytest.fixture(params=MESHES)
def real_mesh(request, shared_data):
    return request.param, load_mesh(shared_data / "meshes" / request.param)


def test_real_meshes_rasterise_like_brute_force_ray_casting(real_mesh, rng):
    name, mesh = real_mesh
    camera = _framing_camera(mesh)
    g = rasterize(mesh, camera).numpy()
    covered = g["mask"] > 0
    assert 0.05 < covered.mean() < 0.9, f"{name}: the framing camera should see the mesh"

    # Coverage and depth agree with an independent ray caster on a random pixel subset.
    origins, directions = camera.rays()
    pixels = rng.choice(covered.size, 150, replace=False)
    rows, cols = np.unravel_index(pixels, covered.shape)
    t, faces, _ = _brute_force_hits(mesh, origins[rows, cols], directions[rows, cols])
    diag = np.linalg.norm(mesh.extents)
    # Rays grazing a triangle edge may go either way; allow a couple of such pixels.
    assert (np.isfinite(t) == covered[rows, cols]).mean() >= 0.98
    both = np.isfinite(t) & covered[rows, cols]
    np.testing.assert_allclose(g["depth"][rows, cols][both], t[both], atol=1e-4 * diag)
    assert (g["triangle"][rows, cols][both] == faces[both]).mean() >= 0.95

    # Every covered position lies on its reported triangle (distance < 1e-4 of the diagonal).
    tri = np.asarray(mesh.vertices)[mesh.faces[g["triangle"][covered]]]
    pos = g["position"][covered].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert np.abs(((pos - tri[:, 0]) * normal).sum(-1)).max() < 1e-4 * diag
    assert (g["triangle"][~covered] == -1).all() and np.isinf(g["depth"][~covered]).all()

    # Normals: unit length, facing the camera.
    view = -directions[covered] / np.linalg.norm(directions[covered], axis=-1, keepdims=True)
    for key in ("normal", "geometric_normal"):
        n = g[key][covered]
        np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
        assert ((n * view).sum(-1) > 0.0).all(), f"{name}: {key} faces away from the camera"


def test_duck_uvs_sample_its_texture_the_right_way_up(shared_data, rng):
    mesh = load_mesh(shared_data / "meshes" / "Duck.glb")
    image = io.srgb_to_linear(np.asarray(mesh.visual.material.baseColorTexture.convert("RGB")) / 255.0)
    camera = _framing_camera(mesh, (128, 128), direction=(0.6, 0.3, 1.0))
    g = rasterize(mesh, camera)
    uv = g.uv()["uv"].numpy()
    covered = g.mask.numpy() > 0

    # UVs at known pixels equal the barycentric interpolation of the brute-force hit.
    rows, cols = np.nonzero(covered)
    pick = rng.choice(len(rows), 60, replace=False)
    origins, directions = camera.rays()
    _, faces, bary = _brute_force_hits(mesh, origins[rows[pick], cols[pick]], directions[rows[pick], cols[pick]])
    agree = faces == g.triangle.numpy()[rows[pick], cols[pick]]
    assert agree.mean() > 0.9
    expected = (np.asarray(mesh.visual.uv)[mesh.faces[faces]] * bary[..., None]).sum(1)
    np.testing.assert_allclose(uv[rows[pick], cols[pick]][agree], expected[agree], atol=1e-4)

    # Sampled colours: the duck is yellow with an orange beak; read upside down, the texture's
    # white background shows on the body. Near-white pixels measure the orientation.
    tex = wt.Texture(image)

    def white_fraction(uvs):
        colour = wt.sample(tex, uvs).numpy()[covered]
        return (colour.min(axis=-1) > 0.8).mean()

    flipped = uv * [1, -1] + [0, 1]
    assert white_fraction(uv) < 0.005
    assert white_fraction(flipped) > 0.03  # the check can tell


def test_plane_derivatives_match_the_analytic_values():
    # A fronto-parallel quad at distance 5 with UV = (x, y) / 4.
    vertices = np.array([[-20, -20, -5], [20, -20, -5], [20, 20, -5], [-20, 20, -5]], np.float64)
    mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=vertices[:, :2] / 4.0)
    h, w = 40, 60
    camera = look_at((0, 0, 0), (0, 0, -1), fov_y=60.0, resolution=(h, w))
    g = rasterize(mesh, camera).numpy()
    assert (g["mask"] == 1).all()
    step = 2 * np.tan(np.radians(30)) * 5 / h  # world size of a pixel at distance 5
    np.testing.assert_allclose(g["depth"], 5.0, rtol=1e-6)
    np.testing.assert_allclose(g["position_dx"], np.broadcast_to([step, 0, 0], (h, w, 3)), atol=1e-6)
    np.testing.assert_allclose(g["position_dy"], np.broadcast_to([0, -step, 0], (h, w, 3)), atol=1e-6)
    np.testing.assert_allclose(g["uv0.uv_dx"], np.broadcast_to([step / 4, 0], (h, w, 2)), atol=1e-6)
    np.testing.assert_allclose(g["uv0.uv_dy"], np.broadcast_to([0, -step / 4], (h, w, 2)), atol=1e-6)
    np.testing.assert_allclose(g["uv0.tangent"], np.broadcast_to([1, 0, 0, 1], (h, w, 4)), atol=1e-6)


def test_ground_plane_derivatives_are_exact_and_lod_grows_with_distance():
    vertices = np.array([[-100, 0, 10], [100, 0, 10], [100, 0, -200], [-100, 0, -200]], np.float64)
    mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=vertices[:, [0, 2]] * [1, -1] / 8.0)
    camera = look_at((0, 2, 0), (0, 1, -6), fov_y=50.0, resolution=(64, 64))
    g = rasterize(mesh, camera).numpy()
    covered = g["mask"] > 0
    # The derivative from ray differentials equals the limit of finite differences of positions
    # of rays shifted by a tiny fraction of a pixel (computed here in float64).
    origins, directions = camera.rays()
    hx, hy = camera.half_extent
    eps = 1e-3
    shifted = directions + camera.right * (2 * hx / 64 * eps)
    t0 = -origins[..., 1] / directions[..., 1]
    t1 = -origins[..., 1] / shifted[..., 1]
    fd = (origins + shifted * t1[..., None] - origins - directions * t0[..., None]) / eps
    np.testing.assert_allclose(g["position_dx"][covered], fd[covered], rtol=1e-3, atol=1e-5)
    footprint = np.maximum(np.linalg.norm(g["uv0.uv_dx"], axis=-1), np.linalg.norm(g["uv0.uv_dy"], axis=-1))
    column = np.log2(footprint[:, 32][covered[:, 32]] * 256)
    depth = g["depth"][:, 32][covered[:, 32]]
    assert np.all(np.diff(column[np.argsort(depth)]) > 0), "LOD must grow with distance"


def test_orthographic_camera_has_constant_derivatives():
    mesh = trimesh.creation.box((4, 4, 4))
    camera = orthographic((0, 0, 10), (0, 0, 0), height=8.0, resolution=(32, 32))
    g = rasterize(mesh, camera).numpy()
    covered = g["mask"] > 0
    assert covered.mean() == pytest.approx(0.25, abs=0.02)
    np.testing.assert_allclose(g["position_dx"][covered], np.broadcast_to([0.25, 0, 0], (covered.sum(), 3)), atol=1e-6)
    np.testing.assert_allclose(g["depth"][covered], 8.0, rtol=1e-6)


def test_gbuffer_exr_round_trip_is_bit_exact(tmp_path, shared_data):
    g = rasterize(shared_data / "meshes" / "Duck.glb", _framing_camera(load_mesh(shared_data / "meshes" / "Duck.glb")))
    save_gbuffer(tmp_path / "g.exr", g)
    loaded = load_gbuffer(tmp_path / "g.exr")
    a, b = g.numpy(), loaded.numpy()
    assert sorted(a) == sorted(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.mark.parametrize("prefix", ["", "ViewLayer."])
def test_blender_named_exr_loads(tmp_path, prefix):
    g = rasterize(trimesh.creation.icosphere(), look_at((0, 0, 4), (0, 0, 0), resolution=(24, 32))).numpy()
    channels = {}
    for i, c in enumerate("XYZ"):
        channels[f"{prefix}Position.{c}"] = g["position"][..., i]
        channels[f"{prefix}Normal.{c}"] = g["normal"][..., i]
    channels[f"{prefix}Depth.Z"] = np.where(g["mask"] > 0, g["depth"], 1e10).astype(np.float32)
    channels[f"{prefix}UV.U"] = np.full((24, 32), 0.25, np.float32)
    channels[f"{prefix}UV.V"] = np.full((24, 32), 0.75, np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {k: np.ascontiguousarray(v) for k, v in channels.items()}
    with OpenEXR.File(header, channels) as f:
        f.write(str(tmp_path / "blender.exr"))
    loaded = load_gbuffer(tmp_path / "blender.exr")
    np.testing.assert_array_equal(loaded.position.numpy(), g["position"])
    np.testing.assert_array_equal(loaded.normal.numpy(), g["normal"])
    np.testing.assert_array_equal(loaded.mask.numpy(), g["mask"])
    np.testing.assert_array_equal(loaded.uv()["uv"].numpy()[..., 1], 0.75)


def test_exr_without_required_channels_names_them(tmp_path):
    io.write_exr(tmp_path / "rgb.exr", np.zeros((4, 4, 3), np.float32))
    with pytest.raises(ValueError, match=r"load_gbuffer\(\): .* has no position channels \(looked for \['P.X'.*'Position.X'.*it has \['B', 'G', 'R'\]"):
        load_gbuffer(tmp_path / "rgb.exr")


def test_exr_with_two_view_layers_needs_a_layer(tmp_path):
    planes = {f"{layer}.{p}.{c}": np.zeros((2, 2), np.float32) for layer in ("A", "B") for p in ("Position", "Normal") for c in "XYZ"}
    io.write_exr(tmp_path / "two.exr", planes)
    with pytest.raises(ValueError, match=r"several view layers \['A', 'B'\]; pass layer="):
        load_gbuffer(tmp_path / "two.exr")
    assert load_gbuffer(tmp_path / "two.exr", layer="B").resolution == (2, 2)


# -- bad input ------------------------------------------------------------------------------------


CAMERA = look_at((0, 0, 5), (0, 0, 0), resolution=(16, 16))


@pytest.mark.parametrize(
    "mesh, error, match",
    [
        (trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int)), ValueError, r"rasterize\(\): the mesh is empty"),
        (trimesh.Trimesh([[0, 0, 0], [1, np.nan, 0], [0, 1, 0]], [[0, 1, 2]], process=False), ValueError, r"vertex 1 is not finite"),
        (trimesh.Trimesh([[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 1, 2]], process=False), ValueError, r"all 1 triangles .* degenerate"),
        (np.zeros((3, 3)), TypeError, r"rasterize\(\): mesh must be a trimesh.Trimesh or a path"),
        (trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False,
                         visual=trimesh.visual.TextureVisuals(uv=[[0, 0], [1, np.inf], [0, 1]])),
         ValueError, r"rasterize\(\): UV set 'uv0' is not finite at 1 vertices, e.g. vertex 1: \[1.0, inf\]"),
    ],
)
def test_bad_meshes_raise(mesh, error, match):
    with pytest.raises(error, match=match):
        rasterize(mesh, CAMERA)


def test_degenerate_triangles_are_skipped_and_ids_stay_those_of_the_mesh():
    vertices = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [5, 5, 0]]
    mesh = trimesh.Trimesh(vertices, [[0, 0, 3], [0, 1, 2]], process=False)  # face 0 has zero area
    g = rasterize(mesh, CAMERA).numpy()
    assert set(np.unique(g["triangle"])) == {-1, 1}


def test_camera_looking_away_gives_an_empty_gbuffer():
    g = rasterize(trimesh.creation.box(), look_at((0, 0, 5), (0, 0, 10), resolution=(8, 8)))
    assert isinstance(g, GBuffer) and g.mask.numpy().sum() == 0 and (g.triangle.numpy() == -1).all()


def test_misses_get_the_background_whatever_the_arrays_held(monkeypatch):
    """The rasteriser's arrays start unfilled (its kernels write every element): with every
    allocation poisoned first (bytes 0x7F: floats of 3.4e38, ints of 2.1e9), each miss still gets the
    background (zeros, depth inf, triangle -1), in every field and UV set: the G-buffer of unpoisoned
    arrays, bit for bit."""
    import warp as wp

    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, :2] * 0.5 + 0.5)
    camera = _framing_camera(mesh, resolution=(40, 56))
    clean = rasterize(mesh, camera, samples=4).numpy()
    empty = wp.empty

    def poisoned(*args, **kwargs):
        a = empty(*args, **kwargs)
        a.numpy().view(np.uint8)[...] = 0x7F
        return a

    monkeypatch.setattr(wp, "empty", poisoned)
    g = rasterize(mesh, camera, samples=4).numpy()
    missed = g["mask"] == 0
    assert missed.any() and (~missed).any()
    assert (g["triangle"][missed] == -1).all() and np.isinf(g["depth"][missed]).all()
    assert any(k.endswith(".tangent") for k in g)
    for key, a in g.items():
        if key not in ("triangle", "depth"):
            assert not a[missed].any(), f"{key} is not 0 at a miss"
        np.testing.assert_array_equal(a, clean[key], err_msg=key)


def test_camera_inside_the_mesh_sees_back_faces_facing_it():
    g = rasterize(trimesh.creation.box((4, 4, 4)), look_at((0, 0, 0), (0, 0, -1), resolution=(8, 8))).numpy()
    assert (g["mask"] == 1).all()
    np.testing.assert_allclose(g["geometric_normal"][4, 4], [0, 0, 1], atol=1e-6)


def test_unreadable_mesh_files(tmp_path):
    (tmp_path / "junk.ply").write_text("this is not a mesh")
    with pytest.raises(ValueError, match=r"load_mesh\(\): .*junk.ply"):
        load_mesh(tmp_path / "junk.ply")
    with pytest.raises(FileNotFoundError, match=r"load_mesh\(\): file not found"):
        load_mesh(tmp_path / "missing.obj")


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: look_at((0, 0, 0), (0, 0, 0)), r"look_at\(\): eye and target must differ"),
        (lambda: look_at((0, 0, 0), (0, 1, 0), up=(0, 1, 0)), r"look_at\(\): up \[0.0, 1.0, 0.0\] must not be parallel"),
        (lambda: look_at((0, 0, 0), (0, 1, 0), up=(0, 0, 0)), r"look_at\(\): up must not be zero"),
        (lambda: look_at((0, 0, 1), (0, 0, 0), resolution=(0, 4)), r"look_at\(\): resolution must be two positive ints"),
        (lambda: look_at((0, 0, 1), (0, 0, 0), fov_y=180), r"look_at\(\): fov_y must be in \(0, 180\)"),
        (lambda: look_at((0, np.nan, 1), (0, 0, 0)), r"look_at\(\): eye must be 3 finite numbers"),
        (lambda: orthographic((0, 0, 1), (0, 0, 0), height=-1), r"orthographic\(\): height must be positive"),
    ],
)
def test_bad_cameras_raise(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize("make", [look_at, orthographic])
def test_a_view_straight_down_or_up_picks_its_own_up_vector(make):
    """Issue 34: a top-down view failed, the default up vector being parallel to the view. Without
    ``up``, a view along -Y has +X right and -Z up in the image; along +Y, +X right and +Z up."""
    down = make((0, 10, 0), (0, 0, 0))
    np.testing.assert_allclose(down.right, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(down.up, [0, 0, -1], atol=1e-12)
    up = make((0, -10, 0), (0, 0, 0))
    np.testing.assert_allclose(up.right, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(up.up, [0, 0, 1], atol=1e-12)
    tilted = make((0, 10, 0), (0, 0, 0), up=(1, 0, 0))  # an explicit up is kept
    np.testing.assert_allclose(tilted.up, [1, 0, 0], atol=1e-12)
    oblique = make((3, 10, 4), (0, 0, 0))  # the default +Y elsewhere, as before
    assert oblique.up[1] > 0 and abs(oblique.right[1]) < 1e-12


def test_look_at_frame_is_right_handed_and_y_up():
    cam = look_at((0, 0, 5), (0, 0, 0))
    np.testing.assert_allclose(cam.forward, [0, 0, -1])
    np.testing.assert_allclose(cam.right, [1, 0, 0])
    np.testing.assert_allclose(cam.up, [0, 1, 0])
    np.testing.assert_allclose(np.cross(cam.right, cam.up), -cam.forward)


def test_gltf_scenes_are_flattened_with_their_node_transforms(tmp_path):
    box = trimesh.creation.box((1, 1, 1))
    scene = trimesh.Scene()
    scene.add_geometry(box, node_name="a", transform=trimesh.transformations.translation_matrix((10, 0, 0)))
    scene.add_geometry(box, node_name="b", transform=trimesh.transformations.translation_matrix((-10, 0, 0)))
    scene.export(tmp_path / "scene.glb")
    mesh = load_mesh(tmp_path / "scene.glb")
    assert len(mesh.faces) == 24
    np.testing.assert_allclose(mesh.bounds, [[-10.5, -0.5, -0.5], [10.5, 0.5, 0.5]], atol=1e-6)


def test_an_stl_mesh_is_shaded_smooth_as_other_formats_are(tmp_path):
    """STL stores every triangle's corners apart: loaded as they were, its vertex normals were the
    faces' own and a sphere rendered faceted (issue 50 item 12). The corners are now joined, and
    the G-buffer's normals follow the sphere as an OBJ's do."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    for ext in ("stl", "obj"):
        ball.export(tmp_path / f"ball.{ext}")
    meshes = {ext: wt.load_mesh(tmp_path / f"ball.{ext}") for ext in ("stl", "obj")}
    assert len(meshes["stl"].vertices) == len(meshes["obj"].vertices) == len(ball.vertices)
    camera = wt.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), resolution=(48, 48))
    errors = {}
    for ext, mesh in meshes.items():
        g = wt.rasterize(mesh, camera)
        covered = g.mask.numpy() > 0
        n, p = g.normal.numpy()[covered], g.position.numpy()[covered]
        errors[ext] = np.degrees(np.arccos(np.clip(np.sum(n * p / np.linalg.norm(p, axis=1, keepdims=True), axis=1), -1, 1)))
    assert np.median(errors["stl"]) < 3.0 and np.percentile(errors["stl"], 99) < 8.0, np.percentile(errors["stl"], [50, 99])
    np.testing.assert_allclose(np.median(errors["stl"]), np.median(errors["obj"]), atol=0.5)


def test_flipped_triangles_shade_like_their_neighbours(tmp_path):
    """A sphere with every fifth triangle wound the other way (as scanned meshes such as the
    bunny's ears have): the shading normal of every pixel faces its triangle's front, so the
    flipped triangles shade as their neighbours do, no dark specks."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    faces = np.asarray(sphere.faces).copy()
    faces[::5] = faces[::5, ::-1]
    flipped = trimesh.Trimesh(sphere.vertices, faces, process=False)
    camera = wt.look_at((0.0, 0.5, 3.0), (0.0, 0.0, 0.0), fov_y=45.0, resolution=(64, 64))
    g = wt.rasterize(flipped, camera)
    covered = g.mask.numpy() > 0
    normal, geometric = g.normal.numpy()[covered], g.geometric_normal.numpy()[covered]
    assert ((normal * geometric).sum(-1) > 0.5).all()
    agreement = (normal * wt.rasterize(sphere, camera).normal.numpy()[covered]).sum(-1)
    assert (agreement > 0.0).all() and (agreement > 0.95).mean() > 0.99  # vertex normals shared with flipped faces lean a little


# -- G-buffers from other renderers -------------------------------------------------------------------


def _uv_sphere_gbuffer(resolution=(48, 64)):
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, [0, 1]] * 0.5 + 0.5)
    return wt.rasterize(mesh, look_at((0.4, 0.6, 3.0), (0.0, 0.0, 0.0), fov_y=45.0, resolution=resolution))


def test_from_arrays_keeps_every_field_it_is_given():
    g = _uv_sphere_gbuffer()
    a = g.numpy()
    back = GBuffer.from_arrays(
        a["position"], a["normal"], a["mask"], uv=a["uv0.uv"], uv_dx=a["uv0.uv_dx"], uv_dy=a["uv0.uv_dy"], tangent=a["uv0.tangent"],
        position_dx=a["position_dx"], position_dy=a["position_dy"], geometric_normal=a["geometric_normal"], depth=a["depth"],
        triangle=a["triangle"], camera=g.camera,
    ).numpy()  # fmt: skip
    assert sorted(back) == sorted(a)
    for name in a:
        np.testing.assert_allclose(back[name], a[name], rtol=1e-6, atol=1e-6, err_msg=name)


def test_from_arrays_estimates_missing_derivatives_from_neighbours():
    """Left out, the derivatives come from screen-space neighbours: on the sphere's interior they
    match the rasteriser's ray differentials, and a technique reads the same mip levels."""
    g = _uv_sphere_gbuffer((96, 128))
    a = g.numpy()
    covered = a["mask"] > 0
    est = GBuffer.from_arrays(a["position"], a["normal"], a["mask"], uv=a["uv0.uv"], camera=g.camera)
    e = est.numpy()
    np.testing.assert_allclose(e["depth"][covered], a["depth"][covered], rtol=1e-5)
    inner = covered.copy()  # pixels whose 8 neighbours are covered too
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            inner &= np.roll(np.roll(covered, dr, 0), dc, 1)
    inner[[0, -1]] = False
    inner[:, [0, -1]] = False
    for name in ("position_dx", "position_dy", "uv0.uv_dx", "uv0.uv_dy"):
        # per pixel, relative: measured 1.2% median, 5.5% at the 95th percentile (the rim, where
        # finite differences and the tangent plane part ways)
        err = np.linalg.norm(e[name][inner] - a[name][inner], axis=-1) / np.linalg.norm(a[name][inner], axis=-1)
        assert np.median(err) < 0.03 and np.percentile(err, 95) < 0.1, name
    tex = wt.Texture(np.random.default_rng(0).random((64, 64, 3)).astype(np.float32))
    exact = wt.triplanar(g, tex, tiling=4.0).numpy()[inner]
    estimated = wt.triplanar(est, tex, tiling=4.0).numpy()[inner]
    assert np.median(np.abs(estimated - exact)) < 0.01


def test_screen_derivatives_take_the_shorter_side_at_a_jump():
    values = np.array([[0.0, 1.0, 2.0, 50.0, 51.0]])[..., None]
    covered = np.array([[True, True, True, True, False]])
    dx, dy = wt.gbuffer.screen_derivatives(values, covered)
    np.testing.assert_array_equal(dx[0, :, 0], [1.0, 1.0, 1.0, 48.0, 0.0])  # at 50: only its backward side
    np.testing.assert_array_equal(dy, 0.0)


def test_from_arrays_flip_y_reads_bottom_up_rows():
    g = _uv_sphere_gbuffer()
    a = g.numpy()
    flipped = {k: v[::-1] for k, v in a.items()}
    back = GBuffer.from_arrays(
        flipped["position"], flipped["normal"], flipped["mask"], uv=flipped["uv0.uv"], uv_dx=flipped["uv0.uv_dx"], uv_dy=-flipped["uv0.uv_dy"],
        position_dx=flipped["position_dx"], position_dy=-flipped["position_dy"], flip_y=True,
    ).numpy()  # fmt: skip
    for name in ("position", "normal", "mask", "uv0.uv", "uv0.uv_dx", "uv0.uv_dy", "position_dx", "position_dy"):
        np.testing.assert_allclose(back[name], a[name], rtol=1e-6, atol=1e-6, err_msg=name)


class _Tensor:
    """What the bridge needs of a torch tensor (no torch here): ``.detach().cpu().numpy()``."""

    def __init__(self, array):
        self.array = array

    def detach(self):
        return self

    def cpu(self):
        return self

    def numpy(self):
        return self.array


def test_from_arrays_takes_tensors_and_wp_arrays_and_checks_its_input():
    g = _uv_sphere_gbuffer()
    a = g.numpy()
    back = GBuffer.from_arrays(_Tensor(a["position"]), g.normal, _Tensor(a["mask"] > 0)).numpy()
    np.testing.assert_allclose(back["normal"], a["normal"], atol=1e-6)
    np.testing.assert_array_equal(back["mask"], a["mask"])
    assert back["triangle"][a["mask"] > 0].max() == 0 and (back["triangle"][a["mask"] == 0] == -1).all()
    bad_position = a["position"].copy()
    bad_position[a["mask"] > 0] = np.nan
    with pytest.raises(ValueError, match=r"GBuffer.from_arrays\(\): position is not finite at covered pixel"):
        GBuffer.from_arrays(bad_position, a["normal"], a["mask"])
    with pytest.raises(ValueError, match=r"GBuffer.from_arrays\(\): normal must have shape \(48, 64, 3\), got \(48, 63, 3\)"):
        GBuffer.from_arrays(a["position"], a["normal"][:, 1:])
    with pytest.raises(ValueError, match=r"GBuffer.from_arrays\(\): position must have shape \(H, W, 3\)"):
        GBuffer.from_arrays(a["position"][..., :2], a["normal"])
    with pytest.raises(TypeError, match=r"GBuffer.from_arrays\(\): uv must hold real numbers"):
        GBuffer.from_arrays(a["position"], a["normal"], uv=np.full((48, 64, 2), "x"))
    with pytest.raises(ValueError, match=r"pass uv too"):
        GBuffer.from_arrays(a["position"], a["normal"], uv_dx=a["uv0.uv_dx"])
    nan_outside = a["position"].copy()
    nan_outside[a["mask"] == 0] = np.nan  # uncovered pixels may hold anything
    assert GBuffer.from_arrays(nan_outside, a["normal"], a["mask"]).numpy()["mask"].sum() == a["mask"].sum()


def test_to_its_own_device_is_itself_and_an_unknown_device_says_which_there_are():
    g = rasterize(trimesh.creation.box(), look_at((0, 0, 5), (0, 0, 0), resolution=(8, 8)), device="cpu")
    assert g.to("cpu") is g and g.to(g.device) is g
    with pytest.raises(ValueError, match=r"GBuffer\.to\(\): device 'cuda:7' does not exist: .*the devices are cpu"):
        g.to("cuda:7")
