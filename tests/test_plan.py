"""Kept plans (``warptex._plan``): a repeated small call on the same objects runs the launch its
earlier call made, with the same bits, reads its inputs' current contents, serves new ``uv`` and
``out=`` arrays of the same layout (on a CUDA device too: ``tests/test_cuda.py``), never outlives an object it names nor holds an
array of a call, and stays out of the way of tapes, ``one_pixel_kernels`` and bad input."""

import gc
import weakref

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex import _plan
from warptex._threads import MIN_PIXELS_PER_THREAD
from warptex.kernels.family import one_pixel_kernels


def _plans() -> dict:
    return _plan._local.__dict__.get("plans", {})


@pytest.fixture(autouse=True)
def _no_plans_of_other_tests():
    """Each test starts with no plans: those of an earlier test's objects go only once a collection
    frees the objects (with Warp 1.17, a texture waits for one)."""
    gc.collect()
    _plans().clear()


def _made(func: str, *objects, out: str = "any") -> list:
    """The kept plans of ``func`` whose objects begin with ``objects``; ``out``: ``"given"`` or
    ``"new"`` (``out=None``) for those plans alone. (A key: the call's, the layouts of its ``out``
    and ``uv``, its objects' ids.)"""
    return [
        p
        for (key, out_layout, _uv, *ids), p in _plans().items()
        if p.cmd is not None and key[0] == func and ids[: len(objects)] == list(map(id, objects)) and out in ("any", "new" if out_layout is None else "given")
    ]


def _kept(texture, uv, out, **options) -> bool:
    """Whether the next ``sample`` of these objects and options would run a kept plan."""
    from warptex.sampling import plan_key

    key = plan_key("sample", texture, uv, options.get("lod"), None, None, options.get("layer"), options.get("sampler"), None, out)
    return key is not None and _plan.recall(key, (texture,), out=out, uv=uv) is not None


@pytest.fixture
def inputs():
    rng = np.random.default_rng(11)
    texture = wt.Texture(rng.random((64, 48, 4), dtype=np.float32))
    uv = wp.array(rng.random((300, 2), dtype=np.float32) * 3 - 1, dtype=wp.vec2)
    return texture, uv, rng


@pytest.mark.parametrize(
    ("sampler", "lod"), [(None, None), (None, 1.5), (wt.Sampler(filter="nearest", address="mirror"), None), (wt.Sampler(filter="trilinear", address="clamp"), 0.7)]
)
def test_a_kept_plan_gives_the_calls_bits(inputs, sampler, lod):
    texture, uv, _ = inputs
    want = wt.sample(texture, uv, sampler=sampler, lod=lod).numpy()
    out = wp.full((300, 4), np.nan, dtype=wp.float32)
    for call in range(4):
        assert _kept(texture, uv, out, sampler=sampler, lod=lod) == (call >= 2)  # made by the second call, run from the third
        out.fill_(np.nan)
        assert wt.sample(texture, uv, sampler=sampler, lod=lod, out=out) is out
        np.testing.assert_array_equal(out.numpy(), want)


@pytest.mark.parametrize("device", [None, "cpu", wp.get_device("cpu")])
def test_a_call_naming_its_device_is_kept_too(inputs, device):
    texture, uv, _ = inputs
    out = wp.empty((300, 4), dtype=wp.float32)
    for _ in range(3):
        wt.sample(texture, uv, device=device, out=out)
    np.testing.assert_array_equal(out.numpy(), wt.sample(texture, uv).numpy())
    assert sum(p.cmd is not None for p in _plans().values()) >= 1


