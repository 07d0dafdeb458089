"""Six-planar textures: a texture per face of the cube of directions (``textures_per_face`` of
triplanar, biplanar and triplanar normal mapping; ``layers_per_face`` of splat layers mapped triplanar).

Projection ``a`` reads the ``+a`` face's texture where the (projected-space) normal has
``n[a] >= 0`` and the ``-a`` face's where ``n[a] < 0``. Checked here: agreement with the NumPy
references on synthetic G-buffers whose normals lie in every octant and on the axis planes (exact
zeros, ``-0.0`` too); that the default and one-texture cases are the three-texture kernels bit for
bit; texel gradients of all six textures (hand-written, generated adjoint, finite differences);
splat ``layers_per_face``; a sphere whose six faces show their own colours with a continuous equator;
and bad input.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh
import warp as wp

import reference_triplanar as rt
import warptex as wt
from backward_paths import assert_same_gradients, splat_inputs, texel_gradients_both_ways
from conftest import normal_mapping
from reference_layers import splat_reference
from warptex.splat import splat
from warptex.triplanar import biplanar, triplanar, triplanar_normal

ATOL = 1e-5
FACES = ("+x", "-x", "+y", "-y", "+z", "-z")

# -- data ---------------------------------------------------------------------------------------------


def _image(seed, h, w, c=3):
    return np.random.default_rng(seed).random((h, w, c)).astype(np.float32)


def _normal_image(seed, h, w):
    """A valid tangent-space normal map: slopes within ±0.3, ``z`` (blue) near 1."""
    im = _image(seed, h, w)
    return np.concatenate([0.2 + 0.6 * im[..., :2], 0.9 + 0.1 * im[..., 2:]], -1).astype(np.float32)


@functools.lru_cache(maxsize=None)
def _six(kind="colour"):
    """Six level-0 images of different sizes (one per face) and their textures."""
    sizes = [(16, 12), (20, 14), (24, 16), (12, 20), (18, 18), (14, 22)]
    make = _normal_image if kind == "normal" else _image
    images = [make(40 + f, *sizes[f]) for f in range(6)]
    return images, [wt.Texture(im) for im in images]


def _octant_normals(rng, count):
    """Unit normals in every octant, and on the axis planes and axes (exact zeros, ``-0.0`` too)."""
    inside = count // 8  # every octant, well inside
    n = rng.normal(size=(count, 3))
    n[:inside] = np.sign(rng.normal(size=(inside, 3))) * rng.uniform(0.2, 1.0, (inside, 3))
    rows = np.arange(inside, count)
    kind = rng.integers(0, 4, len(rows))  # 0: general, 1: one zero, 2: one -0.0, 3: on an axis
    for i, k in zip(rows, kind):
        if k == 1:
            n[i, rng.integers(0, 3)] = 0.0
        elif k == 2:
            n[i, rng.integers(0, 3)] = -0.0
        elif k == 3:
            keep = rng.integers(0, 3)
            n[i] = np.where(np.arange(3) == keep, n[i], rng.choice([0.0, -0.0], 3))
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    assert (n[:inside] != 0).all()
    return n.astype(np.float32)


@functools.lru_cache(maxsize=None)
def _synthetic():
    """A ``(16, 24)`` G-buffer of unrelated pixels: random positions, octant normals, small
    derivatives, UVs; a few pixels uncovered."""
    rng = np.random.default_rng(23)
    h, w = 16, 24
    n = _octant_normals(rng, h * w).reshape(h, w, 3)
    p = rng.uniform(-2, 2, (h, w, 3))
    dx, dy = rng.uniform(-0.03, 0.03, (h, w, 3)), rng.uniform(-0.03, 0.03, (h, w, 3))
    uv = rng.uniform(0, 1, (h, w, 2))
    uv_dx, uv_dy = rng.uniform(-0.02, 0.02, (h, w, 2)), rng.uniform(-0.02, 0.02, (h, w, 2))
    mask = (rng.random((h, w)) > 0.05).astype(np.float32)
    g = wt.GBuffer.from_arrays(p, n, mask, uv=uv, position_dx=dx, position_dy=dy, uv_dx=uv_dx, uv_dy=uv_dy)
    gn = g.numpy()
    normals = gn["normal"][gn["mask"] > 0]
    assert (normals == 0).any(axis=1).mean() > 0.2, "many normals lie on an axis plane"
    assert (np.signbit(normals) & (normals == 0)).any(), "-0.0 components are kept"
    octants = {tuple(s) for s in (normals[(normals != 0).all(1)] < 0).astype(int)}
    assert len(octants) == 8
    return g, gn


def _uv_sphere():
    mesh = trimesh.creation.icosphere(subdivisions=5)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, [0, 2]] * 0.5 + 0.5)
    return mesh


@functools.lru_cache(maxsize=None)
def _two_views(size):
    """One G-buffer of the unit sphere seen from ``(3, 2.5, 4)`` (left half: the +x, +y, +z faces)
    and from the opposite side (right half: the -x, -y, -z faces), ``(size, 2 size)``."""
    mesh = _uv_sphere()
    halves = [wt.rasterize(mesh, wt.orthographic(eye, (0, 0, 0), height=2.2, resolution=(size, size))).numpy() for eye in ((3, 2.5, 4), (-3, -2.5, -4))]
    a = {k: np.concatenate([h[k] for h in halves], axis=1) for k in halves[0]}
    g = wt.GBuffer.from_arrays(
        a["position"], a["normal"], a["mask"], uv=a["uv0.uv"], position_dx=a["position_dx"], position_dy=a["position_dy"], uv_dx=a["uv0.uv_dx"], uv_dy=a["uv0.uv_dy"]
    )
    return g, g.numpy()


def _face_of(n):
    """``[N]`` face index (``+x, -x, +y, -y, +z, -z``) of the dominant component of each normal."""
    a = np.argmax(np.abs(n), axis=-1)
    return 2 * a + (np.take_along_axis(n, a[..., None], -1)[..., 0] < 0)


# -- agreement with the NumPy reference -----------------------------------------------------------------

ROT = trimesh.transformations.rotation_matrix(2.1, [1.0, -2.0, 0.5])

COLOUR_CASES = {
    "triplanar": (triplanar, dict(tiling=1.7), {}),
    "triplanar sharpness 0 (the +face at n[a] = 0)": (triplanar, dict(tiling=1.7, sharpness=0.0), {}),
    "triplanar sharpness 1.5, offsets, tiling per axis": (triplanar, dict(tiling=(1.3, 2.5, -0.7), sharpness=1.5, offsets=[[0.0, 0.33], [0.1, 0.0], [0.33, 0.67]]), {}),
    "triplanar mirror fix off": (triplanar, dict(tiling=1.7, mirror_fix=False), {}),
    "triplanar object space": (triplanar, dict(tiling=1.3, space="object", object_to_world=ROT), dict(object_to_world=ROT)),
    "biplanar": (biplanar, dict(tiling=1.7), dict(biplanar=True, sharpness=8.0)),
    "biplanar k3": (biplanar, dict(tiling=1.7, sharpness=3.0), dict(biplanar=True)),
}


@pytest.mark.parametrize("case", list(COLOUR_CASES))
def test_colour_matches_numpy_reference(case):
    g, gn = _synthetic()
    func, kw, ref_kw = COLOUR_CASES[case]
    images, texs = _six()
    out = func(g, textures_per_face=texs, **kw).numpy()
    ref_args = {k: v for k, v in kw.items() if k not in ("space", "object_to_world")}
    expected = rt.triplanar(gn, images, **ref_args, **ref_kw)
    err = np.abs(out - expected).max()
    # Biplanar below k = 8: the remap's slope r^(k/8 - 1) near its edge r = 0 magnifies float32
    # rounding of the weights (6e-5 on these normals, the same with three textures per axis).
    tol = 1e-4 if func is biplanar and kw.get("sharpness", 8.0) < 8 else ATOL
    assert err <= tol, f"{case}: max error {err:.3g}"
    covered = gn["mask"] != 0
    assert (out[~covered] == 0).all()
    # Not vacuous: the six faces matter (the result differs from reading the + faces only).
    plus_only = rt.triplanar(gn, [images[f] for f in (0, 2, 4)], **ref_args, **ref_kw)
    assert np.abs(plus_only - expected)[covered].max() > 0.2


def test_object_space_picks_faces_by_the_object_space_normal():
    """With ``space="object"`` the face is that of the object-space normal: a rotation sends some
    world-space ``+`` normals to ``-`` faces and back."""
    g, gn = _synthetic()
    images, texs = _six()
    n = gn["normal"][gn["mask"] > 0].astype(np.float64)
    object_n = n @ ROT[:3, :3]  # object space: Rᵀ n, as row vectors
    assert ((n < 0) != (object_n < 0)).any(axis=1).mean() > 0.3
    moved = triplanar(g, textures_per_face=texs, space="object", object_to_world=ROT).numpy()
    expected = rt.triplanar(gn, images, object_to_world=ROT)
    np.testing.assert_allclose(moved, expected, atol=ATOL)
    world_faces = rt.triplanar(gn, images, object_to_world=None)
    assert np.abs(world_faces - moved).max() > 0.2


@pytest.mark.parametrize("blend", ["whiteout", "udn", "rnm"])
@pytest.mark.parametrize("use_biplanar", [False, True])
def test_normal_mapping_matches_numpy_reference(blend, use_biplanar):
    g, gn = _synthetic()
    images, texs = _six("normal")
    kw = dict(tiling=1.7, strength=0.8, sharpness=8.0 if use_biplanar else 4.0)
    out = normal_mapping(use_biplanar)(g, textures_per_face=texs, blend=blend, **kw).numpy()
    kw["biplanar"] = use_biplanar
    expected = rt.triplanar_normal(gn, images, blend_kind=blend, **kw)
    assert np.abs(out - expected).max() <= ATOL
    plus_only = rt.triplanar_normal(gn, [images[f] for f in (0, 2, 4)], blend_kind=blend, **kw)
    assert np.abs(plus_only - expected).max() > 0.05


def test_faces_fall_back_to_the_axis_then_to_the_texture():
    """``None`` faces read ``textures_per_axis[a]``, then ``texture``; the reference gets the six
    resolved images."""
    g, gn = _synthetic()
    images, texs = _six()
    extra_img = _image(77, 10, 30)
    extra = wt.Texture(extra_img)
    per_face = [texs[0], None, None, texs[3], None, texs[5]]
    per_axis = [None, texs[2], extra]
    out = triplanar(g, texs[1], textures_per_axis=per_axis, textures_per_face=per_face, tiling=1.4).numpy()
    resolved = [images[0], images[1], images[2], images[3], extra_img, images[5]]
    np.testing.assert_allclose(out, rt.triplanar(gn, resolved, tiling=1.4), atol=ATOL)


# -- the default and one-texture cases are the three-texture kernels, bit for bit ---------------------------


def _techniques():
    """Each technique as ``run(g, texture_or_None, **kw)``."""
    return {
        "triplanar": lambda g, t, **kw: triplanar(g, t, **kw, tiling=1.3),
        "biplanar": lambda g, t, **kw: biplanar(g, t, **kw, tiling=1.3),
        "triplanar hash4": lambda g, t, **kw: triplanar(g, t, **kw, tiling=1.3, stochastic="hash4"),
        "normal whiteout": lambda g, t, **kw: triplanar_normal(g, t, **kw, tiling=1.3),
        "normal rnm biplanar": lambda g, t, **kw: wt.biplanar_normal(g, t, **kw, tiling=1.3, blend="rnm", sharpness=4.0),
    }


@pytest.mark.parametrize("technique", list(_techniques()))
def test_default_and_identical_faces_are_bit_identical(technique):
    g, _ = _two_views(48)
    run = _techniques()[technique]
    images, texs = _six("normal")
    a, b, c = texs[0], texs[2], texs[4]
    one = run(g, a).numpy()
    assert np.abs(one).max() > 0.1
    np.testing.assert_array_equal(run(g, a, textures_per_face=[None] * 6).numpy(), one)
    np.testing.assert_array_equal(run(g, None, textures_per_face=[a] * 6).numpy(), one)
    per_axis = run(g, None, textures_per_axis=[a, b, c]).numpy()
    assert np.abs(per_axis - one).max() > 0.1
    np.testing.assert_array_equal(run(g, None, textures_per_face=[a, a, b, b, c, c]).numpy(), per_axis)
    np.testing.assert_array_equal(run(g, None, textures_per_axis=[a, b, c], textures_per_face=(None,) * 6).numpy(), per_axis)
    # And on a tape (the texel-gradient or two-step path), the same output and texel gradients.
    grads = []
    for as_faces in (False, True):
        tex = wt.Texture(images[0], requires_grad=True)
        tape = wp.Tape()
        with tape:
            out = run(g, None, textures_per_face=[tex] * 6) if as_faces else run(g, tex)
        np.testing.assert_array_equal(out.numpy(), one)
        out.grad.fill_(1.0)
        tape.backward()
        grads.append(np.concatenate([tex.grad(k).reshape(-1) for k in range(tex.num_levels)]))
    assert np.abs(grads[0]).max() > 0
    np.testing.assert_array_equal(grads[1], grads[0])


# -- texel gradients of all six textures -------------------------------------------------------------------


def _forward(technique, g, textures, tiling):
    kw = {"textures_per_face": textures, "tiling": tiling}
    if technique == "triplanar":
        return triplanar(g, **kw)
    if technique == "biplanar":
        return biplanar(g, **kw)
    if technique == "triplanar hash4":
        return triplanar(g, **kw, stochastic=wt.Stochastic("hash4", mirror=True))
    if technique == "normal whiteout":
        return triplanar_normal(g, **kw, strength=0.8)
    if technique == "normal rnm biplanar":
        return wt.biplanar_normal(g, **kw, strength=0.8, blend="rnm", sharpness=4.0)
    raise ValueError(technique)


GRADIENT_CASES = ["triplanar", "biplanar", "triplanar hash4", "normal whiteout", "normal rnm biplanar"]


@pytest.mark.parametrize("technique", GRADIENT_CASES)
def test_texel_gradients_of_every_face_match_finite_differences(technique):
    """d loss / d level-0 texels of each face's texture (through the mip chain built on the tape),
    along random directions, one texture at a time."""
    g, _ = _two_views(48)
    images, _ = _six("normal" if technique.startswith("normal") else "colour")
    rng = np.random.default_rng(4)
    r = rng.normal(size=(*g.resolution, 3))

    def loss(imgs):
        return float((_forward(technique, g, [wt.Texture(im) for im in imgs], 1.3).numpy().astype(np.float64) * r).sum())

    textures = [wt.Texture(im, requires_grad=True) for im in images]
    tape = wp.Tape()
    with tape:
        for t in textures:
            t.update()
        out = _forward(technique, g, textures, 1.3)
    out.grad.assign(r.astype(np.float32))
    tape.backward()
    step = 2e-3 if technique.startswith("normal") else 0.05  # colour is linear in the texels
    for f, t in enumerate(textures):
        grad = t.grad(0).astype(np.float64)
        assert np.abs(grad).sum() > 1.0, f"the {FACES[f]} face's texture receives gradients"
        d = rng.normal(size=images[f].shape).astype(np.float32)
        plus = [im + step * d if k == f else im for k, im in enumerate(images)]
        minus = [im - step * d if k == f else im for k, im in enumerate(images)]
        fd = (loss(plus) - loss(minus)) / (2 * step)
        np.testing.assert_allclose((grad * d).sum(), fd, rtol=1e-3, atol=2e-3, err_msg=f"{technique}: the {FACES[f]} face")


@pytest.mark.parametrize(("technique", "threads"), [("triplanar", 1), ("triplanar", 2), ("biplanar", 1), ("triplanar hash4", 1), ("normal whiteout", 1), ("normal rnm biplanar", 2), ("triplanar hash4", 3)])  # 3: private copies track tiles
def test_hand_written_texel_gradients_of_every_face_equal_the_generated_adjoint(monkeypatch, technique, threads):
    """Every level of every face's texture: the hand-written texel gradient (only texels need
    gradients), the generated adjoint forced on the same inputs, and the texel gradients when the
    tiling needs its gradient too (plain sampling's hand-written gradient takes it, colour's and
    normal mapping's stored samples'; stochastic sampling, the generated adjoint). 128 × 256 pixels, split over two threads
    where asked; 192 × 384 over three (whose private copies track tiles)."""
    g, _ = _two_views(192 if threads == 3 else 128)
    images, _ = _six("normal" if technique.startswith("normal") else "colour")
    weights = np.random.default_rng(12).normal(size=(*g.resolution, 3)).astype(np.float32)

    def forward(tiling_grad):
        textures = [wt.Texture(im, requires_grad=True) for im in images]
        return _forward(technique, g, textures, wp.array([1.3], dtype=float, requires_grad=tiling_grad)), textures

    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, threads, forward, weights)
    assert scatters == (1 if "hash4" in technique else 2)
    assert len(hand) == 6 and all(np.abs(grad).max() > 0 for _, grad in hand), "every face's texture has gradients"
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


# -- splat layers per face -------------------------------------------------------------------------------

LAYERS_PER_FACE = [None, (1, 2, 3, None, 0, 1), (None,) * 6, [3, 3, 0, 0, None, 2]]
RESOLVED = np.array([[0] * 6, [1, 2, 3, 1, 0, 1], [2] * 6, [3, 3, 0, 0, 3, 2]])


@pytest.mark.parametrize("height", [None, "channel", "array"])
@pytest.mark.parametrize("view", ["synthetic", "sphere"])
def test_splat_layers_per_face_match_numpy_reference(view, height):
    g, gn = _synthetic() if view == "synthetic" else _two_views(48)
    mask = gn["mask"] > 0
    flat = {k: gn[k][mask].astype(np.float64) for k in ("position", "normal", "position_dx", "position_dy")}
    flat.update({k: gn[f"uv0.{k}"][mask].astype(np.float64) for k in ("uv", "uv_dx", "uv_dy")})
    rng = np.random.default_rng(5)
    layers = rng.random((4, 24, 20, 4)).astype(np.float32)
    maps = rng.random((1, 9, 7, 4)).astype(np.float32)
    tiling = np.array([0.7, 1.3, 0.9, 1.1])
    kw, ref_kw = {}, {}
    if height is not None:
        kw["height_blend"] = ref_kw["transition"] = 0.15
    if height == "array":
        heights = rng.random((4, 16, 16, 1)).astype(np.float32)
        kw["heights"], ref_kw["heights"] = wt.TextureArray(heights), heights
    out = splat(g, wt.TextureArray(layers), wt.TextureArray(maps), tiling=tiling, projection="triplanar", layers_per_face=LAYERS_PER_FACE, **kw).numpy()
    expected = splat_reference(flat, layers, maps, tiling=tiling, projection="triplanar", layers_per_face=RESOLVED, **ref_kw)
    np.testing.assert_allclose(out[mask], expected, atol=ATOL)
    np.testing.assert_array_equal(out[~mask], 0.0)
    plain = splat_reference(flat, layers, maps, tiling=tiling, projection="triplanar", **ref_kw)
    assert np.abs(plain - expected).max() > 0.1, "the face layers change the result"


def test_splat_default_layers_per_face_are_bit_identical():
    g, _ = _two_views(48)
    rng = np.random.default_rng(6)
    layers = wt.TextureArray(rng.random((4, 16, 16, 4)).astype(np.float32))
    maps = wt.TextureArray(rng.random((1, 9, 7, 4)).astype(np.float32))
    kw = dict(tiling=0.8, projection="triplanar", height_blend=0.2)
    base = splat(g, layers, maps, **kw).numpy()
    for layers_per_face in ([None] * 4, [[j] * 6 for j in range(4)], np.repeat(np.arange(4), 6).reshape(4, 6)):
        np.testing.assert_array_equal(splat(g, layers, maps, layers_per_face=layers_per_face, **kw).numpy(), base)


SPLAT_BACKWARD_CASES = {
    "height channel": dict(height_blend=0.15),
    "height array, mirror": dict(height_blend=0.15, heights=True, sampler=wt.Sampler(address="mirror")),
    "hex, height array": dict(height_blend=0.15, heights=True, stochastic=wt.Stochastic("hex", rotation=0.5)),
    "plain blend, histogram": dict(histogram=True),
}


@pytest.mark.parametrize("case", list(SPLAT_BACKWARD_CASES))
def test_splat_face_layer_gradients_equal_the_generated_adjoint(monkeypatch, case):
    """The texels of the layers read per face (and the maps, heights, transition, tiling): the
    hand-written gradient against the generated adjoint (a sharpness gradient forces it)."""
    c = dict(SPLAT_BACKWARD_CASES[case])
    g, _ = _two_views(64)
    rng = np.random.default_rng(13)
    layer_data = rng.random((4, 24, 20, 4)).astype(np.float32)
    map_data = rng.random((1, 9, 7, 4)).astype(np.float32) - 0.1
    height_data = rng.random((4, 16, 16, 1)).astype(np.float32)
    heights, histogram = c.pop("heights", False), c.pop("histogram", False)
    plain = "stochastic" not in c and not histogram

    def forward(other_grads):
        layers, maps, kw, textures = splat_inputs(layer_data, map_data, [0.7, 1.3, 0.9, 1.1], other_grads, plain=plain, height_data=height_data if heights else None, histogram=histogram)
        return splat(g, layers, maps, projection="triplanar", layers_per_face=LAYERS_PER_FACE, **c, **kw), textures

    weights = rng.normal(size=(*g.resolution, 4)).astype(np.float32)
    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, 1, forward, weights)
    assert scatters == (0 if histogram else 1)
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


def test_splat_face_layer_texel_gradients_match_finite_differences():
    """Layer 0 reads only other layers (1 on the X faces, 2 on the Y faces, 3 on the Z faces):
    weighted by layer 0's splat map alone, every layer's texels get gradients, layer 0's none."""
    g, _ = _two_views(48)
    rng = np.random.default_rng(8)
    layers = rng.random((4, 12, 10, 4)).astype(np.float32)
    maps = np.zeros((1, 5, 5, 4), np.float32)
    maps[..., 0] = 1.0
    layers_per_face = [(1, 1, 2, 2, 3, 3), None, None, None]
    r = rng.normal(size=(*g.resolution, 4))

    def loss(data):
        return float((splat(g, wt.TextureArray(data), maps, tiling=1.2, projection="triplanar", layers_per_face=layers_per_face).numpy().astype(np.float64) * r).sum())

    lt = wt.TextureArray(layers, requires_grad=True)
    tape = wp.Tape()
    with tape:
        lt.update()
        out = splat(g, lt, maps, tiling=1.2, projection="triplanar", layers_per_face=layers_per_face)
    out.grad.assign(r.astype(np.float32))
    tape.backward()
    grad = lt.grad(0).astype(np.float64)
    assert np.abs(grad[0]).max() == 0.0, "layer 0 itself is read on no face"
    assert all(np.abs(grad[j]).sum() > 1.0 for j in (1, 2, 3))
    step = 0.05  # linear in the texels
    for _ in range(3):
        d = rng.normal(size=layers.shape).astype(np.float32)
        fd = (loss(layers + step * d) - loss(layers - step * d)) / (2 * step)
        np.testing.assert_allclose((grad * d).sum(), fd, rtol=1e-3, atol=2e-3)
    # And what it renders is the six-face triplanar mapping of layers 1, 1, 2, 2, 3, 3.
    faces = [wt.Texture(layers[j]) for j in (1, 1, 2, 2, 3, 3)]
    np.testing.assert_allclose(out.numpy(), triplanar(g, textures_per_face=faces, tiling=1.2).numpy(), atol=1e-6)


