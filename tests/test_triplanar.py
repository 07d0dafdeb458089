"""Triplanar, biplanar and triplanar normal mapping: NumPy-reference agreement, properties, bad input.

The reference is ``reference_triplanar.py`` (float64, vectorised). The properties pin down what a
second implementation of the same formulas cannot: the mirror-fix handedness (faces of a cube read
unmirrored, seen from outside), that normal mapping tilts normals along the directions in which the
colour mapping's u and v grow, and that object space moves the texture with the object.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh
import warp as wp

import reference_triplanar as rt
import warptex as wt
from conftest import normal_mapping, with_sampler
from conftest import SHARED_DATA
from warptex.camera import Camera
from warptex.triplanar import biplanar, triplanar, triplanar_normal

ATOL = 1e-5
BLENDS = ("whiteout", "udn", "rnm")

# -- data ---------------------------------------------------------------------------------------------


def _random(seed, h, w, c):
    return np.random.default_rng(seed).random((h, w, c)).astype(np.float32)


def _smooth_normal_map(seed, h, w, c=3):
    """A tileable normal map with moderate slopes (x, y in [0.25, 0.75] after a 3×3 box blur)."""
    raw = np.random.default_rng(seed).random((h, w, 3))
    blur = sum(np.roll(np.roll(raw, i, 0), j, 1) for i in (-1, 0, 1) for j in (-1, 0, 1)) / 9
    nm = np.concatenate([0.5 + (blur[..., :2] - 0.5), 0.8 + 0.2 * raw[..., 2:]], axis=-1)
    return nm[..., :c].astype(np.float32)


@functools.lru_cache(maxsize=None)
def _images():
    """Level-0 images (float32) and their warptex textures, built once."""
    imgs = {
        "a": _random(1, 32, 32, 3),
        "npot_x": _random(2, 24, 40, 3),
        "npot_y": _random(3, 50, 30, 3),
        "small": _random(4, 16, 16, 3),
        "layers": np.stack([_random(5, 20, 12, 2), _random(6, 20, 12, 2)]),
        "normal": _smooth_normal_map(7, 16, 16),
        "normal_npot": _smooth_normal_map(8, 24, 40),
        "normal_2ch": _smooth_normal_map(9, 20, 20, c=2),
    }
    texs = {k: (wt.TextureArray(v) if v.ndim == 4 else wt.Texture(v)) for k, v in imgs.items()}
    return imgs, texs


@functools.lru_cache(maxsize=None)
def _brick():
    tex = wt.Texture.from_file(SHARED_DATA / "textures" / "brick.png", format="float32")  # float mips, as the reference's
    return tex.numpy(), tex


def _cam_sphere():
    return wt.orthographic((0, 0, 5), (0, 0, 0), height=2.2, resolution=(64, 64))


@functools.lru_cache(maxsize=None)
def _sphere():
    g = wt.rasterize(trimesh.creation.icosphere(subdivisions=4), _cam_sphere())
    return g, g.numpy(), 1.0


@functools.lru_cache(maxsize=None)
def _bunny():
    mesh = wt.load_mesh(SHARED_DATA / "meshes" / "bunny.ply")
    centre = mesh.bounds.mean(axis=0)
    view = np.array([0.55, 0.35, 0.75]) / np.linalg.norm([0.55, 0.35, 0.75])
    g = wt.rasterize(mesh, wt.look_at(centre + 0.3 * view, centre, fov_y=35.0, resolution=(64, 64)))
    return g, g.numpy(), 10.0  # the bunny is ~0.15 units across: tile 10× more densely


@pytest.fixture(params=["sphere", "bunny"])
def scene(request):
    """``(gbuffer, gbuffer.numpy(), tiling scale)`` of the unit sphere (orthographic) or the bunny (pinhole)."""
    if request.param == "bunny":
        request.getfixturevalue("shared_data")  # skips without ../shared/data
        return _bunny()
    return _sphere()


def _covered(gn):
    return gn["mask"] != 0


def _gbuffer(normals, positions=None, mask=None, dpdx=(0.01, 0.0, 0.0), dpdy=(0.0, -0.01, 0.0)):
    """A hand-made ``(1, N)`` G-buffer."""
    normals = np.asarray(normals, np.float32).reshape(1, -1, 3)
    count = normals.shape[1]
    g = wt.GBuffer.empty((1, count))
    g.normal.assign(normals)
    if positions is not None:
        g.position.assign(np.asarray(positions, np.float32).reshape(1, count, 3))
    g.position_dx.assign(np.broadcast_to(np.asarray(dpdx, np.float32), (1, count, 3)).copy())
    g.position_dy.assign(np.broadcast_to(np.asarray(dpdy, np.float32), (1, count, 3)).copy())
    g.mask.assign(np.ones((1, count), np.float32) if mask is None else np.asarray(mask, np.float32).reshape(1, count))
    return g


def _rgb_per_axis():
    """Constant pure red, green, blue textures: triplanar output = the three weights."""
    return [wt.Texture(np.broadcast_to(np.eye(3, dtype=np.float32)[a], (4, 4, 3)).copy()) for a in range(3)]


# -- agreement with the NumPy reference ---------------------------------------------------------------

ROT = trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 3.0])
# A translation of the bunny's size: float32 M⁻¹·p loses ~|t|·1e-7, which × tiling × texture size
# (13 × 50 texels on the bunny) must stay below 1e-5 texel-value error.
OBJECT_TO_WORLD = trimesh.transformations.translation_matrix([0.03, -0.02, 0.05]) @ ROT @ np.diag([1.7, 1.7, 1.7, 1.0])

# name: (function, texture keys for X, Y, Z, kwargs for both, reference-only kwargs)
COLOUR_CASES = {
    "triplanar": (triplanar, "a a a", dict(tiling=1.7), {}),
    "biplanar": (biplanar, "a a a", dict(tiling=1.7), dict(biplanar=True, sharpness=8.0)),
    "biplanar_k3": (biplanar, "a a a", dict(tiling=1.7, sharpness=3.0), dict(biplanar=True)),
    "per_axis_npot": (triplanar, "npot_x npot_y small", dict(tiling=1.3), {}),
    "offsets": (triplanar, "a a a", dict(tiling=1.7, offsets=[[0.0, 0.33], [0.1, 0.0], [0.33, 0.67]]), {}),
    "tiling_per_axis": (triplanar, "a a a", dict(tiling=(1.3, 2.5, -0.7)), {}),
    "biplanar_tiling_per_axis": (biplanar, "npot_x npot_y small", dict(tiling=(1.3, 2.5, -0.7)), dict(biplanar=True, sharpness=8.0)),
    "mirror_fix_off": (triplanar, "a a a", dict(tiling=1.7, mirror_fix=False), {}),
    "sharpness_0": (triplanar, "a a a", dict(tiling=1.7, sharpness=0.0), {}),
    "sharpness_1.5": (triplanar, "a a a", dict(tiling=1.7, sharpness=1.5), {}),
    "layer_1": (triplanar, "layers layers layers", dict(tiling=2.1, layer=1), dict(layer=1)),
    "mirror_address_bilinear_bias": (triplanar, "npot_x npot_x npot_x", dict(tiling=2.1, address="mirror", filter="bilinear", lod_bias=0.6), {}),
    "object_space": (triplanar, "npot_x npot_y small", dict(tiling=1.3, space="object", object_to_world=OBJECT_TO_WORLD), dict(object_to_world=OBJECT_TO_WORLD)),
    "brick": (triplanar, "brick brick brick", dict(tiling=0.8), {}),
    "brick_biplanar": (biplanar, "brick brick brick", dict(tiling=0.8), dict(biplanar=True, sharpness=8.0)),
}

def _scaled(kw, scale):
    out = dict(kw)
    if "tiling" in out:
        out["tiling"] = tuple(scale * np.atleast_1d(np.asarray(out["tiling"], np.float64)))
    return out


def _resolve(keys, request):
    names = keys.split()
    if "brick" in names:
        request.getfixturevalue("shared_data")
        img, tex = _brick()
        return [img] * 3, [tex] * 3
    imgs, texs = _images()
    return [imgs[k] for k in names], [texs[k] for k in names]


@pytest.mark.parametrize("case", list(COLOUR_CASES))
def test_colour_matches_numpy_reference(scene, case, request):
    g, gn, scale = scene
    func, keys, kw, ref_kw = COLOUR_CASES[case]
    images, texs = _resolve(keys, request)
    kw = _scaled(kw, scale)
    per_axis = dict(textures_per_axis=texs[:2] + [None], texture=texs[2]) if len(set(map(id, texs))) > 1 else dict(texture=texs[0])
    out = func(g, **per_axis, **with_sampler(kw)).numpy()
    sampler = {k: v for k, v in kw.items() if k in ("address", "filter", "lod_bias")}
    common = {k: v for k, v in kw.items() if k in ("tiling", "sharpness", "offsets", "mirror_fix")}
    expected = rt.triplanar(gn, images, **common, **sampler, **ref_kw)
    assert out.shape == expected.shape
    err = np.abs(out - expected).max()
    assert err <= ATOL, f"{case}: max error {err:.3g}"
    covered = _covered(gn)
    assert covered.mean() > 0.1 and expected[covered].std() > 0.01, "the comparison is not vacuous"
    assert (out[~covered] == 0).all()


NORMAL_CASES = {
    "default": ("normal", dict(tiling=1.7, strength=0.7), {}),
    "strong_flip_green": ("normal_npot", dict(tiling=1.3, strength=1.5, flip_green=True), {}),
    "biplanar": ("normal", dict(tiling=1.7, biplanar=True, sharpness=8.0), {}),
    "mirror_off_tiling_per_axis_offsets": ("normal_npot", dict(tiling=(2.0, 1.0, -1.5), mirror_fix=False, offsets=[[0.2, 0.1], [0.0, 0.5], [0.7, 0.3]]), {}),
    "two_channel": ("normal_2ch", dict(tiling=1.7, sharpness=2.0), {}),
    "object_space_rigid": ("normal", dict(tiling=1.7, space="object", object_to_world=ROT), dict(object_to_world=ROT)),
    "object_space_scaled": ("normal_npot", dict(tiling=1.3, space="object", object_to_world=OBJECT_TO_WORLD), dict(object_to_world=OBJECT_TO_WORLD)),
}


@pytest.mark.parametrize("blend", BLENDS)
@pytest.mark.parametrize("case", list(NORMAL_CASES))
def test_normal_mapping_matches_numpy_reference(scene, case, blend):
    g, gn, scale = scene
    key, kw, ref_kw = NORMAL_CASES[case]
    imgs, texs = _images()
    kw = _scaled(kw, scale)
    out = normal_mapping(kw.get("biplanar", False))(g, texs[key], blend=blend, **{k: v for k, v in kw.items() if k != "biplanar"}).numpy()
    ref_args = {k: v for k, v in kw.items() if k not in ("space", "object_to_world")}
    expected = rt.triplanar_normal(gn, [imgs[key]] * 3, blend_kind=blend, **ref_args, **ref_kw)
    err = np.abs(out - expected).max()
    assert err <= ATOL, f"{case}/{blend}: max error {err:.3g}"
    covered = _covered(gn)
    np.testing.assert_allclose(np.linalg.norm(out[covered], axis=-1), 1.0, atol=1e-6)
    assert (out[~covered] == 0).all()
    tilt = np.degrees(np.arccos(np.clip(np.sum(expected[covered] * gn["normal"][covered], -1), -1, 1)))
    assert tilt.mean() > 3.0, "the map visibly perturbs the normals (the comparison is not vacuous)"


# -- weights --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("func, sharpness", [(triplanar, 0.0), (triplanar, 1.0), (triplanar, 4.0), (triplanar, 200.0), (biplanar, 8.0), (biplanar, 2.0), (biplanar, 0.0)])
def test_weights_sum_to_one_and_match_reference(scene, func, sharpness):
    g, gn, _ = scene
    w = func(g, textures_per_axis=_rgb_per_axis(), sharpness=sharpness).numpy()
    covered = _covered(gn)
    np.testing.assert_allclose(w[covered].sum(-1), 1.0, atol=1e-6)
    assert (w >= 0).all() and (w[~covered] == 0).all()
    n = gn["normal"][covered]
    ref = rt.biplanar_weights(n, sharpness) if func is biplanar else rt.triplanar_weights(n, sharpness)
    # float32 conditioning: d w / d n grows like the sharpness (triplanar), and like r^(k/8 - 1)
    # near the remap's edge r = 0 (biplanar, k < 8): 1e-6 × k / 20, resp. a few 1e-6 at k = 2.
    tol = 1e-5 if func is biplanar and sharpness < 8 else 1e-6 * max(1.0, sharpness / 20)
    np.testing.assert_allclose(w[covered], ref, atol=tol)
    if func is biplanar:
        assert ((w[covered] > 0).sum(-1) <= 2).all(), "biplanar blends at most two projections"
    if sharpness == 0.0:  # 0^0 = 1: equal weights (biplanar: the minor axis still gets 0)
        expected = 1 / 3 if func is triplanar else np.where(w[covered] > 0, 0.5, 0.0)
        np.testing.assert_allclose(w[covered], expected, atol=1e-7)
        assert func is triplanar or ((w[covered] > 0).sum(-1) == 2).all()


AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float32)


@pytest.mark.parametrize("func, sharpness", [(triplanar, 0.5), (triplanar, 4.0), (triplanar, 200.0), (biplanar, 8.0), (biplanar, 1.0)])
def test_axis_normal_reads_only_that_projection(func, sharpness):
    positions = np.random.default_rng(11).uniform(-2, 2, (6, 3)).astype(np.float32)
    g = _gbuffer(AXES, positions, dpdx=(0.02, 0.01, -0.03), dpdy=(-0.01, 0.03, 0.02))
    w = func(g, textures_per_axis=_rgb_per_axis(), sharpness=sharpness).numpy()[0]
    np.testing.assert_array_equal(w, np.abs(AXES), err_msg="exactly one projection, weight exactly 1")
    # And the colour is that projection's own sample: its UV (mirror-fixed), its LOD.
    imgs, texs = _images()
    out = func(g, texs["npot_x"], sharpness=sharpness, tiling=1.3).numpy()[0]
    for i, n in enumerate(AXES):
        a = int(np.argmax(np.abs(n)))
        s = rt.MIRROR[a] * np.sign(n[a])
        plane = rt.PLANES[a]
        uv = positions[i, plane] * np.float32(1.3) * np.array([s, 1], np.float32)
        dx = np.array([0.02, 0.01, -0.03], np.float32)[plane] * np.float32(1.3)
        dy = np.array([-0.01, 0.03, 0.02], np.float32)[plane] * np.float32(1.3)
        single = wt.sample(texs["npot_x"], uv[None], uv_dx=dx[None], uv_dy=dy[None]).numpy()[0]
        np.testing.assert_allclose(out[i], single, atol=1e-6, err_msg=f"normal {n}")


def test_high_sharpness_approaches_the_dominant_projection():
    g, gn, _ = _sphere()
    covered = _covered(gn)
    n = gn["normal"]
    snapped = np.where(np.abs(n) == np.abs(n).max(-1, keepdims=True), np.sign(n), 0.0) * covered[..., None]
    g_dominant = _gbuffer(snapped.reshape(-1, 3), gn["position"].reshape(-1, 3), covered.reshape(-1))
    g_dominant.position_dx.assign(gn["position_dx"].reshape(1, -1, 3))
    g_dominant.position_dy.assign(gn["position_dy"].reshape(1, -1, 3))
    tex = _images()[1]["a"]
    dominant = triplanar(g_dominant, tex, tiling=1.7).numpy().reshape(n.shape)
    a = np.sort(np.abs(n), axis=-1)
    clear = covered & (a[..., 1] < 0.9 * a[..., 2])  # the largest component leads by 10 %
    errors = [np.abs(triplanar(g, tex, tiling=1.7, sharpness=k).numpy() - dominant)[clear].max() for k in (4.0, 16.0, 64.0, 200.0)]
    assert all(e1 > e2 for e1, e2 in zip(errors, errors[1:])), f"error falls with sharpness: {errors}"
    assert errors[-1] < 1e-5, f"sharpness 200 is the dominant projection where one axis leads: {errors}"


@pytest.mark.parametrize("func", [triplanar, biplanar])
def test_zero_and_non_finite_normals_give_finite_zero_output(func):
    bad = [[0, 0, 0], [np.nan, 0, 1], [np.inf, 0, 0], [0, -np.inf, np.nan]]
    normals = bad + [[0.6, 0.0, 0.8], [0.6, 0.0, 0.8]]
    g = _gbuffer(normals, positions=np.full((6, 3), 0.3), mask=[1, 1, 1, 1, 1, 0])
    imgs, texs = _images()
    out = func(g, texs["a"]).numpy()[0]
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[:4], 0.0)
    np.testing.assert_array_equal(out[5], 0.0)  # masked out
    assert (out[4] > 0).all()
    for blend in BLENDS:
        nrm = normal_mapping(func is biplanar)(g, texs["normal"], blend=blend).numpy()[0]
        assert np.isfinite(nrm).all()
        np.testing.assert_array_equal(nrm[[0, 1, 2, 3, 5]], 0.0)
        assert abs(np.linalg.norm(nrm[4]) - 1) < 1e-6


# -- the mirror fix: cube faces seen from outside -------------------------------------------------------

FACES = [(a, s) for a in range(3) for s in (1, -1)]


@functools.lru_cache(maxsize=None)
def _cube():
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    tri = box.vertices[box.faces].reshape(-1, 3)  # unshared corners: flat normals on every face
    return trimesh.Trimesh(tri, np.arange(len(tri)).reshape(-1, 3), process=False)


@functools.lru_cache(maxsize=None)
def _face(axis, sign):
    """G-buffer of one cube face seen head-on from outside: up = +Y for sides, +Z for top/bottom."""
    eye = np.zeros(3)
    eye[axis] = 3.0 * sign
    up = (0, 0, 1) if axis == 1 else (0, 1, 0)
    g = wt.rasterize(_cube(), wt.orthographic(eye, (0, 0, 0), up=up, height=1.5, resolution=(32, 32)))
    gn = g.numpy()
    m = _covered(gn)
    interior = m.copy()
    interior[1:-1, 1:-1] &= m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
    interior[[0, -1], :] = interior[:, [0, -1]] = False
    normal = np.zeros(3)
    normal[axis] = sign
    np.testing.assert_allclose(gn["normal"][m], np.broadcast_to(normal, (m.sum(), 3)), atol=1e-6)
    return g, gn, interior


RAMP_SIZE = 64
RAMP_KW = dict(tiling=0.5, offsets=np.full((3, 2), 0.5), sampler=wt.Sampler(filter="bilinear", max_lod=0.0, address="clamp"))


@functools.lru_cache(maxsize=None)
def _ramp():
    """R = u, G = v under bilinear filtering away from the edges."""
    centres = (np.arange(RAMP_SIZE) + 0.5) / RAMP_SIZE
    u, v = np.meshgrid(centres, centres[::-1])
    return wt.Texture(np.stack([u, v, np.zeros_like(u)], -1).astype(np.float32), mipmaps=False)


def _uv_jacobian(uv, interior):
    """d(u, v) / d(screen right, screen up), mean finite differences over the face interior."""
    right = (uv[:, 2:] - uv[:, :-2])[interior[:, 1:-1]] / 2
    up = (uv[:-2, :] - uv[2:, :])[interior[1:-1, :]] / 2  # row 0 is the top
    return np.stack([right.mean(0), up.mean(0)], axis=1)  # columns: right, up


@pytest.mark.parametrize("func", [triplanar, biplanar])
@pytest.mark.parametrize("axis, sign", FACES)
def test_every_cube_face_reads_unmirrored_from_outside(axis, sign, func):
    g, gn, interior = _face(axis, sign)
    uv = func(g, _ramp(), **RAMP_KW).numpy()[..., :2]
    jac = _uv_jacobian(uv, interior)
    assert np.linalg.det(jac) > 0, f"face {'+-'[sign < 0]}{'XYZ'[axis]} reads mirrored: d(u,v)/d(right,up) = {jac.tolist()}"
    step = RAMP_KW["tiling"] * 1.5 / 32  # world units per pixel × tiling
    np.testing.assert_allclose(jac, step * np.eye(2), atol=1e-6, err_msg="u grows to the right, v upward")
    # Without the fix one face of each opposite pair is mirrored (so the fix is what makes it right).
    jac_off = _uv_jacobian(func(g, _ramp(), **RAMP_KW, mirror_fix=False).numpy()[..., :2], interior)
    assert np.linalg.det(jac_off) < 0 if (sign > 0) != (axis == 2) else np.linalg.det(jac_off) > 0


def _arrow_texture():
    """An asymmetric 16×16 arrow pointing right with a mark at its top-left: any mirror shows."""
    img = np.zeros((16, 16, 3), np.float32)
    img[7:9, 2:12, 0] = 1.0  # shaft
    for k in range(4):  # head, narrowing to the right
        img[4 + k : 12 - k, 11 + k, 0] = 1.0
    img[2:4, 2:4, 1] = 1.0  # a green mark at the top left
    return wt.Texture(img)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_arrow_reads_the_same_way_round_on_opposite_faces(axis):
    arrow = _arrow_texture()
    kw = dict(tiling=0.5, offsets=np.full((3, 2), 0.5), sampler=wt.Sampler(address="clamp"))
    (gp, _, mp), (gm, _, mm) = _face(axis, 1), _face(axis, -1)
    np.testing.assert_array_equal(mp, mm)
    plus, minus = triplanar(gp, arrow, **kw).numpy(), triplanar(gm, arrow, **kw).numpy()
    assert plus[mp].std() > 0.1
    np.testing.assert_allclose(plus[mp], minus[mm], atol=1e-6, err_msg="+/- faces show the same image")
    assert np.abs(plus - plus[:, ::-1]).max() > 0.5, "the arrow is asymmetric"
    # mirror_fix=False: the two faces show mirror images of each other.
    plus_off, minus_off = triplanar(gp, arrow, **kw, mirror_fix=False).numpy(), triplanar(gm, arrow, **kw, mirror_fix=False).numpy()
    np.testing.assert_allclose(plus_off, minus_off[:, ::-1], atol=1e-6)


# -- normal mapping ---------------------------------------------------------------------------------------


def _tangent_frame(g, gn, interior):
    """World directions T = dp/du, B = dp/dv of the colour mapping, fitted from a ramp render."""
    uv = triplanar(g, _ramp(), **RAMP_KW).numpy()[..., :2][interior]
    p = gn["position"][interior].astype(np.float64)
    coef, *_ = np.linalg.lstsq(np.c_[uv, np.ones(len(uv))], p, rcond=None)
    t, b = coef[0], coef[1]
    return t / np.linalg.norm(t), b / np.linalg.norm(b)


@pytest.mark.parametrize("blend", BLENDS)
@pytest.mark.parametrize("axis, sign", FACES)
def test_tilted_map_tilts_along_the_colour_tangent_frame(axis, sign, blend):
    t = np.array([0.4, -0.25, 0.88])
    t /= np.linalg.norm(t)
    flat_tilt = wt.Texture(np.broadcast_to(((t + 1) / 2).astype(np.float32), (4, 4, 3)).copy())
    g, gn, interior = _face(axis, sign)
    tangent, bitangent = _tangent_frame(g, gn, interior)
    normal = np.zeros(3)
    normal[axis] = sign
    assert abs(np.dot(np.cross(tangent, bitangent), normal) - 1) < 1e-6, "(T, B, N) is right-handed"
    out = triplanar_normal(g, flat_tilt, blend=blend, **RAMP_KW).numpy()[interior]
    tz = 1.0 if blend == "udn" else t[2]  # UDN keeps the surface normal's z
    expected = t[0] * tangent + t[1] * bitangent + tz * normal
    expected /= np.linalg.norm(expected)
    np.testing.assert_allclose(out, np.broadcast_to(expected, out.shape), atol=1e-5)


@pytest.mark.parametrize("blend", BLENDS)
@pytest.mark.parametrize("channels", [2, 3, 4])
@pytest.mark.parametrize("use_biplanar", [False, True])
def test_flat_normal_map_returns_the_surface_normal(scene, blend, channels, use_biplanar):
    g, gn, scale = scene
    flat = wt.Texture(np.broadcast_to(np.array([0.5, 0.5, 1.0, 0.3], np.float32)[:channels], (8, 8, channels)).copy())
    out = normal_mapping(use_biplanar)(g, flat, blend=blend, tiling=1.7 * scale, strength=1.3).numpy()
    covered = _covered(gn)
    np.testing.assert_allclose(out[covered], gn["normal"][covered], atol=1e-6)
    assert (out[~covered] == 0).all()


# -- object space -----------------------------------------------------------------------------------------


def _moved_camera(cam: Camera, m) -> Camera:
    lin = m[:3, :3]
    scale = np.cbrt(np.linalg.det(lin))
    rot = lin / scale
    return Camera(
        eye=(m @ np.r_[cam.eye, 1])[:3],
        forward=rot @ cam.forward,
        right=rot @ cam.right,
        up=rot @ cam.up,
        resolution=cam.resolution,
        fov_y=cam.fov_y,
        ortho_height=None if cam.ortho_height is None else cam.ortho_height * scale,
    )


@functools.lru_cache(maxsize=None)
def _object_pair(scale):
    """The same view of an ellipsoid at rest (world space) and moved by M with its camera."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.vertices *= (1.0, 0.7, 1.3)
    cam = wt.look_at((2.0, 1.5, 3.0), (0, 0, 0), fov_y=40.0, resolution=(48, 48))
    m = trimesh.transformations.translation_matrix([0.3, -2.0, 1.5]) @ ROT @ np.diag([scale, scale, scale, 1.0])
    moved = mesh.copy()
    moved.apply_transform(m)
    g_rest, g_moved = wt.rasterize(mesh, cam), wt.rasterize(moved, _moved_camera(cam, m))
    both = (g_rest.mask.numpy() != 0) & (g_moved.mask.numpy() != 0)
    assert (g_rest.mask.numpy() != g_moved.mask.numpy()).mean() < 0.01
    return g_rest, g_moved, m, both


