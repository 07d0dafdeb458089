"""warptex.torch, the PyTorch bridge: every technique's outputs and gradients equal the native
call's, gradients agree with finite differences, bilinear sampling equals ``grid_sample``, the ops
compile under ``torch.compile``, and bad input raises clearly."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import trimesh
import pytest
import warp as wp

torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")

import warptex as wt  # noqa: E402
import warptex.torch as wtt
from warptex._torch_spec import op_arguments  # noqa: E402
from warptex.gbuffer import FIELDS  # noqa: E402
from warptex.scenes import terrain_camera  # noqa: E402
from warptex.scenes.terrain import terrain  # noqa: E402
from warptex._torch_op import _states  # noqa: E402

from fd import check_parameter_gradient  # noqa: E402

TEXTURES = {"texture", "layers", "heights", "splat_maps"}


@pytest.fixture(scope="module")
def gbuffer():
    return wt.rasterize(terrain(resolution=(17, 17)), terrain_camera((20, 24)))


def _t(rng, *shape, low=0.0, high=1.0, grad=True):
    return torch.tensor(rng.uniform(low, high, shape).astype(np.float32), requires_grad=grad)


def _native(name: str, value):
    """A torch argument as the native functions take it, with gradients where the tensor has them."""
    if not isinstance(value, torch.Tensor):
        return value
    data = value.detach().numpy()
    grad = value.requires_grad
    if name in TEXTURES:
        if name == "splat_maps":
            return wt.TextureArray(data if data.ndim == 4 else data[None], mipmaps=False, requires_grad=grad)
        return wt.Texture(data, requires_grad=grad) if data.ndim == 3 else wt.TextureArray(data, requires_grad=grad)
    if name in ("uv", "uv_dx", "uv_dy"):
        return wp.array(data, dtype=wp.vec2, requires_grad=grad)
    if name in ("layer", "indices"):
        return wp.array(data.astype(np.int32), dtype=wp.int32)
    return wp.array(data.reshape(-1) if data.ndim == 0 else data, dtype=float, requires_grad=grad)


def _native_grad(value):
    if isinstance(value, wt.TextureArray):
        return value.grad(0)
    g = value.grad.numpy()
    return g.reshape(g.shape[0], 2) if value.dtype == wp.vec2 and g.ndim == 1 else g


def _compare(func, native_func, args: dict, positional: tuple, rng, *, rtol=1e-6, atol=1e-7):
    """``func`` (the bridge) and ``native_func`` on the same inputs: equal outputs, and equal
    gradients of ``Σ r · out`` for every tensor that requires one."""
    out = func(*[args[k] for k in positional], **{k: v for k, v in args.items() if k not in positional})
    r = torch.tensor(rng.standard_normal(tuple(out.shape)).astype(np.float32))
    (out * r).sum().backward()

    native = {k: _native(k, v) for k, v in args.items()}
    tape = wp.Tape()
    with tape:
        for v in native.values():  # the bridge builds its mips on the tape: coarse-level gradients reach level 0
            if isinstance(v, wt.TextureArray):
                v.update()
        expected = native_func(*[native[k] for k in positional], **{k: v for k, v in native.items() if k not in positional})
    expected.grad.assign(r.numpy())
    tape.backward()
    np.testing.assert_array_equal(out.detach().numpy().reshape(expected.numpy().shape), expected.numpy())
    checked = 0
    for k, v in args.items():
        if isinstance(v, torch.Tensor) and v.requires_grad:
            np.testing.assert_allclose(v.grad.numpy().reshape(np.shape(_native_grad(native[k]))), _native_grad(native[k]), rtol=rtol, atol=atol, err_msg=k)
            assert np.abs(v.grad.numpy()).max() > 0, f"{k}: no gradient reached it"
            checked += 1
    assert checked > 0
    return out


# -- every technique equals its native call --------------------------------------------------------


@pytest.mark.parametrize(
    "case",
    ["bilinear", "trilinear-lod", "anisotropic", "array-per-sample-layer", "clamp"],
)
def test_sample_matches_native(case, rng):
    n = 300
    args = {"texture": _t(rng, 16, 12, 3), "uv": _t(rng, n, 2, low=-1.0, high=2.0)}
    if case == "trilinear-lod":
        args.update(lod=_t(rng, n, low=0.0, high=3.0), sampler=wt.Sampler(filter="trilinear"))
    elif case == "anisotropic":
        args.update(uv_dx=_t(rng, n, 2, low=-0.2, high=0.2), uv_dy=_t(rng, n, 2, low=-0.05, high=0.05), sampler=wt.Sampler(filter="anisotropic"))
    elif case == "array-per-sample-layer":
        args.update(texture=_t(rng, 3, 8, 8, 4), layer=torch.tensor(rng.integers(0, 3, n)))
    elif case == "clamp":
        args.update(sampler=wt.Sampler(address="clamp"))
    _compare(wtt.sample, wt.sample, args, ("texture", "uv"), rng)


@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
def test_stochastic_matches_native(method, rng):
    args = {"texture": _t(rng, 16, 16, 3), "uv": _t(rng, 200, 2, low=0.0, high=4.0), "method": method, "lod": 0.5, "sampler": wt.Sampler(filter="trilinear")}
    _compare(wtt.stochastic, wt.stochastic, args, ("texture", "uv", "method"), rng)


@pytest.mark.parametrize("decorrelate", [False, True])
def test_stochastic_histogram_gradients_reach_the_gaussianised_texture(decorrelate, rng):
    source = _t(rng, 16, 16, 3, grad=False)
    h = wtt.prepare_histogram(source, lut_size=64, decorrelate=decorrelate)
    assert h.texture.shape == source.shape and isinstance(h.lut, torch.Tensor)
    gauss = h.texture.clone().requires_grad_(True)
    option = wt.Stochastic(method="hex", histogram=wt.Histogram(**{**h.__dict__, "texture": gauss}))
    uv = _t(rng, 150, 2, low=0.0, high=3.0)
    out = wtt.stochastic(source, uv, option)
    r = torch.tensor(rng.standard_normal(tuple(out.shape)).astype(np.float32))
    (out * r).sum().backward()
    assert source.grad is None and np.abs(gauss.grad.numpy()).max() > 0

    native_h = wt.prepare_histogram(wt.Texture(source.numpy()), lut_size=64, decorrelate=decorrelate, requires_grad=True)
    np.testing.assert_array_equal(native_h.texture.numpy(0), h.texture.numpy())
    u = wp.array(uv.detach().numpy(), dtype=wp.vec2, requires_grad=True)
    tape = wp.Tape()
    with tape:
        expected = wt.stochastic(wt.Texture(source.numpy()), u, wt.Stochastic(method="hex", histogram=native_h))
    expected.grad.assign(r.numpy())
    tape.backward()
    np.testing.assert_array_equal(out.detach().numpy(), expected.numpy())
    np.testing.assert_allclose(gauss.grad.numpy(), native_h.texture.grad(0), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(uv.grad.numpy(), u.grad.numpy(), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("technique", ["triplanar", "biplanar", "triplanar_normal"])
def test_projections_match_native(technique, gbuffer, rng):
    bridge, native = getattr(wtt, technique), getattr(wt, technique)
    args = {
        "gbuffer": gbuffer,
        "texture": _t(rng, 16, 16, 3 if technique == "triplanar_normal" else 4),
        "tiling": torch.tensor([0.3, 0.25, 0.2], requires_grad=True),
        "sharpness": torch.tensor(3.0, requires_grad=True),
        "offsets": _t(rng, 3, 2, low=-0.5, high=0.5),
    }
    if technique == "triplanar_normal":
        args.pop("offsets")  # normal mapping takes no offsets
    _compare(bridge, native, args, ("gbuffer", "texture"), rng, rtol=2e-5, atol=1e-6)


def test_triplanar_textures_per_axis_and_face(gbuffer, rng):
    args = {
        "gbuffer": gbuffer,
        "texture": _t(rng, 8, 8, 3),
        "textures_per_face": [None, _t(rng, 8, 8, 3), _t(rng, 16, 8, 3), None, None, None],
        "tiling": 0.3,
    }
    out = wtt.triplanar(**args)
    out.sum().backward()
    faces = [None if t is None else wt.Texture(t.detach().numpy()) for t in args["textures_per_face"]]
    expected = wt.triplanar(gbuffer, wt.Texture(args["texture"].detach().numpy()), textures_per_face=faces, tiling=0.3)
    np.testing.assert_array_equal(out.detach().numpy(), expected.numpy())
    assert args["textures_per_face"][1].grad is not None and args["texture"].grad is not None


@pytest.mark.parametrize("projection", ["uv", "world_xz", "triplanar"])
def test_splat_matches_native(projection, gbuffer, rng):
    args = {
        "gbuffer": gbuffer,
        "layers": _t(rng, 4, 8, 8, 4),
        "splat_maps": _t(rng, 6, 6, 4),
        "heights": _t(rng, 4, 8, 8, 1),
        "tiling": torch.tensor([2.0, 3.0, 0.5, 1.0], requires_grad=True),
        "height_blend": torch.tensor(0.2, requires_grad=True),
        "projection": projection,
    }
    if projection != "uv":
        args["tiling"] = torch.tensor([0.2, 0.3, 0.25, 0.4], requires_grad=True)
    _compare(wtt.splat, wt.splat, args, ("gbuffer", "layers", "splat_maps"), rng, rtol=2e-5, atol=1e-6)


def test_splat_atlas_gradients_reach_layers_weights_and_tiling(gbuffer, rng):
    layers = _t(rng, 3, 8, 8, 3)
    indices = torch.tensor(rng.integers(0, 3, (5, 5, 2)))
    weights = _t(rng, 5, 5, 2)
    tiling = torch.tensor([2.0, 1.0, 3.0], requires_grad=True)
    out = wtt.splat_atlas(gbuffer, layers, indices, weights, gutter=2, tiling=tiling)
    r = torch.tensor(rng.standard_normal(tuple(out.shape)).astype(np.float32))
    (out * r).sum().backward()

    source = wt.TextureArray(layers.detach().numpy(), mipmaps=False, requires_grad=True)
    w = wp.array(weights.detach().numpy(), dtype=float, requires_grad=True)
    til = wp.array(tiling.detach().numpy(), dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        atlas = wt.pack_atlas(source, gutter=2)
        expected = wt.splat_atlas(gbuffer, atlas, indices.numpy().astype(np.int32), w, tiling=til)
    expected.grad.assign(r.numpy())
    tape.backward()
    np.testing.assert_array_equal(out.detach().numpy(), expected.numpy())
    for name, got, want in (("layers", layers.grad, source.grad(0)), ("weights", weights.grad, w.grad.numpy()), ("tiling", tiling.grad, til.grad.numpy())):
        np.testing.assert_allclose(got.numpy(), want, rtol=2e-5, atol=1e-6, err_msg=name)
        assert np.abs(got.numpy()).max() > 0, name


# -- gradients against finite differences -----------------------------------------------------------


def test_texel_gradients_pass_gradcheck(rng):
    """Sampling is linear in the texels: torch's gradcheck holds at float32 rounding."""
    texture = torch.tensor(rng.uniform(0, 1, (4, 5, 2)), dtype=torch.float64, requires_grad=True)
    uv = torch.tensor(rng.uniform(-0.5, 1.5, (12, 2)).astype(np.float32))
    lod = torch.tensor(rng.uniform(0.0, 2.0, 12).astype(np.float32))
    smp = wt.Sampler(filter="trilinear", address="mirror")
    assert torch.autograd.gradcheck(lambda t: wtt.sample(t, uv, lod=lod, sampler=smp).double(), (texture,), eps=1e-2, atol=1e-4, rtol=1e-3)


