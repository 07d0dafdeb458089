"""``out=``: every sampling function fills a caller's buffer in place, with the same bits, the same
gradients and the same errors as a new output; a wrong buffer is refused before any work."""

import re

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex.scenes import terrain_camera
from warptex.scenes.terrain import terrain


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(7)
    g = wt.rasterize(terrain(resolution=(33, 33)), terrain_camera((12, 16)))
    texture = wt.Texture(rng.random((32, 32, 4), dtype=np.float32))
    normal_map = wt.Texture(np.concatenate([rng.uniform(0.3, 0.7, (32, 32, 2)), np.ones((32, 32, 1))], axis=2).astype(np.float32))
    layers = wt.TextureArray(rng.random((4, 16, 16, 3), dtype=np.float32))
    maps = rng.random((1, 9, 7, 4), dtype=np.float32)
    atlas = wt.pack_atlas(layers, gutter=2)
    indices, weights = wt.export_index_maps(maps, 2)
    uv = wp.array(rng.random((5, 3, 2), dtype=np.float32) * 3, dtype=wp.vec2)
    return {
        "sample": (lambda **kw: wt.sample(texture, uv, **kw), (5, 3, 4)),
        "sample one UV": (lambda **kw: wt.sample(texture, np.float32([0.3, 0.6]), **kw), (4,)),
        "stochastic": (lambda **kw: wt.stochastic(texture, uv, "hash4", **kw), (5, 3, 4)),
        "triplanar": (lambda **kw: wt.triplanar(g, texture, tiling=0.3, **kw), (12, 16, 4)),
        "biplanar": (lambda **kw: wt.biplanar(g, texture, tiling=0.3, **kw), (12, 16, 4)),
        "triplanar_normal": (lambda **kw: wt.triplanar_normal(g, normal_map, tiling=0.3, **kw), (12, 16, 3)),
        "biplanar_normal": (lambda **kw: wt.biplanar_normal(g, normal_map, tiling=0.3, **kw), (12, 16, 3)),
        "splat": (lambda **kw: wt.splat(g, layers, maps, projection="world_xz", tiling=0.2, **kw), (12, 16, 3)),
        "splat_atlas": (lambda **kw: wt.splat_atlas(g, atlas, indices, weights, **kw), (12, 16, 3)),
    }


CASES = ["sample", "sample one UV", "stochastic", "triplanar", "biplanar", "triplanar_normal", "biplanar_normal", "splat", "splat_atlas"]


@pytest.mark.parametrize("case", CASES)
def test_out_is_filled_in_place_with_the_same_bits(scene, case):
    call, shape = scene[case]
    want = call().numpy()
    assert want.shape == shape
    out = wp.full(shape, np.nan, dtype=wp.float32)  # stale contents must not show through
    for _ in range(2):  # reused, as a loop reuses it
        got = call(out=out)
        assert got is out
        np.testing.assert_array_equal(out.numpy(), want)


@pytest.mark.parametrize("case", ["sample", "triplanar", "splat"])
def test_out_carries_the_same_gradients(case):
    """Under a tape, a buffer made with ``requires_grad=True`` gives the texels the gradients a new
    output gives them; one without is refused (the tape would have no ``.grad`` to read), unchanged."""
    rng = np.random.default_rng(3)
    if case == "splat":
        texture = wt.TextureArray(rng.random((4, 16, 16, 3), dtype=np.float32), requires_grad=True)
        g = wt.rasterize(terrain(resolution=(33, 33)), terrain_camera((12, 16)))
        maps = rng.random((1, 9, 7, 4), dtype=np.float32)
        call, shape = (lambda **kw: wt.splat(g, texture, maps, projection="world_xz", tiling=0.2, **kw)), (12, 16, 3)
    else:
        texture = wt.Texture(rng.random((32, 32, 4), dtype=np.float32), requires_grad=True)
        if case == "sample":
            uv = wp.array(rng.random((5, 3, 2), dtype=np.float32) * 3, dtype=wp.vec2)
            call, shape = (lambda **kw: wt.sample(texture, uv, **kw)), (5, 3, 4)
        else:
            g = wt.rasterize(terrain(resolution=(33, 33)), terrain_camera((12, 16)))
            call, shape = (lambda **kw: wt.triplanar(g, texture, tiling=0.3, **kw)), (12, 16, 4)
    weights = wp.array(np.linspace(-1, 1, int(np.prod(shape)), dtype=np.float32).reshape(shape), dtype=wp.float32)

    def texel_grads(**kw):
        texture.view.texels.grad.zero_()  # the whole mip chain
        tape = wp.Tape()
        with tape:
            result = call(**kw)
        tape.backward(grads={result: weights})
        return texture.view.texels.grad.numpy().copy()

    want = texel_grads()
    assert np.abs(want).max() > 0
    out = wp.zeros(shape, dtype=wp.float32, requires_grad=True)
    np.testing.assert_array_equal(texel_grads(out=out), want)

    plain = wp.full(shape, 5.0, dtype=wp.float32)
    with wp.Tape(), pytest.raises(ValueError, match=r"out= must be made with requires_grad=True"):
        call(out=plain)
    np.testing.assert_array_equal(plain.numpy(), 5.0)


