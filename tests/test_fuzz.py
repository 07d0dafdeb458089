"""Property-based fuzzing (hypothesis) of the public API and the file readers and writers.

The property every test checks: a call either raises a clear ``ValueError``/``TypeError``/``OSError``
whose message names the function (``"read_exr(): ..."``), or returns a well-formed result that is
finite for finite input; never a crash, a hang, another exception type, or (writers) a partial or
temporary file left behind.

Inputs: random shapes and dtypes of textures and G-buffers, UVs up to ±1e6 (and finite extremes,
1e30 to float max) with inf and NaN, zero, huge, tiny and NaN normals, random layer counts and sizes of texture arrays and splat maps, and
truncated or byte-flipped PNG / EXR / OBJ / PLY / STL / GLB files (made here with the library's
writers and trimesh, then corrupted).

Profiles: ``warptex-ci`` (derandomised, ``$WARPTEX_FUZZ_EXAMPLES`` examples per test, default 30) is
loaded unless another profile was chosen (``--hypothesis-profile``). A bigger run, with fresh random
inputs (``WARPTEX_FUZZ_RANDOM=1``; leave it out to repeat the CI inputs and more)::

    WARPTEX_FUZZ_EXAMPLES=300 WARPTEX_FUZZ_RANDOM=1 python -m pytest -q tests/test_fuzz.py --hypothesis-show-statistics

The twelve product bugs this file found (F1-F12: errors that named no function, a wrong output
shape, overflows to 0, inf or NaN from finite input) are fixed; their minimal reproducers stay at
the end of this file as regression tests (``test_finding_*``). A new finding goes into
:data:`KNOWN_FINDINGS` (tolerated by the property tests, narrowly, and counted as a hypothesis
event) with a strict ``xfail`` reproducer until it is fixed.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import tempfile
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")

import trimesh
import warp as wp
from hypothesis import HealthCheck, event, given, note, settings
from hypothesis import strategies as st

import warptex as wt
from warptex import io as wio
from warptex.gbuffer import FIELDS, UV_FIELDS, GBuffer

# -- settings ---------------------------------------------------------------------------------------

EXAMPLES = int(os.environ.get("WARPTEX_FUZZ_EXAMPLES", "30"))
settings.register_profile(
    "warptex-ci",
    derandomize=os.environ.get("WARPTEX_FUZZ_RANDOM", "") in ("", "0"),
    max_examples=EXAMPLES,
    deadline=None,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)
_chosen = getattr(settings, "get_current_profile_name", lambda: getattr(settings, "_current_profile", "default"))()
if _chosen == "default":  # not chosen with --hypothesis-profile
    settings.load_profile("warptex-ci")

#: Seconds one example may take before it counts as a hang (Python-level; a kernel is not interrupted).
HANG_SECONDS = 30
ALLOWED = (ValueError, TypeError, OSError)
INF, NAN = math.inf, math.nan


# -- the property -------------------------------------------------------------------------------------


class Hang(AssertionError):
    pass


@contextlib.contextmanager
def time_limit(seconds: float = HANG_SECONDS):
    """Fail with :class:`Hang` if the block runs longer than ``seconds`` (main thread only)."""

    def on_alarm(signum, frame):
        raise Hang(f"no result after {seconds} s: a hang")

    if not hasattr(signal, "setitimer"):  # Windows: no alarm
        yield
        return
    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


# Known, unfixed product bugs found by this file: id -> a predicate on the exception it raises. Each
# has a strict-xfail reproducer (``test_finding_<id>``); the property tests tolerate exactly these
# (counted as hypothesis events, see ``--hypothesis-show-statistics``) so that the file stays green
# and keeps looking for new ones. Delete an entry once the bug is fixed. None today.
KNOWN_FINDINGS: dict = {}


def call(names, fn, *args, known=(), **kwargs):
    """``fn(*args, **kwargs)``, or ``None`` when it raised a clear error: a ValueError, TypeError or
    OSError whose message names one of ``names`` (``"read_exr"`` -> ``"read_exr(): ..."``). Any other
    outcome (another exception type, a message that names no function, a hang) fails the test,
    unless it is one of the ``known`` findings (ids of :data:`KNOWN_FINDINGS`)."""
    names = (names,) if isinstance(names, str) else tuple(names)
    try:
        with time_limit():
            return fn(*args, **kwargs)
    except Hang:
        raise
    except Exception as err:
        message = str(err)
        for finding in known:
            if KNOWN_FINDINGS[finding](err):
                event(f"known finding {finding}")
                note(f"known finding {finding}: {type(err).__name__}: {message}")
                return None
        if not isinstance(err, ALLOWED):
            raise AssertionError(f"{' / '.join(names)}() raised {type(err).__name__} (not ValueError/TypeError/OSError): {message}") from err  # noqa: TRY004
        assert any(f"{n}()" in message for n in names), f"{type(err).__name__} does not name {' or '.join(names)}(): {message!r}"
        note(f"clear error: {type(err).__name__}: {message}")
        return None


def expect_error(names, fn, *args, **kwargs):
    """Like :func:`call`, but the call must fail (the input is invalid)."""
    result = call(names, fn, *args, **kwargs)
    assert result is None, f"{names}() accepted an invalid input and returned {type(result).__name__}"


def mips_may_overflow(data) -> bool:
    """Texels within a few times of float32's largest value: differences and sums of texels (UV
    gradients, blends of taps, histogram transforms) overflow to inf there, which float32 cannot
    avoid; such textures' outputs are not checked for finiteness. (The mip chain itself no longer
    overflows: it scales each texel before summing, finding F11.)"""
    if float(np.abs(np.asarray(data, np.float64)).max(initial=0.0)) > 8.5e37 / 4:
        event("texels near float32's largest value")
        return True
    return False


def assert_finite(values, what: str):
    bad = ~np.isfinite(values)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise AssertionError(f"{what}: non-finite output {values[where]} at {where} for finite input")


def assert_within(values, lo, hi, what: str, scale: float = 1.0):
    """``values`` inside ``[lo, hi]`` up to float32 rounding (a convex combination of texels)."""
    tol = 1e-4 * max(1.0, scale)
    assert values.min(initial=lo) >= lo - tol and values.max(initial=hi) <= hi + tol, (
        f"{what}: output range [{values.min()}, {values.max()}] leaves the input range [{lo}, {hi}]"
    )


# -- strategies ---------------------------------------------------------------------------------------

SPECIAL_COORDS = [0.0, -0.0, 0.5, 1.0, -1.0, 1e-30, 0.999999, 1e6, -1e6, 123456.78, INF, -INF, NAN]
coords = st.one_of(st.floats(-1e6, 1e6, width=32), st.sampled_from(SPECIAL_COORDS))
finite_coords = st.one_of(st.floats(-1e6, 1e6, width=32), st.sampled_from([c for c in SPECIAL_COORDS if math.isfinite(c)]))
#: Finite extremes (float32 max, denormals), for UVs, LODs and derivatives that are used as they are.
EXTREMES = [1e30, -1e30, 3.4e38, -3.4e38, 1.2e-38, 1e-45]
extreme_coords = st.one_of(coords, st.sampled_from(EXTREMES))
extreme_floats = st.one_of(st.floats(-1e6, 1e6, width=32), st.sampled_from(EXTREMES))
FILTERS = ["nearest", "bilinear", "trilinear", "anisotropic", "auto"]
ADDRESSES = ["wrap", "clamp", "mirror", "border"]
METHODS = ["none", "hash4", "cheap2", "hex"]
BAD_DTYPES = [np.bool_, np.complex64, object, "U2"]
GOOD_DTYPES = [np.float16, np.float32, np.float64, np.uint8, np.uint16]
#: Integer texels: uint8/uint16 are unorm (divided by 255/65535); other integer dtypes are refused.
UNORM = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}
OTHER_INTS = [np.int8, np.int32, np.int64, np.uint32]


def flat_array(draw, shape, elements, dtype=np.float32) -> np.ndarray:
    """An array of ``shape`` whose entries come from ``elements`` (a shrinkable list)."""
    n = math.prod(shape)
    values = draw(st.lists(elements, min_size=n, max_size=n))
    return np.array(values, dtype=dtype).reshape(shape)


@st.composite
def texel_data(draw, *, layers=None, max_layers=4, min_channels=1, max_channels=4, max_side=16):
    """``[L, H, W, C]`` finite float32 texels: seeded random values at a random scale."""
    num = layers if layers is not None else draw(st.integers(1, max_layers))
    h, w = draw(st.integers(1, max_side)), draw(st.integers(1, max_side))
    c = draw(st.integers(min_channels, max_channels))
    seed = draw(st.integers(0, 2**32 - 1))
    kind = draw(st.sampled_from(["unit", "signed", "constant", "huge", "tiny", "max"]))
    rng = np.random.default_rng(seed)
    data = {
        "unit": lambda: rng.random((num, h, w, c)),
        "signed": lambda: rng.uniform(-4, 4, (num, h, w, c)),
        "constant": lambda: np.full((num, h, w, c), 0.25),
        "huge": lambda: rng.uniform(-1e6, 1e6, (num, h, w, c)),
        "tiny": lambda: rng.uniform(-1e-30, 1e-30, (num, h, w, c)),
        "max": lambda: rng.choice([-3.4e38, 3.4e38, 3.0e38, 0.0], (num, h, w, c)),
    }[kind]()
    return data.astype(np.float32)


@st.composite
def samplers(draw, *, filters=FILTERS, addresses=ADDRESSES):
    kw = {"filter": draw(st.sampled_from(filters)), "address": draw(st.sampled_from(addresses))}
    if draw(st.booleans()):
        kw["border"] = tuple(draw(st.lists(st.floats(-2, 2, width=32), min_size=1, max_size=4)))
    if draw(st.booleans()):
        kw["lod_bias"] = draw(st.floats(-20, 20, width=32))
        lo = draw(st.floats(-5, 20, width=32))
        kw["min_lod"], kw["max_lod"] = lo, draw(st.one_of(st.just(INF), st.floats(lo, 40, width=32)))
    if kw["filter"] == "anisotropic" and draw(st.booleans()):
        kw["max_aniso"] = draw(st.integers(1, 64))
    return wt.Sampler(**kw)


@st.composite
def stochastic_options(draw, *, allow_turns=True):
    method = draw(st.sampled_from(METHODS))
    kw = {"method": method, "seed": draw(st.integers(0, 2**32 - 1))}
    if method in ("hash4", "cheap2"):
        if draw(st.booleans()):
            lo = draw(st.floats(0, 0.9))
            kw["blend"] = (lo, draw(st.floats(lo + 0.05, 1.0)))
        kw["mirror"] = allow_turns and draw(st.booleans())
        kw["noise_frequency"] = draw(st.floats(1e-3, 100))
        kw["noise_levels"] = draw(st.floats(1e-3, 100))
    if method == "hex":
        kw["contrast"] = draw(st.floats(1, 64))
        kw["rotation"] = draw(st.floats(0, 1)) if allow_turns else 0.0
    return wt.Stochastic(**kw)


NORMAL_KINDS = ["unit", "unit", "unit", "axis", "diagonal", "zero", "nan", "inf", "tiny", "huge", "negzero"]


def make_normals(draw, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` normals of random kinds (unit, axis-aligned, diagonal, zero, NaN, inf, tiny 1e-30,
    huge 1e30), which are usable (finite, not tiny) and which unusable (zero or non-finite: output 0);
    tiny ones are neither (they may count as zero)."""
    kinds = draw(st.lists(st.sampled_from(NORMAL_KINDS), min_size=count, max_size=count))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    out = np.zeros((count, 3), np.float64)
    for i, kind in enumerate(kinds):
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        out[i] = {
            "unit": v,
            "axis": np.eye(3)[rng.integers(3)] * rng.choice([-1, 1]),
            "diagonal": rng.choice([-1, 1], size=3) / math.sqrt(3),
            "zero": 0.0,
            "nan": [NAN, v[1], v[2]],
            "inf": [INF, 0.0, 0.0],
            "tiny": v * 1e-30,
            "huge": v * 1e30,
            "negzero": [-0.0, -0.0, -0.0],
        }[kind]
    normals = out.astype(np.float32)
    good = np.isfinite(normals).all(axis=1) & (np.abs(normals).max(axis=1) > 0)
    tiny = good & (np.linalg.norm(normals.astype(np.float64), axis=1) < 1e-20)  # may count as zero
    return normals, good & ~tiny, ~good