def test_triplanar_texel_gradients_pass_gradcheck(gbuffer, rng):
    texture = torch.tensor(rng.uniform(0, 1, (4, 4, 1)), dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: wtt.triplanar(gbuffer, t, tiling=0.3).double(), (texture,), eps=1e-2, atol=1e-4, rtol=1e-3)


PARAMS = {"tiling": 0.3, "sharpness": 3.0}


@pytest.mark.parametrize("name", ["tiling", "sharpness"])
def test_triplanar_parameter_gradients_match_finite_differences(name, gbuffer, rng):
    texture = torch.tensor(rng.uniform(0, 1, (16, 16, 3)).astype(np.float32))
    value = np.array([PARAMS[name]])

    def render(v):
        with torch.no_grad():
            return wtt.triplanar(gbuffer, texture, **{**PARAMS, name: torch.tensor(v, dtype=torch.float32)}).numpy()

    def gradient(v, r):
        p = torch.tensor(v, dtype=torch.float32, requires_grad=True)
        (wtt.triplanar(gbuffer, texture, **{**PARAMS, name: p}) * torch.tensor(r)).sum().backward()
        return p.grad.numpy()

    r = rng.standard_normal((*gbuffer.resolution, 3))
    check_parameter_gradient(render, gradient, value, r, 2e-5 if name == "tiling" else 1e-2, rtol=2e-2, atol=2e-2, label=name)


