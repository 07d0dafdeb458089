"""Forward sampling: texel-centre exactness, NumPy-reference agreement, LOD rules, bad input."""

import gc

import numpy as np
import pytest
import warp as wp

import reference as ref
import warptex as wt
from conftest import with_sampler
from warptex.kernels import native
from warptex.kernels.footprint import lod_log2

BORDER = (0.25, 0.5, 0.75, 1.0)


def _image(rng, h, w, c=4):
    return rng.random((h, w, c), dtype=np.float32)


def _sample(tex, uv, **kw):
    return wt.sample(tex, uv, **with_sampler(kw)).numpy()


# -- texel centres ----------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ref.MODES)
@pytest.mark.parametrize("filt", ["nearest", "bilinear"])
def test_texel_centres_are_exact(rng, mode, filt):
    # Power-of-two sizes: texel-centre UVs are exact in float32, so the lookup must be bit-exact.
    img = _image(rng, 8, 16)
    out = _sample(wt.Texture(img), ref.texel_centres(8, 16), filter=filt, address=mode)
    np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize("filt", ["nearest", "bilinear"])
def test_texel_centres_non_power_of_two(rng, filt):
    # (j + 0.5) / 7 is not representable: the lookup is exact up to that rounding.
    img = _image(rng, 5, 7, 3)
    out = _sample(wt.Texture(img), ref.texel_centres(5, 7), filter=filt)
    np.testing.assert_allclose(out, img, atol=1e-6, rtol=0)


def test_row_zero_is_the_top_of_the_image():
    img = np.zeros((4, 4, 1), np.float32)
    img[0] = 1.0  # top row
    tex = wt.Texture(img)
    top, bottom = _sample(tex, [[0.5, 0.99], [0.5, 0.01]], filter="nearest")[:, 0]
    assert top == 1.0 and bottom == 0.0


# -- agreement with the NumPy reference ------------------------------------------------------------


def _random_uvs(rng, h, w):
    """Random UVs near the texture, far outside it (±1000), and exactly on texel borders."""
    near = rng.uniform(-2.0, 3.0, (400, 2))
    far = rng.uniform(-1000.0, 1000.0, (400, 2))
    cols, rows = rng.integers(-2 * w, 3 * w, 200), rng.integers(-2 * h, 3 * h, 200)
    borders = np.stack([cols / w, 1.0 - rows / h], axis=-1)  # texel corners: bilinear weights 0/1
    edges = np.array([[0, 0], [1, 1], [0, 1], [1, 0], [-1, 2], [1000, -1000], [-0.0, 0.5]])
    return np.concatenate([near, far, borders, edges]).astype(np.float32)


@pytest.mark.parametrize("mode", ref.MODES)
@pytest.mark.parametrize("size", [(8, 8), (13, 17), (1, 5)])
def test_bilinear_matches_reference(rng, mode, size):
    img = _image(rng, *size)
    uv = _random_uvs(rng, *size)
    out = _sample(wt.Texture(img), uv, filter="bilinear", address=mode, border=BORDER)
    np.testing.assert_allclose(out, ref.bilinear(img, uv, mode, BORDER), atol=1e-5, rtol=0)


@pytest.mark.parametrize("mode", ref.MODES)
def test_nearest_matches_reference(rng, mode):
    img = _image(rng, 9, 6)
    # Random UVs only: exactly on a texel border, float32 and float64 may pick different sides.
    uv = np.concatenate([rng.uniform(-3, 4, (500, 2)), rng.uniform(-1000, 1000, (500, 2))]).astype(np.float32)
    out = _sample(wt.Texture(img), uv, filter="nearest", address=mode, border=BORDER)
    expected = ref.nearest(img, uv, mode, BORDER)
    # Far from the origin, u * w rounds in float32: allow a handful of UVs that sit within
    # float32 rounding of a texel border to land on the neighbour.
    x = np.concatenate([np.asarray(uv, np.float64)[:, 0] * 6, (1 - np.asarray(uv, np.float64)[:, 1]) * 9])
    ambiguous = np.abs(x - np.round(x)).reshape(2, -1).min(axis=0) < 1e-3
    np.testing.assert_array_equal(out[~ambiguous], expected[~ambiguous])
    assert ambiguous.mean() < 0.01