@pytest.mark.parametrize("option", ["hash4", wt.Method.CHEAP2, wt.Stochastic("hex", seed=3, rotation=0.4), "histogram"])
def test_stochastic_calls_are_kept_but_not_with_a_histogram(inputs, option):
    texture, uv, _ = inputs
    if option == "histogram":
        option = wt.Stochastic("hex", histogram=wt.prepare_histogram(texture))
    want = wt.stochastic(texture, uv, option).numpy()
    out = wp.full((300, 4), np.nan, dtype=wp.float32)
    for _ in range(3):
        out.fill_(np.nan)
        np.testing.assert_array_equal(wt.stochastic(texture, uv, option, out=out).numpy(), want)
    assert len(_made("stochastic", texture, out="given")) == (0 if isinstance(option, wt.Stochastic) and option.histogram is not None else 1)


def test_a_plan_reads_its_inputs_current_contents(inputs):
    texture, uv, rng = inputs
    out = wp.empty((300, 4), dtype=wp.float32)
    for _ in range(3):
        wt.sample(texture, uv, out=out)
    assert _kept(texture, uv, out)
    uv.assign(rng.random((300, 2), dtype=np.float32))  # new UVs, same array
    texels = rng.random((64, 48, 4), dtype=np.float32)
    texture.texels.assign(texels)
    texture.update()
    wt.sample(texture, uv, out=out)
    fresh = wt.Texture(texels)
    np.testing.assert_array_equal(out.numpy(), wt.sample(fresh, uv.numpy()).numpy())


def test_other_objects_options_or_layouts_are_not_served_by_a_plan(inputs):
    texture, uv, rng = inputs
    out = wp.empty((300, 4), dtype=wp.float32)
    for _ in range(3):
        wt.sample(texture, uv, out=out)
    assert _kept(texture, wp.clone(uv), wp.empty((300, 4), dtype=wp.float32))  # new arrays, the same layouts
    assert not _kept(texture, uv, out, lod=2.0)
    assert not _kept(wt.Texture(rng.random((64, 48, 4), dtype=np.float32)), uv, out)
    assert not _kept(texture, uv[:150], out[:150])
    assert not _kept(texture, uv.reshape((20, 15)), out.reshape((20, 15, 4)))
    assert not _kept(texture, wp.clone(uv, requires_grad=True), out)
    assert not _kept(texture, uv, wp.empty((300, 2, 4), dtype=wp.float32)[:, 0])  # strided: refused by the call, as before
    np.testing.assert_array_equal(wt.sample(texture, uv, lod=2.0, out=out).numpy(), wt.sample(texture, uv, lod=2.0).numpy())
    with pytest.raises(ValueError, match="out must be a contiguous float32"):
        wt.sample(texture, uv, out=wp.empty((300, 2, 4), dtype=wp.float32)[:, 0])


@pytest.mark.parametrize("func", ["sample", "stochastic"])
def test_a_plan_serves_new_arrays_of_its_layout(inputs, func):
    """A loop that makes new UVs and a new ``out=`` each call (a torch tensor's view, a
    ``wp.empty``) runs one plan, pointed at each call's arrays: each call's bits, every array
    left to its caller (the plan holds none)."""
    texture, _, rng = inputs
    call = getattr(wt, func)
    held = []
    for step in range(6):
        uv = wp.array(rng.random((300, 2), dtype=np.float32) * 3 - 1, dtype=wp.vec2)
        out = wp.full((300, 4), np.nan, dtype=wp.float32)
        assert _kept(texture, uv, out) == (func == "sample" and step >= 2)
        assert call(texture, uv, out=out) is out
        np.testing.assert_array_equal(out.numpy(), call(texture, uv.numpy()).numpy())
        new = call(texture, uv)  # and without out=: the new output's plan
        np.testing.assert_array_equal(new.numpy(), out.numpy())
        held += [weakref.ref(uv), weakref.ref(out)]
    assert len(_made(func, texture, out="given")) == 1 and len(_made(func, texture, out="new")) == 1
    del uv, out
    gc.collect()
    assert all(h() is None for h in held)