def warp_field(values: np.ndarray, dtype) -> wp.array:
    values = np.ascontiguousarray(values, np.float32)
    if dtype == wp.int32:
        return wp.array(values.astype(np.int32), dtype=wp.int32)
    return wp.array(values, dtype=dtype)


@st.composite
def gbuffers(draw, *, with_uv=True, max_side=6, finite_geometry=False):
    """A random G-buffer built directly from arrays: positions and derivatives (finite or not),
    normals of every kind, a 0/1 mask, and a ``uv0`` set; with the per-pixel facts the property needs."""
    h, w = draw(st.integers(1, max_side)), draw(st.integers(1, max_side))
    n = h * w
    element = finite_coords if finite_geometry else coords
    position = flat_array(draw, (n, 3), st.one_of(st.floats(-1e3, 1e3, width=32), element))
    scale = draw(st.sampled_from([0.0, 1e-6, 1e-2, 1.0, 1e3]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    pdx = (rng.normal(size=(n, 3)) * scale).astype(np.float32)
    pdy = (rng.normal(size=(n, 3)) * scale).astype(np.float32)
    if not finite_geometry and draw(st.booleans()):
        pdx[draw(st.integers(0, n - 1))] = draw(st.sampled_from([INF, NAN, 1e30]))
    normal, good_normal, bad_normal = make_normals(draw, n)
    mask = np.array(draw(st.lists(st.sampled_from([0.0, 1.0, 1.0]), min_size=n, max_size=n)), np.float32)
    arrays = {
        "position": position,
        "normal": normal,
        "geometric_normal": normal,
        "depth": np.where(mask > 0, 1.0, INF),
        "mask": mask,
        "triangle": np.where(mask > 0, 0, -1),
        "position_dx": pdx,
        "position_dy": pdy,
    }
    uv_sets, uv_finite = {}, np.ones(n, bool)
    if with_uv:
        uv = flat_array(draw, (n, 2), coords)
        uv_scale = draw(st.sampled_from([0.0, 1e-4, 1e-2, 1.0]))
        uvs = {"uv": uv, "uv_dx": rng.normal(size=(n, 2)) * uv_scale, "uv_dy": rng.normal(size=(n, 2)) * uv_scale, "tangent": np.zeros((n, 4))}
        uv_sets["uv0"] = {k: warp_field(np.reshape(uvs[k], (h, w, -1)), t) for k, t in UV_FIELDS.items()}
        uv_finite = np.isfinite(uv).all(axis=1)
    fields = {}
    for name, dtype in FIELDS.items():
        v = np.asarray(arrays[name])
        fields[name] = warp_field(v.reshape(h, w, -1) if v.ndim == 2 else v.reshape(h, w), dtype)
    g = GBuffer(**fields, uv_sets=uv_sets)
    facts = {
        "shape": (h, w),
        "covered": mask > 0,
        "good_normal": good_normal,
        "bad_normal": bad_normal,
        "finite_geometry": np.isfinite(position).all(axis=1) & np.isfinite(pdx).all(axis=1) & np.isfinite(pdy).all(axis=1),
        "finite_uv": uv_finite,
        "arrays": {"position": position, "normal": normal, "position_dx": pdx, "position_dy": pdy},
    }
    return g, facts


# -- Sampler, Stochastic, mip_sizes, cameras: validation without kernels ---------------------------------

anything = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**40), 2**40), st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=6),
    st.lists(st.floats(-5, 5), max_size=5).map(tuple), st.just(np.float32(2.5)), st.just(np.int64(3)), st.just(object()),
    st.just(np.array([0.1, 0.2])), st.just(np.array(["a"])),
)  # fmt: skip


@given(
    filter=st.one_of(st.sampled_from(FILTERS + ["NEAREST", "Bilinear", "cubic", ""]), anything),
    address=st.one_of(st.sampled_from(ADDRESSES + ["repeat", "CLAMP"]), anything),
    border=st.one_of(st.lists(coords, max_size=6).map(tuple), anything),
    lod_bias=st.one_of(coords, anything), min_lod=st.one_of(coords, anything), max_lod=st.one_of(coords, anything),
)  # fmt: skip
def test_sampler_options(filter, address, border, lod_bias, min_lod, max_lod):
    """``Sampler(...)`` with arbitrary values: a clear error naming ``Sampler()``, or a checked object."""
    s = call("Sampler", wt.Sampler, filter=filter, address=address, border=border, lod_bias=lod_bias, min_lod=min_lod, max_lod=max_lod)
    if s is not None:
        assert isinstance(s.filter, wt.Filter) and isinstance(s.address, wt.Address)
        assert len(s.border) == 4 and all(math.isfinite(c) for c in s.border)
        assert math.isfinite(s.lod_bias) and not math.isnan(s.min_lod) and s.min_lod <= s.max_lod


@given(
    method=st.one_of(st.sampled_from(METHODS + ["HEX", "quad"]), anything), seed=st.one_of(st.integers(-5, 2**33), anything),
    blend=st.one_of(st.none(), st.lists(st.floats(-1, 2), max_size=3).map(tuple), anything), mirror=anything,
    contrast=st.one_of(st.floats(0, 10), anything), rotation=st.one_of(st.floats(-1, 2), anything),
    noise_frequency=st.one_of(st.floats(-1, 10), anything), noise_levels=st.one_of(st.floats(-1, 10), anything),
)  # fmt: skip
def test_stochastic_options(method, seed, blend, mirror, contrast, rotation, noise_frequency, noise_levels):
    """``Stochastic(...)`` with arbitrary values: a clear error naming ``Stochastic()``, or a checked object."""
    s = call("Stochastic", wt.Stochastic, method=method, seed=seed, blend=blend, mirror=mirror, contrast=contrast, rotation=rotation,
             noise_frequency=noise_frequency, noise_levels=noise_levels)  # fmt: skip
    if s is not None:
        lo, hi = s.blend_window
        assert 0 <= lo < hi <= 1 and 0 <= s.seed < 2**32 and s.contrast >= 1 and 0 <= s.rotation <= 1
        assert s.noise_frequency > 0 and s.noise_levels > 0


@given(height=st.one_of(st.integers(-3, 5000), anything), width=st.one_of(st.integers(-3, 5000), anything),
       max_levels=st.one_of(st.none(), st.integers(-2, 20), anything))  # fmt: skip
def test_mip_sizes(height, width, max_levels):
    sizes = call("mip_sizes", wt.mip_sizes, height, width, max_levels)
    if sizes is not None:
        assert sizes[0] == (height, width) and all(h >= 1 and w >= 1 for h, w in sizes)
        assert sizes[-1] == (1, 1) or len(sizes) == max_levels