def test_border_colour_uses_the_texture_channels(rng):
    tex = wt.Texture(_image(rng, 4, 4, 2))
    out = _sample(tex, [[-5.0, -5.0]], address="border", border=(0.1, 0.2))
    np.testing.assert_allclose(out, [[0.1, 0.2]], rtol=0, atol=1e-7)


# -- mip chains and trilinear filtering -------------------------------------------------------------


@pytest.mark.parametrize("size", [(64, 64), (37, 23), (1, 9), (6, 1)])
def test_mip_chain_matches_box_filter(rng, size):
    img = _image(rng, *size, 3)
    tex = wt.Texture(img)
    expected = ref.mip_chain(img)
    assert tex.level_sizes == [level.shape[:2] for level in expected]
    for k, level in enumerate(expected):
        np.testing.assert_allclose(tex.numpy(k), level, atol=1e-6, rtol=0)


def test_mip_chain_preserves_the_mean_of_even_levels(rng):
    img = _image(rng, 32, 48, 1)
    tex = wt.Texture(img)
    for k in range(tex.num_levels):
        np.testing.assert_allclose(tex.numpy(k).mean(), img.mean(), rtol=1e-5)


@pytest.mark.parametrize("size", [(16, 16), (21, 10)])
def test_constant_texture_is_constant_at_every_lod(size):
    colour = np.array([0.2, 0.4, 0.6, 0.8], np.float32)
    tex = wt.Texture(np.broadcast_to(colour, (*size, 4)))
    uv = np.random.default_rng(0).uniform(-3, 3, (300, 2)).astype(np.float32)
    for lod in np.linspace(-1.0, tex.num_levels + 1.0, 17):
        for mode in ("wrap", "clamp", "mirror"):
            np.testing.assert_allclose(_sample(tex, uv, lod=float(lod), address=mode), np.broadcast_to(colour, (300, 4)), atol=1e-6)


@pytest.mark.parametrize("mode", ["wrap", "clamp", "mirror"])
def test_level_k_lookup_is_bilinear_on_the_kth_box_level(rng, mode):
    img = _image(rng, 40, 24)
    tex = wt.Texture(img)
    chain = ref.mip_chain(img)
    uv = rng.uniform(-2, 3, (300, 2)).astype(np.float32)
    for k in range(tex.num_levels):
        out = _sample(tex, uv, lod=float(k), filter="trilinear", address=mode)
        np.testing.assert_allclose(out, ref.bilinear(chain[k], uv, mode), atol=1e-5, rtol=0)


def test_trilinear_matches_reference_between_levels(rng):
    img = _image(rng, 32, 20)
    tex = wt.Texture(img)
    uv = rng.uniform(-2, 3, (500, 2)).astype(np.float32)
    lod = rng.uniform(-1, tex.num_levels + 1, 500).astype(np.float32)
    out = _sample(tex, uv, lod=lod)
    np.testing.assert_allclose(out, ref.trilinear(ref.mip_chain(img), uv, lod), atol=1e-5, rtol=0)


def test_lod_from_derivatives_is_log2_of_the_footprint(rng):
    h, w = 64, 32
    img = _image(rng, h, w)
    tex = wt.Texture(img)
    uv = rng.uniform(0, 1, (400, 2)).astype(np.float32)
    scale = 2.0 ** rng.uniform(-9, 1, (400, 1))
    dx = (rng.normal(size=(400, 2)) * scale).astype(np.float32)
    dy = (rng.normal(size=(400, 2)) * scale).astype(np.float32)
    lod = ref.lod_from_derivatives(dx, dy, h, w)
    out = _sample(tex, uv, uv_dx=dx, uv_dy=dy)
    np.testing.assert_allclose(out, ref.trilinear(ref.mip_chain(img), uv, lod), atol=1e-5, rtol=0)
    # An axis-aligned footprint of exactly 4 texels is LOD 2: level 2 alone.
    out = _sample(tex, uv, uv_dx=np.tile([[4.0 / w, 0.0]], (400, 1)), uv_dy=np.zeros((400, 2)))
    np.testing.assert_allclose(out, ref.bilinear(ref.mip_chain(img)[2], uv), atol=1e-5, rtol=0)