@pytest.mark.parametrize("scale", [1.0, 1.7])
@pytest.mark.parametrize("func", [triplanar, biplanar])
def test_object_space_colour_moves_with_the_object(scale, func):
    g_rest, g_moved, m, both = _object_pair(scale)
    imgs, texs = _images()
    kw = dict(tiling=1.3, offsets=[[0.1, 0.2], [0.3, 0.0], [0.0, 0.6]], textures_per_axis=[texs["npot_x"], texs["npot_y"], texs["small"]])
    rest = func(g_rest, **kw).numpy()
    moved = func(g_moved, **kw, space="object", object_to_world=m).numpy()
    assert rest[both].std() > 0.01
    np.testing.assert_allclose(moved[both], rest[both], atol=1e-4)
    world = func(g_moved, **kw).numpy()
    assert np.abs(world[both] - rest[both]).max() > 0.1, "world space does not follow the object"


@pytest.mark.parametrize("blend", BLENDS)
@pytest.mark.parametrize("scale", [1.0, 1.7])
def test_object_space_normals_move_with_the_object(scale, blend):
    """Normal mapping in object space: moved = R · rest, for rotation + translation + uniform scale."""
    g_rest, g_moved, m, both = _object_pair(scale)
    imgs, texs = _images()
    kw = dict(tiling=1.3, blend=blend, strength=1.2)
    rest = triplanar_normal(g_rest, texs["normal"], **kw).numpy()
    moved = triplanar_normal(g_moved, texs["normal"], **kw, space="object", object_to_world=m).numpy()
    rot = m[:3, :3] / scale
    np.testing.assert_allclose(moved[both], rest[both] @ rot.T, atol=1e-4)