vec3 = st.one_of(st.lists(st.one_of(st.floats(-1e6, 1e6), st.sampled_from([0.0, INF, NAN, 1e300])), min_size=0, max_size=4), anything)


@given(eye=vec3, target=vec3, up=vec3, extent=st.one_of(st.floats(-10, 200), anything),
       resolution=st.one_of(st.tuples(st.integers(-2, 2000), st.integers(-2, 2000)), anything), ortho=st.booleans())  # fmt: skip
def test_cameras(eye, target, up, extent, resolution, ortho):
    """``look_at``/``orthographic`` with arbitrary vectors: a clear error, or a finite orthonormal frame."""
    name, fn = ("orthographic", wt.orthographic) if ortho else ("look_at", wt.look_at)
    kw = {"height" if ortho else "fov_y": extent}
    cam = call(name, fn, eye, target, up, resolution=resolution, **kw)
    if cam is not None:
        frame = np.stack([cam.forward, cam.right, cam.up])
        assert_finite(frame, name)
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-6)
        hx, hy = cam.half_extent
        assert math.isfinite(hx) and math.isfinite(hy) and hx > 0 and hy > 0


# -- textures ------------------------------------------------------------------------------------------------


@st.composite
def image_like(draw):
    """Any array-like: random rank (0-5), sides (0-5), dtype (good and bad), non-finite values, ragged lists."""
    kind = draw(st.sampled_from(["array", "array", "array", "ragged", "scalar", "nested_list"]))
    if kind == "ragged":
        return [[[0.1, 0.2]], [[0.3]]]
    if kind == "scalar":
        return draw(st.sampled_from([1.0, "text", None, object()]))
    shape = tuple(draw(st.lists(st.integers(0, 5), min_size=0, max_size=5)))
    dtype = draw(st.sampled_from(GOOD_DTYPES + BAD_DTYPES + OTHER_INTS))
    n = math.prod(shape)
    if dtype in BAD_DTYPES:
        data = np.zeros(shape, dtype=dtype)
    else:
        values = draw(st.lists(st.one_of(st.floats(-1e6, 1e6), st.sampled_from([0.0, 3.0e38, 1e300, INF, NAN])), min_size=min(n, 1), max_size=min(n, 1)))
        data = np.full(shape, values[0] if values else 0.0)
        if n:
            data = data + np.random.default_rng(draw(st.integers(0, 2**32 - 1))).random(shape)
        with np.errstate(all="ignore"):
            data = data.astype(dtype) if np.issubdtype(np.dtype(dtype), np.floating) else np.clip(np.nan_to_num(data), 0, 100).astype(dtype)
    return data.tolist() if kind == "nested_list" else data