def test_zero_derivatives_read_level_zero(rng):
    img = _image(rng, 16, 16)
    uv = rng.uniform(0, 1, (50, 2)).astype(np.float32)
    zeros = np.zeros_like(uv)
    out = _sample(wt.Texture(img), uv, uv_dx=zeros, uv_dy=zeros)
    np.testing.assert_allclose(out, ref.bilinear(img, uv), atol=1e-6)


def test_lod_bias_and_clamp(rng):
    img = _image(rng, 64, 64)
    tex = wt.Texture(img)
    chain = ref.mip_chain(img)
    uv = rng.uniform(0, 1, (100, 2)).astype(np.float32)
    biased = _sample(tex, uv, lod=0.25, lod_bias=1.5)
    np.testing.assert_allclose(biased, ref.trilinear(chain, uv, 1.75), atol=1e-5)
    clamped = _sample(tex, uv, lod=5.0, max_lod=2.5)
    np.testing.assert_allclose(clamped, ref.trilinear(chain, uv, 2.5), atol=1e-5)
    raised = _sample(tex, uv, lod=0.0, min_lod=1.0)
    np.testing.assert_allclose(raised, ref.bilinear(chain[1], uv), atol=1e-5)
    past_the_end = _sample(tex, uv, lod=40.0)
    np.testing.assert_allclose(past_the_end, np.broadcast_to(chain[-1][0, 0], (100, 4)), atol=1e-5)


def test_bilinear_with_lod_reads_the_nearest_level(rng):
    img = _image(rng, 16, 16)
    chain = ref.mip_chain(img)
    uv = rng.uniform(0, 1, (100, 2)).astype(np.float32)
    out = _sample(wt.Texture(img), uv, lod=1.6, filter="bilinear")
    np.testing.assert_allclose(out, ref.bilinear(chain[2], uv), atol=1e-5)

@pytest.mark.parametrize("filt", ["nearest", "bilinear", "trilinear"])
def test_one_lod_for_all_reads_as_per_sample_lods(rng, filt):
    # A number as lod= has its levels resolved on the host (sample_level_kernel); an array of the
    # same value goes through the per-sample kernel. Both must read the same levels, bit for bit,
    # through the bias and clamps, at rounding boundaries (x.5) and past both ends of the chain.
    tex = wt.Texture(_image(rng, 24, 40), requires_grad=True)
    uv = np.concatenate([rng.uniform(-2, 3, (200, 2)), [[np.nan, 0.5]]]).astype(np.float32)
    cases = [(lod, {}) for lod in (-3.0, 0.0, 0.49999997, 0.5, 1.25, 2.5, 3.999, 40.0)]
    cases += [(0.25, {"lod_bias": 1.5}), (5.0, {"max_lod": 2.5}), (0.0, {"min_lod": 1.0}), (1.1, {"lod_bias": -0.6, "min_lod": -1.0, "max_lod": 4.0})]
    for lod, kw in cases:
        one = _sample(tex, uv, lod=lod, filter=filt, **kw)
        each = _sample(tex, uv, lod=np.full(len(uv), lod, np.float32), filter=filt, **kw)
        np.testing.assert_array_equal(one, each, err_msg=f"lod={lod} {kw}")
    no_lod = _sample(tex, uv, filter="bilinear" if filt == "trilinear" else filt)
    np.testing.assert_array_equal(no_lod, _sample(tex, uv, lod=np.zeros(len(uv), np.float32), filter="bilinear" if filt == "trilinear" else filt))



def test_options_on_one_texture_each_read_their_own(rng):
    # sample() packs a texture's arguments once per set of options (warptex._pack.packed): calls on
    # one texture that alternate sampler, LOD and layer must each read what a fresh texture reads.
    layers = rng.random((2, 16, 16, 4), dtype=np.float32)
    shared = wt.TextureArray(layers)
    uv = rng.uniform(-1, 2, (300, 2)).astype(np.float32)
    cases = [
        {"layer": 0}, {"layer": 1}, {"layer": 1, "lod": 1.25}, {"layer": 1, "lod": 2.0}, {"layer": 0, "lod": 1.25},
        {"layer": 1, "lod": 1.25, "filter": "bilinear"}, {"layer": 1, "address": "clamp"}, {"layer": 1, "address": "border", "border": BORDER},
        {"layer": 1, "lod": 1.25, "lod_bias": 0.5}, {"layer": 0, "filter": "nearest"},
    ]
    for rounds in range(2):
        for kw in cases:
            fresh = _sample(wt.TextureArray(layers), uv, **kw)
            np.testing.assert_array_equal(_sample(shared, uv, **kw), fresh, err_msg=f"round {rounds}: {kw}")