# -- must-show: a sphere with six faces ----------------------------------------------------------------------

FACE_COLOURS = np.array(
    [
        [0.85, 0.10, 0.08],  # +x red
        [0.05, 0.70, 0.75],  # -x cyan
        [0.20, 0.65, 0.15],  # +y grass
        [0.40, 0.27, 0.17],  # -y rock
        [0.10, 0.20, 0.85],  # +z blue
        [0.90, 0.80, 0.10],  # -z yellow
    ],
    np.float32,
)


def _neighbour_pairs(gn):
    """``(colour index pairs, normal pairs)`` of covered horizontal and vertical neighbours in each half."""
    mask = gn["mask"] > 0
    n = gn["normal"]
    h, w = mask.shape
    half = w // 2
    pairs = []
    for di, dj in ((0, 1), (1, 0)):
        i, j = np.nonzero(mask[: h - di, : w - dj] & mask[di:, dj:])
        same_half = (j // half) == ((j + dj) // half)
        pairs.append(np.stack([i[same_half], j[same_half], i[same_half] + di, j[same_half] + dj], 1))
    pairs = np.concatenate(pairs)
    return pairs, n[pairs[:, 0], pairs[:, 1]], n[pairs[:, 2], pairs[:, 3]]


def _seam_jumps(out, pairs, n1, n2):
    """Per neighbour pair: the colour jump, and which of the X, Y, Z seams (``n[a] = 0``) it crosses."""
    jump = np.abs(out[pairs[:, 0], pairs[:, 1]] - out[pairs[:, 2], pairs[:, 3]]).max(-1)
    crosses = (n1 < 0) != (n2 < 0)  # [P, 3]: the sign of n[a] changes (sign(0) = +1)
    return jump, crosses


def _shaded(gn, colour):
    """A Lambert preview (for the PNG only): a key light from the upper left of each view."""
    n = gn["normal"]
    half = n.shape[1] // 2
    light = np.where(np.arange(n.shape[1])[None, :, None] < half, np.array([0.2, 0.9, 0.6]), np.array([-0.6, -0.9, -0.2]))
    light = light / np.linalg.norm(light, axis=-1, keepdims=True)
    lit = 0.45 + 0.55 * np.clip((n * light).sum(-1, keepdims=True), 0, 1)
    background = np.full(3, 0.02)
    return np.where(gn["mask"][..., None] > 0, colour * lit, background)


def test_sphere_shows_six_faces_with_a_continuous_equator(tmp_path):
    """Six constant colours at sharpness 24 on a sphere seen from both sides. Where one ±axis
    dominates, the pixel shows that face's colour; across the three seams (``n[a] = 0``, where
    the ``+a`` and ``-a`` faces meet) the colour is continuous: the jump between neighbours there
    is no larger than across the other seams, and what the face switch itself adds to it (the
    jump against the same render with ``-a`` reading the ``+a`` face's colour) is below 1e-3 —
    while at sharpness 0, where every projection keeps weight 1/3 at its seam, it is a third of
    the colour difference, which is what the measure would see of a real seam."""
    g, gn = _two_views(160)
    textures = [wt.Texture(np.broadcast_to(c, (4, 4, 3)).copy()) for c in FACE_COLOURS]
    out = triplanar(g, textures_per_face=textures, sharpness=24.0).numpy()
    mask = gn["mask"] > 0
    n = gn["normal"]

    wt.io.write_png(tmp_path / "sixplanar_sphere.png", _shaded(gn, out))  # to look at: never into the repository's out/

    # Each face's region shows its colour.
    face = _face_of(n)
    dominant = mask & (np.abs(n).max(-1) > 0.8)
    for f in range(6):
        region = dominant & (face == f)
        assert region.sum() > 200, f"the {FACES[f]} face is in view"
        np.testing.assert_allclose(out[region], np.broadcast_to(FACE_COLOURS[f], (region.sum(), 3)), atol=1e-3, err_msg=FACES[f])

    pairs, n1, n2 = _neighbour_pairs(gn)
    jump, crosses = _seam_jumps(out, pairs, n1, n2)
    assert all(crosses[:, a].sum() > 100 for a in range(3))
    # Where a seam meets a diagonal (|n.x| = |n.z| on the equator) the blend of two projections
    # changes colour steeply at sharpness 24, with or without faces; away from those (both pixels'
    # second-largest |n| below 0.7 of the largest, weights below 0.7^24 = 2e-4), a seam's jump is
    # the face switch alone: the equator's is comparable to the X and Z seams', and all are no larger
    # than the jumps away from every seam (float rounding, ~1e-4).
    a = np.sort(np.abs(np.stack([n1, n2])), axis=-1)
    clear = (a[..., 1] < 0.7 * a[..., 2]).all(axis=0)
    seam_max = [jump[crosses[:, k] & clear].max() for k in range(3)]
    assert all((crosses[:, k] & clear).sum() > 50 for k in range(3))
    assert seam_max[1] <= 1.5 * max(seam_max[0], seam_max[2]), f"equator jump {seam_max[1]:.3g} vs X/Z seams {seam_max[0]:.3g}, {seam_max[2]:.3g}"
    elsewhere = jump[~crosses.any(axis=1) & clear].max()
    print(f"max neighbour jump across the X, Y, Z seams {seam_max}, elsewhere {elsewhere:.3g}")
    assert max(seam_max) <= elsewhere + 1e-6 and max(seam_max) < 1e-3, f"jumps across the X, Y, Z seams {seam_max} vs {elsewhere:.3g} away from every seam"

    def face_switch(sharpness, rendered):
        """Per seam, the most the face switch adds to a neighbour jump across it."""
        added = []
        for a in range(3):
            same = list(textures)
            same[2 * a + 1] = textures[2 * a]  # -a reads the +a face's colour: no switch at this seam
            base_jump = _seam_jumps(triplanar(g, textures_per_face=same, sharpness=sharpness).numpy(), pairs, n1, n2)[0]
            added.append(np.abs(_seam_jumps(rendered, pairs, n1, n2)[0] - base_jump)[crosses[:, a]].max())
        return added

    switch = face_switch(24.0, out)
    assert max(switch) < 1e-3, f"what the face switch adds at the X, Y, Z seams: {switch}"
    flat = triplanar(g, textures_per_face=textures, sharpness=0.0).numpy()
    switch_flat = face_switch(0.0, flat)
    differences = [np.abs(FACE_COLOURS[2 * a] - FACE_COLOURS[2 * a + 1]).max() / 3 for a in range(3)]
    np.testing.assert_allclose(switch_flat, differences, rtol=1e-3, err_msg="the measure sees a real seam")


# -- bad input ---------------------------------------------------------------------------------------------


class _Elsewhere(wt.Texture):
    """A texture that says it lives on another device (this machine may have no GPU)."""

    @property
    def device(self):
        return "cuda:7"


def test_bad_input_raises_with_a_clear_message():
    g = wt.GBuffer.from_arrays(np.zeros((1, 2, 3)), np.array([[[0, 0, 1], [0, -1, 0]]]))
    images, texs = _six()
    tex = texs[0]
    two_channel = wt.Texture(np.ones((4, 4, 2), np.float32))
    layered = wt.TextureArray(np.ones((2, 4, 4, 3), np.float32))
    six = list(texs)
    cases = [
        (ValueError, r"triplanar\(\): textures_per_face must be a sequence of 6 textures \(\+X, -X, \+Y, -Y, \+Z, -Z faces\) or None, got", lambda: triplanar(g, tex, textures_per_face=six[:3])),
        (ValueError, r"biplanar\(\): textures_per_face must be a sequence of 6", lambda: biplanar(g, tex, textures_per_face="abcdef")),
        (ValueError, r"triplanar_normal\(\): textures_per_face must be a sequence of 6", lambda: triplanar_normal(g, tex, textures_per_face=tex)),
        (TypeError, r"triplanar\(\): the -Y face's texture must be a Texture or TextureArray, got ndarray", lambda: triplanar(g, tex, textures_per_face=[None, None, None, images[3], None, None])),
        (ValueError, r"triplanar\(\): all projections need the same channel count; X has 3, -Z has 2", lambda: triplanar(g, tex, textures_per_face=[None] * 5 + [two_channel])),
        (ValueError, r"biplanar\(\): all projections need the same channel count; \+X has 2, X has 3", lambda: biplanar(g, tex, textures_per_face=[two_channel] + [None] * 5)),
        (ValueError, r"triplanar\(\): the \+Z face's texture is on cuda:7 but the G-buffer on cpu", lambda: triplanar(g, tex, textures_per_face=[None] * 4 + [_Elsewhere(images[4]), None])),
        (ValueError, r"triplanar\(\): no texture for the -Y face: pass texture=, textures_per_axis or all six textures_per_face", lambda: triplanar(g, textures_per_face=six[:3] + [None] + six[4:])),
        (ValueError, r"triplanar\(\): layer must be an int in \[0, 0\] for the -X face's texture, got 1", lambda: triplanar(g, layered, layer=1, textures_per_face=[None, tex, None, None, None, None])),
        (
            ValueError,
            r"triplanar\(\): a stochastic histogram needs one texture for every projection \(textures_per_axis or textures_per_face differ\)",
            lambda: triplanar(g, tex, textures_per_face=[None, None, None, texs[3], None, None], stochastic=wt.Stochastic("hex", histogram=wt.prepare_histogram(tex))),
        ),
        (ValueError, r"triplanar_normal\(\): a normal map needs 2 to 4 channels, got 1", lambda: triplanar_normal(g, textures_per_face=[wt.Texture(np.ones((4, 4, 1), np.float32))] * 6)),
    ]
    for exc, match, call in cases:
        with pytest.raises(exc, match=match):
            call()


def test_splat_bad_layers_per_face_raise_with_a_clear_message():
    g, _ = _two_views(48)
    rng = np.random.default_rng(3)
    layers = wt.TextureArray(rng.random((4, 8, 8, 4)).astype(np.float32))
    maps = rng.random((1, 5, 5, 4)).astype(np.float32)
    tri = dict(projection="triplanar")
    cases = [
        (ValueError, r"splat\(\): layers_per_face needs projection='triplanar'", lambda: splat(g, layers, maps, layers_per_face=[None] * 4)),
        (ValueError, r"splat\(\): layers_per_face needs projection='triplanar'", lambda: splat(g, layers, maps, projection="world_xz", layers_per_face=[None] * 4)),
        (ValueError, r"splat\(\): layers_per_face must be a sequence of 4 entries \(one per layer\), each None or 6 layer indices", lambda: splat(g, layers, maps, **tri, layers_per_face=[None] * 3)),
        (ValueError, r"splat\(\): layers_per_face must be a sequence of 4 entries", lambda: splat(g, layers, maps, **tri, layers_per_face=(0, 1, 2, 3, 0, 1))),
        (ValueError, r"splat\(\): layers_per_face\[1\] must be None or 6 layer indices \(\+x, -x, \+y, -y, \+z, -z\), got \(0, 1\)", lambda: splat(g, layers, maps, **tri, layers_per_face=[None, (0, 1), None, None])),
        (ValueError, r"splat\(\): layers_per_face\[2\]\[3\] \(the -y face\) must be a layer in \[0, 3\], got 4", lambda: splat(g, layers, maps, **tri, layers_per_face=[None, None, (0, 0, 0, 4, 0, 0), None])),
        (ValueError, r"splat\(\): layers_per_face\[0\]\[0\] \(the \+x face\) must be a layer in \[0, 3\], got -1", lambda: splat(g, layers, maps, **tri, layers_per_face=[(-1, 0, 0, 0, 0, 0), None, None, None])),
        (TypeError, r"splat\(\): layers_per_face\[3\]\[5\] \(the -z face\) must be a layer index or None, got 1.0", lambda: splat(g, layers, maps, **tri, layers_per_face=[None, None, None, (0, 0, 0, 0, 0, 1.0)])),
        (TypeError, r"splat\(\): layers_per_face\[0\]\[2\] \(the \+y face\) must be a layer index or None, got True", lambda: splat(g, layers, maps, **tri, layers_per_face=[(0, 0, True, 0, 0, 0), None, None, None])),
        (ValueError, r"splat\(\): layers_per_face as an array must have shape \(4, 6\), got \(4, 3\)", lambda: splat(g, layers, maps, **tri, layers_per_face=np.zeros((4, 3), int))),
    ]
    for exc, match, call in cases:
        with pytest.raises(exc, match=match):
            call()