def _texels(data):
    """What a Texture should hold for ``data``: float32 ``[H, W, C]``, or ``None`` if it is invalid."""
    try:
        arr = np.asarray(data)
    except ValueError:
        return None
    if np.issubdtype(arr.dtype, np.integer) and arr.dtype in UNORM:
        arr = (arr / UNORM[arr.dtype]).astype(np.float32)
    elif not np.issubdtype(arr.dtype, np.floating):
        return None
    with np.errstate(over="ignore"):
        arr = arr.astype(np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    ok = arr.ndim == 3 and arr.shape[0] > 0 and arr.shape[1] > 0 and 1 <= arr.shape[2] <= 4 and bool(np.isfinite(arr).all())
    return arr if ok else None


@given(image=image_like(), mipmaps=st.one_of(st.booleans(), st.integers(-2, 8), st.sampled_from([1.5, None, "yes"])), requires_grad=st.booleans())
def test_texture_construction(image, mipmaps, requires_grad):
    """``Texture(image)`` from any array-like: a clear error naming ``Texture()``, or the texels as given."""
    tex = call("Texture", wt.Texture, image, mipmaps=mipmaps, requires_grad=requires_grad)
    valid_mips = isinstance(mipmaps, bool) or (isinstance(mipmaps, int) and mipmaps >= 1)
    expected = _texels(image)
    if tex is None:
        assert expected is None or not valid_mips, "a valid image was refused"  # a known finding is never a valid image
        return
    assert expected is not None and valid_mips, "an invalid image was accepted"
    np.testing.assert_array_equal(tex.numpy(), expected)
    if mips_may_overflow(expected):
        return
    for level in range(tex.num_levels):
        texels = tex.numpy(level)
        assert_finite(texels, f"mip level {level}")
        assert_within(texels, expected.min(), expected.max(), f"mip level {level}", scale=np.abs(expected).max())


@given(layers=st.one_of(st.lists(image_like(), min_size=0, max_size=4), image_like()), mipmaps=st.one_of(st.booleans(), st.integers(1, 5)))
def test_texture_array_construction(layers, mipmaps):
    """``TextureArray(layers)`` from a list of array-likes or one array: a clear error, or the layers as given."""
    arr = call("TextureArray", wt.TextureArray, layers, mipmaps=mipmaps)
    if arr is not None:
        data = arr.numpy()
        assert data.ndim == 4 and data.shape[0] == arr.num_layers >= 1
        if mips_may_overflow(data):
            return
        for level in range(arr.num_levels):
            assert_finite(arr.numpy(level), f"mip level {level}")


# -- sample and stochastic ---------------------------------------------------------------------------------


@st.composite
def sample_case(draw, *, stochastic=False):
    data = draw(texel_data())
    as_array = data.shape[0] > 1 or draw(st.booleans())
    texture = wt.TextureArray(data, mipmaps=draw(st.one_of(st.booleans(), st.integers(1, 4)))) if as_array else wt.Texture(data[0])
    uv_shape = tuple(draw(st.lists(st.integers(0 if not stochastic else 1, 5), min_size=0, max_size=2))) + (2,)
    uv = flat_array(draw, uv_shape, extreme_coords)
    count = math.prod(uv_shape[:-1])
    kw = {}
    lod_kind = draw(st.sampled_from(["none", "constant", "per_uv", "derivatives"]))
    lods = st.one_of(st.floats(-50, 50, width=32), st.sampled_from(EXTREMES))
    if lod_kind == "constant":
        kw["lod"] = draw(lods)
    elif lod_kind == "per_uv":
        kw["lod"] = flat_array(draw, uv_shape[:-1], lods)
    elif lod_kind == "derivatives":
        kw["uv_dx"] = flat_array(draw, uv_shape, extreme_floats)
        kw["uv_dy"] = flat_array(draw, uv_shape, extreme_floats)
    layer_kind = draw(st.sampled_from(["none", "int", "per_uv"]))
    if layer_kind == "int":
        kw["layer"] = draw(st.integers(-1, texture.num_layers))
    elif layer_kind == "per_uv":
        kw["layer"] = flat_array(draw, uv_shape[:-1], st.integers(-(2**31), 2**31 - 1), dtype=np.int64)
    kw["sampler"] = draw(samplers(addresses=["wrap", "mirror"] if stochastic else ADDRESSES))
    note(f"texture {data.shape}, uv {uv_shape}, lod {lod_kind}, layer {layer_kind}, {kw['sampler']}")
    return texture, data, uv, count, kw


def check_samples(func, out, data, uv, kw, tolerated=None):
    """``sample``/``stochastic`` outputs: the shape of ``uv`` plus channels, NaN for non-finite UVs,
    finite and in the texels' range (exactly the value of a constant texture) for finite ones;
    ``tolerated`` rows (known findings) are only checked for their shape."""
    c = data.shape[-1]
    values = out.numpy()
    assert values.shape == uv.shape[:-1] + (c,), f"{func}: output shape {values.shape} for uv {uv.shape}"
    values = values.reshape(-1, c)
    finite_uv = np.isfinite(uv.reshape(-1, 2)).all(axis=1)
    assert np.isnan(values[~finite_uv]).all(), f"{func}: a non-finite UV must give NaN in every channel"
    if mips_may_overflow(data):
        return
    good = values[finite_uv & ~tolerated] if tolerated is not None else values[finite_uv]
    assert_finite(good, func)
    lo, hi = float(data.min()), float(data.max())
    if kw["sampler"].address == wt.Address.BORDER:
        lo, hi = min(lo, min(kw["sampler"].border[:c])), max(hi, max(kw["sampler"].border[:c]))
    assert_within(good, lo, hi, func, scale=float(np.abs(data).max()))
    if data.min() == data.max() and kw["sampler"].address != wt.Address.BORDER and good.size:
        np.testing.assert_allclose(good, np.broadcast_to(data.flat[0], good.shape), rtol=1e-5, err_msg=f"{func}: a constant texture must give its value")


@given(case=sample_case())
def test_sample(case):
    """``sample`` with random textures, UVs up to ±1e6 with inf/NaN, LODs, derivatives and layers:
    finite output in the texels' range for finite UVs, NaN for non-finite ones, or a clear error."""
    texture, data, uv, _count, kw = case
    out = call("sample", wt.sample, texture, uv, **kw)
    if out is not None:
        check_samples("sample", out, data, uv, kw)


@given(case=sample_case(), bad=st.sampled_from(["uv_shape", "uv_dtype", "lod_shape", "layer_dtype", "dx_only", "lod_and_dx", "texture", "sampler", "wp_uv", "uv_ragged"]))
def test_sample_bad_arguments(case, bad):
    """``sample`` with one argument wrong: always a clear error naming ``sample()``."""
    texture, data, uv, count, kw = case
    kw = {k: v for k, v in kw.items() if k == "sampler"}
    if bad == "uv_shape":
        uv = np.zeros(uv.shape[:-1] + (3,), np.float32)
    elif bad == "uv_dtype":
        uv = uv.astype(np.complex64)
    elif bad == "lod_shape":
        kw["lod"] = np.zeros(count + 1, np.float32)
    elif bad == "layer_dtype":
        kw["layer"] = np.zeros(uv.shape[:-1], np.float32)
    elif bad == "dx_only":
        kw["uv_dx"] = uv
    elif bad == "lod_and_dx":
        kw.update(lod=1.0, uv_dx=uv, uv_dy=uv)
    elif bad == "texture":
        texture = data
    elif bad == "sampler":
        kw["sampler"] = {"filter": "nearest"}
    elif bad == "wp_uv":
        uv = wp.array(np.zeros((max(count, 1), 3), np.float32), dtype=wp.vec3)
    elif bad == "uv_ragged":
        uv = [[0.1, 0.2], [0.3]]
    expect_error("sample", wt.sample, texture, uv, **kw)


@given(case=sample_case(stochastic=True), option=stochastic_options(), use_histogram=st.booleans(), decorrelate=st.booleans())
def test_stochastic(case, option, use_histogram, decorrelate):
    """``stochastic`` with every method and option: finite output for finite UVs (in the texels' range
    unless the histogram is decorrelated), NaN for non-finite UVs, or a clear error."""
    texture, data, uv, _count, kw = case
    if use_histogram and option.method == wt.Method.HEX:
        histogram = call("prepare_histogram", wt.prepare_histogram, texture, lut_size=64, decorrelate=decorrelate)
        if histogram is None:
            return
        option = option.replace(histogram=histogram)
        if decorrelate:  # colours rotated back from principal axes may leave the per-channel range
            with np.errstate(over="ignore"):
                spread = 4 * np.abs(data.astype(np.float64)).max()
                data = np.concatenate([data, np.full_like(data[:1], data.min() - spread), np.full_like(data[:1], data.max() + spread)])
    out = call("stochastic", wt.stochastic, texture, uv, option, **kw)
    if out is not None:
        check_samples("stochastic", out, data, uv, kw)


@given(uv=st.integers(0, 6).flatmap(lambda n: st.lists(st.tuples(extreme_coords, extreme_coords), min_size=n, max_size=n)),
       seed=st.integers(0, 2**32 - 1), contrast=st.floats(1, 64), rotation=st.floats(0, 1))  # fmt: skip
def test_hex_taps(uv, seed, contrast, rotation):
    uv = np.array(uv, np.float32).reshape(-1, 2)
    result = call("hex_taps", wt.hex_taps, uv, seed=seed, contrast=contrast, rotation=rotation)
    if result is not None:
        weights, _vertices, taps = result
        finite = np.isfinite(uv).all(axis=1)
        assert_finite(weights[finite], "hex_taps weights")
        np.testing.assert_allclose(weights[finite].sum(axis=-1), 1.0, atol=1e-4)
        assert (weights[finite] >= 0).all()
        assert_finite(taps[finite], "hex_taps taps")
        assert (taps[finite] > -2).all() and (taps[finite] < 4).all(), "hex_taps: taps must be reduced to [0, 2) plus an offset"


@given(data=texel_data(max_layers=1, max_side=8), n=st.integers(1, 6), lod_kind=st.sampled_from(["none", "constant", "per_uv", "derivatives"]),
       sampler=samplers(), seed=st.integers(0, 2**32 - 1), special=st.lists(st.sampled_from(SPECIAL_COORDS), max_size=3),
       method=st.sampled_from(["sample", "hash4", "cheap2", "hex"]), on_tape=st.booleans())  # fmt: skip
def test_sample_gradients(data, n, lod_kind, sampler, seed, special, method, on_tape):
    """Backward passes of ``sample``/``stochastic``: gradients to the texels, the UVs and per-UV
    LODs/derivatives are finite, and zero for non-finite UVs (docs/library.md), whatever the UVs."""
    if method != "sample" and sampler.address not in (wt.Address.WRAP, wt.Address.MIRROR):
        sampler = sampler.replace(address="wrap")
    if mips_may_overflow(data):
        return
    rng = np.random.default_rng(seed)
    uv_np = rng.uniform(-3, 3, (n, 2)).astype(np.float32)
    for i, value in enumerate(special):
        uv_np[i % n, i % 2] = value
    texture = wt.Texture(data[0], requires_grad=True)
    uv = wp.array(uv_np, dtype=wp.vec2, requires_grad=True)
    kw, grads = {"sampler": sampler}, [uv]
    if lod_kind == "constant":
        kw["lod"] = float(rng.uniform(-2, 6))
    elif lod_kind == "per_uv":
        kw["lod"] = wp.array(rng.uniform(-2, 6, n).astype(np.float32), dtype=float, requires_grad=True)
        grads.append(kw["lod"])
    elif lod_kind == "derivatives":
        scale = rng.choice([0.0, 1e-3, 1.0, 1e30])
        kw["uv_dx"] = wp.array((rng.normal(size=(n, 2)) * scale).astype(np.float32), dtype=wp.vec2, requires_grad=True)
        kw["uv_dy"] = wp.array((rng.normal(size=(n, 2)) * scale).astype(np.float32), dtype=wp.vec2, requires_grad=True)
        grads += [kw["uv_dx"], kw["uv_dy"]]
    tape = wp.Tape()
    with tape:
        if on_tape:
            texture.update()
        if method == "sample":
            out = call("sample", wt.sample, texture, uv, **kw)
        else:
            out = call("stochastic", wt.stochastic, texture, uv, method, **kw)
    if out is None:
        return
    out.grad.fill_(1.0)
    call("backward", tape.backward)
    for level in range(texture.num_levels):
        assert_finite(texture.grad(level), f"{method}: texel gradient of level {level}")
    for array in grads:
        assert_finite(array.grad.numpy(), f"{method}: UV/LOD gradient")
    bad = ~np.isfinite(uv_np).all(axis=1)
    assert (uv.grad.numpy()[bad] == 0).all(), f"{method}: a non-finite UV must get a zero gradient"


@given(g=gbuffers(with_uv=False, finite_geometry=True), data=texel_data(max_layers=1, max_side=6, min_channels=2), which=st.sampled_from(["triplanar", "biplanar", "triplanar_normal"]),
       tiling=st.floats(1e-2, 1e2), sharpness=st.one_of(st.floats(0, 32), st.sampled_from([0.0, 1.0, 8.0])), option=st.sampled_from([None, "hash4", "cheap2", "hex"]))  # fmt: skip
def test_triplanar_gradients(g, data, which, tiling, sharpness, option):
    """Backward passes of the triplanar techniques over G-buffers with zero, NaN, inf, tiny and huge
    normals (finite positions): every gradient (texels, tiling, sharpness, offsets) is finite."""
    gbuffer, _facts = g
    if mips_may_overflow(data):
        return
    texture = wt.Texture(data[0], requires_grad=True)
    params = {
        "tiling": wp.array([tiling], dtype=float, requires_grad=True),
        "sharpness": wp.array([sharpness], dtype=float, requires_grad=True),
        "offsets": wp.array(np.full((3, 2), 0.25, np.float32), dtype=float, requires_grad=True),
    }
    tape = wp.Tape()
    with tape:
        out = call(which, getattr(wt, which), gbuffer, texture, stochastic=option, **params)
    if out is None:
        return
    out.grad.fill_(1.0)
    call("backward", tape.backward)
    assert_finite(texture.grad(0), f"{which}: texel gradient")
    for name, array in params.items():
        assert_finite(array.grad.numpy(), f"{which}: gradient of {name}")


# -- triplanar, biplanar, triplanar normal mapping -------------------------------------------------------------


@st.composite
def projection_options(draw):
    kw = {}
    tiling_kind = draw(st.sampled_from(["one", "three", "bad"]))
    magnitude = st.floats(1e-3, 1e3).flatmap(lambda m: st.sampled_from([m, -m]))
    if tiling_kind == "one":
        kw["tiling"] = draw(magnitude)
    elif tiling_kind == "three":
        kw["tiling"] = draw(st.lists(magnitude, min_size=3, max_size=3))
    else:
        kw["tiling"] = draw(st.sampled_from([0.0, NAN, INF, [1.0, 2.0], "x"]))
    kw["sharpness"] = draw(st.one_of(st.floats(0, 64), st.sampled_from([0.0, 1.0, 200.0, 1e4, 1e6, -1.0, NAN])))
    if draw(st.booleans()):
        kw["offsets"] = draw(st.lists(st.floats(-10, 10), min_size=6, max_size=6).map(lambda v: np.reshape(v, (3, 2))))
    kw["mirror_fix"] = draw(st.booleans())
    if draw(st.booleans()):
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        m = np.eye(4)
        m[:3, :3] = rng.normal(size=(3, 3)) * draw(st.sampled_from([1e-6, 1.0, 100.0]))
        m[:3, 3] = rng.normal(size=3)
        kw.update(space="object", object_to_world=m)
    return kw


def pixel_note(facts, i) -> str:
    """The inputs of pixel ``i`` of a fuzzed G-buffer, for failure reports."""
    return ", ".join(f"{k}={v[i].tolist()}" for k, v in facts["arrays"].items()) + f", mask={int(facts['covered'][i])}"


FLOAT32_SQRT_MAX = 1.8e19  # |n| past which |n|^2 overflows float32


def biplanar_weight_sum(normals: np.ndarray, sharpness: float) -> np.ndarray:
    """Sum of the un-normalised biplanar weights (major and median axes), in float64."""
    with np.errstate(all="ignore"):
        a = np.abs(normals.astype(np.float64))
        a = np.sort(a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300), axis=1)[:, 1:]
        return (np.clip((a - 0.5773) / (1 - 0.5773), 0, 1) ** (sharpness / 8.0)).sum(axis=1)