def test_packed_arguments_are_shared_bounded_and_dropped_with_their_texture(rng):
    from warptex import _pack

    tex = wt.Texture(_image(rng, 8, 8))
    uv = rng.random((10, 2)).astype(np.float32)
    wt.sample(tex, uv)
    (first,) = _pack._packed[tex].values()
    wt.sample(tex, uv)
    assert _pack._packed[tex] == {next(iter(_pack._packed[tex])): first}  # the same arguments, not a new set
    for k in range(3 * _pack.MAX_PACKED_PER_OWNER):  # a sweep through many LODs keeps the newest few
        wt.sample(tex, uv, lod=k / 8)
    assert len(_pack._packed[tex]) == _pack.MAX_PACKED_PER_OWNER
    owners = len(_pack._packed)
    del tex
    gc.collect()
    assert len(_pack._packed) == owners - 1


def test_a_packed_entry_dropped_with_the_last_reference_to_another_entrys_object_does_not_hang():
    """An entry pushed out of a full table can hold the last reference to an object that another
    entry's key names weakly; that object's callback, on the same thread, drops its entry too
    while the table's lock is held (a plain lock hung the texel gradients' kept structs)."""
    import threading

    from warptex import _pack

    class Owner:
        pass

    class Held:
        pass

    owner = Owner()

    def fill():
        for k in range(2 * _pack.MAX_PACKED_PER_OWNER):
            held = Held()
            _pack.packed(owner, ("entry", k), lambda held=held: [held], weakly=[held])  # its value holds what its key names weakly
            del held

    worker = threading.Thread(target=fill, daemon=True)
    worker.start()
    worker.join(timeout=30)
    assert not worker.is_alive(), "packed() hung"
    assert len(_pack._packed[owner]) == _pack.MAX_PACKED_PER_OWNER


def test_output_keeps_the_uv_shape(rng):
    tex = wt.Texture(_image(rng, 4, 4, 3))
    out = wt.sample(tex, rng.random((5, 6, 2)))
    assert out.shape == (5, 6, 3) and out.dtype == wp.float32
    assert wt.sample(tex, np.zeros((0, 2))).shape == (0, 3)


# -- texture arrays -----------------------------------------------------------------------------------


def test_texture_array_layers_sample_like_single_textures(rng):
    layers = rng.random((3, 12, 10, 2), dtype=np.float32)
    arr = wt.TextureArray(layers)
    uv = rng.uniform(-1, 2, (200, 2)).astype(np.float32)
    for k in range(3):
        single = _sample(wt.Texture(layers[k]), uv, lod=1.3)
        np.testing.assert_allclose(_sample(arr, uv, layer=k, lod=1.3), single, atol=1e-6)
        np.testing.assert_allclose(arr.numpy(1)[k], ref.mip_chain(layers[k])[1], atol=1e-6)
    per_sample = rng.integers(0, 3, 200)
    out = _sample(arr, uv, layer=per_sample, filter="nearest")
    for k in range(3):
        np.testing.assert_array_equal(out[per_sample == k], _sample(arr, uv[per_sample == k], layer=k, filter="nearest"))


def test_per_sample_layers_out_of_range_are_clamped(rng):
    layers = rng.random((2, 4, 4, 1), dtype=np.float32)
    arr = wt.TextureArray(layers)
    uv = ref.texel_centres(4, 4).reshape(-1, 2)
    out = _sample(arr, uv, layer=np.full(16, 7), filter="nearest")
    np.testing.assert_array_equal(out, layers[1].reshape(-1, 1))


# -- non-finite input -----------------------------------------------------------------------------------


