"""Backward passes of triplanar, biplanar and triplanar normal mapping against finite differences.

The loss is ``L = Σ r · out`` over a 64×64 orthographic sphere G-buffer with random weights ``r``,
accumulated in float64 from the float32 outputs. Texel gradients are checked along random
directions (the colour techniques are linear in the texels, so central differences are exact up to
rounding); the parameters shared by every pixel (tiling, sharpness, offsets) with
:func:`fd.check_parameter_gradient`, which leaves out the pixels whose step crosses a slope jump.
"""

import dataclasses
import functools

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import _op
from warptex.kernels import triplanar as kt
from backward_paths import assert_same_gradients, launches, texel_gradients_both_ways
from conftest import normal_mapping
from fd import check_parameter_gradient
from warptex.triplanar import biplanar, triplanar, triplanar_normal

TECHNIQUES = {
    "triplanar": lambda g, t, **kw: triplanar(g, t, **kw),
    "biplanar": lambda g, t, **kw: biplanar(g, t, **kw),
    "normal_whiteout": lambda g, t, **kw: triplanar_normal(g, t, blend="whiteout", **kw),
    "normal_rnm": lambda g, t, **kw: triplanar_normal(g, t, blend="rnm", **kw),
    "normal_udn_biplanar": lambda g, t, **kw: wt.biplanar_normal(g, t, blend="udn", **{"sharpness": 4.0, **kw}),
}


@pytest.fixture(scope="module")
def sphere():
    """An orthographic view of the unit sphere, seen obliquely so that every axis has weight."""
    camera = wt.orthographic((3.0, 2.0, 4.0), (0.0, 0.0, 0.0), height=2.2, resolution=(64, 64))
    return wt.rasterize(trimesh.creation.icosphere(subdivisions=4), camera)


def smooth_texture(h: int, w: int, seed: int) -> np.ndarray:
    """A smooth periodic RGB image in ``[0.2, 0.8]``: a few low-frequency Fourier modes."""
    rng = np.random.default_rng(seed)
    y, x = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    img = np.full((h, w, 3), 0.5)
    for _ in range(4):
        fx, fy = rng.integers(-2, 3, size=2)
        img += 0.07 * np.sin(2 * np.pi * (fx * x + fy * y)[..., None] + rng.uniform(0, 2 * np.pi, 3))
    return img.astype(np.float32)


def normal_map_texture(h: int, w: int, seed: int) -> np.ndarray:
    """A smooth, valid tangent-space normal map: slopes within ±0.3, ``z`` (blue) near 1."""
    img = smooth_texture(h, w, seed)
    img[..., 2] = 0.9 + 0.25 * (img[..., 2] - 0.5)
    return img


def _texture_for(technique: str, h: int, w: int, seed: int) -> np.ndarray:
    return normal_map_texture(h, w, seed) if technique.startswith("normal") else smooth_texture(h, w, seed)


def _weights(g, channels: int, seed: int = 7) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(*g.resolution, channels)).astype(np.float32)


def _loss(g, technique, img, r, **params) -> float:
    out = TECHNIQUES[technique](g, wt.Texture(img), **params).numpy()
    return float((out.astype(np.float64) * r).sum())


def _gradients(g, technique, img, r, **params):
    """Analytic gradients of the loss: ``(texel_grad, {param: grad})`` for the array parameters."""
    tex = wt.Texture(img, requires_grad=True)
    arrays = {k: wp.array(np.asarray(v, np.float32), dtype=float, requires_grad=True) for k, v in params.items()}
    tape = wp.Tape()
    with tape:
        tex.update()
        out = TECHNIQUES[technique](g, tex, **arrays)
    out.grad.assign(r.reshape(out.shape))
    tape.backward()
    return tex.grad(0), {k: a.grad.numpy().astype(np.float64) for k, a in arrays.items()}


PARAMS = {"tiling": np.array([1.3, 0.9, 1.7]), "sharpness": np.array([3.0]), "offsets": np.array([[0.1, 0.33], [0.25, -0.4], [0.67, 0.05]])}