def test_a_plan_goes_with_any_of_its_objects(inputs):
    _, uv, rng = inputs
    texture = wt.Texture(rng.random((64, 48, 4), dtype=np.float32))
    out = wp.empty((300, 4), dtype=wp.float32)
    for _ in range(3):
        wt.sample(texture, uv, out=out)
    before = len(_plans())
    texels = weakref.ref(texture.texels)
    del texture
    gc.collect()
    assert len(_plans()) == before - 1
    assert texels() is None  # the plan held the texture's arrays through its structs: not past the texture
    for _ in range(3):
        wt.sample(wt.Texture(rng.random((8, 8, 4), dtype=np.float32)), uv, out=out)  # a texture of one call
    gc.collect()
    assert len(_plans()) == before - 1


def test_plans_are_bounded_and_not_made_for_one_off_objects(inputs):
    _, uv, rng = inputs
    out = wp.empty((300, 4), dtype=wp.float32)
    kept = [wt.Texture(rng.random((4, 4, 4), dtype=np.float32)) for _ in range(_plan.MAX_PLANS + 5)]
    for texture in kept:
        for _ in range(3):
            wt.sample(texture, uv, out=out)
    assert len(_plans()) <= _plan.MAX_PLANS
    assert sum(p.cmd is not None for p in _plans().values()) >= _plan.MAX_PLANS - 1
    for _ in range(5):  # a new texture every call: seen once each, never planned
        wt.sample(wt.Texture(rng.random((4, 4, 4), dtype=np.float32)), uv, out=out)
    gc.collect()
    assert all(r() is not None for p in _plans().values() for r in p.refs)


def test_a_call_split_over_threads_is_not_kept(inputs):
    texture, _, rng = inputs
    count = 4 * MIN_PIXELS_PER_THREAD
    uv = wp.array(rng.random((count, 2), dtype=np.float32), dtype=wp.vec2)
    out = wp.empty((count, 4), dtype=wp.float32)
    for _ in range(3):
        wt.sample(texture, uv, out=out)
    assert not _kept(texture, uv, out)


def test_no_plan_is_run_or_made_under_a_tape_or_one_pixel_kernels(inputs):
    texture, uv, _ = inputs
    out = wp.empty((300, 4), dtype=wp.float32, requires_grad=True)
    out.grad = None
    for _ in range(3):
        wt.sample(texture, uv, out=out)
    assert _kept(texture, uv, out)
    with one_pixel_kernels():
        assert not _kept(texture, uv, out)
    out.grad = wp.full((300, 4), 7.0, dtype=wp.float32)
    wt.sample(texture, uv, out=out)  # as a new output's, the buffer's gradient is zeroed
    assert _kept(texture, uv, out) and not out.grad.numpy().any()

    fitted = wt.Texture(texture.texels.numpy(), requires_grad=True)
    tape = wp.Tape()
    with tape:
        assert not _kept(texture, uv, out)
        for _ in range(3):
            wt.sample(fitted, uv, out=out)
    assert not _kept(fitted, uv, out)
    tape.backward(grads={out: wp.ones((300, 4), dtype=wp.float32)})
    want = wp.Tape()
    fresh = wt.Texture(texture.texels.numpy(), requires_grad=True)
    with want:
        result = wt.sample(fresh, uv)
    want.backward(grads={result: wp.ones((300, 4), dtype=wp.float32)})
    assert np.abs(fresh.grad(0)).sum() > 0
    np.testing.assert_allclose(fitted.grad(0), 3 * fresh.grad(0), rtol=1e-5, atol=1e-6)  # three recorded calls, each counted


def test_errors_are_unchanged_after_a_plan(inputs):
    texture, uv, _ = inputs
    out = wp.empty((300, 4), dtype=wp.float32)
    with pytest.raises(Exception) as before:
        wt.sample(texture, uv, out=out, layer=True)
    for _ in range(3):
        wt.sample(texture, uv, out=out, layer=1 - 1)
    assert _kept(texture, uv, out, layer=0)
    with pytest.raises(type(before.value)) as after:
        wt.sample(texture, uv, out=out, layer=True)  # True == 1: a key that compared by value would hit
    assert str(after.value) == str(before.value)