def test_non_finite_uvs_give_nan_and_never_crash(rng):
    tex = wt.Texture(_image(rng, 8, 8), requires_grad=True)
    uv = np.array([[np.nan, 0.5], [0.5, np.inf], [-np.inf, -np.inf], [0.5, 0.5]], np.float32)
    for mode in ref.MODES:
        for kw in ({}, {"lod": 1.0}, {"filter": "nearest"}):
            out = _sample(tex, uv, address=mode, **kw)
            assert np.isnan(out[:3]).all() and np.isfinite(out[3]).all()


def test_derivatives_nan_give_nan_and_huge_give_the_coarsest_level(rng):
    """A NaN derivative is a NaN LOD (as a NaN ``lod`` is); derivatives too large for their squared
    length to be a float (a tiling of 1e30) read the coarsest level, never NaN."""
    image = _image(rng, 16, 16)
    tex = wt.Texture(image)
    uv = rng.uniform(-2, 3, (6, 2)).astype(np.float32)
    small = np.full((6, 2), 0.01, np.float32)
    nan_dx = small.copy()
    nan_dx[1, 0] = np.nan
    out = wt.sample(tex, uv, uv_dx=nan_dx, uv_dy=small).numpy()
    assert np.isnan(out[1]).all() and np.isfinite(np.delete(out, 1, axis=0)).all()
    out = wt.sample(tex, uv, uv_dy=nan_dx, uv_dx=small).numpy()
    assert np.isnan(out[1]).all()
    coarsest = image.mean(axis=(0, 1))  # the 1x1 level of a power-of-two chain
    for scale in (1e19, 1e25, 3e38):
        out = wt.sample(tex, uv, uv_dx=small * scale, uv_dy=small).numpy()
        np.testing.assert_allclose(out, np.broadcast_to(coarsest, out.shape), rtol=1e-5)


# -- bad input ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        ({"uv": np.zeros((4, 3))}, ValueError, r"sample\(\): uv must have shape \(\.\.\., 2\), got \(4, 3\)"),
        ({"uv": np.zeros(2, dtype=object)}, TypeError, r"sample\(\): uv must hold real numbers"),
        ({"uv": wp.zeros(4, dtype=wp.vec3)}, TypeError, r"sample\(\): uv must be a wp.array of wp.vec2"),
        ({"sampler": "bilinear"}, TypeError, r"sample\(\): sampler must be a warptex.Sampler or None, got str"),
        ({"sampler": wt.Sampler(filter="trilinear")}, ValueError, r"sample\(\): filter='trilinear' needs lod="),
        ({"lod": 1.0, "uv_dx": np.zeros((4, 2)), "uv_dy": np.zeros((4, 2))}, ValueError, "either lod= or uv_dx="),
        ({"uv_dx": np.zeros((4, 2))}, ValueError, "uv_dx and uv_dy must be given together"),
        ({"uv_dx": np.zeros((3, 2)), "uv_dy": np.zeros((3, 2))}, ValueError, r"uv_dx must have the shape of uv"),
        ({"lod": np.zeros(5)}, ValueError, r"sample\(\): lod must have shape \(4,\)"),
        ({"lod": float("nan")}, ValueError, r"sample\(\): lod must be finite, got nan"),
        ({"layer": 1}, ValueError, r"sample\(\): layer must be in \[0, 0\], got 1"),
        ({"layer": np.zeros(4)}, TypeError, r"sample\(\): layer must hold integers"),
        ({"device": "cuda:7"}, (ValueError, RuntimeError), r"cuda"),
    ],
)
def test_bad_arguments_raise_naming_the_value(kwargs, error, match):
    tex = wt.Texture(np.ones((4, 4, 3), np.float32))
    kwargs = {"uv": np.zeros((4, 2), np.float32), **kwargs}
    uv = kwargs.pop("uv")
    with pytest.raises(error, match=match):
        wt.sample(tex, uv, **kwargs)