@pytest.mark.parametrize("case", CASES)
def test_a_wrong_out_is_refused_before_any_work(scene, case):
    call, shape = scene[case]
    func = case.split()[0]
    expected = re.escape(f"{func}(): out must be a contiguous float32 wp.array of shape {shape} on cpu, got ")
    wrong = {
        "a NumPy array": (np.zeros(shape, np.float32), TypeError, re.escape(f"{func}(): out must be a wp.array of float32, got ndarray")),
        "float64": (wp.zeros(shape, dtype=wp.float64), ValueError, expected + re.escape(f"float64 {shape} on cpu")),
        "another shape": (wp.zeros((*shape[:-1], shape[-1] + 1), dtype=wp.float32), ValueError, expected + re.escape(f"float32 {(*shape[:-1], shape[-1] + 1)} on cpu")),
        "a strided view": (wp.zeros((*shape[:-1], 2 * shape[-1]), dtype=wp.float32)[(slice(None),) * (len(shape) - 1) + (slice(None, None, 2),)], ValueError,
                           expected + re.escape(f"a non-contiguous float32 {shape} on cpu")),
    }
    for name, (out, error, message) in wrong.items():
        before = out.numpy().copy() if isinstance(out, wp.array) else out.copy()
        with pytest.raises(error, match=message):
            call(out=out)
        np.testing.assert_array_equal(out.numpy() if isinstance(out, wp.array) else out, before, err_msg=name)


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("lookup", ["one LOD", "a LOD per UV", "derivatives", "anisotropic"])
def test_samples_one_pixel_kernel_writes_every_entry(channels, lookup):
    """``sample``'s one-pixel kernel (CUDA's) writes every entry of its output, so a launch does not
    zero it first (``Kernels.fills``): an ``out=`` full of NaN, and one holding another call's
    values, come back as the lanes' output, bit for bit; so does the generated adjoint's forward."""
    from warptex._op import force_generated_adjoint, one_pixel_kernels

    rng = np.random.default_rng(11)
    texture = wt.Texture(rng.random((32, 32, channels), dtype=np.float32), requires_grad=True)
    uv = wp.array(rng.random((300, 2), dtype=np.float32) * 3 - 1, dtype=wp.vec2)
    kw = {"one LOD": {"lod": 1.5}, "a LOD per UV": {"lod": rng.uniform(-1, 5, 300).astype(np.float32)},
          "derivatives": {"uv_dx": rng.uniform(-0.05, 0.05, (300, 2)).astype(np.float32), "uv_dy": rng.uniform(-0.05, 0.05, (300, 2)).astype(np.float32)},
          "anisotropic": {"uv_dx": np.full((300, 2), [0.08, 0.0], np.float32), "uv_dy": np.full((300, 2), [0.0, 0.01], np.float32),
                          "sampler": wt.Sampler(filter="anisotropic")}}[lookup]  # fmt: skip
    want = wt.sample(texture, uv, **kw).numpy()
    with one_pixel_kernels(True):
        for fill in (np.nan, 7.0):
            out = wp.full((300, channels), fill, dtype=wp.float32)
            np.testing.assert_array_equal(wt.sample(texture, uv, out=out, **kw).numpy(), want)
        with wp.Tape(), force_generated_adjoint():
            out = wp.full((300, channels), np.nan, dtype=wp.float32, requires_grad=True)
            np.testing.assert_array_equal(wt.sample(texture, uv, out=out, **kw).numpy(), want)