@pytest.mark.parametrize("func", ["triplanar", "biplanar"])
def test_a_projections_plan_follows_its_g_buffer(func):
    """Colour mapping's plans: the same bits, and none once a G-buffer array or its origin is replaced."""
    rng = np.random.default_rng(5)
    g = wt.GBuffer.empty((6, 5))
    g.position.assign(rng.random((6, 5, 3), dtype=np.float32))
    g.normal.assign(rng.normal(size=(6, 5, 3)).astype(np.float32))
    g.mask.fill_(1)
    texture = wt.Texture(rng.random((16, 16, 4), dtype=np.float32))
    call = getattr(wt, func)
    want = call(g, texture, tiling=1.5).numpy()
    out = wp.empty((6, 5, 4), dtype=wp.float32)
    for _ in range(3):
        np.testing.assert_array_equal(call(g, texture, tiling=1.5, out=out).numpy(), want)
    assert sum(p.cmd is not None for p in _plans().values()) >= 1
    g.normal = wp.array(rng.normal(size=(6, 5, 3)).astype(np.float32), dtype=wp.vec3)  # a new array: the plan does not apply
    fresh = call(g, texture, tiling=1.5).numpy()
    assert not np.array_equal(fresh, want)
    np.testing.assert_array_equal(call(g, texture, tiling=1.5, out=out).numpy(), fresh)
    g.origin = np.array([0.25, 0.0, 0.0])
    np.testing.assert_array_equal(call(g, texture, tiling=1.5, out=out).numpy(), call(g, texture, tiling=1.5).numpy())
    with pytest.raises(ValueError, match="layer must be an int"):  # a float layer equals an int one as a key, and is refused
        call(g, texture, tiling=1.5, layer=0.0, out=out)


def _splat_scene(rng):
    g = wt.GBuffer.empty((6, 5), uv_sets=("uv0",))
    g.position.assign(rng.random((6, 5, 3), dtype=np.float32))
    g.normal.assign(rng.normal(size=(6, 5, 3)).astype(np.float32))
    g.mask.fill_(1)
    for name, scale in (("uv", 1.0), ("uv_dx", 0.02), ("uv_dy", 0.01)):
        g.uv_sets["uv0"][name].assign(rng.random((6, 5, 2), dtype=np.float32) * scale)
    layers = wt.TextureArray(rng.random((4, 16, 16, 4), dtype=np.float32))
    maps = wt.TextureArray(rng.random((1, 8, 8, 4), dtype=np.float32), mipmaps=False)
    return g, layers, maps


@pytest.mark.parametrize("options", [{}, {"projection": "triplanar", "height_blend": 0.2}, {"stochastic": "hash4", "tiling": 2}, {"heights": "own"}])
def test_a_splat_plan_gives_the_calls_bits_and_reads_current_contents(options):
    rng = np.random.default_rng(8)
    g, layers, maps = _splat_scene(rng)
    if options.get("heights") == "own":
        options = {"height_blend": 0.3, "heights": wt.TextureArray(rng.random((4, 8, 8, 1), dtype=np.float32))}
    out = wp.empty((6, 5, 4), dtype=wp.float32)
    want = wt.splat(g, layers, maps, **options).numpy()
    for _ in range(3):
        out.fill_(np.nan)
        assert wt.splat(g, layers, maps, **options, out=out) is out
        np.testing.assert_array_equal(out.numpy(), want)
    assert len(_made("splat", g, layers, out="given")) == 1
    maps.assign(rng.random((1, 8, 8, 4), dtype=np.float32))  # in place: the plan reads the new weights
    np.testing.assert_array_equal(wt.splat(g, layers, maps, **options, out=out).numpy(), wt.splat(g, layers, maps, **options).numpy())
    other = wt.TextureArray(rng.random((1, 8, 8, 4), dtype=np.float32), mipmaps=False)  # another object: not served by the plan
    np.testing.assert_array_equal(wt.splat(g, layers, other, **options, out=out).numpy(), wt.splat(g, layers, other, **options).numpy())