def check_surface(func, out, facts, lo, hi, scale, *, unit=False, constant=None, tolerated=None):
    """The surface techniques' property: 0 where uncovered or the normal is unusable; finite (unit
    normals, or values in ``[lo, hi]``, exactly ``constant`` for a constant texture) on finite geometry."""
    h, w = facts["shape"]
    values = out.numpy()
    for i in np.flatnonzero(facts["covered"]):
        note(f"pixel {i}: {pixel_note(facts, i)} -> {values.reshape(h * w, -1)[i].tolist()}")
    assert values.shape[:2] == (h, w), f"{func}: output shape {values.shape} for a {h}x{w} G-buffer"
    values = values.reshape(h * w, -1)
    empty = ~facts["covered"] | facts["bad_normal"]
    assert (values[empty] == 0).all(), f"{func}: pixels without coverage or without a usable normal must be 0, got {values[empty]}"
    good = facts["covered"] & facts["good_normal"] & facts["finite_geometry"]
    assert_finite(values[good], func)
    if tolerated is not None:
        good &= ~tolerated
    if constant is not None and good.any():
        np.testing.assert_allclose(values[good], np.broadcast_to(constant, values[good].shape), rtol=1e-4, atol=1e-6, err_msg=f"{func}: a constant texture must give its value")
    if unit:
        norms = np.linalg.norm(values[good], axis=1)
        assert (np.abs(norms - 1) < 1e-3).all(), f"{func}: normals must have unit length, got lengths {norms}"
    else:
        assert_within(values[good], min(lo, 0.0), max(hi, 0.0), func, scale)


@given(g=gbuffers(with_uv=False), data=texel_data(max_side=8), per_axis=st.booleans(), per_face=st.booleans(), opts=projection_options(),
       option=st.one_of(st.none(), stochastic_options()), sampler=st.one_of(st.none(), samplers()), which=st.sampled_from(["triplanar", "biplanar"]))  # fmt: skip
def test_triplanar_biplanar(g, data, per_axis, per_face, opts, option, sampler, which):
    """``triplanar``/``biplanar`` over random G-buffers (zero, NaN, inf, tiny, huge, diagonal normals;
    positions up to ±1e6 with inf/NaN), with one texture, one per axis or one per face: 0 where
    uncovered or without a usable normal, finite and in the texels' range on finite geometry, or a
    clear error."""
    gbuffer, facts = g
    layer = int(data.shape[0] - 1)
    texture = wt.TextureArray(data)
    textures = faces = None
    if per_axis:
        textures = [None, wt.TextureArray(data[:, ::-1].copy()), wt.Texture(data[layer, :3, :2]) if layer == 0 else None]
    if per_face:  # the texels rearranged: the same range
        faces = [None, wt.TextureArray(data[:, :, ::-1].copy()), None, wt.TextureArray(data[:, ::-1, ::-1].copy()), wt.TextureArray(data[:, :2].copy()), None]
    fn = getattr(wt, which)
    out = call(which, fn, gbuffer, texture, textures_per_axis=textures, textures_per_face=faces, layer=layer, stochastic=option, sampler=sampler, **opts)
    if out is not None:
        if mips_may_overflow(data):
            return
        border = sampler is not None and sampler.address == wt.Address.BORDER
        constant = data[layer, 0, 0] if data.min() == data.max() and not border else None
        colours = np.concatenate([data.reshape(-1), sampler.border[: data.shape[-1]]]) if border else data
        check_surface(which, out, facts, float(colours.min()), float(colours.max()), float(np.abs(data).max()), constant=constant,
                      )  # fmt: skip


@given(g=gbuffers(with_uv=False), data=texel_data(min_channels=2, max_side=8, layers=1), opts=projection_options(),
       option=st.one_of(st.none(), stochastic_options(allow_turns=False)), blend=st.sampled_from(["whiteout", "udn", "rnm"]),
       strength=st.one_of(st.floats(0, 10), st.sampled_from([0.0, 1e6, -1.0])), flip_green=st.booleans(), biplanar=st.booleans())  # fmt: skip
def test_triplanar_normal(g, data, opts, option, blend, strength, flip_green, biplanar):
    """``triplanar_normal``: unit normals on finite geometry (any map values, any strength), 0 where
    uncovered or without a usable normal, or a clear error."""
    gbuffer, facts = g
    name = "biplanar_normal" if biplanar else "triplanar_normal"
    out = call(name, getattr(wt, name), gbuffer, wt.Texture(data[0]), stochastic=option, blend=blend, strength=strength, flip_green=flip_green, **opts)
    if out is not None:
        check_surface(name, out, facts, -1.0, 1.0, 1.0, unit=True)


@given(g=gbuffers(with_uv=True), bad=st.sampled_from(["shape", "dtype", "not_gbuffer", "missing_texture", "per_axis", "per_face", "layer", "space"]))
def test_triplanar_bad_arguments(g, bad):
    """Malformed G-buffers and arguments: always a clear error naming the function."""
    gbuffer, facts = g
    h, w = facts["shape"]
    texture = wt.Texture(np.ones((2, 2, 3), np.float32))
    kw = {}
    if bad == "shape":
        gbuffer.normal = wp.zeros((h + 1, w), dtype=wp.vec3)
    elif bad == "dtype":
        gbuffer.position = wp.zeros((h, w), dtype=wp.vec4)
    elif bad == "not_gbuffer":
        gbuffer = {"position": gbuffer.position}
    elif bad == "missing_texture":
        texture = None
    elif bad == "per_axis":
        kw["textures_per_axis"] = [texture, wt.Texture(np.ones((2, 2, 2), np.float32)), None]
    elif bad == "per_face":
        kw["textures_per_face"] = [None, None, None, wt.Texture(np.ones((2, 2, 2), np.float32)), None, None]
    elif bad == "layer":
        kw["layer"] = 1
    elif bad == "space":
        kw["object_to_world"] = np.eye(4)
    for name in ("triplanar", "biplanar", "triplanar_normal"):
        expect_error(name, getattr(wt, name), gbuffer, texture, **kw)


# -- splat layers and the atlas ----------------------------------------------------------------------------------