@pytest.mark.parametrize("technique", list(TECHNIQUES))
def test_parameter_gradients_match_finite_differences(sphere, technique):
    """d loss / d (tiling, sharpness, offsets), every component, against central differences."""
    img = _texture_for(technique, 32, 24, seed=1)
    r = _weights(sphere, 3)
    steps = {"tiling": 1e-3, "sharpness": 1e-2, "offsets": 1e-3}
    for name, value in PARAMS.items():
        _, grads = _gradients(sphere, technique, img, r, **PARAMS)
        assert np.abs(grads[name]).max() > 0, f"{name}: zero gradient"
        check_parameter_gradient(
            lambda v: TECHNIQUES[technique](sphere, wt.Texture(img), **{**PARAMS, name: v}).numpy(),
            lambda v, kept: _gradients(sphere, technique, img, kept, **{**PARAMS, name: v})[1][name],
            value,
            r,
            steps[name],
            rtol=2e-2,
            atol=2e-2,
            label=f"{technique}: {name}",
        )


@pytest.mark.parametrize("technique", list(TECHNIQUES))
def test_texel_gradients_match_finite_differences(sphere, technique):
    """Gradients to level-0 texels (through the mip chain built on the tape), along random directions."""
    rng = np.random.default_rng(3)
    img = _texture_for(technique, 16, 20, seed=2)
    r = _weights(sphere, 3)
    grad, _ = _gradients(sphere, technique, img, r, **PARAMS)
    assert np.abs(grad).sum() > 0
    step = 0.05 if technique in ("triplanar", "biplanar") else 2e-3  # colour is linear in the texels
    for _ in range(3):
        direction = rng.normal(size=img.shape).astype(np.float32)
        fp = _loss(sphere, technique, img + step * direction, r, **PARAMS)
        fm = _loss(sphere, technique, img - step * direction, r, **PARAMS)
        fd = (fp - fm) / (2 * step)
        np.testing.assert_allclose((grad.astype(np.float64) * direction).sum(), fd, rtol=1e-3, atol=2e-3)