def test_a_splat_plan_keeps_the_errors_and_follows_its_g_buffer():
    rng = np.random.default_rng(9)
    g, layers, maps = _splat_scene(rng)
    out = wp.empty((6, 5, 4), dtype=wp.float32)
    with pytest.raises(ValueError) as before:
        wt.splat(g, layers, maps, height_blend=0.2, height_channel=True, out=out)
    for _ in range(3):
        wt.splat(g, layers, maps, height_blend=0.2, height_channel=1, out=out)
    with pytest.raises(ValueError) as after:  # True == 1: a key that compared by value would hit
        wt.splat(g, layers, maps, height_blend=0.2, height_channel=True, out=out)
    assert str(after.value) == str(before.value)
    g.uv_sets["uv0"]["uv"] = wp.array(rng.random((6, 5, 2), dtype=np.float32), dtype=wp.vec2)  # a new array: the plan does not apply
    np.testing.assert_array_equal(wt.splat(g, layers, maps, height_blend=0.2, height_channel=1, out=out).numpy(), wt.splat(g, layers, maps, height_blend=0.2, height_channel=1).numpy())


def test_splats_packed_arguments_go_with_their_maps():
    """A splat into a new output reuses the arguments an earlier call packed for the same layers,
    maps and options; they hold the maps' arrays, so they go when the maps do, and a new maps
    object (an id may be reused) is packed anew."""
    from warptex import _pack

    rng = np.random.default_rng(10)
    g, layers, maps = _splat_scene(rng)
    data = [rng.random((1, 8, 8, 4), dtype=np.float32) for _ in range(3)]
    maps = wt.TextureArray(data[0], mipmaps=False)
    first = wt.splat(g, layers, maps).numpy()
    np.testing.assert_array_equal(wt.splat(g, layers, maps).numpy(), first)
    assert len(_pack._packed.get(layers, {})) == 1
    held = weakref.ref(maps.view.texels)
    del maps
    gc.collect()
    assert not _pack._packed.get(layers) and held() is None, "the packed arguments went with the maps, and held none of their arrays"
    for values in data[1:]:
        maps = wt.TextureArray(values, mipmaps=False)
        fresh = wt.splat(g, wt.TextureArray(layers.numpy(0)), maps).numpy()  # other layers: nothing kept applies
        np.testing.assert_array_equal(wt.splat(g, layers, maps).numpy(), fresh)
        del maps


def test_normal_mappings_packed_arguments_follow_its_options():
    """triplanar_normal and biplanar_normal reuse the arguments an earlier call packed for the same
    normal map and options; the normal map's own options (blend, strength, flip_green) are part
    of what is kept, so a call that changes one is packed anew, and a refused call stays refused."""
    rng = np.random.default_rng(12)
    g = wt.GBuffer.empty((6, 5))
    g.position.assign(rng.random((6, 5, 3), dtype=np.float32))
    g.normal.assign(rng.normal(size=(6, 5, 3)).astype(np.float32))
    g.mask.fill_(1)
    image = rng.random((16, 16, 3), dtype=np.float32)
    normal_map = wt.Texture(image)
    variants = [{}, {"strength": 0.5}, {"flip_green": True}, {"blend": "rnm"}, {"strength": 0.5, "blend": "udn"}, {}]
    for func in (wt.triplanar_normal, wt.biplanar_normal):
        for options in variants:
            for _ in range(2):
                np.testing.assert_array_equal(func(g, normal_map, tiling=1.5, **options).numpy(), func(g, wt.Texture(image), tiling=1.5, **options).numpy())
    grey = wt.Texture(image[..., :1])
    for _ in range(2):
        with pytest.raises(ValueError, match="a normal map needs 2 to 4 channels, got 1"):
            wt.triplanar_normal(g, grey)


def _new_output_plans() -> list:
    return [p for (_key, out, *_), p in _plans().items() if p.cmd is not None and out is None]