@st.composite
def splat_case(draw):
    num = draw(st.integers(1, 8))
    layers = draw(texel_data(layers=num, max_side=8))
    map_channels = draw(st.integers(1, 4))
    need = -(-num // map_channels)
    maps_count = draw(st.sampled_from([need, need, need, max(1, need - 1), need + 1]))
    mh, mw = draw(st.integers(1, 8)), draw(st.integers(1, 8))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    weight_kind = draw(st.sampled_from(["unit", "signed", "zero", "huge"]))
    maps = {"unit": rng.random, "signed": lambda s: rng.uniform(-1, 1, s), "zero": np.zeros, "huge": lambda s: rng.uniform(0, 1e6, s)}[weight_kind](
        (maps_count, mh, mw, map_channels)
    ).astype(np.float32)
    kw = {"projection": draw(st.sampled_from(["uv", "world_xz", "triplanar"])), "normalize": draw(st.booleans())}
    kw["tiling"] = draw(st.one_of(st.floats(1e-3, 1e3), st.lists(st.floats(-1e3, 1e3).filter(lambda t: abs(t) > 1e-3), min_size=num, max_size=num), st.sampled_from([0.0, NAN])))
    height = draw(st.sampled_from(["none", "channel", "array", "bad"]))
    if height != "none":
        kw["height_blend"] = draw(st.one_of(st.floats(1e-4, 10), st.sampled_from([0.0, -1.0, NAN]))) if height != "bad" else draw(st.sampled_from([0.0, -1.0, NAN]))
    if height == "channel":
        kw["height_channel"] = draw(st.integers(-1, 4))
    if height == "array":
        kw["heights"] = wt.TextureArray(draw(texel_data(layers=num, max_channels=1, max_side=8)))
    kw["stochastic"] = draw(st.one_of(st.none(), stochastic_options()))
    kw["sampler"] = draw(st.one_of(st.none(), samplers()))
    kw["sharpness"] = draw(st.floats(0, 64))
    maps_as = draw(st.sampled_from(["texture_array", "numpy"]))
    splat_maps = wt.TextureArray(maps, mipmaps=False) if maps_as == "texture_array" else (maps[0] if maps_count == 1 and draw(st.booleans()) else maps)
    note(f"layers {layers.shape}, maps {maps.shape} as {maps_as}, {height} heights, weights {weight_kind}")
    return wt.TextureArray(layers), layers, splat_maps, maps, kw, weight_kind


@given(g=gbuffers(with_uv=True), case=splat_case())
def test_splat(g, case):
    """``splat`` with random layer counts, splat-map counts and channels, sizes, projections, height
    blends and stochastic sampling: finite output on finite geometry and UVs (in the layers' range when
    normalised), 0 where uncovered, or a clear error naming ``splat()``."""
    gbuffer, facts = g
    layers, data, splat_maps, maps, kw, weight_kind = case
    out = call("splat", wt.splat, gbuffer, layers, splat_maps, **kw)
    if out is None:
        return
    h, w = facts["shape"]
    values = out.numpy().reshape(h * w, -1)
    assert (values[~facts["covered"]] == 0).all(), "splat: uncovered pixels must be 0"
    good = facts["covered"] & facts["finite_geometry"] & facts["finite_uv"]
    if kw["projection"] == "triplanar":
        good &= facts["good_normal"]
    if mips_may_overflow(data) or (kw.get("heights") is not None and mips_may_overflow(kw["heights"].numpy())):
        return
    if kw["normalize"] or float(np.abs(maps).max()) * data.shape[0] * float(np.abs(data).max()) < 1e38:  # else it may overflow
        assert_finite(values[good], "splat")
    if kw["normalize"]:
        border = kw.get("sampler") is not None and kw["sampler"].address == wt.Address.BORDER
        colours = np.concatenate([data.reshape(-1), kw["sampler"].border[: data.shape[-1]], [0.0]]) if border else np.append(data, 0.0)
        assert_within(values[good], float(colours.min()), float(colours.max()), "splat", float(np.abs(data).max()))
        if data.min() == data.max() and weight_kind in ("unit", "huge") and (kw.get("sampler") is None or kw["sampler"].address != wt.Address.BORDER) and good.any():
            np.testing.assert_allclose(values[good], np.broadcast_to(data.flat[0], values[good].shape), rtol=1e-4, err_msg="splat: constant layers must give their value")


@given(data=texel_data(max_layers=6, max_side=8), gutter=st.integers(-1, 5), columns=st.one_of(st.none(), st.integers(0, 7)),
       k=st.integers(0, 5), map_side=st.tuples(st.integers(1, 6), st.integers(1, 6)), seed=st.integers(0, 2**32 - 1),
       index_kind=st.sampled_from(["exported", "random", "out_of_range"]), normalize=st.booleans(),
       tiling=st.one_of(st.floats(-1e3, 1e3), st.sampled_from([0.0, NAN])), g=gbuffers(with_uv=True),
       sampler=st.one_of(st.none(), samplers(addresses=["wrap", "wrap", "clamp"])))  # fmt: skip
def test_atlas(data, gutter, columns, k, map_side, seed, index_kind, normalize, tiling, g, sampler):
    """``pack_atlas``, ``export_index_maps`` and ``splat_atlas`` with random layers, gutters, grids,
    ``k`` and index maps: finite output on finite UVs, 0 where uncovered, or clear errors."""
    gbuffer, facts = g
    num = data.shape[0]
    atlas = call("pack_atlas", wt.pack_atlas, data, gutter=gutter, columns=columns)
    rng = np.random.default_rng(seed)
    splat_maps = rng.uniform(-0.5, 1, (1, *map_side, num)).astype(np.float32)
    exported = call("export_index_maps", wt.export_index_maps, splat_maps, k)
    if exported is not None:
        indices, weights = exported
        assert indices.shape == weights.shape == (*map_side, k)
        assert ((0 <= indices) & (indices < num)).all() and (weights >= 0).all()
        assert_finite(weights, "export_index_maps")
    if atlas is None:
        return
    assert_within(atlas.texture.numpy(), min(float(data.min()), 0.0), max(float(data.max()), 0.0), "pack_atlas", float(np.abs(data).max()))  # spare cells are 0
    kk = max(1, min(k, 4))
    if index_kind == "exported" and exported is not None:
        indices, weights = exported
    else:
        high = num if index_kind == "random" else num + 3
        indices = rng.integers(-1 if index_kind == "out_of_range" else 0, high, (*map_side, kk))
        weights = rng.uniform(-1, 2, (*map_side, kk)).astype(np.float32)
    out = call("splat_atlas", wt.splat_atlas, gbuffer, atlas, indices, weights, tiling=tiling, normalize=normalize, sampler=sampler)
    if out is None:
        return
    h, w = facts["shape"]
    values = out.numpy().reshape(h * w, -1)
    assert (values[~facts["covered"]] == 0).all(), "splat_atlas: uncovered pixels must be 0"
    good = facts["covered"] & facts["finite_uv"]
    if mips_may_overflow(data):
        return
    assert_finite(values[good], "splat_atlas")
    assert np.isnan(values[facts["covered"] & ~facts["finite_uv"]]).all(), "splat_atlas: a non-finite UV must give NaN"


# -- rasterising random meshes -----------------------------------------------------------------------------------


@given(nv=st.integers(0, 8), nf=st.integers(0, 6), seed=st.integers(0, 2**32 - 1), special=st.sampled_from([None, INF, NAN, 1e30, 1e-30]),
       face_shift=st.sampled_from([0, 0, 0, 1, -1, 100]), ortho=st.booleans(), res=st.tuples(st.integers(1, 6), st.integers(1, 6)))  # fmt: skip
def test_rasterize_random_meshes(nv, nf, seed, special, face_shift, ortho, res):
    """``rasterize`` of random (degenerate, non-finite, out-of-range) meshes: a clear error naming
    ``rasterize()``, or a G-buffer that is finite where covered and background elsewhere."""
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(-1, 1, (nv, 3))
    if special is not None and nv:
        vertices[rng.integers(nv)] *= special
    faces = rng.integers(0, max(nv, 1), (nf, 3)) + face_shift
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces.reshape(-1, 3), process=False, validate=False)
    camera = (wt.orthographic if ortho else wt.look_at)((0.3, 0.4, 3.0), (0, 0, 0), resolution=res)
    g = call("rasterize", wt.rasterize, mesh, camera)
    if g is not None:
        check_gbuffer(g, res, vertices)


def check_gbuffer(g: GBuffer, res, vertices) -> None:
    """A rasterised G-buffer: finite where covered (unit normals), the background elsewhere."""
    data = g.numpy()
    covered = data["mask"] > 0
    assert data["mask"].shape == tuple(res)
    names = ["position", "normal", "geometric_normal", "position_dx", "position_dy"]
    for name in names:
        assert_finite(data[name][covered], f"rasterize {name}")
    n = np.linalg.norm(data["normal"][covered], axis=-1)
    assert (np.abs(n - 1) < 1e-3).all(), f"rasterize: normals must be unit, got lengths {n}"
    assert (data["triangle"][~covered] == -1).all() and np.isinf(data["depth"][~covered]).all()


# -- file readers: corrupted files -------------------------------------------------------------------------------


corruptions = st.lists(
    st.one_of(
        st.tuples(st.just("truncate"), st.floats(0, 1)),
        st.tuples(st.just("flip"), st.one_of(st.integers(0, 80), st.floats(0, 1)), st.integers(1, 255)),
        st.tuples(st.just("insert"), st.floats(0, 1), st.binary(min_size=1, max_size=8)),
        st.tuples(st.just("zero"), st.floats(0, 1), st.integers(1, 64)),
    ),
    min_size=1,
    max_size=4,
)


def corrupt(data: bytes, edits) -> bytes:
    b = bytearray(data)
    for edit in edits:
        at = lambda x: (x if isinstance(x, int) else int(x * len(b))) % max(len(b), 1)
        if edit[0] == "truncate":
            del b[int(edit[1] * len(b)) :]
        elif edit[0] == "flip" and b:
            b[at(edit[1])] ^= edit[2]
        elif edit[0] == "insert":
            i = at(edit[1])
            b[i:i] = edit[2]
        elif edit[0] == "zero" and b:
            i = at(edit[1])
            b[i : i + edit[2]] = bytes(len(b[i : i + edit[2]]))
    return bytes(b)


@contextlib.contextmanager
def scratch():
    """A temporary folder for one example's files. A hard crash of the interpreter (which no test can
    report) leaves it behind: the newest ``$TMPDIR/warptex-fuzz-*`` then holds the input that crashed."""
    with tempfile.TemporaryDirectory(prefix="warptex-fuzz-") as d:
        yield Path(d)


@given(channels=st.integers(1, 4), size=st.tuples(st.integers(1, 9), st.integers(1, 9)), bits=st.sampled_from([8, 16]),
       fmt=st.sampled_from(["png", "exr", "exr_half", "exr_named"]), edits=corruptions, seed=st.integers(0, 2**32 - 1),
       data_flag=st.booleans(), want=st.sampled_from([None, 1, 2, 3, 4, 0, ("R",), ("Y",)]))  # fmt: skip
def test_read_corrupted_images(channels, size, bits, fmt, edits, seed, data_flag, want):
    """Truncated and byte-flipped PNG/EXR files through ``read_image``, ``read_exr``,
    ``exr_channel_names`` and ``Texture.from_file``: a clear error naming the reader, or an
    ``[H, W, C]`` float32 image (finite for PNG)."""
    rng = np.random.default_rng(seed)
    image = rng.random((*size, channels)).astype(np.float32)
    with scratch() as d:
        path = d / f"image.{fmt[:3]}"
        if fmt == "png":
            wio.write_png(path, image[..., :1] if bits == 16 else image, bits=bits)
        else:
            names = [f"layer.{c}" for c in "XYZW"[:channels]] if fmt == "exr_named" else None
            wio.write_exr(path, image, half=fmt == "exr_half", channel_names=names)
        bad = corrupt(path.read_bytes(), edits)
        path.write_bytes(bad)
        note(f"{fmt}: {len(bad)} bytes after {edits}")
        for names, fn, options in (
            ("read_image", wio.read_image, {"data": data_flag, "channels": want}),
            ("read_image", wio.read_image, {}),
            ("read_texels", wio.read_texels, {"data": data_flag, "channels": want}),
            (("read_exr",), wio.read_exr, {"channels": want if isinstance(want, tuple) else None}),
            (("exr_channel_names",), wio.exr_channel_names, {}),
            (("Texture.from_file", "read_texels", "Texture"), wt.Texture.from_file, {"data": data_flag}),
            (("TextureArray.from_files", "read_texels", "TextureArray"), lambda p, **k: wt.TextureArray.from_files([p, p], **k), {"mipmaps": 2}),
        ):
            out = call(names, fn, path, **options)
            if out is None:
                continue
            if fn is wio.exr_channel_names:
                assert isinstance(out, tuple) and all(isinstance(n, str) for n in out)
                continue
            if fn is wio.read_exr:
                out, got = out
                assert len(got) == out.shape[-1]
            if isinstance(out, wt.TextureArray):
                continue
            kept = (np.float32, np.float16, np.uint8) if fn is wio.read_texels else (np.float32,)  # the file's own precision
            assert isinstance(out, np.ndarray) and out.dtype in kept and out.ndim == 3, f"{names}: bad result {type(out)}"
            if fmt == "png" and bad[:4] != b"\x76\x2f\x31\x01":  # a PNG decodes to codes / 255: finite
                assert_finite(out, f"{names} of a PNG")
        assert sorted(p.name for p in d.iterdir()) == [path.name], "a reader left files behind"