@pytest.mark.parametrize(("technique", "sharpness"), [("triplanar", 3.0), ("triplanar", 2.5), ("biplanar", 8.0), ("normal_whiteout", 4.0)])
def test_surface_normal_gradients_match_finite_differences(sphere, technique, sharpness):
    """d loss / d (G-buffer normal) along random directions, through the blend weights (integer
    sharpness takes the multiplication path of ``power_weight``, with its hand-written adjoint).
    Pixels where the weights have a corner are left out: a normal component near 0 (the mirror fix
    flips) or near biplanar's edge 1/sqrt(3) (its remap clamps)."""
    rng = np.random.default_rng(5)
    img = _texture_for(technique, 32, 24, seed=6)
    r = _weights(sphere, 3)
    normals = sphere.normal.numpy()
    a = np.abs(normals) / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    smooth = ((a > 0.05) & (np.abs(a - 0.5773) > 0.01)).all(-1, keepdims=True)

    def loss(n):
        g = dataclasses.replace(sphere, normal=wp.array(n, dtype=wp.vec3))
        return float((TECHNIQUES[technique](g, wt.Texture(img), sharpness=sharpness).numpy().astype(np.float64) * r).sum())

    normal = wp.array(normals, dtype=wp.vec3, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = TECHNIQUES[technique](dataclasses.replace(sphere, normal=normal), wt.Texture(img), sharpness=sharpness)
    out.grad.assign(r.reshape(out.shape))
    tape.backward()
    grad = normal.grad.numpy().astype(np.float64)
    assert np.abs(grad).max() > 0
    step = 1e-3
    for _ in range(2):
        direction = (rng.normal(size=normals.shape) * smooth).astype(np.float32)
        fd = (loss(normals + step * direction) - loss(normals - step * direction)) / (2 * step)
        np.testing.assert_allclose((grad * direction).sum(), fd, rtol=1e-2, atol=1e-2)


def test_sharpness_gradient_at_zero_is_the_one_sided_slope(sphere):
    """At sharpness 0 every weight is ``r^0 = 1``, but the slope ``ln r`` is not 0: a sharpness
    fitted from 0 can move. Checked against a forward difference (sharpness cannot go below 0)."""
    img = smooth_texture(32, 24, seed=8)
    r = _weights(sphere, 3)
    _, grads = _gradients(sphere, "triplanar", img, r, sharpness=[0.0])
    step = 1e-3
    fd = (_loss(sphere, "triplanar", img, r, sharpness=step) - _loss(sphere, "triplanar", img, r, sharpness=0.0)) / step
    assert abs(fd) > 1e-2
    np.testing.assert_allclose(grads["sharpness"][0], fd, rtol=1e-2)


@pytest.mark.parametrize("technique", list(TECHNIQUES))
def test_every_kernel_variant_computes_the_same_forward(sphere, technique):
    """Without a tape (the forward-only plain-sampling kernels), on a tape where only texels need
    gradients (the same, or the two-step normal mapping) and where a parameter does too (the
    general kernels, with the generated adjoint): the same output, to the bit."""
    img = _texture_for(technique, 32, 24, seed=10)
    plain = TECHNIQUES[technique](sphere, wt.Texture(img), **PARAMS).numpy()
    for tiling_grad in (False, True):
        params = {**PARAMS, "tiling": wp.array(PARAMS["tiling"].astype(np.float32), dtype=float, requires_grad=tiling_grad)}
        with wp.Tape():
            out = TECHNIQUES[technique](sphere, wt.Texture(img, requires_grad=True), **params).numpy()
        np.testing.assert_array_equal(out, plain)


def test_scalar_tiling_gradient_is_the_sum_over_projections(sphere):
    """A tiling array of shape (1,) receives the sum of the three per-projection gradients."""
    img = smooth_texture(32, 24, seed=4)
    r = _weights(sphere, 3)
    _, per_axis = _gradients(sphere, "triplanar", img, r, tiling=[1.5, 1.5, 1.5])
    _, shared = _gradients(sphere, "triplanar", img, r, tiling=[1.5])
    np.testing.assert_allclose(shared["tiling"][0], per_axis["tiling"].sum(), rtol=1e-4, atol=1e-5)


def test_gradients_reach_each_per_axis_texture(sphere):
    """With textures_per_axis, each texture receives gradients only from its own projection."""
    img = smooth_texture(16, 16, seed=5)
    r = _weights(sphere, 3)
    textures = [wt.Texture(img, requires_grad=True) for _ in range(3)]
    tape = wp.Tape()
    with tape:
        out = triplanar(sphere, textures_per_axis=textures, tiling=1.2)
    out.grad.assign(r)
    tape.backward()
    single = wt.Texture(img, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = triplanar(sphere, single, tiling=1.2)
    out.grad.assign(r)
    tape.backward()
    grads = [t.grad(k) for t in textures for k in range(t.num_levels)]
    assert all(np.abs(t.grad(0)).sum() > 0 for t in textures)
    total = sum(g.sum() for g in grads)
    np.testing.assert_allclose(total, sum(single.grad(k).sum() for k in range(single.num_levels)), rtol=1e-4)


@pytest.mark.parametrize("technique", list(TECHNIQUES))
def test_hand_written_texel_gradients_match_finite_differences(sphere, technique):
    """With only the texels needing gradients (numbers for tiling, sharpness, offsets), the
    hand-written texel gradient runs in place of the generated adjoint of the sampling kernel
    (normal mapping: the gradient of the normal from stored samples, then the samples' texel
    gradient, both by hand): checked the same way."""
    rng = np.random.default_rng(8)
    img = _texture_for(technique, 16, 20, seed=6)
    r = _weights(sphere, 3)
    params = {"tiling": [1.3, 0.9, 1.7], "sharpness": 3.0, "offsets": PARAMS["offsets"]}
    tex = wt.Texture(img, requires_grad=True)
    tape = wp.Tape()
    with tape:
        tex.update()
        out = TECHNIQUES[technique](sphere, tex, **params)
    out.grad.assign(r)
    tape.backward()
    recorded = [launch[0].key for launch in tape.launches if isinstance(launch, (list, tuple))]  # a recorded launch is a list (or tuple) whose first item is its kernel
    sampling_adjoints = {kt.triplanar_kernels(normal=normal, stochastic=False, faces=False).adjoint.key for normal in (False, True)}
    assert not sampling_adjoints & set(recorded), "the sampling kernel's generated adjoint was recorded"
    grad = tex.grad(0).astype(np.float64)
    assert np.abs(grad).sum() > 0
    step = 2e-3 if technique.startswith("normal") else 0.05  # colour is linear in the texels
    for _ in range(3):
        direction = rng.normal(size=img.shape).astype(np.float32)
        fd = (_loss(sphere, technique, img + step * direction, r, **params) - _loss(sphere, technique, img - step * direction, r, **params)) / (2 * step)
        np.testing.assert_allclose((grad * direction).sum(), fd, rtol=1e-3, atol=2e-3)


CASES = [
    "triplanar",
    "biplanar nearest mirror",
    "per-axis textures, one fixed",
    "stochastic hash4 mirrored",
    "stochastic hex rotated",
    "stochastic hex histogram",
    "normal whiteout",
    "normal rnm, per-axis textures, one fixed",
    "normal udn biplanar nearest mirror",
    "normal hash4",
    "normal hex histogram",
]


@pytest.mark.parametrize("threads", [1, 2, 3])  # 3: private copies track tiles
@pytest.mark.parametrize("case", CASES)
def test_hand_written_texel_gradients_equal_the_generated_adjoint(monkeypatch, case, threads):
    """The hand-written texel gradient (only texels need gradients) against the generated adjoint
    (the G-buffer's normals need gradients too), over every level of every texture, on a 256² sphere
    (65 536 pixels: split over two threads). The histogram blend, not linear in the texels,
    always takes the generated adjoint."""
    camera = wt.orthographic((3.0, 2.0, 4.0), (0.0, 0.0, 0.0), height=2.2, resolution=(256, 256))
    g = wt.rasterize(trimesh.creation.icosphere(subdivisions=4), camera)
    rng = np.random.default_rng(9)
    normal = case.startswith("normal")
    images = [rng.random((37, 29, 3)).astype(np.float32) for _ in range(3)]
    if normal:  # tangent-space normals: slopes within ±0.3, z near 1
        images = [np.concatenate([0.2 + 0.6 * im[..., :2], 0.9 + 0.1 * im[..., 2:]], -1) for im in images]
    stochastic = {
        "stochastic hash4 mirrored": wt.Stochastic("hash4", mirror=True),
        "stochastic hex rotated": wt.Stochastic("hex", rotation=0.5, contrast=2.0),
        "normal hash4": wt.Stochastic("hash4"),
    }

    def forward(normal_grad):
        if "per-axis" in case:
            textures = [wt.Texture(images[0], requires_grad=True), wt.Texture(images[1]), wt.Texture(images[2], requires_grad=True)]
            kw = {"textures_per_axis": textures}
        else:
            textures = [wt.Texture(images[0], requires_grad=True)]
            kw = {"texture": textures[0], **({"sampler": wt.Sampler(filter="nearest", address="mirror")} if "nearest" in case else {})}
        if case in stochastic:
            kw["stochastic"] = stochastic[case]
        elif case.endswith("hex histogram"):
            histogram = wt.prepare_histogram(textures[0], requires_grad=True)
            kw["stochastic"] = wt.Stochastic("hex", histogram=histogram)
            textures = [histogram.texture]
        if normal:
            kw["normal_map"] = kw.pop("texture", None)
            blend = next((b for b in ("rnm", "udn") if b in case), "whiteout")
            technique = functools.partial(normal_mapping("biplanar" in case), blend=blend, strength=0.8)
        else:
            technique = biplanar if case.startswith("biplanar") else triplanar
        gbuffer = dataclasses.replace(g, normal=wp.array(g.normal.numpy(), dtype=wp.vec3, requires_grad=True)) if normal_grad else g
        return technique(gbuffer, tiling=2.5, sharpness=4.0, **kw), textures

    weights = rng.normal(size=(256, 256, 3)).astype(np.float32)
    hand, forced, generated, scatters = texel_gradients_both_ways(monkeypatch, threads, forward, weights)
    assert scatters == (0 if case.endswith("histogram") else 1)
    assert_same_gradients(hand, forced)
    assert_same_gradients(hand, generated)


TILING_CASES = {  # a call's keywords beside the G-buffer, texture and tiling
    "triplanar": {},
    "biplanar": {"technique": "biplanar"},
    "triplanar anisotropic": {"sampler": wt.Sampler(filter="anisotropic")},
    "triplanar nearest mirror": {"sampler": wt.Sampler(filter="nearest", address="mirror")},
    "biplanar per face": {"technique": "biplanar", "faces": True},
    "triplanar per face, object space": {"faces": True, "space": "object"},
    "normal whiteout": {"technique": "normal", "blend": "whiteout"},
    "normal rnm biplanar anisotropic": {"technique": "biplanar_normal", "blend": "rnm", "sampler": wt.Sampler(filter="anisotropic")},
    "normal udn per face": {"technique": "normal", "blend": "udn", "faces": True},
}


@pytest.mark.parametrize("threads", [1, 3])  # 3: private copies of the tiling's gradient, summed in chunk order
@pytest.mark.parametrize("tiling", [[2.5], [1.3, 0.9, 1.7]])
@pytest.mark.parametrize("case", TILING_CASES)
def test_parameter_gradients_by_hand_equal_the_generated_adjoint(monkeypatch, case, tiling, threads):
    """Plain sampling with the tiling, offsets and sharpness needing their gradients (and the
    texels theirs): the hand-written gradient runs (on lanes with one texture per axis; one pixel
    per index with one per face; normal mapping's tiling and offsets in its first step, its stored
    samples, and its sharpness in its second, through the stored weights), and gives the generated
    adjoint's parameter and texel gradients, one tiling or one per axis."""
    camera = wt.orthographic((3.0, 2.0, 4.0), (0.0, 0.0, 0.0), height=2.2, resolution=(192, 192))
    g = wt.rasterize(trimesh.creation.icosphere(subdivisions=4), camera)
    kw = dict(TILING_CASES[case])
    name = kw.pop("technique", "triplanar")
    technique = {"triplanar": triplanar, "biplanar": biplanar, "normal": triplanar_normal, "biplanar_normal": wt.biplanar_normal}[name]
    normal = "normal" in name
    faces = kw.pop("faces", False)
    if kw.get("space") == "object":
        kw["object_to_world"] = np.diag([1.5, 0.8, 1.2, 1.0]).astype(np.float32)
    images = [(normal_map_texture if normal else smooth_texture)(37, 29, seed) for seed in range(6 if faces else 1)]
    weights = np.random.default_rng(4).normal(size=(192, 192, 3)).astype(np.float32)
    launched = launches(monkeypatch)
    wt.set_num_threads(threads)
    try:
        results = []
        for generated in (False, True):
            launched.clear()
            textures = [wt.Texture(im, requires_grad=True) for im in images]
            t = wp.array(np.float32(tiling), dtype=float, requires_grad=True)
            params = [t, wp.array(np.float32([[0.1, 0.33], [0.25, -0.4], [0.67, 0.05]]), dtype=float, requires_grad=True)]
            params.append(wp.array([6.0 if "biplanar" in name else 3.0], dtype=float, requires_grad=True))
            shared = {"offsets": params[1], "sharpness": params[2]}
            tape = wp.Tape()
            with tape, _op.force_generated_adjoint(generated):
                out = technique(g, **({"textures_per_face": textures} if faces else {"normal_map" if normal else "texture": textures[0]}), tiling=t, **shared, **kw)
            out.grad.assign(weights)
            tape.backward()
            results.append([p.grad.numpy().copy() for p in params] + [tex.grad(k) for tex in textures for k in range(tex.num_levels)])
            assert any(k.endswith("_adjoint") for k in launched) == generated, launched
    finally:
        wt.set_num_threads(None)
    hand, gen = results
    params = 3
    for k in range(params):  # the tiling and offsets move no nearest read; the sharpness moves the blend
        assert np.abs(gen[k]).max() > 0 or ("nearest" in case and k < 2)
        if "nearest" in case and k < 2:
            np.testing.assert_array_equal(hand[k], 0.0)
        np.testing.assert_allclose(hand[k], gen[k], rtol=1e-3, atol=1e-3 * max(np.abs(gen[k]).max(), 1e-6), err_msg=f"parameter {k}")
    assert_same_gradients([(False, h.reshape(-1)) for h in hand[params:]], [(False, x.reshape(-1)) for x in gen[params:]])


@pytest.mark.parametrize("space", ["world", "object"])
@pytest.mark.parametrize("technique", ["normal_whiteout", "normal_rnm", "normal_udn_biplanar"])
def test_normal_mapping_sharpness_alone_by_hand_equals_the_generated_adjoint(monkeypatch, technique, space):
    """Normal mapping with only the sharpness needing its gradient: the stored samples need none,
    so the first step records no backward, and the second step adds the sharpness' gradient through
    the stored weights, one pixel per index (its lanes decline: ``sharpness_lanes_take``); the
    generated adjoint's, to rounding."""
    img = _texture_for(technique, 32, 24, seed=2)
    g = wt.rasterize(trimesh.creation.icosphere(subdivisions=4), wt.orthographic((3.0, 2.0, 4.0), (0.0, 0.0, 0.0), height=2.2, resolution=(96, 96)))
    kw = {"space": "object", "object_to_world": np.diag([1.5, 0.8, 1.2, 1.0]).astype(np.float32)} if space == "object" else {}
    weights = np.random.default_rng(6).normal(size=(96, 96, 3)).astype(np.float32)
    launched = launches(monkeypatch)
    results = []
    for generated in (False, True):
        launched.clear()
        sharpness = wp.array([5.0 if "biplanar" in technique else 3.5], dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape, _op.force_generated_adjoint(generated):
            out = TECHNIQUES[technique](g, wt.Texture(img), tiling=1.7, sharpness=sharpness, **kw)
        out.grad.assign(weights)
        tape.backward()
        results.append(sharpness.grad.numpy().copy())
        assert any(k.endswith("_adjoint") for k in launched) == generated, launched
        assert generated or not any("samples_texel_grad" in k for k in launched), launched  # the first step recorded nothing
    assert np.abs(results[1]).max() > 0
    np.testing.assert_allclose(results[0], results[1], rtol=1e-3, atol=1e-3 * np.abs(results[1]).max())


@pytest.mark.parametrize("technique", ["triplanar", "biplanar", "normal_rnm", "normal_udn_biplanar"])
def test_tiling_gradient_by_hand_matches_finite_differences(sphere, technique):
    """The tiling alone needing its gradient (the hand-written path), per axis, against central
    differences (pixels whose step crosses a slope jump left out, :func:`fd.check_parameter_gradient`)."""
    img = _texture_for(technique, 32, 24, seed=1)
    r = _weights(sphere, 3)
    value = np.array([1.3, 0.9, 1.7])
    check_parameter_gradient(
        lambda v: TECHNIQUES[technique](sphere, wt.Texture(img), tiling=v.astype(np.float32)).numpy(),
        lambda v, kept: _gradients(sphere, technique, img, kept, tiling=v)[1]["tiling"],
        value,
        r,
        1e-3,
        rtol=2e-2,
        atol=2e-2,
        label=f"{technique}: tiling",
    )