@pytest.mark.parametrize(("sampler", "lod"), [(None, None), (wt.Sampler(filter="nearest", address="border", border=(1, 2, 3, 4)), None), (wt.Sampler(filter="trilinear"), 0.7)])
@pytest.mark.parametrize("shape", [(300,), (20, 15)])
def test_a_plan_without_out_makes_a_new_output_each_call(inputs, sampler, lod, shape):
    """Without ``out=``, a kept plan gives each call a new array, of the call's shape and bits,
    leaves the arrays of earlier calls as they were, and keeps at most ``SPARES`` of them alive,
    until the plan goes."""
    _, uv, rng = inputs
    texture = wt.Texture(rng.random((64, 48, 4), dtype=np.float32))
    uv = uv.reshape(shape)
    want = wt.sample(texture, uv, sampler=sampler, lod=lod).numpy()
    results = [wt.sample(texture, uv, sampler=sampler, lod=lod) for _ in range(4)]
    assert len(_new_output_plans()) == 1
    assert len({id(r) for r in results}) == 4
    for r in results:
        assert r.shape == (*shape, 4) and r.dtype == wp.float32 and not r.requires_grad
        np.testing.assert_array_equal(r.numpy(), want)
    held = [weakref.ref(r) for r in results]
    del results, r
    gc.collect()
    assert sum(h() is not None for h in held) == _plan.SPARES  # the plan's spares
    del texture
    gc.collect()
    assert all(h() is None for h in held)  # gone with the plan


def _loop(call, steps: int) -> tuple[list, np.ndarray]:
    """``y = call()`` ``steps`` times, as a loop does: its outputs (weakly), and the last's values."""
    got = []
    for _ in range(steps):
        y = call()
        got.append(weakref.ref(y))
    return got, y.numpy()


def _holders():
    """Ways a caller keeps a result without naming it: each, what it shows of the result now."""
    yield "a view", lambda y: y[1:3], lambda h: h.numpy()
    yield "a reshape", lambda y: y.reshape((-1,)), lambda h: h.numpy()
    yield "numpy()", lambda y: y.numpy(), lambda h: h
    yield "np.asarray", np.asarray, lambda h: h
    yield "a list", lambda y: [y], lambda h: h[0].numpy()


@pytest.mark.parametrize("holder", [h[0] for h in _holders()] + ["wp.to_torch"])
def test_a_new_output_is_written_again_only_once_nothing_refers_to_it(inputs, holder):
    """A loop's dropped outputs are written again (the loop settles on a few arrays, each call's
    bits right), and an output that anything still refers to, however indirectly, never is."""
    texture, uv, rng = inputs
    want = wt.sample(texture, uv).numpy()
    got, last = _loop(lambda: wt.sample(texture, uv), 12)
    outputs = [r() for r in got[4:]]  # the plan's, once made (by the second call)
    assert all(o is not None for o in outputs) and len({id(o) for o in outputs}) == _plan.SPARES  # live: its spares, in turn
    np.testing.assert_array_equal(last, want)
    if holder == "wp.to_torch":
        pytest.importorskip("torch")
        hold, show = wp.to_torch, lambda h: h.numpy()
    else:
        hold, show = next((h, s) for name, h, s in _holders() if name == holder)
    kept = hold(wt.sample(texture, uv))
    before = np.array(show(kept), copy=True)
    other = wp.array(rng.random((300, 2), dtype=np.float32), dtype=wp.vec2)
    uv.assign(other)  # the calls below write other values
    for _ in range(6):
        np.testing.assert_array_equal(wt.sample(texture, uv).numpy(), wt.sample(texture, other).numpy())
    np.testing.assert_array_equal(show(kept), before)


def test_spares_are_small_outputs(inputs):
    texture, _, rng = inputs
    big = _plan.SPARE_BYTES // 16 + 1  # rows of 4 floats: just over
    for rows, kept in ((300, True), (big, False)):
        uv = wp.array(rng.random((rows, 2), dtype=np.float32), dtype=wp.vec2)
        for _ in range(4):
            wt.sample(texture, uv)
        plans = [p for p in _new_output_plans() if p.like[0] == (rows, 4)]
        assert len(plans) == 1 and bool(plans[0].spares) == kept