def test_splat_map_gradients_match_finite_differences(gbuffer, rng):
    """Splat maps enter through the weights' normalisation (not linear): a directional derivative."""
    layers = torch.tensor(rng.uniform(0, 1, (4, 8, 8, 3)).astype(np.float32))
    maps = torch.tensor(rng.uniform(0.2, 1.0, (6, 6, 4)), dtype=torch.float64, requires_grad=True)
    r = torch.tensor(rng.standard_normal((*gbuffer.resolution, 3)))

    def loss(m):
        return (wtt.splat(gbuffer, layers, m, tiling=2.0).double() * r).sum()

    loss(maps).backward()
    direction = torch.tensor(rng.standard_normal(maps.shape))
    step = 1e-3
    with torch.no_grad():
        numeric = (loss(maps + step * direction) - loss(maps - step * direction)) / (2 * step)
    analytic = (maps.grad * direction).sum()
    np.testing.assert_allclose(analytic.item(), numeric.item(), rtol=2e-3, atol=2e-3)


# -- torch's own sampler ---------------------------------------------------------------------------


def test_bilinear_clamp_sample_equals_grid_sample(rng):
    """UV (0, 0) is the bottom-left corner; ``grid_sample``'s (-1, -1) the top-left: ``x = 2u - 1``,
    ``y = 1 - 2v``. Outputs and gradients (texels and UVs) agree."""
    h, w, c = 7, 9, 3
    image = rng.uniform(0, 1, (h, w, c)).astype(np.float32)
    uv_values = rng.uniform(-0.2, 1.2, (500, 2)).astype(np.float32)
    r = torch.tensor(rng.standard_normal((500, c)).astype(np.float32))

    texture, uv = torch.tensor(image, requires_grad=True), torch.tensor(uv_values, requires_grad=True)
    ours = wtt.sample(texture, uv, sampler=wt.Sampler(filter="bilinear", address="clamp"))
    (ours * r).sum().backward()

    texture2, uv2 = torch.tensor(image, requires_grad=True), torch.tensor(uv_values, requires_grad=True)
    grid = torch.stack([2 * uv2[:, 0] - 1, 1 - 2 * uv2[:, 1]], dim=-1).reshape(1, 500, 1, 2)
    theirs = torch.nn.functional.grid_sample(texture2.permute(2, 0, 1)[None], grid, mode="bilinear", padding_mode="border", align_corners=False)
    theirs = theirs[0, :, :, 0].T
    (theirs * r).sum().backward()

    np.testing.assert_allclose(ours.detach().numpy(), theirs.detach().numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(texture.grad.numpy(), texture2.grad.numpy(), rtol=1e-5, atol=1e-5)
    inside = ((uv_values > 0.5 / np.array([w, h])) & (uv_values < 1 - 0.5 / np.array([w, h]))).all(axis=1)  # clamped UVs: torch's slope there is a choice
    np.testing.assert_allclose(uv.grad.numpy()[inside], uv2.grad.numpy()[inside], rtol=1e-4, atol=1e-4)


# -- autograd plumbing -------------------------------------------------------------------------------


def test_retain_graph_gives_the_same_gradients_twice(rng):
    texture, uv = _t(rng, 8, 8, 3), _t(rng, 50, 2)
    out = wtt.sample(texture, uv)
    out.sum().backward(retain_graph=True)
    first = texture.grad.clone(), uv.grad.clone()
    texture.grad, uv.grad = None, None
    out.sum().backward()
    np.testing.assert_array_equal(texture.grad.numpy(), first[0].numpy())
    np.testing.assert_array_equal(uv.grad.numpy(), first[1].numpy())


def test_a_gradient_handed_to_torch_is_never_written_again(rng):
    """An RGBA texture read at level 0 gets its gradient buffer as it is, no copy. A second
    backward of the same graph adds into that buffer again, returns a copy and gives the buffer
    back as torch held it; a second call on the texture in one graph has a buffer of its own."""
    texture, uv, uv2 = _t(rng, 8, 8, 4), _t(rng, 50, 2), _t(rng, 30, 2)
    out = wtt.sample(texture, uv)
    out.sum().backward(retain_graph=True)
    first = texture.grad.clone()
    assert first.abs().sum() > 0
    out.sum().backward()  # accumulates into .grad, which is the first backward's buffer
    np.testing.assert_array_equal(texture.grad.numpy(), 2 * first.numpy())
    texture.grad = None
    wtt.sample(texture, uv2).sum().backward()
    second = texture.grad.clone()
    texture.grad = None
    (wtt.sample(texture, uv).sum() + wtt.sample(texture, uv2).sum()).backward()
    np.testing.assert_allclose(texture.grad.numpy(), first.numpy() + second.numpy(), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("layout", ["rgba-level-0", "rgb-mips"])
def test_a_loop_on_one_texture_tensor_reuses_its_texture_and_follows_its_values(layout, monkeypatch, rng):
    """The bridge keeps the texture it made around a tensor for the tensor's next calls
    (issue 51): a loop that changes the tensor in place between steps (an optimiser's step) reads
    its new values every step, each step's gradient is the native call's, a gradient the user
    still holds is never written again, and the kept textures go with the tensor."""
    import warptex._torch_texture as kept_textures

    made = []
    real = kept_textures._kept_texture

    def spy(*args, **kwargs):
        kept = real(*args, **kwargs)
        made.append(kept.texture)
        return kept

    monkeypatch.setattr(kept_textures, "_kept_texture", spy)
    channels, sampler = (4, wt.Sampler(filter="bilinear", address="wrap")) if layout == "rgba-level-0" else (3, wt.Sampler(filter="trilinear"))
    texture = _t(rng, 16, 12, channels)
    uv = torch.tensor(rng.random((300, 2), dtype=np.float32) * 3)
    lod = None if layout == "rgba-level-0" else torch.tensor(rng.random(300, dtype=np.float32) * 3)
    kept_grads = []
    for step in range(4):
        out = wtt.sample(texture, uv, lod=lod, sampler=sampler)
        weights = torch.tensor(rng.standard_normal(out.shape).astype(np.float32))
        (out * weights).sum().backward()
        native_tex = wt.Texture(texture.detach().numpy(), requires_grad=True)
        tape = wp.Tape()
        with tape:
            native_tex.update()  # as the bridge builds its mips: coarse-level gradients reach level 0
            native = wt.sample(native_tex, uv.numpy(), lod=None if lod is None else wp.array(lod.numpy(), dtype=float), sampler=sampler)
        tape.backward(grads={native: wp.array(weights.numpy(), dtype=float)})
        np.testing.assert_array_equal(out.detach().numpy(), native.numpy())
        np.testing.assert_allclose(texture.grad.numpy(), native_tex.grad(), rtol=1e-6, atol=1e-7)
        if step == 1:  # the user keeps this step's gradient: the next steps must not touch it
            kept_grads.append((texture.grad, texture.grad.clone()))
        texture.grad = None
        with torch.no_grad():
            texture.mul_(0.9).add_(0.05)  # in place: same storage, new values
    # one texture for every step; an RGBA level 0 hands its gradient buffer to torch, so the step
    # after the gradient the user kept gets a second one
    assert len({id(t) for t in made}) == (2 if layout == "rgba-level-0" else 1)
    for held, copy in kept_grads:
        assert torch.equal(held, copy)
    ref = weakref.ref(made[0])
    made.clear()
    del texture, out
    gc.collect()
    assert ref() is None


@pytest.mark.parametrize("shape", [(8, 8, 4), (2, 8, 8, 4), (8, 8, 3)])
@pytest.mark.parametrize("grad", [False, True])
def test_the_textures_kept_for_a_tensor_keep_nothing_alive(shape, grad, rng):
    """A texture the bridge keeps for a tensor's next calls goes with the tensor, and keeps neither
    it nor its storage alive."""
    texture = _t(rng, *shape, grad=grad)
    uv = torch.tensor(rng.random((20, 2), dtype=np.float32))
    out = wtt.sample(texture, uv, layer=1 if len(shape) == 4 else None)
    if grad:
        out.sum().backward()
    storage = texture.untyped_storage()._weak_ref()
    refs = [weakref.ref(texture)]
    del texture, out
    gc.collect()
    assert refs[0]() is None
    assert torch.UntypedStorage._expired(storage)


def test_a_tensor_whose_storage_is_swapped_is_read_from_its_new_storage(rng):
    """A kept texture names its tensor's storage: after ``t.data = ...`` (a new storage) the
    bridge reads the new texels, and their gradients are the native call's."""
    texture = _t(rng, 8, 8, 4)
    uv = torch.tensor(rng.random((64, 2), dtype=np.float32))
    wtt.sample(texture, uv).sum().backward()
    for _ in range(3):
        texture.grad = None
        texture.data = torch.tensor(rng.random((8, 8, 4), dtype=np.float32))
        out = wtt.sample(texture, uv)
        out.sum().backward()
        native_tex = wt.Texture(texture.detach().numpy(), mipmaps=False, requires_grad=True)
        tape = wp.Tape()
        with tape:
            native = wt.sample(native_tex, uv.numpy())
        tape.backward(grads={native: wp.ones(native.shape, dtype=float)})
        np.testing.assert_array_equal(out.detach().numpy(), native.numpy())
        np.testing.assert_allclose(texture.grad.numpy(), native_tex.grad(), rtol=1e-6, atol=1e-7)


def test_no_tape_is_kept_without_gradients_and_a_graph_frees_its_tape(rng):
    texture, uv = _t(rng, 8, 8, 3), _t(rng, 50, 2)
    gc.collect()
    before = len(_states)
    with torch.no_grad():
        wtt.sample(texture, uv)
    wtt.sample(texture.detach(), uv.detach())
    assert len(_states) == before
    out = wtt.sample(texture, uv)
    assert len(_states) == before + 1
    del out
    gc.collect()
    assert len(_states) == before
    wtt.sample(texture, uv).sum().backward()
    gc.collect()
    assert len(_states) == before


def test_no_grad_leaves_every_tensor_alone(gbuffer, rng):
    """Under torch.no_grad() nothing is recorded, and no tensor that requires gradients is given a
    .grad (wp.from_torch would allocate one)."""
    texture, uv, tiling = _t(rng, 8, 8, 3), _t(rng, 30, 2), torch.tensor(0.3, requires_grad=True)
    lod = _t(rng, 30, low=0.0, high=2.0)
    with torch.no_grad():
        wtt.sample(texture, uv, lod=lod)
        wtt.triplanar(gbuffer, texture, tiling=tiling)
    assert texture.grad is None and uv.grad is None and tiling.grad is None and lod.grad is None


def test_only_the_tensors_that_require_gradients_get_them(gbuffer, rng):
    texture = _t(rng, 8, 8, 3, grad=False)
    tiling = torch.tensor(0.3, requires_grad=True)
    wtt.triplanar(gbuffer, texture, tiling=tiling).sum().backward()
    assert texture.grad is None and tiling.grad is not None and tiling.grad.shape == ()


def test_compiles_into_one_graph(gbuffer, rng):
    """``torch.compile(fullgraph=True)``: no graph break at the bridge; results equal eager mode."""
    tensors = wtt.gbuffer_tensors(gbuffer)
    smp = wt.Sampler(filter="anisotropic")

    def loss(texture, tiling):
        return wtt.triplanar(tensors, texture, tiling=tiling, sampler=smp).square().mean()

    texture, tiling = _t(rng, 16, 16, 3), torch.tensor(0.3, requires_grad=True)
    compiled = torch.compile(loss, backend="aot_eager", fullgraph=True)
    value = compiled(texture, tiling)
    value.backward()
    grads = texture.grad.clone(), tiling.grad.clone()
    texture.grad, tiling.grad = None, None
    eager = loss(texture, tiling)
    eager.backward()
    assert value.item() == eager.item()
    np.testing.assert_array_equal(grads[0].numpy(), texture.grad.numpy())
    np.testing.assert_array_equal(grads[1].numpy(), tiling.grad.numpy())


@pytest.mark.parametrize("dtype", [torch.float64, torch.float16])
def test_outputs_keep_the_inputs_floating_dtype(dtype, rng):
    """Computed in float32, returned in the inputs' floating dtype (torch's promotion), as is every
    gradient: a float64 pipeline stays float64, and the values are the float32 ones, cast."""
    texture, uv = _t(rng, 8, 8, 3), _t(rng, 40, 2)
    wide_texture = texture.detach().to(dtype).requires_grad_()
    wide_uv = uv.detach().to(dtype).requires_grad_()
    out = wtt.sample(wide_texture, wide_uv)
    assert out.dtype == dtype
    np.testing.assert_array_equal(out.detach().float().numpy(), wtt.sample(wide_texture.detach().float(), wide_uv.detach().float()).to(dtype).float().numpy())
    out.sum().backward()
    assert wide_texture.grad.dtype == dtype and wide_uv.grad.dtype == dtype
    mixed = wtt.sample(texture.detach(), uv.detach().double())  # float32 texels, float64 UVs: float64
    assert mixed.dtype == torch.float64


def test_opcheck(rng):
    """torch.library.opcheck: the op's schema, fake (shape) function and autograd registration agree
    with what it does."""
    texture, uv = _t(rng, 8, 8, 3), _t(rng, 40, 2)
    spec, tensors = op_arguments("sample", {"texture": texture, "uv": uv})
    torch.library.opcheck(torch.ops.warptex.technique.default, (spec, tensors), test_utils=("test_schema", "test_faketensor", "test_autograd_registration"))


def test_a_spec_written_from_its_kept_head_is_the_one_written_out(monkeypatch, rng):
    """A call whose structure an earlier call had reuses that spec's head (issue 51): the spec is
    the one written out in full, its tensors are converted and checked as before, and what makes
    two specs differ still does (a sampler, a float's sign, which tensors want gradients)."""
    import warptex._torch_spec as ts

    texture, uv, lod = _t(rng, 8, 8, 3), _t(rng, 40, 2), _t(rng, 40)
    calls = [
        {"texture": texture, "uv": uv},
        {"texture": texture.detach(), "uv": uv},
        {"texture": texture, "uv": uv, "lod": lod, "sampler": wt.Sampler(filter="trilinear")},
        {"texture": texture, "uv": uv, "lod": 0.0},
        {"texture": texture, "uv": uv, "lod": -0.0},
        {"texture": texture.double(), "uv": uv, "layer": None},
    ]
    monkeypatch.setattr(ts, "_heads", {})
    first = [op_arguments("sample", dict(c)) for c in calls]
    assert len(ts._heads) == len(calls) - 1  # the first two share a head
    again = [op_arguments("sample", dict(c)) for c in calls]
    monkeypatch.setattr(ts, "_spec_key", lambda name, args: None)  # written out every time
    written = [op_arguments("sample", dict(c)) for c in calls]
    for (s1, t1), (s2, t2), (s3, t3) in zip(first, again, written):
        assert s1 == s2 == s3
        assert len(t1) == len(t2) == len(t3) and all(a.dtype == b.dtype == c.dtype and torch.equal(a, c) for a, b, c in zip(t1, t2, t3))
    assert len({s for s, _ in first}) == len(calls)
    monkeypatch.undo()
    with pytest.raises(ValueError, match=r"uv must have shape"):
        op_arguments("sample", {"texture": texture, "uv": uv[:, :1]})


# -- bad input ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "call, error, match",
    [
        (lambda t, uv, g: wtt.sample(t[..., 0], uv), ValueError, r"texture must be a texture \[H, W, C\]"),
        (lambda t, uv, g: wtt.sample(torch.zeros(8, 8, 5), uv), ValueError, r"1 <= C <= 4, got shape \(8, 8, 5\)"),
        (lambda t, uv, g: wtt.sample(wt.Texture(np.zeros((4, 4, 3))), uv), TypeError, "texture must be a torch tensor"),
        (lambda t, uv, g: wtt.sample(t, uv[:, :1]), ValueError, r"uv must have shape \(\.\.\., 2\)"),
        (lambda t, uv, g: wtt.sample(t, uv, layer=torch.zeros(40)), TypeError, "layer must be an integer tensor"),
        (lambda t, uv, g: wtt.triplanar({k: v for k, v in g.items() if k != "mask"}, t), ValueError, "G-buffer dict lacks mask"),
        (lambda t, uv, g: wtt.triplanar({**g, "normal": g["normal"][..., :2].contiguous()}, t), ValueError, r"'normal' must be a torch.float32 tensor of shape \(H, W, 3\)"),
        (lambda t, uv, g: wtt.triplanar(g, t, tiling=torch.tensor([1.0, 2.0])), ValueError, r"tiling as a wp.array must be float32 with shape \(1,\) or \(3,\)"),
        (lambda t, uv, g: wtt.stochastic(t, uv, wt.Stochastic(method="hex", histogram=wt.prepare_histogram(wt.Texture(np.ones((4, 4, 3)))))), TypeError, "warptex.torch.prepare_histogram"),
        (lambda t, uv, g: wtt.triplanar(g, t.detach().numpy()), TypeError, r"warptex.torch.triplanar\(\): texture must be a torch tensor, got a NumPy array"),
        (lambda t, uv, g: wtt.sample(t, uv.detach().numpy()), TypeError, r"warptex.torch.sample\(\): uv must be a torch tensor, got a NumPy array"),
        (lambda t, uv, g: wtt.sample(torch.zeros(8, 8, 3, dtype=torch.int32), uv), TypeError, "texture has integer dtype torch.int32; pass floats"),
        (lambda t, uv, g: wtt.sample(torch.zeros(8, 8, 3, dtype=torch.bool), uv), TypeError, "texture has integer dtype torch.bool"),
    ],
)
def test_bad_input_raises(call, error, match, gbuffer, rng):
    texture, uv = _t(rng, 8, 8, 3), _t(rng, 40, 2)
    with pytest.raises(error, match=match):
        call(texture, uv, wtt.gbuffer_tensors(gbuffer))


def test_a_camera_relative_supersampled_gbuffer_keeps_its_origin_and_samples(rng):
    """``gbuffer_tensors`` carries a G-buffer's float64 origin and its samples per pixel, so the
    bridge folds whole texture periods out of a far scene exactly as the native call does."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    g = wt.rasterize(mesh, wt.look_at((0, 0, 3), (0, 0, 0), resolution=(16, 16)), samples=4, origin=(1e6 + 0.375, 2.0, -3e6 + 0.25))
    tensors = wtt.gbuffer_tensors(g)
    assert tensors["origin"].dtype == torch.float64 and tensors["samples"].item() == 4
    texture = _t(rng, 16, 16, 3, grad=False)
    got = wtt.triplanar(tensors, texture, tiling=0.5).numpy()
    want = wt.triplanar(g, wt.Texture(texture.numpy()), tiling=0.5).numpy()
    np.testing.assert_array_equal(got, want)
    moved = wt.GBuffer(**{k: getattr(g, k) for k in FIELDS}, uv_sets=g.uv_sets, samples=4)  # the same arrays at the world origin
    assert np.abs(wt.triplanar(moved, wt.Texture(texture.numpy()), tiling=0.5).numpy() - want).max() > 0.05  # the origin matters here


def test_the_torch_functions_take_no_out():
    """The native functions' ``out=`` fills a Warp array in place; a torch function returns a new
    tensor (autograd needs one), so it has no ``out`` and refuses one by any route."""
    import inspect

    texture, uv = torch.rand(8, 8, 3), torch.rand(4, 2)
    for function in (wtt.sample, wtt.stochastic, wtt.triplanar, wtt.biplanar, wtt.triplanar_normal, wtt.biplanar_normal, wtt.splat, wtt.splat_atlas):
        assert "out" not in inspect.signature(function).parameters, function.__name__
    with pytest.raises(TypeError, match="unexpected keyword argument 'out'"):
        wtt.sample(texture, uv, out=torch.empty(4, 3))
    g = wt.GBuffer.empty((2, 3))
    with pytest.raises(TypeError, match=r"biplanar\(\) got an unexpected keyword argument 'out': the torch functions return a new tensor"):
        wtt.biplanar(g, texture, out=torch.empty(2, 3, 3))


@pytest.mark.parametrize("sampler, mips", [(None, False), (wt.Sampler(filter="nearest"), False), (wt.Sampler(lod_bias=0.4), False),
                                           (wt.Sampler(lod_bias=1.0), True), (wt.Sampler(min_lod=2.0), True)])
def test_sample_without_a_lod_builds_mips_only_where_its_sampler_reads_them(monkeypatch, sampler, mips):
    """The op builds a texture's mips (and runs their backward) only where the call may read past
    level 0: a small call's time was mostly that. A sampler whose bias or clamp moves LOD 0 to a
    coarser level still reads it, as natively."""
    from warptex import _torch_op

    built, around = [], _torch_op.texture_around
    monkeypatch.setattr(_torch_op, "texture_around", lambda t, *, mipmaps, **kw: (built.append(mipmaps), around(t, mipmaps=mipmaps, **kw))[1])
    rng = np.random.default_rng(5)
    image = torch.tensor(rng.random((16, 16, 3), dtype=np.float32), requires_grad=True)
    uv = torch.tensor(rng.random((50, 2), dtype=np.float32) * 2)
    out = wtt.sample(image, uv, sampler=sampler)
    assert built == [mips]
    tex = wt.Texture(image.detach().numpy(), requires_grad=True)
    tape = wp.Tape()
    with tape:
        native = wt.sample(tex, uv.numpy(), sampler=sampler)
    np.testing.assert_array_equal(out.detach().numpy(), native.numpy())
    assert out.detach().numpy().std() > 0.01  # not a constant (level 2 is a 4 x 4 average)
    if not mips:  # level 0 alone is read: its gradient is the native one (with mips, the other tests' path)
        weights = rng.random((50, 3), dtype=np.float32)
        (out * torch.tensor(weights)).sum().backward()
        tape.backward(grads={native: wp.array(weights, dtype=float)})
        np.testing.assert_array_equal(image.grad.numpy(), tex.texels.grad.numpy()[..., :3])
        assert np.abs(image.grad.numpy()).max() > 0


@pytest.mark.parametrize("layout", ["rgba", "rgb", "strided", "float64"])
def test_a_level_0_texture_is_read_in_place_or_copied_with_the_same_bits(layout, rng):
    """Issue 51: a call that reads level 0 only (bilinear, no LOD) of a contiguous float32 RGBA
    tensor wraps the tensor itself rather than a zeroed copy (most of a small call's time); other
    layouts are copied as before. Outputs and texel gradients are the native call's bits either
    way, and the tensor is left as it was."""
    image = rng.random((16, 12, 4), dtype=np.float32)
    channels = 3 if layout == "rgb" else 4
    if layout == "strided":
        base = torch.tensor(np.ascontiguousarray(image.transpose(1, 0, 2))).permute(1, 0, 2)  # (16, 12, 4), not contiguous
    else:
        base = torch.tensor(image[..., :channels], dtype=torch.float64 if layout == "float64" else torch.float32)
    texture = base.detach().clone() if layout != "strided" else base.detach()
    texture.requires_grad_(True)
    before = texture.detach().clone()
    uv = rng.random((200, 2), dtype=np.float32)
    sampler = wt.Sampler(filter="bilinear", address="clamp")
    out = wtt.sample(texture, torch.tensor(uv), sampler=sampler)
    weights = torch.tensor(rng.random(out.shape, dtype=np.float32))
    (out * weights).sum().backward()
    native_tex = wt.Texture(image[..., :channels], mipmaps=False, requires_grad=True)
    tape = wp.Tape()
    with tape:
        native = wt.sample(native_tex, uv, sampler=sampler)
    tape.backward(grads={native: wp.array(weights.numpy(), dtype=float)})
    np.testing.assert_array_equal(out.detach().numpy(), native.numpy())
    np.testing.assert_array_equal(texture.grad.float().numpy(), native_tex.grad()[..., :channels])
    assert torch.equal(texture.detach(), before)


@pytest.mark.parametrize("dtype", ["uint8", "uint16"])
def test_integer_textures_are_read_as_the_native_textures_read_them(dtype, gbuffer, rng):
    """A uint8 (uint16) texture tensor holds codes, divided by 255 (65535) as ``wt.Texture`` divides
    a NumPy array of them: the same outputs, bit for bit, in sample and triplanar."""
    if not hasattr(torch, dtype):
        pytest.skip(f"this PyTorch has no torch.{dtype}")
    codes = rng.integers(0, 256 if dtype == "uint8" else 65536, (16, 12, 3)).astype(dtype)
    uv = rng.random((200, 2), dtype=np.float32)
    tensor = torch.from_numpy(codes.astype(np.int64)).to(getattr(torch, dtype))
    np.testing.assert_array_equal(wtt.sample(tensor, torch.tensor(uv)).numpy(), wt.sample(wt.Texture(codes), uv).numpy())
    np.testing.assert_array_equal(wtt.triplanar(gbuffer, tensor, tiling=0.3).numpy(), wt.triplanar(gbuffer, wt.Texture(codes), tiling=0.3).numpy())