@pytest.mark.parametrize(
    "fields, error, match",
    [
        ({"filter": "cubic"}, ValueError, r"Sampler\(\): filter must be one of .*'cubic'"),
        ({"address": "repeat"}, ValueError, r"Sampler\(\): address must be one of .*'repeat'"),
        ({"lod_bias": "1"}, TypeError, r"Sampler\(\): lod_bias must be a number"),
        ({"lod_bias": float("inf")}, ValueError, r"Sampler\(\): lod_bias must be finite"),
        ({"min_lod": float("nan")}, ValueError, r"Sampler\(\): min_lod must be finite, got nan"),
        ({"min_lod": 3.0, "max_lod": 1.0}, ValueError, r"Sampler\(\): min_lod \(3.0\) must not exceed max_lod"),
        ({"border": (1, 2, 3, 4, 5)}, ValueError, r"Sampler\(\): border must be 1 to 4 finite numbers"),
        ({"border": (0.5, np.nan)}, ValueError, r"Sampler\(\): border must be 1 to 4 finite numbers"),
    ],
)
def test_bad_sampler_fields_raise_naming_the_value(fields, error, match):
    with pytest.raises(error, match=match):
        wt.Sampler(**fields)


def test_sampler_normalises_its_fields_and_replace_checks_them():
    smp = wt.Sampler(filter="NEAREST", address="mirror", border=(0.5, 0.25), max_lod=3)
    assert smp.filter is wt.Filter.NEAREST and smp.address is wt.Address.MIRROR
    assert smp.border == (0.5, 0.25, 0.0, 0.0) and smp.max_lod == 3.0 and isinstance(smp.max_lod, float)
    assert smp.replace(lod_bias=1.0).lod_bias == 1.0 and smp.lod_bias == 0.0
    with pytest.raises(ValueError, match=r"Sampler\(\): min_lod \(4.0\) must not exceed max_lod \(3.0\)"):
        smp.replace(min_lod=4.0)


def test_sample_refuses_non_textures():
    with pytest.raises(TypeError, match=r"sample\(\): texture must be a Texture or TextureArray, got ndarray"):
        wt.sample(np.ones((4, 4, 3)), np.zeros((1, 2)))


def test_texture_array_needs_a_layer():
    arr = wt.TextureArray(np.ones((2, 4, 4, 1), np.float32))
    with pytest.raises(ValueError, match=r"sample\(\): layer is required for a TextureArray of 2 layers"):
        wt.sample(arr, np.zeros((1, 2)))


# -- the LODs' log2 ------------------------------------------------------------------------------------


@wp.kernel(module=native.use("tests.lod_log2"))  # lod_log2's CPU code is in the native headers
def _lod_log2_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = lod_log2(x[i])


def _lod_log2(x: np.ndarray) -> np.ndarray:
    out = wp.empty(len(x), dtype=float, device="cpu")
    wp.launch(_lod_log2_kernel, len(x), [wp.array(x, dtype=float, device="cpu"), out], device="cpu")
    return out.numpy()


def test_lod_log2_is_log2_to_the_nearest_float_but_at_its_hardest_cases(rng):
    """The CPU's own log2 (``wt_log2`` of native/wt_log2.h, which the CPU lanes compute a lane at a time): every float
    in [0.5, 2) (its 16 subintervals, both sides of 1) and random ones from 1e-38 to 3e38, against
    float64 NumPy rounded to float32: within one ulp everywhere, the nearest float for 99.95% of the
    first and 99.998% of the second (glibc's log2f here: 99.0% and 99.98%), exact at powers of two."""
    mantissas = np.arange(1 << 23, dtype=np.uint32)
    ones = (mantissas | np.uint32(0x3F800000)).view(np.float32)
    for x, nearest in ((np.concatenate([ones, ones * np.float32(0.5)]), 0.9995), (np.exp2(rng.uniform(-125.9, 127.9, 1 << 20)).astype(np.float32), 0.99998)):
        want = np.log2(x.astype(np.float64)).astype(np.float32)
        ulps = np.abs(_lod_log2(x).view(np.int32).astype(np.int64) - want.view(np.int32))
        assert ulps.max() <= 1
        assert (ulps == 0).mean() > nearest
    powers = np.exp2(np.arange(-126, 128, dtype=np.float64)).astype(np.float32)
    np.testing.assert_array_equal(_lod_log2(powers), np.arange(-126, 128, dtype=np.float32))


def test_lod_log2_is_nan_outside_the_positive_normal_floats():
    odd = np.array([0.0, -0.0, -1.0, 1e-40, np.inf, -np.inf, np.nan], dtype=np.float32)
    assert np.isnan(_lod_log2(odd)).all()