@pytest.mark.parametrize("blend", BLENDS)
def test_object_space_normal_mapping_ignores_uniform_scale(blend):
    """Minimal case of the test above (a bug in 5acbc6a, fixed in defb8d5): one pixel, M = s·I.
    Scaling the object must not change the mapped normal; the normal transformed to object space
    has length s and must be renormalised before the blends."""
    t = np.array([0.4, -0.25, 0.88]) / np.linalg.norm([0.4, -0.25, 0.88])
    tilted = wt.Texture(np.broadcast_to(((t + 1) / 2).astype(np.float32), (4, 4, 3)).copy())
    g = _gbuffer([[0.6, 0.0, 0.8]], positions=[[0.1, 0.2, 0.3]])
    results = {s: triplanar_normal(g, tilted, blend=blend, space="object", object_to_world=np.diag([s, s, s, 1.0])).numpy()[0, 0] for s in (0.5, 1.0, 2.0)}
    np.testing.assert_allclose(results[1.0], triplanar_normal(g, tilted, blend=blend).numpy()[0, 0], atol=1e-6)
    for s in (0.5, 2.0):
        np.testing.assert_allclose(results[s], results[1.0], atol=1e-5, err_msg=f"object_to_world = diag({s}, {s}, {s}, 1)")


# -- bad input --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_g():
    return _gbuffer([[0, 0, 1], [1, 0, 0]], positions=[[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])


def test_bad_input_raises_with_a_clear_message(small_g):
    imgs, texs = _images()
    tex = texs["a"]
    g = small_g
    cases = [
        (TypeError, r"triplanar\(\): gbuffer must be a warptex GBuffer, got dict", lambda: triplanar(g.numpy(), tex)),
        (ValueError, r"no texture for the X projection", lambda: triplanar(g)),
        (ValueError, r"biplanar\(\): no texture for the Y projection", lambda: biplanar(g, textures_per_axis=[tex, None, tex])),
        (TypeError, r"X projection's texture must be a Texture or TextureArray, got ndarray", lambda: triplanar(g, imgs["a"])),
        (ValueError, r"textures_per_axis must be a sequence of 3", lambda: triplanar(g, tex, textures_per_axis=[tex, tex])),
        (ValueError, r"same channel count; X has 3, Z has 2", lambda: triplanar(g, textures_per_axis=[tex, tex, texs["normal_2ch"]])),
        (ValueError, r"layer must be an int in \[0, 1\]", lambda: triplanar(g, texs["layers"], layer=2)),
        (ValueError, r"layer must be an int in \[0, 0\]", lambda: triplanar(g, tex, layer=-1)),
        (ValueError, r"tiling must be non-zero", lambda: triplanar(g, tex, tiling=0.0)),
        (ValueError, r"tiling must be non-zero", lambda: triplanar(g, tex, tiling=(1.0, 0.0, 2.0))),
        (ValueError, r"tiling must be finite", lambda: triplanar(g, tex, tiling=float("nan"))),
        (ValueError, r"tiling must have shape \(1,\) or \(3,\), got \(2,\)", lambda: triplanar(g, tex, tiling=(1.0, 2.0))),
        (ValueError, r"tiling as a wp.array must be float32", lambda: triplanar(g, tex, tiling=wp.array([1.0, 2.0], dtype=float))),
        (ValueError, r"sharpness must be >= 0", lambda: triplanar(g, tex, sharpness=-1.0)),
        (ValueError, r"biplanar\(\): sharpness must be >= 0", lambda: biplanar(g, tex, sharpness=-0.5)),
        (ValueError, r"offsets must have shape \(3, 2\), got \(3,\)", lambda: triplanar(g, tex, offsets=[0.1, 0.2, 0.3])),
        (ValueError, r"offsets must have shape \(3, 2\), got \(2, 3\)", lambda: triplanar(g, tex, offsets=np.zeros((2, 3)))),
        (ValueError, r"space must be one of 'world', 'object'", lambda: triplanar(g, tex, space="tangent")),
        (ValueError, r"space='object' needs object_to_world", lambda: triplanar(g, tex, space="object")),
        (TypeError, r"biplanar\(\) got an unexpected keyword argument 'tilling'", lambda: wt.biplanar(g, tex, tilling=2.0)),
        (ValueError, r"object_to_world is only used with space='object'", lambda: triplanar(g, tex, object_to_world=np.eye(4))),
        (ValueError, r"object_to_world is singular", lambda: triplanar(g, tex, space="object", object_to_world=np.diag([1.0, 0.0, 1.0, 1.0]))),
        (ValueError, r"object_to_world must be a finite 4x4 matrix", lambda: triplanar(g, tex, space="object", object_to_world=np.eye(3))),
        (ValueError, r"object_to_world must be affine", lambda: triplanar(g, tex, space="object", object_to_world=np.ones((4, 4)))),
        (ValueError, r"triplanar_normal\(\): blend must be one of 'whiteout', 'udn', 'rnm', got 'overlay'", lambda: triplanar_normal(g, texs["normal"], blend="overlay")),
        (ValueError, r"strength must be >= 0, got -0.5", lambda: triplanar_normal(g, texs["normal"], strength=-0.5)),
        (ValueError, r"a normal map needs 2 to 4 channels, got 1", lambda: triplanar_normal(g, wt.Texture(np.ones((4, 4, 1), np.float32)))),
        (TypeError, r"triplanar\(\): sampler must be a warptex.Sampler or None, got dict", lambda: triplanar(g, tex, sampler={"filter": "cubic"})),
        (TypeError, r"biplanar\(\): sampler must be a warptex.Sampler or None, got str", lambda: biplanar(g, tex, sampler="repeat")),
    ]
    for exc, match, call in cases:
        with pytest.raises(exc, match=match):
            call()


def test_bad_gbuffer_array_is_named():
    g = wt.GBuffer.empty((1, 2))
    g.normal = wp.zeros((1, 3), dtype=wp.vec3)
    with pytest.raises(ValueError, match=r"gbuffer.normal must be a contiguous wp.array of vec3f with shape \(1, 2\)"):
        triplanar(g, _images()[1]["a"])


@pytest.mark.parametrize("func", [triplanar, biplanar])
def test_kept_launch_arguments_follow_their_inputs(func):
    """Issue 51: colour mapping keeps its packed Warp structs per texture and options (and the
    G-buffer's surface arrays with the G-buffer), so that a small call does not pack them again.
    A kept call gives the bits of a fresh one; a change of options, of the G-buffer's arrays or
    origin, or of the texels in place, is seen; a texture that is dropped takes its entry along."""
    import gc
    import sys
    import weakref

    rng = np.random.default_rng(5)
    normals = rng.normal(size=(40, 3))
    g = _gbuffer(normals, positions=rng.random((40, 3)))
    kept = sys.modules["warptex._pack"]._packed
    texels = rng.random((16, 16, 4)).astype(np.float32)
    tex = wt.Texture(texels)
    first = func(g, tex, tiling=3.0).numpy()
    assert len(kept.get(tex, {})) == 1
    np.testing.assert_array_equal(func(g, tex, tiling=3.0).numpy(), first)  # kept: the same bits
    fresh = func(g, wt.Texture(texels), tiling=3.0).numpy()
    np.testing.assert_array_equal(fresh, first)
    assert not np.array_equal(func(g, tex, tiling=2.0).numpy(), first)  # another option set
    assert len(kept[tex]) == 2
    moved = _gbuffer(normals, positions=rng.random((40, 3)))
    g.position = moved.position  # a G-buffer array replaced
    np.testing.assert_array_equal(func(g, tex, tiling=3.0).numpy(), func(moved, wt.Texture(texels), tiling=3.0).numpy())
    g.origin = np.array([0.25, 0.0, 0.5])  # another origin: packed anew
    np.testing.assert_array_equal(func(g, tex, tiling=3.0).numpy(), func(g, wt.Texture(texels), tiling=3.0, sharpness=4.0 if func is triplanar else 8.0).numpy())
    tex.view.texels.fill_(wp.vec4(0.5, 0.5, 0.5, 0.5))  # every level's texels, in place
    assert np.allclose(func(g, tex, tiling=3.0, sampler=wt.Sampler(filter="bilinear")).numpy()[g.mask.numpy() > 0], 0.5)  # texels changed in place
    gone = weakref.ref(tex)
    del tex
    gc.collect()
    assert gone() is None  # the kept arguments did not keep the texture
    assert all(t is not None for t in kept.keys())