@pytest.mark.parametrize("held", ["nothing", "its gradient", "a view of its gradient", "a new gradient"])
def test_a_spare_with_a_gradient_is_written_again_only_once_nothing_refers_to_either(inputs, held):
    """An output that requires gradients comes back with a zero gradient, and is not written
    again while its gradient is held, or where the caller gave it another gradient."""
    texture, uv, _ = inputs
    fitted = wt.Texture(texture.texels.numpy(), requires_grad=True)
    for _ in range(4):
        wt.sample(fitted, uv)
    y = wt.sample(fitted, uv)
    y.grad.fill_(7.0)
    keep = {"nothing": None, "its gradient": y.grad, "a view of its gradient": y.grad[2:5]}.get(held)
    if held == "a new gradient":
        y.grad = keep = wp.full(y.shape, 7.0, dtype=wp.float32)
    used = weakref.ref(y)
    del y
    got = [wt.sample(fitted, uv) for _ in range(_plan.SPARES)]
    assert any(g is used() for g in got) == (held == "nothing")
    for g in got:
        assert g.requires_grad and not g.grad.numpy().any()
        np.testing.assert_array_equal(g.numpy(), wt.sample(texture, uv).numpy())
    if keep is not None:
        assert (keep.numpy() == 7.0).all()


@pytest.mark.skipif(tuple(map(int, wp.config.version.split(".")[:2])) < (1, 19), reason="CPU graph capture came with Warp 1.19")
def test_a_kept_call_is_recorded_by_a_cpu_graph_capture(inputs):
    """Within a CPU graph capture a call that has a plan takes its usual path, which the capture
    records (a plan's launch keeps addresses only, which a capture cannot record)."""
    texture, uv, _ = inputs
    out = wp.zeros((300, 4), dtype=wp.float32)
    for _ in range(3):
        wt.sample(texture, uv, out=out)
    want = out.numpy().copy()
    out.zero_()
    with wp.ScopedCapture(device="cpu") as capture:
        wt.sample(texture, uv, out=out)
    out.zero_()
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(out.numpy(), want)


def test_a_new_output_plan_keeps_the_outputs_requires_grad(inputs):
    """A texture that requires gradients gives outputs that do, outside a tape too; a plan's new
    outputs as well, with zero gradients."""
    texture, uv, _ = inputs
    fitted = wt.Texture(texture.texels.numpy(), requires_grad=True)
    for _ in range(4):
        r = wt.sample(fitted, uv)
        assert r.requires_grad and r.grad is not None and not r.grad.numpy().any()
    assert len(_new_output_plans()) == 1
    np.testing.assert_array_equal(r.numpy(), wt.sample(texture, uv).numpy())


@pytest.mark.parametrize("func", ["triplanar", "biplanar", "splat"])
def test_projection_and_splat_plans_without_out_give_the_calls_bits(func):
    """New outputs from a kept plan on a G-buffer with uncovered pixels: the call's shape and bits
    (0 where uncovered, whichever kernel ran)."""
    rng = np.random.default_rng(6)
    g, layers, maps = _splat_scene(rng)
    mask = np.ones((6, 5), np.float32)
    mask[2:4, 1:3] = 0.0
    g.mask.assign(mask)
    if func == "splat":
        call = lambda: wt.splat(g, layers, maps, tiling=2)  # noqa: E731
    else:
        call = lambda: getattr(wt, func)(g, layers, tiling=1.5, layer=1)  # noqa: E731
    want = call().numpy()
    assert not want[2:4, 1:3].any()
    results = [call() for _ in range(4)]
    assert len(_new_output_plans()) == 1 and len({id(r) for r in results}) == 4
    for r in results:
        np.testing.assert_array_equal(r.numpy(), want)