@given(kind=st.sampled_from(["missing", "directory", "empty", "random_bytes", "png_as_exr", "exr_as_png"]), blob=st.binary(max_size=64))
def test_read_odd_paths(kind, blob):
    """Missing files, directories, empty and random files: OSError or ValueError naming the reader."""
    with scratch() as d:
        path = d / "x.exr"
        if kind == "directory":
            path.mkdir()
        elif kind in ("empty", "random_bytes"):
            path.write_bytes(b"" if kind == "empty" else blob)
        elif kind == "png_as_exr":
            wio.write_png(d / "p.png", np.zeros((2, 2, 3)))
            (d / "p.png").rename(path)
        elif kind == "exr_as_png":
            path = d / "x.png"
            wio.write_exr(path, np.zeros((2, 2, 3)))
        for name, fn in (("read_image", wio.read_image), ("read_texels", wio.read_texels), ("read_exr", wio.read_exr), ("exr_channel_names", wio.exr_channel_names),
                         ("load_gbuffer", wt.load_gbuffer), ("load_mesh", wt.load_mesh)):  # fmt: skip
            out = call(name, fn, path if name == "load_gbuffer" else ())
            if kind in ("missing", "directory", "empty"):
                assert out is None, f"{name}() read a {kind} path"


CHANNEL_VOCABULARY = [
    "P.X", "P.Y", "P.Z", "N.X", "N.Y", "N.Z", "Ng.X", "Ng.Y", "Ng.Z", "Z", "mask", "triangle", "dPdx.X", "dPdx.Y", "dPdx.Z",
    "dPdy.X", "dPdy.Y", "dPdy.Z", "uv0.U", "uv0.V", "uv0.dUdx", "uv1.U", "uv1.V", "uv0.T.X",
    "Position.X", "Position.Y", "Position.Z", "Normal.X", "Normal.Y", "Normal.Z", "UV.U", "UV.V", "UV.X", "UV.Y", "Depth.Z", "Depth",
    "ViewLayer.Position.X", "ViewLayer.Position.Y", "ViewLayer.Position.Z", "ViewLayer.Normal.X", "ViewLayer.Normal.Y",
    "ViewLayer.Normal.Z", "Other.Position.X", "R", "G", "B", "A", "Y",
]  # fmt: skip


@given(names=st.lists(st.sampled_from(CHANNEL_VOCABULARY), min_size=1, max_size=20, unique=True), size=st.tuples(st.integers(1, 5), st.integers(1, 5)),
       fill=st.sampled_from(["random", "zero", "nan", "inf", "huge"]), seed=st.integers(0, 2**32 - 1), layer=st.sampled_from([None, "ViewLayer", "Nope"]))  # fmt: skip
def test_load_gbuffer_channel_sets(names, size, fill, seed, layer):
    """``load_gbuffer`` of EXRs with random subsets of warptex's and Blender's channel names and
    random values: a clear error naming ``load_gbuffer()``, or a G-buffer every technique takes."""
    rng = np.random.default_rng(seed)
    value = {"random": lambda: rng.normal(size=size), "zero": lambda: np.zeros(size), "nan": lambda: np.full(size, NAN),
             "inf": lambda: np.full(size, INF), "huge": lambda: np.full(size, 1e30)}[fill]  # fmt: skip
    with scratch() as d:
        path = d / "g.exr"
        wio.write_exr(path, {n: value() for n in names})
        g = call("load_gbuffer", wt.load_gbuffer, path, layer=layer)
        if g is None:
            return
        assert g.resolution == size
        texture = wt.Texture(np.full((2, 2, 3), 0.5, np.float32))
        out = call("triplanar", wt.triplanar, g, texture)
        if out is not None and fill in ("random", "zero"):
            assert_finite(out.numpy(), "triplanar of a loaded G-buffer")
        if "uv0" in g.uv_sets:
            call("splat", wt.splat, g, wt.TextureArray(np.ones((2, 2, 2, 3), np.float32)), np.ones((2, 2, 2), np.float32))


def _small_gbuffer(size, seed) -> GBuffer:
    mesh = trimesh.creation.box()
    mesh.visual = trimesh.visual.TextureVisuals(uv=np.random.default_rng(seed).random((len(mesh.vertices), 2)))
    return wt.rasterize(mesh, wt.look_at((2.0, 1.5, 2.5), (0, 0, 0), resolution=size))


@given(size=st.tuples(st.integers(1, 6), st.integers(1, 6)), seed=st.integers(0, 100), edits=corruptions)
def test_load_corrupted_gbuffer(size, seed, edits):
    """``save_gbuffer`` then truncate or flip bytes: ``load_gbuffer`` gives a clear error naming it
    (or the EXR reader it delegates to), or a G-buffer of the right resolution."""
    g = _small_gbuffer(size, seed)
    with scratch() as d:
        path = d / "g.exr"
        wt.save_gbuffer(path, g)
        bad = corrupt(path.read_bytes(), edits)
        path.write_bytes(bad)
        note(f"{len(bad)} bytes after {edits}")
        loaded = call("load_gbuffer", wt.load_gbuffer, path)
        if loaded is not None:
            assert isinstance(loaded, GBuffer)
            for name in FIELDS:
                assert getattr(loaded, name).shape == loaded.resolution


MESH_FORMATS = ["obj", "ply", "ply_ascii", "stl", "stl_ascii", "glb", "off"]


def _export(mesh: trimesh.Trimesh, fmt: str) -> bytes:
    if fmt == "ply_ascii":
        return mesh.export(file_type="ply", encoding="ascii")
    data = mesh.export(file_type=fmt)
    return data.encode() if isinstance(data, str) else data


@given(fmt=st.sampled_from(MESH_FORMATS), shape=st.sampled_from(["box", "icosphere", "triangle"]), uv=st.booleans(), edits=corruptions,
       res=st.tuples(st.integers(1, 5), st.integers(1, 5)))  # fmt: skip
def test_load_corrupted_meshes(fmt, shape, uv, edits, res):
    """Truncated and byte-flipped OBJ/PLY/STL/GLB/OFF files: ``load_mesh`` gives a clear error naming
    it, or a Trimesh; ``rasterize`` of the file gives a clear error or a well-formed G-buffer."""
    mesh = {"box": lambda: trimesh.creation.box(), "icosphere": lambda: trimesh.creation.icosphere(subdivisions=0),
            "triangle": lambda: trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)}[shape]()  # fmt: skip
    if uv:
        mesh.visual = trimesh.visual.TextureVisuals(uv=np.linspace(0, 1, 2 * len(mesh.vertices)).reshape(-1, 2))
    with scratch() as d:
        path = d / f"mesh.{fmt.split('_')[0]}"
        bad = corrupt(_export(mesh, fmt), edits)
        path.write_bytes(bad)
        note(f"{fmt}: {len(bad)} bytes after {edits}")
        loaded = call("load_mesh", wt.load_mesh, path)
        if loaded is not None:
            assert isinstance(loaded, trimesh.Trimesh)
        g = call(("rasterize", "load_mesh"), wt.rasterize, path, wt.look_at((1.5, 2.0, 2.5), (0, 0, 0), resolution=res))
        if g is not None:
            check_gbuffer(g, res, loaded.vertices)


# -- writers: atomic, nothing left behind -------------------------------------------------------------------------


@st.composite
def small_images(draw):
    """Mostly well-formed small images (1-5 channels, values with NaN/inf/huge), else any array-like."""
    if draw(st.integers(0, 3)) == 0:
        return draw(image_like())
    shape = (draw(st.integers(1, 5)), draw(st.integers(1, 5)), draw(st.integers(1, 5)))
    if draw(st.booleans()):
        return flat_array(draw, shape, st.integers(0, 255), np.uint8)
    return flat_array(draw, shape, st.one_of(st.floats(-0.5, 1.5), st.sampled_from([0.0, 1.0, 1e30, INF, NAN])), draw(st.sampled_from([np.float32, np.float64])))


@given(image=small_images(), half=st.booleans(), bits=st.sampled_from([8, 8, 16, 12, True]), data_flag=st.booleans(),
       names=st.one_of(st.none(), st.none(), st.lists(st.text(min_size=0, max_size=300), min_size=0, max_size=5)),
       target=st.sampled_from(["plain", "nested/dir/x", "parent_is_file", "is_directory"]))  # fmt: skip
def test_writers_leave_nothing_behind(image, half, bits, data_flag, names, target):
    """``write_png``/``write_exr`` with any image, channel names (empty, long, non-ASCII, NUL) and
    target: a clear error and no file at all, or exactly the target file, which reads back."""
    for fmt in ("png", "exr"):
        with scratch() as d:
            path = d / f"out.{fmt}"
            if target == "nested/dir/x":
                path = d / "nested" / "dir" / f"x.{fmt}"
            elif target == "parent_is_file":
                (d / "file").write_bytes(b"x")
                path = d / "file" / f"x.{fmt}"
            elif target == "is_directory":
                path.mkdir()
            before = {p.relative_to(d) for p in d.rglob("*")}
            if fmt == "png":
                result = call("write_png", wio.write_png, path, image, bits=bits, data=data_flag)
            else:
                result = call("write_exr", wio.write_exr, path, image, half=half, channel_names=names)
            after = {p.relative_to(d) for p in d.rglob("*")}
            created = {p for p in after - before if (d / p).is_file()}
            event(f"{fmt}: {'written' if path.is_file() else 'refused'}")
            if result is None and not path.is_file():
                assert not created, f"{fmt} writer failed but left {sorted(map(str, created))}"
                continue
            assert created == {path.relative_to(d)}, f"{fmt} writer left {sorted(map(str, created))}"
            back = call(("read_image", "read_exr"), wio.read_image if fmt == "png" else lambda p: wio.read_exr(p, channels=wio.exr_channel_names(p)), path)
            assert back is not None, f"{fmt}: the written file does not read back"


@given(size=st.tuples(st.integers(1, 5), st.integers(1, 5)), seed=st.integers(0, 100), breakage=st.sampled_from(["none", "wrong_type", "bad_field", "parent_is_file"]))
def test_save_gbuffer_atomic(size, seed, breakage):
    """``save_gbuffer``: a clear error and nothing written, or exactly the target file, bit-exact on load."""
    g = _small_gbuffer(size, seed)
    with scratch() as d:
        path = d / "g.exr"
        arg = g
        if breakage == "wrong_type":
            arg = g.numpy()
        elif breakage == "bad_field":
            g.normal = wp.zeros((size[0] + 1, size[1]), dtype=wp.vec3)
        elif breakage == "parent_is_file":
            (d / "f").write_bytes(b"")
            path = d / "f" / "g.exr"
        result = call("save_gbuffer", wt.save_gbuffer, path, arg)
        files = sorted(p.name for p in d.rglob("*") if p.is_file())
        if breakage == "none":
            assert files == ["g.exr"]
            back = wt.load_gbuffer(path)
            for name in FIELDS:
                np.testing.assert_array_equal(getattr(back, name).numpy(), getattr(g, name).numpy())
        else:
            assert result is None, f"save_gbuffer accepted a {breakage} G-buffer"
            assert files == (["f"] if breakage == "parent_is_file" else []), f"save_gbuffer left {files}"


# -- findings: minimal reproducers of the bugs this file found, now regression tests ----------------------------


def _one_pixel_gbuffer(normal) -> GBuffer:
    g = GBuffer.empty((1, 1))
    g.mask.fill_(1.0)
    g.normal = wp.array(np.array([[normal]], np.float32), dtype=wp.vec3)
    return g


def _exr_with_bad_channel_name(path: Path) -> None:
    """A 1x1 RGB EXR whose first channel name starts with the byte 0x80 (not UTF-8)."""
    wio.write_exr(path, np.zeros((1, 1, 3), np.float32))
    data = bytearray(path.read_bytes())
    data[data.index(b"chlist\0") + 11] = 0x80  # "chlist\0", its 4-byte size, then the first name
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("eye", [np.array(["a"]), object(), "abc"], ids=["str-array", "object", "str"])
def test_finding_F1_camera_non_numeric_vector(eye):
    with pytest.raises((ValueError, TypeError), match=r"look_at\(\)"):
        wt.look_at(eye, (0, 0, 0), (0, 1, 0))


@pytest.mark.parametrize("func", ["sample", "stochastic"])
def test_finding_F2_single_uv_shape(func):
    out = getattr(wt, func)(wt.Texture(np.ones((2, 2, 3), np.float32)), np.array([0.5, 0.5], np.float32))
    assert out.shape == (3,)


@pytest.mark.parametrize("name", ["exr_channel_names", "load_gbuffer"])
def test_finding_F3_exr_header_not_utf8(tmp_path, name):
    path = tmp_path / "bad.exr"
    _exr_with_bad_channel_name(path)
    fn = wio.exr_channel_names if name == "exr_channel_names" else wt.load_gbuffer
    with pytest.raises(ValueError, match=rf"{name}\(\)") as info:
        fn(path)
    assert not isinstance(info.value, UnicodeDecodeError)


@pytest.mark.parametrize("kind", ["missing", "directory", "not_exr"])
def test_finding_F4_load_gbuffer_error_names(tmp_path, kind):
    path = tmp_path / "g.exr"
    if kind == "directory":
        path.mkdir()
    elif kind == "not_exr":
        path.write_bytes(b"not an exr")
    with pytest.raises((OSError, ValueError), match=r"load_gbuffer\(\)"):
        wt.load_gbuffer(path)


@pytest.mark.parametrize("writer", ["write_png", "write_exr", "save_gbuffer"])
def test_finding_F5_writer_parent_is_file(tmp_path, writer):
    (tmp_path / "file").write_bytes(b"x")
    target = tmp_path / "file" / "out.exr"
    with pytest.raises(OSError, match=rf"{writer}\(\)"):
        if writer == "save_gbuffer":
            wt.save_gbuffer(target, GBuffer.empty((1, 1)))
        else:
            getattr(wio, writer)(target, np.zeros((1, 1, 3), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_finding_F6_save_gbuffer_misshaped_field(tmp_path):
    g = GBuffer.empty((2, 2))
    g.normal = wp.zeros((3, 2), dtype=wp.vec3)
    with pytest.raises(ValueError, match=r"save_gbuffer\(\)"):
        wt.save_gbuffer(tmp_path / "g.exr", g)


RAGGED = [[[0.1, 0.2]], [[0.3]]]


@pytest.mark.parametrize("name", ["write_png", "write_exr", "sample"])
def test_finding_F7_ragged_lists(tmp_path, name):
    calls = {
        "write_png": lambda: wio.write_png(tmp_path / "x.png", RAGGED),
        "write_exr": lambda: wio.write_exr(tmp_path / "x.exr", RAGGED),
        "sample": lambda: wt.sample(wt.Texture(np.ones((2, 2, 1), np.float32)), [[0.1, 0.2], [0.3]]),
    }
    with pytest.raises((ValueError, TypeError), match=rf"{name}\(\)"):
        calls[name]()


@pytest.mark.parametrize("name", ["biplanar", "triplanar_normal"])
def test_finding_F8_huge_normal(name):
    g = _one_pixel_gbuffer((0.0, 0.0, 1e20))
    texture = wt.Texture(np.full((2, 2, 3), 0.5, np.float32))
    out = getattr(wt, name)(g, texture).numpy().reshape(-1)
    expected = [0.0, 0.0, 1.0] if name == "triplanar_normal" else [0.5, 0.5, 0.5]  # as for the unit normal (0, 0, 1)
    np.testing.assert_allclose(out, expected, atol=1e-5)


@pytest.mark.parametrize("normal, sharpness", [((0.6, 0.8, 0.0), 1000.0), ((1.0, 1.0, 1.0), 64.0)], ids=["0.6-0.8-0", "diagonal"])
def test_finding_F9_biplanar_high_sharpness(normal, sharpness):
    g = _one_pixel_gbuffer(np.array(normal) / np.linalg.norm(normal))
    out = wt.biplanar(g, wt.Texture(np.full((2, 2, 1), 0.5, np.float32)), sharpness=sharpness).numpy()
    np.testing.assert_allclose(out.reshape(-1), [0.5], rtol=1e-5)


def test_finding_F10_rasterize_large_triangle():
    s = 3e9
    mesh = trimesh.Trimesh([[-s, -s, 0], [s, -s, 0], [0, s, 0]], [[0, 1, 2]], process=False)
    g = wt.rasterize(mesh, wt.look_at((0.3, 0.4, 3.0), (0, 0, 0), resolution=(1, 1))).numpy()
    assert g["mask"][0, 0] == 1
    np.testing.assert_allclose(g["geometric_normal"][0, 0], [0, 0, 1], atol=1e-6)
    assert_finite(g["position_dx"], "position_dx")


def test_finding_F11_mip_overflow():
    texture = wt.Texture(np.full((2, 2, 1), 2e38, np.float32))
    np.testing.assert_array_equal(texture.numpy(1), np.full((1, 1, 1), 2e38, np.float32))


def test_finding_F12_hex_rotation_huge_uv():
    uv = np.array([[3.4e38, 0.0]], np.float32)
    texture = wt.Texture(np.random.default_rng(0).random((4, 4, 1)).astype(np.float32))
    out = wt.stochastic(texture, uv, wt.Stochastic("hex", seed=1, rotation=1.0)).numpy()
    assert_finite(out, "stochastic(hex, rotation=1)")
    taps = wt.hex_taps(np.array([[1e30, 0.0]], np.float32), seed=1, rotation=1.0)[2]
    assert (np.abs(taps) < 4).all(), f"taps not reduced to a tile: {taps.tolist()}"
