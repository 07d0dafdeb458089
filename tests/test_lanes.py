"""CPU lane kernels (``warptex.kernels.lanes``): the same bits as the one-pixel kernels they stand for.

A lane kernel computes ``LANES`` pixels per launch index with a native helper that restates the
scalar ``@wp.func`` blocks; every case here compares its output with the one-pixel kernel's, bit for
bit (NaN payloads aside), over every filter, address mode, level, layer and channel case, and over
launches whose pixel count is not a multiple of the lane width.
"""

import dataclasses
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import _launch, _memory
from warptex._op import one_pixel_kernels
from warptex.kernels import native
from warptex.kernels.family import cpu_only
from warptex.kernels.lanes import LANES
from warptex.kernels.texels import read_channels


FUNCTION = type(read_channels)  # Warp's @wp.func type (its module path differs across releases)

#: The lane kernels the running test launched (``lane_kernels_launched``), for failure messages.
_LANE_KERNELS: dict = {}


def native_helpers(kernel) -> dict[str, str]:
    """The native functions a lane kernel calls, each with the header that defines it: the ``wt_*``
    calls of every ``wp.func_native`` its body reaches (through globals and factory closures)."""
    headers = {h.name: h.read_text() for h in native.folder().glob("*.h")}
    helpers, seen, stack = {}, set(), [kernel.func]
    while stack:
        f = stack.pop()
        if id(f) in seen or not hasattr(f, "__code__"):
            continue
        seen.add(id(f))
        refs = [f.__globals__.get(name) for name in f.__code__.co_names]
        for cell in f.__closure__ or ():
            try:
                refs.append(cell.cell_contents)
            except ValueError:  # an empty cell
                pass
        for ref in refs:
            if isinstance(ref, FUNCTION) and getattr(ref, "native_snippet", None):
                for name in re.findall(r"\b(wt_\w+)\s*\(", ref.native_snippet.split("#else")[0]):
                    helpers[name] = next((h for h, text in headers.items() if re.search(rf"\b{name}\s*\(", text) and f" {name}(" in text), "?")
            elif isinstance(ref, FUNCTION) and getattr(ref, "func", None) is not None:
                stack.append(ref.func)
    return helpers


def _same_bits(a: np.ndarray, b: np.ndarray) -> None:
    """``a`` and ``b`` are the same floats bit for bit, NaN wherever either is (any payload). A
    failure names the case (the test's parameters), the first pixel that differs and its lane, and
    the lane kernels the test launched with the native helpers (and headers) each calls."""
    assert a.shape == b.shape
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    differs = (nan_a != nan_b) | (~nan_a & ~nan_b & (a.view(np.uint32) != b.view(np.uint32)))
    if differs.any():
        where = np.argwhere(differs)
        first = tuple(int(i) for i in where[0])
        # a trailing axis of at most 4 is the channel; the launch index is the flat pixel before it
        channels = a.ndim >= 2 and a.shape[-1] <= 4
        pixel = int(np.ravel_multi_index(first[:-1], a.shape[:-1])) if channels else int(np.ravel_multi_index(first, a.shape))
        kernels = "; ".join(f"{key}: " + ", ".join(f"{h} ({header})" for h, header in sorted(native_helpers(k).items())) for key, k in _LANE_KERNELS.items())
        pytest.fail(
            f"{len(where)} entries differ in {os.environ.get('PYTEST_CURRENT_TEST', '?').split(' ')[0]}: first at {first} "
            f"(pixel {pixel}, lane {pixel % LANES}): lanes {float(a[first])!r}, one-pixel {float(b[first])!r}\n"
            f"lane kernels launched: {kernels or 'none'}"
        )



def _both_on_threads(threads: int, call):
    """:func:`_both` with warptex on ``threads`` CPU threads."""
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        return _both(call)
    finally:
        wt.set_num_threads(previous)

@pytest.fixture(autouse=True)
def lane_kernels_launched(monkeypatch):
    """Records the lane kernels each test launches (:data:`_LANE_KERNELS`)."""
    _LANE_KERNELS.clear()
    _spy_launches(monkeypatch, lambda kernel, dim: cpu_only(kernel) and _LANE_KERNELS.setdefault(kernel.key, kernel))


def _spy_launches(monkeypatch, seen) -> None:
    """Call ``seen(kernel, dim)`` for every launch of ``warptex._launch``: through ``wp.launch``,
    and through the ``wp.Launch`` it keeps for an unsplit launch (``_launch.replay``)."""
    launch, replay = wp.launch, _launch.replay

    def spy(kernel, dim, *args, **kwargs):
        if not kwargs.get("record_cmd"):  # replay's own recording: seen by spy_replay
            seen(kernel, dim)
        return launch(kernel, dim, *args, **kwargs)

    def spy_replay(kernel, dim, *args):
        seen(kernel, dim)
        return replay(kernel, dim, *args)

    monkeypatch.setattr(_launch.wp, "launch", spy)
    monkeypatch.setattr(_launch, "replay", spy_replay)


def _both(call):
    """``call()`` through the lane kernels, and through the one-pixel kernels, as NumPy arrays."""
    lanes = call().numpy()
    with one_pixel_kernels():
        scalar = call().numpy()
    return lanes, scalar


@pytest.fixture(autouse=True)
def nan_outputs(monkeypatch):
    """Every new output holds NaN until written: ``warptex._launch`` zeroes a one-pixel kernel's
    outputs but not a lane kernel's (a lane body writes every entry), so a lane output that left an
    entry alone shows NaN where the one-pixel kernel's shows 0, and the bits differ."""
    output = _launch.output

    def nan_filled(*args, **kwargs):
        out = output(*args, **kwargs)
        out.fill_(np.nan)
        return out

    monkeypatch.setattr(_launch, "output", nan_filled)
    monkeypatch.setattr("warptex._op.output", nan_filled)


@pytest.fixture
def launched(monkeypatch):
    """The names of the kernels ``warptex._launch`` launches, with their launch sizes."""
    seen = []
    _spy_launches(monkeypatch, lambda kernel, dim: seen.append((kernel.key, dim)))
    return seen


def _uvs(rng, n):
    """UVs over several periods, with the cases the scalar blocks treat apart: non-finite UVs (NaN
    out), huge ones (a period folded out exactly), a tiny negative one (reduced to 1.0 by wrap) and
    texel centres and edges of a 48 × 64 level (the floors' edges)."""
    uv = rng.uniform(-3.0, 3.0, (n, 2)).astype(np.float32)
    special = [(np.nan, 0.5), (0.5, np.inf), (-np.inf, np.nan), (1e30, -1e30), (-1e-10, -1e-10), (0.5 / 48, 1 - 0.5 / 64), (1.0, 0.0), (0.0, 1.0), (2.0, -1.0)]
    uv[: len(special)] = special
    return uv


def _sample_lane_inputs(rng, filter: str, address: str):
    """``(tex, n, uv, per_sample, smp)`` of the sample lane tests: a 3-layer array, ``n`` UVs (not a
    multiple of LANES) with :func:`_uvs`' special cases, per-sample layers (out-of-range ones clamp)
    and the sampler."""
    tex = wt.TextureArray(rng.random((3, 64, 48, 4), dtype=np.float32))
    n = 1037
    uv = _uvs(rng, n)
    per_sample = rng.integers(-2, 5, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address=address, border=(0.1, 0.2, 0.3, 0.4))
    return tex, n, uv, per_sample, smp


@pytest.mark.parametrize("address", ["wrap", "clamp", "mirror", "border"])
@pytest.mark.parametrize("filter,lod", [("bilinear", None), ("nearest", None), ("nearest", 1.6), ("trilinear", 1.3), ("trilinear", 0.0), ("trilinear", 40.0), ("trilinear", -2.0)])
def test_sample_lanes_give_the_one_pixel_bits(rng, launched, filter, lod, address):
    tex, n, uv, per_sample, smp = _sample_lane_inputs(rng, filter, address)
    for layer in (2, per_sample):
        lanes, scalar = _both(lambda: wt.sample(tex, uv, layer=layer, lod=lod, sampler=smp))
        _same_bits(lanes, scalar)
        assert np.isnan(lanes[:3]).all() and np.isfinite(lanes[3:]).all()
    names = [name for name, _ in launched]
    assert names.count("sample_level_lanes") == 2 and names.count("sample_level_forward") == 2
    assert (("sample_level_lanes", -(-n // LANES)) in launched) and (("sample_level_forward", n) in launched)


def _lod_inputs(rng, n, source: str) -> dict:
    """A LOD per sample (``lod``: -2 to 9 on a 7-level chain, and non-finite ones) or UV
    derivatives (``derivatives``: from 1/100 to 8 texels, stretched and skewed, zero, huge and
    non-finite ones), for ``sample``'s per-sample kernels."""
    if source == "lod":
        lod = rng.uniform(-2.0, 9.0, n).astype(np.float32)
        lod[20:24] = (np.nan, np.inf, -np.inf, 0.5)
        return {"lod": lod}
    scale = np.exp(rng.uniform(np.log(0.01), np.log(8.0), (n, 1))) / 64.0
    dx = (rng.normal(size=(n, 2)) * scale).astype(np.float32)
    dy = (rng.normal(size=(n, 2)) * scale * rng.uniform(0.05, 1.0, (n, 1))).astype(np.float32)  # anisotropic
    dx[20:26] = ((0.0, 0.0), (np.nan, 0.0), (np.inf, 1.0), (1e30, 1e30), (1e-30, 0.0), (0.01, 0.0))
    dy[20:26] = ((0.0, 0.0), (0.0, 0.0), (0.0, 1.0), (1e30, -1e30), (0.0, 1e-30), (0.0, 0.01))  # the last: round
    return {"uv_dx": dx, "uv_dy": dy}


@pytest.mark.parametrize("address", ["wrap", "clamp", "mirror", "border"])
@pytest.mark.parametrize("filter,source", [("nearest", "lod"), ("bilinear", "derivatives"), ("trilinear", "lod"), ("trilinear", "derivatives"), ("anisotropic", "derivatives")])
def test_sample_lanes_of_a_lod_per_sample_give_the_one_pixel_bits(rng, launched, filter, source, address):
    """A LOD per sample, given or from UV derivatives (``sampling.sample_lane``), every filter."""
    tex, n, uv, per_sample, smp = _sample_lane_inputs(rng, filter, address)
    lod = _lod_inputs(rng, n, source)
    for layer in (2, per_sample):
        lanes, scalar = _both(lambda: wt.sample(tex, uv, layer=layer, sampler=smp, **lod))
        _same_bits(lanes, scalar)
        assert np.isnan(lanes[:3]).all() and np.isfinite(lanes[30:]).all()
    names = [name for name, _ in launched]
    assert names.count("sample_lanes") == 2 and names.count("sample_forward") == 2
    assert (("sample_lanes", -(-n // LANES)) in launched) and (("sample_forward", n) in launched)


@pytest.mark.parametrize("address", ["wrap", "mirror"])  # the periodic modes stochastic sampling takes
@pytest.mark.parametrize("filter,source", [("nearest", "lod"), ("bilinear", "derivatives"), ("trilinear", "lod"), ("trilinear", "derivatives"), ("anisotropic", "derivatives")])
@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
def test_stochastic_lanes_give_the_one_pixel_bits(rng, launched, method, filter, source, address):
    """``stochastic.stochastic_lane``: each pixel's taps, then the lane's reads natively, tap by
    tap; non-finite UVs and LODs give NaN; the anisotropic filter goes pixel by pixel. UVs past
    1e8 take hex's rotation about each vertex from the skewed offsets."""
    tex = wt.TextureArray(rng.random((3, 64, 48, 3), dtype=np.float32))
    n = 1037
    uv = _uvs(rng, n)
    uv[30:62] = rng.uniform(1.0e8, 4.0e8, (32, 2)) * rng.choice([-1.0, 1.0], (32, 2))
    per_sample = rng.integers(-2, 5, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address=address)
    lod = _lod_inputs(rng, n, source)
    for layer in (2, per_sample):
        for option in (wt.Stochastic(method), wt.Stochastic(method, seed=7, mirror=True, blend=(0.1, 0.3), noise_frequency=3.7, noise_levels=5.5, contrast=3.0, rotation=0.6)):
            lanes, scalar = _both(lambda: wt.stochastic(tex, uv, option, layer=layer, sampler=smp, **lod))
            _same_bits(lanes, scalar)
            assert np.isnan(lanes[:3]).all() and np.isfinite(lanes[30:]).all()
    assert ("stochastic_lanes", -(-n // LANES)) in launched


def test_stochastic_lanes_with_a_histogram_and_on_a_real_texture(shared_data, launched):
    """brick.png, hex with the histogram-preserving blend (which the one-pixel kernel runs:
    ``linear_blend_take``) and without, at the Duck's UVs with a LOD per UV."""
    tex = wt.Texture.from_file(shared_data / "textures" / "brick.png")
    mesh = trimesh.load(shared_data / "meshes" / "Duck.glb", force="mesh")
    uv = (np.asarray(mesh.visual.uv, np.float32) * 5.0).astype(np.float32)
    lod = np.linspace(-1.0, 6.0, len(uv)).astype(np.float32)
    histogram = wt.prepare_histogram(tex)
    for option in (wt.Stochastic("hex"), wt.Stochastic("hex", histogram=histogram), wt.Stochastic("hash4", mirror=True)):
        launched.clear()
        lanes, scalar = _both(lambda: wt.stochastic(tex, uv, option, lod=lod))
        _same_bits(lanes, scalar)
        assert np.isfinite(lanes).all()
        assert any(name == "stochastic_lanes" for name, _ in launched) == (option.histogram is None)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("n", [1, LANES - 1, LANES, LANES + 1, 3 * LANES + 5])
def test_sample_lanes_write_only_their_pixels_and_channels(rng, channels, n):
    tex = wt.Texture(rng.random((20, 36, channels), dtype=np.float32))
    uv = rng.uniform(-1.0, 2.0, (n, 2)).astype(np.float32)
    lanes, scalar = _both(lambda: wt.sample(tex, uv))
    assert lanes.shape == (n, channels)
    _same_bits(lanes, scalar)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_sample_lanes_over_threads(rng, threads):
    """Chunks of a threaded launch end anywhere, so each has its own last, short lane."""
    tex = wt.Texture(rng.random((256, 256, 4), dtype=np.float32))
    uv = rng.uniform(0.0, 4.0, (100_003, 2)).astype(np.float32)
    lanes, scalar = _both_on_threads(threads, lambda: wt.sample(tex, uv, lod=0.7))
    _same_bits(lanes, scalar)


@pytest.mark.parametrize("threads", [1, 3])
def test_sample_lanes_stream_large_outputs(rng, threads):
    """An output of 4 MB or more (``WT_STREAM_BYTES``) is written by streaming stores
    (``wt_store_lane``), by the level lanes and the footprint lanes: every row written (the outputs
    start as NaN), the one-pixel kernels' bits, on 1 and 3 threads."""
    tex = wt.Texture(rng.random((128, 96, 4), dtype=np.float32))
    n = (4 << 20) // 16 + 1003
    uv = rng.uniform(-1.0, 3.0, (n, 2)).astype(np.float32)
    dx, dy = (rng.normal(size=(n, 2)).astype(np.float32) * 0.01 for _ in range(2))
    trilinear = wt.Sampler(filter="trilinear")
    for call in (lambda: wt.sample(tex, uv), lambda: wt.sample(tex, uv, uv_dx=dx, uv_dy=dy, sampler=trilinear)):
        lanes, scalar = _both_on_threads(threads, call)
        assert np.isfinite(lanes).all()
        _same_bits(lanes, scalar)


def test_sample_lanes_read_a_view_of_uvs_and_layers(rng):
    """UVs and layers given as ``wp.array`` views of larger arrays (their strides as given)."""
    tex = wt.TextureArray(rng.random((2, 32, 32, 4), dtype=np.float32))
    grid = wp.array(rng.uniform(0.0, 1.0, (4, 600, 2)).astype(np.float32), dtype=wp.vec2)
    layers = wp.array(rng.integers(0, 2, (4, 600)).astype(np.int32))
    lanes, scalar = _both(lambda: wt.sample(tex, grid[1], layer=layers[2]))
    _same_bits(lanes, scalar)


def test_sample_lanes_on_a_real_texture_and_mesh(shared_data):
    """brick.png sampled at the Duck's own UVs (as loaded, repeated and mirrored), every address mode."""
    tex = wt.Texture.from_file(shared_data / "textures" / "brick.png")
    mesh = trimesh.load(shared_data / "meshes" / "Duck.glb", force="mesh")
    uv = np.asarray(mesh.visual.uv, np.float32)
    uv = np.concatenate([uv, uv * 3.0 - 1.0]).astype(np.float32)
    for address in ("wrap", "clamp", "mirror", "border"):
        for lod in (None, 2.4):
            smp = wt.Sampler(address=address)
            lanes, scalar = _both(lambda: wt.sample(tex, uv, lod=lod, sampler=smp))
            _same_bits(lanes, scalar)


@pytest.mark.parametrize("filter", ["trilinear", "anisotropic"])
def test_sample_lanes_at_a_rasterised_meshs_uv_derivatives(shared_data, filter):
    """brick.png on the Duck at its own UV0 and the UV derivatives of a view of it: the lookup a
    renderer makes (a LOD per pixel from its derivatives), forward and texel gradients."""
    mesh = trimesh.load(shared_data / "meshes" / "Duck.glb", force="mesh")
    centre = mesh.bounds.mean(0)
    eye = centre + np.array((0.8, 0.5, 1.2)) * np.linalg.norm(mesh.extents)
    g = wt.rasterize(mesh, wt.look_at(eye, centre, fov_y=35.0, resolution=(120, 160)))
    uv = {k: g.uv("uv0")[k].numpy().reshape(-1, 2) for k in ("uv", "uv_dx", "uv_dy")}
    covered = g.mask.numpy().reshape(-1) > 0
    assert covered.mean() > 0.15  # the Duck is in view
    uv = {k: np.ascontiguousarray(v[covered] * 3.0) for k, v in uv.items()}  # repeated: every level is read
    rgb = wt.Texture.from_file(shared_data / "textures" / "brick.png")
    smp = wt.Sampler(filter=filter)
    lanes, scalar = _both(lambda: wt.sample(rgb, uv["uv"], uv_dx=uv["uv_dx"], uv_dy=uv["uv_dy"], sampler=smp))
    _same_bits(lanes, scalar)
    assert np.isfinite(lanes).all()
    tex = wt.Texture(rgb.numpy(0), requires_grad=True)
    _same_grads(lambda: wt.sample(tex, uv["uv"], uv_dx=uv["uv_dx"], uv_dy=uv["uv_dy"], sampler=smp), [tex], np.random.default_rng(0), tex.channels, len(uv["uv"]))


# -- triplanar and biplanar colour --------------------------------------------------------------------


def _hand_gbuffer(rng, count=1000, uv_sets=()):
    """A ``(1, count)`` G-buffer of random surface points, with the cases the scalar body treats
    apart: uncovered pixels (and whole lanes of them), zero, axis-aligned and non-finite normals,
    NaN and huge positions, zero and huge derivatives."""
    normals = rng.normal(size=(count, 3)).astype(np.float32)
    normals[:6] = [(0, 0, 0), (1, 0, 0), (0, -1, 0), (0, 0, 1), (np.nan, 0, 1), (np.inf, 0, 0)]
    positions = rng.uniform(-3.0, 3.0, (count, 3)).astype(np.float32)
    positions[6:9] = [(np.nan, 0, 0), (1e30, 0, 0), (0, -np.inf, 0)]
    scale = np.exp(rng.uniform(-6.0, 1.0, (count, 1))).astype(np.float32)
    dpdx = rng.normal(size=(count, 3)).astype(np.float32) * scale
    dpdy = rng.normal(size=(count, 3)).astype(np.float32) * scale
    dpdx[9], dpdy[9] = 0.0, 0.0
    dpdx[10], dpdy[10] = 1e20, 1e20
    mask = (rng.random(count) > 0.2).astype(np.float32)
    mask[3 * LANES : 6 * LANES] = 0.0  # whole lanes uncovered (a lane kernel skips them: family.lane_kernel's covered) ...
    mask[7 * LANES : 8 * LANES] = 0.0
    mask[7 * LANES + 5] = 1.0  # ... and a lane of one covered pixel
    g = wt.GBuffer.empty((1, count), uv_sets=uv_sets)
    for name, value in (("normal", normals), ("position", positions), ("position_dx", dpdx), ("position_dy", dpdy)):
        getattr(g, name).assign(value.reshape(1, count, 3))
    g.mask.assign(mask.reshape(1, count))
    return g


@pytest.mark.parametrize("address", ["wrap", "clamp", "mirror", "border"])
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
def test_triplanar_lanes_give_the_one_pixel_bits(rng, launched, filter, address):
    g = _hand_gbuffer(rng)
    tex = wt.TextureArray(rng.random((2, 64, 32, 4), dtype=np.float32))
    smp = wt.Sampler(filter=filter, address=address, border=(0.5, 0.25, 0.125, 1.0), lod_bias=0.3, max_aniso=4)
    for func, kw in ((wt.triplanar, {"tiling": (1.5, 2.0, 0.75), "sharpness": 3.0, "layer": 1}), (wt.biplanar, {"sharpness": 8.0}), (wt.triplanar, {"sharpness": 0.0, "mirror_fix": False, "offsets": [(0.3, 0.1), (0.0, 0.5), (0.25, 0.25)]})):
        lanes, scalar = _both(lambda: func(g, tex, sampler=smp, **kw))
        _same_bits(lanes, scalar)
        assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5
    assert ("triplanar_lanes", -(-1000 // LANES)) in launched


@pytest.mark.parametrize("sharpness", [0.0, 2.5, 8.0, 40.0, 256.0, 3000.0])  # exponents 0, exp/log, 1, 5, 32 (not by squares), and underflow
def test_biplanar_lanes_give_the_one_pixel_bits(rng, launched, sharpness):
    """Biplanar weights (``projection_lanes.triplanar_reads_lane``: the axes chosen by selects, the
    pairs whose powers underflow pixel by pixel) on every kind of normal: ties between axes, normals on a diagonal (both remapped bases 0: equal
    weights), normals too long to square, tiny ones, zero and non-finite ones."""
    g = _hand_gbuffer(rng)
    normals = g.normal.numpy().reshape(-1, 3)
    normals[11:20] = [(1, 1, 1), (1, 1, 0), (-1, 0, 1), (0.5, 0.5, 0.2), (3e19, 1e19, -2e19), (1e-30, 2e-30, 0), (1e38, 1e38, 1e38), (0.2, 0.6, -0.6), (0.7, 0.7, 0.1)]
    g.normal.assign(normals.reshape(1, -1, 3))
    g.mask.assign(np.maximum(g.mask.numpy(), (np.arange(normals.shape[0]) < 20).reshape(1, -1).astype(np.float32)))
    tex = wt.TextureArray(rng.random((2, 64, 32, 4), dtype=np.float32))
    for smp in (wt.Sampler(), wt.Sampler(filter="anisotropic", address="mirror", max_aniso=4)):
        lanes, scalar = _both(lambda: wt.biplanar(g, tex, sharpness=sharpness, tiling=(1.5, 2.0, 0.75), sampler=smp))
        _same_bits(lanes, scalar)
        assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5
    assert ("triplanar_lanes", -(-1000 // LANES)) in launched


@pytest.mark.parametrize("channels", [2, 3, 4])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_triplanar_normal_lanes_give_the_one_pixel_bits(rng, launched, filter, channels):
    """Normal mapping's lane (``triplanar.normal_lane``): every blend, in world and object space,
    and normals with a component so small that it rounds to zero as the normal is made unit length,
    which turns that projection's mirror fix (read, at sharpness 0), and normals whose square
    overflows (scaled down before they are made unit length: their signs turn the mirror fix)."""
    g = _hand_gbuffer(rng)
    normals = g.normal.numpy().reshape(-1, 3)
    normals[11:15] = [(10.0, 0.0, -1e-45), (0.0, -1e-45, 4.0), (3e19, -1e-30, 2e19), (2e19, -3e19, -1e19)]
    g.normal.assign(normals.reshape(1, -1, 3))
    g.mask.assign(np.maximum(g.mask.numpy(), (np.arange(normals.shape[0]) < 20).reshape(1, -1).astype(np.float32)))
    tex = wt.Texture(rng.random((64, 32, channels), dtype=np.float32))
    smp = wt.Sampler(filter=filter, max_aniso=4)
    placement = np.array([[0.0, 0.8, 0.0, 0.3], [-0.8, 0.0, 0.0, 0.0], [0.0, 0.0, 1.5, -0.2], [0.0, 0.0, 0.0, 1.0]], np.float32)
    for blend in ("whiteout", "udn", "rnm"):
        for kw in ({"sharpness": 3.0, "strength": 0.7}, {"sharpness": 0.0, "flip_green": True}, {"space": "object", "object_to_world": placement, "tiling": (1.5, 2.0, 0.75)}):
            lanes, scalar = _both(lambda: wt.triplanar_normal(g, tex, blend=blend, sampler=smp, **kw))
            _same_bits(lanes, scalar)
            assert (np.abs(lanes).sum(-1) > 0.5).mean() > 0.5
    assert ("triplanar_normal_lanes", -(-1000 // LANES)) in launched


@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_stochastic_triplanar_normal_lanes_give_the_one_pixel_bits(rng, launched, method, filter):
    """Normal mapping with a stochastic method (``triplanar_lanes.normal_lane_bodies`` with pixel
    bodies): each projection's sample read over its footprint through its stochastic taps, as
    stochastic colour reads it, then the normal made natively; a seed, a blend and a contrast,
    object space. A histogram's blend runs the one-pixel kernel."""
    g = _hand_gbuffer(rng)
    tex = wt.Texture(rng.random((64, 32, 3), dtype=np.float32))
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    placement = np.array([[0.0, 0.8, 0.0, 0.3], [-0.8, 0.0, 0.0, 0.0], [0.0, 0.0, 1.5, -0.2], [0.0, 0.0, 0.0, 1.0]], np.float32)
    option = wt.Stochastic(method, seed=7, blend=(0.1, 0.3), contrast=2.5)  # (no mirror nor rotation: normal mapping refuses them)
    for blend, kw in (("rnm", {"sharpness": 3.0}), ("whiteout", {"sharpness": 0.0, "space": "object", "object_to_world": placement, "tiling": (1.5, 2.0, 0.75)})):
        lanes, scalar = _both(lambda: wt.triplanar_normal(g, tex, blend=blend, sampler=smp, stochastic=option, **kw))
        _same_bits(lanes, scalar)
        assert (np.abs(np.nan_to_num(lanes)).sum(-1) > 0.5).mean() > 0.5
    assert ("triplanar_stochastic_normal_lanes", -(-1000 // LANES)) in launched
    if method == "hex" and filter == "trilinear":
        launched.clear()
        histogram = wt.prepare_histogram(tex)
        wt.triplanar_normal(g, histogram.texture, sampler=smp, stochastic=wt.Stochastic("hex", histogram=histogram))
        assert [name for name, _ in launched] == ["triplanar_stochastic_normal_forward"]  # linear_blend_take


def _face_inputs(rng):
    """``(g, faces)``: a hand-made G-buffer whose normals have components that are -0, tiny negative
    or exactly 0 (the - face is chosen by ``n < 0``), and six face textures of their own sizes (the
    LODs differ) that take gradients."""
    g = _hand_gbuffer(rng, 5000)
    normals = g.normal.numpy().reshape(-1, 3)
    normals[11:16] = [(-0.0, 1.0, 0.5), (-1e-45, 0.3, 2.0), (0.0, -0.0, -1.0), (0.4, -1e-38, 0.0), (-3e19, 1e19, -2e19)]
    g.normal.assign(normals.reshape(1, -1, 3))
    g.mask.assign(np.maximum(g.mask.numpy(), (np.arange(normals.shape[0]) < 20).reshape(1, -1).astype(np.float32)))
    faces = [wt.Texture(rng.random((16 << (k % 3), 24 + 8 * k, 3), dtype=np.float32), requires_grad=True) for k in range(6)]
    return g, faces


def _same_face_bits(rng, calls):
    """Each ``(call, textures)`` of :func:`_face_inputs`' G-buffer: the lanes' output and texel
    gradients of ``textures`` are the one-pixel kernels' bits, on 1 and 3 threads."""
    previous = wt.get_num_threads()
    try:
        for threads in (1, 3):
            wt.set_num_threads(threads)
            for call, textures in calls:
                lanes, scalar = _both(call)
                _same_bits(lanes, scalar)
                assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5
                _same_grads(call, textures, rng, 3, 5000)
    finally:
        wt.set_num_threads(previous)


@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
def test_face_lanes_give_the_one_pixel_bits(rng, launched, filter):
    """A texture per face (``triplanar_lanes.face_lane_bodies``): each projection read on the + and
    on the - face (``triplanar_reads_lane``'s ``side``), every face a texture of its own size (the
    LODs differ), normals whose components are -0, tiny negative or exactly 0 (the - face is
    chosen by ``n < 0``), in world and object space, triplanar and biplanar; forward and texel
    gradient (every face's), on 3 threads too."""
    g, faces = _face_inputs(rng)
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    placement = np.array([[0.0, 0.8, 0.0, 0.3], [-0.8, 0.0, 0.0, 0.0], [0.0, 0.0, 1.5, -0.2], [0.0, 0.0, 0.0, 1.0]], np.float32)
    calls = (lambda: wt.triplanar(g, textures_per_face=faces, sampler=smp, sharpness=3.0),
             lambda: wt.triplanar(g, textures_per_face=faces, sampler=smp, sharpness=0.0, space="object", object_to_world=placement, tiling=(1.5, 2.0, 0.75)),
             lambda: wt.biplanar(g, textures_per_face=faces, sampler=smp))  # fmt: skip
    _same_face_bits(rng, [(call, faces) for call in calls])
    names = {name for name, _ in launched}
    assert {"triplanar_faces_lanes", "triplanar_faces_texel_grad_lanes"} <= names


@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_stochastic_face_lanes_give_the_one_pixel_bits(rng, launched, method, filter):
    """Stochastic colour with a texture per face (``triplanar_lanes.face_lane_bodies``, stochastic):
    each projection's stochastic taps on the face its pixel reads, as :func:`test_face_lanes_give_the_one_pixel_bits`
    reads the faces; forward and texel gradient (every face's, and a texture shared by a + and a -
    face, whose adds interleave), on 3 threads too."""
    g, faces = _face_inputs(rng)
    shared = [faces[0], faces[0], faces[2], faces[3], faces[3], faces[5]]  # x+ and x-, y- and z+ share a texture
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    placement = np.array([[0.0, 0.8, 0.0, 0.3], [-0.8, 0.0, 0.0, 0.0], [0.0, 0.0, 1.5, -0.2], [0.0, 0.0, 0.0, 1.0]], np.float32)
    option = wt.Stochastic(method, seed=3, mirror=True, rotation=0.5)
    calls = ((lambda: wt.triplanar(g, textures_per_face=faces, sampler=smp, stochastic=option, sharpness=3.0), faces),
             (lambda: wt.triplanar(g, textures_per_face=shared, sampler=smp, stochastic=method, sharpness=0.0, space="object", object_to_world=placement, tiling=(1.5, 2.0, 0.75)), [faces[0], faces[2], faces[3], faces[5]]),
             (lambda: wt.biplanar(g, textures_per_face=faces, sampler=smp, stochastic=option), faces))  # fmt: skip
    _same_face_bits(rng, calls)
    names = {name for name, _ in launched}
    assert {"triplanar_stochastic_faces_lanes", "triplanar_stochastic_faces_texel_grad_lanes"} <= names


@pytest.mark.parametrize("method", [None, "hash4", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_face_normal_lanes_give_the_one_pixel_bits(rng, launched, method, filter):
    """Normal mapping with a normal map per face (``triplanar_lanes.normal_lane_bodies`` with
    ``faces``), plain and stochastic: each projection read on the face the unit normal looks at
    (a huge normal, whose length overflows, has a unit normal of zeros and reads the + faces, as
    the pixel body does), forward and both steps of the two-step gradient (every face's texels, and
    a texture shared by a + and a - face), on 3 threads too."""
    g, faces = _face_inputs(rng)
    shared = [faces[0], faces[0], faces[2], faces[3], faces[3], faces[5]]
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    placement = np.array([[0.0, 0.8, 0.0, 0.3], [-0.8, 0.0, 0.0, 0.0], [0.0, 0.0, 1.5, -0.2], [0.0, 0.0, 0.0, 1.0]], np.float32)
    option = None if method is None else wt.Stochastic(method, seed=3, blend=(0.1, 0.3), contrast=2.0)
    calls = ((lambda: wt.triplanar_normal(g, textures_per_face=faces, blend="rnm", sampler=smp, stochastic=option, sharpness=3.0), faces),
             (lambda: wt.triplanar_normal(g, textures_per_face=shared, sampler=smp, stochastic=option, sharpness=0.0, space="object", object_to_world=placement, tiling=(1.5, 2.0, 0.75)), [faces[0], faces[2], faces[3], faces[5]]))  # fmt: skip
    _same_face_bits(rng, calls)
    kind = "_stochastic" if method else ""
    names = {name for name, _ in launched}
    assert {f"triplanar{kind}_faces_normal_lanes", f"triplanar{kind}_faces_samples_lanes", f"triplanar{kind}_faces_samples_texel_grad_lanes"} <= names


@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
def test_stochastic_triplanar_lanes_give_the_one_pixel_bits(rng, launched, method, filter):
    """Stochastic triplanar and biplanar colour (``triplanar_lanes.stochastic_lane_body``): each
    projection's taps from its read (``stochastic_sample.projection_taps_lane``), read tap by tap and
    weighted in the pixel body's order; non-finite positions and normals, mirrored taps, rotated hex
    taps, a contrast, object space; the anisotropic filter's footprint taps each with their
    stochastic taps; a histogram's blend by the one-pixel kernel (``linear_blend_take``)."""
    g = _hand_gbuffer(rng)
    tex = wt.Texture(rng.random((64, 32, 3), dtype=np.float32))
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    placement = np.array([[0.0, 0.8, 0.0, 0.3], [-0.8, 0.0, 0.0, 0.0], [0.0, 0.0, 1.5, -0.2], [0.0, 0.0, 0.0, 1.0]], np.float32)
    options = (wt.Stochastic(method), wt.Stochastic(method, seed=7, mirror=True, blend=(0.1, 0.3), noise_frequency=3.7, noise_levels=5.5, contrast=2.5, rotation=0.6))
    for option in options:
        for technique, kw in ((wt.triplanar, {"sharpness": 3.0}), (wt.triplanar, {"sharpness": 0.0, "space": "object", "object_to_world": placement, "tiling": (1.5, 2.0, 0.75)}), (wt.biplanar, {})):
            lanes, scalar = _both(lambda: technique(g, tex, sampler=smp, stochastic=option, **kw))
            _same_bits(lanes, scalar)
            assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5
    assert ("triplanar_stochastic_lanes", -(-1000 // LANES)) in launched
    if method == "hex" and filter == "trilinear":
        histogram = wt.prepare_histogram(tex)
        launched.clear()
        lanes, scalar = _both(lambda: wt.triplanar(g, histogram.texture, sampler=smp, stochastic=wt.Stochastic("hex", histogram=histogram)))
        _same_bits(lanes, scalar)
        assert not any(name == "triplanar_stochastic_lanes" for name, _ in launched)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_stochastic_triplanar_gradient_lanes_add_the_one_pixel_sums(rng, launched, method, filter, threads):
    """Stochastic triplanar's texel gradient (``lane_scatter.scatter_projection_taps_lanes``): every
    tap of every projection adds its share pixel by pixel, projection by projection and tap by tap
    as the pixel body does, into one texture shared by the three projections (their adds
    interleave in its texels) and into a texture per axis, on 3 threads too; the anisotropic
    filter's every footprint tap's stochastic taps in order (``scatter_stochastic_reads_lanes``)."""
    g = _hand_gbuffer(rng, 20_000)
    shared = wt.Texture(rng.random((64, 32, 3), dtype=np.float32), requires_grad=True)
    axes = [wt.Texture(rng.random((32 << a, 48, 3), dtype=np.float32), requires_grad=True) for a in range(3)]
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        option = wt.Stochastic(method, seed=5, mirror=True, rotation=0.4)
        _same_grads(lambda: wt.triplanar(g, shared, sampler=smp, stochastic=option, sharpness=3.0), [shared], rng, 3, 20_000)
        _same_grads(lambda: wt.biplanar(g, textures_per_axis=axes, sampler=smp, stochastic=wt.Stochastic(method)), axes, rng, 3, 20_000)
    finally:
        wt.set_num_threads(previous)
    assert any(name == "triplanar_stochastic_texel_grad_lanes" for name, _ in launched)


@pytest.mark.parametrize("address", ["wrap", "clamp"])  # the origin folded by whole periods, or added exactly
@pytest.mark.parametrize("sharpness", [2.5, 1.0, 31.0, 40.0])  # exp and log, and the integer exponents' edges
def test_triplanar_lanes_far_from_the_origin(rng, address, sharpness):
    """Sharpness raised by ``exp`` and ``log`` as well as by squares, and a G-buffer whose positions are
    relative to a float64 origin far from the world's, which the plane UVs add in float64."""
    g = _hand_gbuffer(rng, 500)
    g.origin = np.array([1.0e5 + 0.3, -3.0e4, 2.5e6 + 0.7])
    tex = wt.Texture(rng.random((32, 64, 4), dtype=np.float32))
    smp = wt.Sampler(filter="trilinear", address=address)
    lanes, scalar = _both(lambda: wt.triplanar(g, tex, tiling=(0.75, 1.25, 2.0), sharpness=sharpness, sampler=smp))
    _same_bits(lanes, scalar)
    assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5


def test_triplanar_lanes_with_a_texture_per_axis_in_object_space(rng):
    g = _hand_gbuffer(rng, 777)
    textures = [wt.Texture(rng.random((16 << a, 32, 3), dtype=np.float32)) for a in range(3)]
    m = np.eye(4, dtype=np.float32)
    m[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0] * 1.7
    m[:3, 3] = (0.5, -2.0, 3.0)
    lanes, scalar = _both(lambda: wt.triplanar(g, textures_per_axis=textures, space="object", object_to_world=m, sampler=wt.Sampler(filter="trilinear")))
    _same_bits(lanes, scalar)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_triplanar_lanes_on_a_real_mesh(shared_data, threads):
    """The bunny rasterised from a view, brick.png projected on it: the image a user renders."""
    mesh = trimesh.load(shared_data / "meshes" / "bunny.ply", force="mesh")
    centre = mesh.bounds.mean(0)
    g = wt.rasterize(mesh, wt.look_at(centre + (0.0, 0.05, 0.25), centre, fov_y=35.0, resolution=(160, 200)))
    tex = wt.Texture.from_file(shared_data / "textures" / "brick.png")
    lanes, scalar = _both_on_threads(threads, lambda: wt.triplanar(g, tex, tiling=20.0))
    _same_bits(lanes, scalar)
    assert (lanes[..., :3] > 0).mean() > 0.3  # the bunny covers the view


# -- splat layers --------------------------------------------------------------------------------------


def _splat_gbuffer(rng, count=1000):
    """:func:`_hand_gbuffer` with UV0 and its derivatives (NaN, huge and zero ones among them)."""
    g = _hand_gbuffer(rng, count, uv_sets=("uv0",))
    uv = rng.uniform(-2.0, 3.0, (count, 2)).astype(np.float32)
    uv[11:14] = [(np.nan, 0.0), (1e30, 0.5), (0.25, -np.inf)]
    dx = rng.normal(size=(count, 2)).astype(np.float32) * 0.01
    dy = rng.normal(size=(count, 2)).astype(np.float32) * 0.01
    dx[14], dy[14] = 0.0, 0.0
    for name, value in (("uv", uv), ("uv_dx", dx), ("uv_dy", dy)):
        g.uv_sets["uv0"][name].assign(value.reshape(1, count, 2))
    mask = g.mask.numpy()
    mask[0, 11:15] = 1.0  # those UVs and derivatives on covered pixels
    g.mask.assign(mask)
    return g


SPLAT_CASES = {
    "uv": {},
    "uv, height channel": {"height_blend": 0.2},
    "uv, not normalized, tiling per layer": {"normalize": False, "tiling": [1.0, 2.5, 0.5, 3.0, 1.5]},
    "world xz, height array": {"projection": "world_xz", "height_blend": 0.3, "heights": True},
    "triplanar": {"projection": "triplanar", "sharpness": 3.0, "height_blend": 0.1},
    "triplanar, no heights": {"projection": "triplanar", "sharpness": 3.0},
    "triplanar, face layers": {"projection": "triplanar", "layers_per_face": [None, (1, 2, 3, 4, 0, 1), None, (0, 0, 4, 4, 2, 2), None], "offsets": [(0.1, 0.2), (0.0, 0.3), (0.5, 0.5)]},
    "triplanar, face layers, height array": {"projection": "triplanar", "layers_per_face": [(3, 3, 1, 1, 0, 2), None, (4, 0, 1, 2, 3, 2), None, None], "height_blend": 0.2, "heights": True},
}


def _splat_inputs(rng, case: str, count: int, requires_grad: bool = False):
    """``(g, layers, maps, options, textures)`` of a splat lane test: :func:`_splat_gbuffer` of
    ``count`` pixels, five layers, two splat maps, the options of ``SPLAT_CASES[case]`` (with its
    height layers where it asks for them) and the textures that take gradients."""
    g = _splat_gbuffer(rng, count)
    layers = wt.TextureArray(rng.random((5, 32, 64, 4), dtype=np.float32), requires_grad=requires_grad)
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (2, 16, 16, 4)).astype(np.float32), mipmaps=False, requires_grad=requires_grad)
    kw = dict(SPLAT_CASES[case])
    textures = [layers, maps]
    if kw.pop("heights", False):
        kw["heights"] = wt.TextureArray(rng.random((5, 48, 24, 1), dtype=np.float32), requires_grad=requires_grad)
        textures.append(kw["heights"])
    return g, layers, maps, kw, textures


@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
@pytest.mark.parametrize("case", list(SPLAT_CASES))
def test_splat_lanes_give_the_one_pixel_bits(rng, launched, case, filter):
    g, layers, maps, kw, _ = _splat_inputs(rng, case, 1000)
    smp = wt.Sampler(filter=filter, address="mirror", lod_bias=-0.4, max_aniso=3)
    lanes, scalar = _both(lambda: wt.splat(g, layers, maps, sampler=smp, **kw))
    _same_bits(lanes, scalar)
    assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5  # most pixels blend something
    assert ("splat8_lanes", -(-1000 // LANES)) in launched  # face layers too: each read on its face's array layer (wt_read_layers)


@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
@pytest.mark.parametrize("case", list(SPLAT_CASES))
def test_stochastic_splat_lanes_give_the_one_pixel_bits(rng, launched, case, filter, method):
    """A stochastic splat (``lanes.splat_layers.layer_values_stochastic_lane``): each layer's reads, then
    each read's stochastic taps read tap by tap, as the stochastic triplanar lane reads a
    projection; the anisotropic filter's footprint taps each with their stochastic taps. Face
    layers: each read on its face's array layer."""
    g, layers, maps, kw, _ = _splat_inputs(rng, case, 1000)
    smp = wt.Sampler(filter=filter, address="mirror", lod_bias=-0.4, max_aniso=3)
    option = wt.Stochastic(method, rotation=0.5, contrast=2.0) if method == "hex" else wt.Stochastic(method)
    lanes, scalar = _both(lambda: wt.splat(g, layers, maps, sampler=smp, stochastic=option, **kw))
    _same_bits(lanes, scalar)
    assert (np.nan_to_num(lanes) > 0).any(-1).mean() > 0.5  # most pixels blend something
    assert ("splat8_stochastic_lanes", -(-1000 // LANES)) in launched


def test_stochastic_splat_lanes_with_a_histogram_and_in_8_bits(rng, launched):
    """A histogram-preserving hex blend is not linear: the one-pixel kernels run it. 8-bit layers
    and more than eight layers (the kernels of 16) take the lanes."""
    g = _splat_gbuffer(rng, 700)
    layers = wt.TextureArray(rng.random((3, 32, 32, 4), dtype=np.float32))
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (1, 8, 8, 4)).astype(np.float32), mipmaps=False)
    histogram = wt.prepare_histogram(layers)
    lanes, scalar = _both(lambda: wt.splat(g, histogram.texture, maps, stochastic=wt.Stochastic("hex", histogram=histogram)))
    _same_bits(lanes, scalar)
    assert not any(name.startswith("splat8_stochastic_lanes") for name, _ in launched)
    eight = wt.TextureArray((rng.random((10, 16, 32, 4)) * 255).astype(np.uint8), format="srgb8")
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (3, 8, 8, 4)).astype(np.float32), mipmaps=False)
    lanes, scalar = _both(lambda: wt.splat(g, eight, maps, height_blend=0.25, stochastic="hash4"))
    _same_bits(lanes, scalar)
    assert ("splat16_stochastic_lanes", -(-700 // LANES)) in launched


@pytest.mark.parametrize("height_blend", [None, 0.25])
def test_splat_lanes_of_more_than_eight_layers(rng, launched, height_blend):
    """Ten layers take the kernels of 16, whose lanes weigh and blend each pixel through the scalar
    blocks (those of up to 8 do it for the whole lane in native code)."""
    g = _splat_gbuffer(rng, 700)
    layers = wt.TextureArray(rng.random((10, 16, 32, 4), dtype=np.float32))
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (3, 8, 8, 4)).astype(np.float32), mipmaps=False)
    lanes, scalar = _both(lambda: wt.splat(g, layers, maps, height_blend=height_blend))
    _same_bits(lanes, scalar)
    assert ("splat16_lanes", -(-700 // LANES)) in launched
    layers, maps = (wt.TextureArray(t.numpy(0), mipmaps=t.num_levels > 1, requires_grad=True) for t in (layers, maps))
    _same_grads(lambda: wt.splat(g, layers, maps, height_blend=height_blend), [layers, maps], rng, 4, 700)  # the kept colours, through Warp's matrices
    assert ("splat16_texel_grad_lanes", -(-700 // LANES)) in launched


@pytest.mark.parametrize("channels", [1, 2, 3])
def test_splat_lanes_with_maps_of_fewer_channels(rng, launched, channels):
    """Splat maps of 1-3 channels: map ``m``'s channel ``c`` holds layer ``m C + c``, forward and in
    the texel gradients (``map_values_lane8``, ``blend_backward_lane8``)."""
    g = _splat_gbuffer(rng, 600)
    layers = wt.TextureArray(rng.random((5, 16, 32, 4), dtype=np.float32), requires_grad=True)
    count = -(-5 // channels)
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (count, 8, 8, channels)).astype(np.float32), mipmaps=False, requires_grad=True)
    lanes, scalar = _both(lambda: wt.splat(g, layers, maps, height_blend=0.2))
    _same_bits(lanes, scalar)
    assert ("splat8_lanes", -(-600 // LANES)) in launched
    _same_grads(lambda: wt.splat(g, layers, maps, height_blend=0.2), [layers, maps], rng, 4, 600)
    assert ("splat8_texel_grad_lanes", -(-600 // LANES)) in launched


@pytest.mark.parametrize("projection", ["uv", "triplanar"])
def test_splat_lanes_on_the_default_terrain(projection):
    """The terrain ``warptex render`` draws: its height/slope splat map, its four generated layers,
    height blending, seen from its camera (sky pixels included)."""
    from warptex.scenes import TERRAIN_GRID, terrain_camera
    from warptex.scenes.material import terrain_layers, terrain_splat_maps
    from warptex.scenes.terrain import terrain

    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    g = wt.rasterize(mesh, terrain_camera((96, 128)))
    maps = wt.TextureArray(terrain_splat_maps(mesh, TERRAIN_GRID)[None], mipmaps=False)
    layers = terrain_layers(size=64)
    lanes, scalar = _both(lambda: wt.splat(g, layers, maps, tiling=[4.0, 6.0, 3.0, 5.0], projection=projection, height_blend=0.2))
    _same_bits(lanes, scalar)
    assert 0.2 < (g.mask.numpy() > 0).mean() < 1.0


# -- texel gradients ----------------------------------------------------------------------------------


def _texel_grads(call, textures, weights, one_pixel: bool, arrays=()) -> list:
    """Every level's texel gradient of ``textures`` after ``call()``'s output, weighted by ``weights``,
    is taken backwards, through the lane kernels or the one-pixel ones; first, copies of the
    gradients of ``arrays`` (UVs, LODs, a tiling: zeroed before)."""
    for t in textures:
        t.zero_grad()
    for a in arrays:
        a.grad.zero_()
    with one_pixel_kernels(one_pixel):
        tape = wp.Tape()
        with tape:
            out = call()
        out.grad.assign(weights.reshape(out.shape))
        tape.backward()
    return [a.grad.numpy().copy() for a in arrays] + [t.grad(level) for t in textures for level in range(t.num_levels)]


def _same_grads(call, textures, rng, channels, count):
    weights = rng.normal(size=(count, channels)).astype(np.float32)
    lanes = _texel_grads(call, textures, weights, False)
    scalar = _texel_grads(call, textures, weights, True)
    for a, b in zip(lanes, scalar):
        _same_bits(a, b)
    assert sum(np.abs(np.nan_to_num(g)).sum() for g in lanes) > 0  # something was added (NaN UVs may add NaN)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("address", ["wrap", "clamp", "mirror", "border"])
@pytest.mark.parametrize("filter,lod", [("bilinear", None), ("nearest", 1.6), ("trilinear", 1.3), ("trilinear", 40.0)])
def test_sample_gradient_lanes_add_the_one_pixel_sums(rng, launched, filter, lod, address, threads):
    """The same sums in the same order: the texel gradients are the same bits, on 3 threads too (where
    private copies mark the tiles they add into)."""
    tex = wt.TextureArray(rng.random((3, 64, 48, 4), dtype=np.float32), requires_grad=True)
    n = 40_003
    uv = _uvs(rng, n)
    layers = rng.integers(-2, 5, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address=address, border=(0.1, 0.2, 0.3, 0.4))
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        for layer in (1, layers):
            _same_grads(lambda: wt.sample(tex, uv, layer=layer, lod=lod, sampler=smp), [tex], rng, 4, n)
    finally:
        wt.set_num_threads(previous)
    assert any(name == "sample_level_texel_grad_lanes" for name, _ in launched)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("address", ["wrap", "clamp", "mirror", "border"])
@pytest.mark.parametrize("filter,source", [("bilinear", None), ("nearest", 1.6), ("trilinear", 1.3), ("nearest", "lod"), ("trilinear", "lod"), ("trilinear", "derivatives"), ("anisotropic", "derivatives")])
def test_sample_uv_and_lod_gradient_lanes_give_the_one_pixel_bits(rng, launched, filter, source, address, threads):
    """``sample``'s UV gradients (one LOD for all: ``wt_scatter_levels_lane``; a LOD per sample or
    from UV derivatives: ``wt_scatter_footprint_lane``) and a LOD per sample's, with the texels'
    and without: the same bits as the one-pixel kernel's, on 3 threads too."""
    data = rng.random((3, 64, 48, 4), dtype=np.float32)
    n = 10_007
    uv = _uvs(rng, n)
    layers = rng.integers(-2, 5, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address=address, border=(0.1, 0.2, 0.3, 0.4))
    weights = rng.normal(size=(n, 4)).astype(np.float32)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        for texels, layer in ((False, 1), (True, layers)):
            tex = wt.TextureArray(data, requires_grad=texels)
            inputs = [wp.array(uv, dtype=wp.vec2, requires_grad=True)]
            kw = {"lod": source} if not isinstance(source, str) else _lod_inputs(rng, n, source)
            if source == "lod":
                kw["lod"] = wp.array(kw["lod"], dtype=float, requires_grad=True)
                inputs.append(kw["lod"])
            lanes, scalar = (_texel_grads(lambda: wt.sample(tex, inputs[0], layer=layer, sampler=smp, **kw), [tex] if texels else [], weights, one_pixel, inputs) for one_pixel in (False, True))
            for a, b in zip(lanes, scalar):
                _same_bits(a, b)
            assert (np.abs(np.nan_to_num(lanes[0])).sum() > 0) == (filter != "nearest")
    finally:
        wt.set_num_threads(previous)
    kernel = "sample_level_texel_grad_lanes" if source is None or not isinstance(source, str) else "sample_texel_grad_lanes"
    assert any(name == kernel for name, _ in launched)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("filter,source", [("nearest", "lod"), ("trilinear", "lod"), ("trilinear", "derivatives"), ("anisotropic", "derivatives")])
@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
def test_stochastic_gradient_lanes_add_the_one_pixel_sums(rng, launched, method, filter, source, threads):
    """``stochastic.scatter_stochastic_lane``: every tap's share of the gradient added natively,
    pixel by pixel and tap by tap (``lane_scatter.scatter_taps_lane``), the same bits as the
    one-pixel kernel's, on 3 threads too; the anisotropic filter's (up to 16 footprint taps) every
    footprint tap's stochastic taps in order (``scatter_stochastic_footprint_lane``)."""
    tex = wt.TextureArray(rng.random((3, 64, 48, 4), dtype=np.float32), requires_grad=True)
    n = 30_011
    uv = _uvs(rng, n)
    layers = rng.integers(-2, 5, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address="mirror")
    lod = _lod_inputs(rng, n, source)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        for layer, option in ((1, wt.Stochastic(method, mirror=True)), (layers, wt.Stochastic(method, seed=3, contrast=2.5))):
            _same_grads(lambda: wt.stochastic(tex, uv, option, layer=layer, sampler=smp, **lod), [tex], rng, 4, n)
    finally:
        wt.set_num_threads(previous)
    assert any(name == "stochastic_texel_grad_lanes" for name, _ in launched)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_triplanar_normal_gradient_lanes_add_the_one_pixel_sums(rng, launched, filter, threads):
    """Normal mapping's two-step gradient: the first step's lanes (``triplanar._samples_lanes``)
    store the one-pixel kernel's samples and weights, and add each projection's own gradient into
    the texels in its order (``wt_triplanar_scatter_samples_lane``), and the second step's lanes
    make the normal and its gradient in the samples (``normal_lanes``), on 3 threads too."""
    g = _hand_gbuffer(rng, 20_000)
    tex = wt.Texture(rng.random((64, 32, 3), dtype=np.float32), requires_grad=True)
    smp = wt.Sampler(filter=filter, max_aniso=4)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        for kw in ({"sharpness": 3.0, "blend": "rnm"}, {"sharpness": 0.0, "blend": "whiteout", "space": "object", "object_to_world": np.diag([0.5, 2.0, 1.0, 1.0]).astype(np.float32)}):
            call = lambda: wt.triplanar_normal(g, tex, sampler=smp, **kw)  # noqa: E731
            _same_grads(call, [tex], rng, 3, 20_000)
            outs = []
            for one in (False, True):
                with one_pixel_kernels(one), wp.Tape():
                    outs.append(call().numpy())
            _same_bits(*outs)
    finally:
        wt.set_num_threads(previous)
    names = {name for name, _ in launched}
    assert {"triplanar_samples_lanes", "triplanar_samples_texel_grad_lanes", "triplanar_samples_forward", "triplanar_samples_texel_grad"} <= names
    assert {"triplanar_normal_blend_lanes", "triplanar_normal_blend_texel_grad_lanes", "triplanar_normal_blend_forward", "triplanar_normal_blend_texel_grad"} <= names


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("method", ["hash4", "hex"])
@pytest.mark.parametrize("filter", ["nearest", "trilinear", "anisotropic"])
def test_stochastic_triplanar_normal_gradient_lanes_add_the_one_pixel_sums(rng, launched, method, filter, threads):
    """Normal mapping's two-step gradient with a stochastic method: the first step's lanes store the
    one-pixel kernel's samples and weights and add each projection's own gradient back through its
    stochastic taps (``scatter_projection_taps_lanes``; the anisotropic filter's every footprint
    tap's, ``scatter_stochastic_reads_lanes``), into one texture and a texture per axis, on 3
    threads too."""
    g = _hand_gbuffer(rng, 20_000)
    tex = wt.Texture(rng.random((64, 32, 3), dtype=np.float32), requires_grad=True)
    axes = [wt.Texture(rng.random((32 << a, 48, 3), dtype=np.float32), requires_grad=True) for a in range(3)]
    smp = wt.Sampler(filter=filter, address="mirror", max_aniso=4)
    option = wt.Stochastic(method, seed=5, contrast=2.0)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        _same_grads(lambda: wt.triplanar_normal(g, tex, sampler=smp, stochastic=option, sharpness=3.0, blend="rnm"), [tex], rng, 3, 20_000)
        _same_grads(lambda: wt.triplanar_normal(g, textures_per_axis=axes, sampler=smp, stochastic=option, blend="udn"), axes, rng, 3, 20_000)
    finally:
        wt.set_num_threads(previous)
    names = {name for name, _ in launched}
    assert {"triplanar_stochastic_samples_lanes", "triplanar_stochastic_samples_texel_grad_lanes"} <= names


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("address", ["wrap", "clamp", "border"])
@pytest.mark.parametrize("filter,source", [("nearest", "lod"), ("trilinear", "lod"), ("trilinear", "derivatives"), ("anisotropic", "derivatives")])
def test_sample_gradient_lanes_of_a_lod_per_sample_add_the_one_pixel_sums(rng, launched, filter, source, address, threads):
    """The per-sample LOD's texel gradients (``sampling.scatter_sample_lane``; the anisotropic
    filter's pixel by pixel inside the lane) are the one-pixel kernels' bits, on 3 threads too."""
    tex = wt.TextureArray(rng.random((3, 64, 48, 4), dtype=np.float32), requires_grad=True)
    n = 40_003
    uv = _uvs(rng, n)
    layers = rng.integers(-2, 5, n).astype(np.int32)
    smp = wt.Sampler(filter=filter, address=address, border=(0.1, 0.2, 0.3, 0.4))
    lod = _lod_inputs(rng, n, source)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        for layer in (1, layers):
            _same_grads(lambda: wt.sample(tex, uv, layer=layer, sampler=smp, **lod), [tex], rng, 4, n)
    finally:
        wt.set_num_threads(previous)
    assert any(name == "sample_texel_grad_lanes" for name, _ in launched)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("address", ["wrap", "mirror", "border"])
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
def test_triplanar_gradient_lanes_add_the_one_pixel_sums(rng, launched, filter, address, threads):
    """One texture for the three projections (their adds interleave in the texels), and a texture
    per axis of which one needs no gradient."""
    g = _hand_gbuffer(rng, 30_000)
    shared = wt.TextureArray(rng.random((2, 64, 32, 4), dtype=np.float32), requires_grad=True)
    per_axis = [wt.Texture(rng.random((16 << a, 32, 3), dtype=np.float32), requires_grad=a != 1) for a in range(3)]
    smp = wt.Sampler(filter=filter, address=address, lod_bias=0.3, max_aniso=4)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        _same_grads(lambda: wt.triplanar(g, shared, tiling=(1.5, 2.0, 0.75), sharpness=3.0, layer=1, sampler=smp), [shared], rng, 4, 30_000)
        _same_grads(lambda: wt.biplanar(g, textures_per_axis=per_axis, sampler=smp), [per_axis[0], per_axis[2]], rng, 3, 30_000)
    finally:
        wt.set_num_threads(previous)
    assert any(name == "triplanar_texel_grad_lanes" for name, _ in launched)


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("address", ["wrap", "mirror", "border"])
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
def test_triplanar_slope_gradient_lanes_give_the_one_pixel_bits(rng, launched, filter, address, threads):
    """Plain sampling's tiling, offsets and sharpness gradients by hand (``wt_add_plane_slopes``,
    added pixel by pixel and projection by projection: colour's, and normal mapping's stored
    samples', which take no sharpness): their gradients and the texels' the same bits as the
    one-pixel kernel's, one tiling or one per axis, triplanar and biplanar weights (a sharpness of
    0 too), with the mirror fix and without, offsets, object space, and a G-buffer far from the
    world origin; the tiling alone, and with the offsets or the sharpness or both."""
    tex = wt.TextureArray(rng.random((2, 64, 32, 4), dtype=np.float32), requires_grad=True)
    smp = wt.Sampler(filter=filter, address=address, border=(0.5, 0.25, 0.125, 1.0), lod_bias=0.3, max_aniso=4)
    calls = []
    for count in (20_000, 137):  # a few pixels too: each term's last bits then reach the tiling's sums
        g = _hand_gbuffer(rng, count)
        mask = g.mask.numpy()
        mask[0, 4:9] = 0.0  # non-finite normals and positions, whose slopes make the whole tiling gradient NaN (in both)
        g.mask.assign(mask)
        far = dataclasses.replace(g, origin=np.array([3.0e5, -1.25e4, 7.5e3]))
        calls += [  # (G-buffer, technique, tiling, keywords, those of them that need gradients besides the tiling)
            (g, wt.triplanar, [1.5, 2.0, 0.75], {"sharpness": 3.0, "layer": 1}, {"sharpness"}),
            (g, wt.biplanar, [2.5], {"sharpness": 8.0, "offsets": np.zeros((3, 2))}, {"sharpness", "offsets"}),
            (g, wt.triplanar, [0.7], {"sharpness": 0.0, "mirror_fix": False, "offsets": [(0.3, 0.1), (0.0, 0.5), (0.25, 0.25)]}, {"sharpness", "offsets"}),
            (g, wt.triplanar, [1.1, 0.6, 1.9], {"space": "object", "object_to_world": np.diag([1.5, 0.8, 1.2, 1.0]).astype(np.float32)}, set()),
            (far, wt.triplanar, [0.35], {"sharpness": 2.5}, {"sharpness"}),
            (far, wt.biplanar, [0.35], {"offsets": [(0.3, 0.1), (0.0, 0.5), (0.25, 0.25)]}, {"offsets"}),
            (g, wt.triplanar_normal, [1.5, 2.0, 0.75], {"blend": "rnm", "sharpness": 3.0}, set()),  # the stored samples' gradient (wt_triplanar_scatter_samples_lane)
            (g, wt.triplanar_normal, [1.5], {"blend": "udn", "offsets": np.full((3, 2), 0.25)}, {"offsets"}),
            (far, wt.biplanar_normal, [0.35], {"blend": "whiteout"}, set()),
        ]
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    moved = []
    try:
        for gbuffer, func, tiling, kw, differentiated in calls:
            t = wp.array(np.float32(tiling), dtype=float, requires_grad=True)
            kw = {**kw, **{k: wp.array(np.float32(np.atleast_1d(kw[k])), dtype=float, requires_grad=True) for k in differentiated}}
            weights = np.random.default_rng(5).normal(size=(gbuffer.mask.size, 3 if "normal" in func.__name__ else 4)).astype(np.float32)
            arrays = [t, *(kw[k] for k in sorted(differentiated))]
            launched.clear()
            grads = [_texel_grads(lambda: func(gbuffer, tex, tiling=t, sampler=smp, **kw), [tex], weights, False, arrays)]
            lane = "triplanar_samples_texel_grad_lanes" if "normal" in func.__name__ else "triplanar_texel_grad_lanes"
            assert lane in {name for name, _ in launched}, (func.__name__, differentiated)  # the lanes took it
            grads.append(_texel_grads(lambda: func(gbuffer, tex, tiling=t, sampler=smp, **kw), [tex], weights, True, arrays))
            for a, b in zip(*grads):
                _same_bits(a, b)
            moved.append(np.abs(grads[0][0]).max() > 0)  # 0 where every read is the border colour (far from the origin)
    finally:
        wt.set_num_threads(previous)
    assert any(moved) == (filter != "nearest")


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
@pytest.mark.parametrize("case", list(SPLAT_CASES))
def test_splat_gradient_lanes_add_the_one_pixel_sums(rng, launched, case, filter, threads):
    """The layers', height layers' and splat maps' texel gradients: the same bits through the lane
    kernels, whose layers add layer by layer (each into texels of its own), then the height layers,
    as pixel by pixel; with face layers (layers sharing array layers), every layer's reads pixel by
    pixel, layer by layer. The anisotropic filter's reads of several taps add pixel by pixel, their
    taps in order."""
    g, layers, maps, kw, textures = _splat_inputs(rng, case, 3000, requires_grad=True)
    smp = wt.Sampler(filter=filter, address="mirror", lod_bias=-0.4, max_aniso=3)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        _same_grads(lambda: wt.splat(g, layers, maps, sampler=smp, **kw), textures, rng, 4, 3000)
    finally:
        wt.set_num_threads(previous)
    assert threads > 1 or ("splat8_texel_grad_lanes", -(-3000 // LANES)) in launched


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("method", ["hash4", "cheap2", "hex"])
@pytest.mark.parametrize("filter", ["trilinear", "anisotropic"])
@pytest.mark.parametrize("case", ["uv", "uv, height channel", "world xz, height array", "triplanar", "triplanar, no heights", "triplanar, face layers",
                                  "triplanar, face layers, height array"])  # fmt: skip
def test_stochastic_splat_gradient_lanes_add_the_one_pixel_sums(rng, launched, case, filter, method, threads):
    """The stochastic splat's texel gradients through its lanes: each layer's reads add their
    shares through their stochastic taps (``scatter_layer_stochastic_lane``), layer by layer, as
    pixel by pixel; the anisotropic filter's through every footprint tap's stochastic taps in
    order (``wt_scatter_stochastic_rows``); height layers' after the colour layers'. With face
    layers, every layer's reads at once, pixel by pixel (``scatter_face_layers_stochastic_lane``)."""
    g, layers, maps, kw, textures = _splat_inputs(rng, case, 3000, requires_grad=True)
    smp = wt.Sampler(filter=filter, address="mirror", lod_bias=-0.4, max_aniso=5)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        _same_grads(lambda: wt.splat(g, layers, maps, sampler=smp, stochastic=method, **kw), textures, rng, 4, 3000)
    finally:
        wt.set_num_threads(previous)
    assert threads > 1 or ("splat8_stochastic_texel_grad_lanes", -(-3000 // LANES)) in launched


# The tiling-gradient cases: the splat's options, an address mode and the layers' texel format (one each, to keep the test short).
_TILING_CASES = {
    "uv": (SPLAT_CASES["uv"], "wrap", "float32"),
    "uv, height channel": (SPLAT_CASES["uv, height channel"], "clamp", "unorm8"),
    "uv, not normalized, tiling per layer": (SPLAT_CASES["uv, not normalized, tiling per layer"], "border", "float32"),
    "world xz, height channel": ({"projection": "world_xz", "height_blend": 0.3, "tiling": [0.8, 1.2, 1.9, 0.6, 2.2]}, "mirror", "float32"),
    "uv, height array": ({"height_blend": 0.25, "heights": True}, "mirror", "float32"),
    "triplanar, height array": ({"projection": "triplanar", "sharpness": 3.0, "height_blend": 0.1, "heights": True, "tiling": [0.8, 1.2, 1.9, 0.6, 2.2]}, "wrap", "unorm8"),
    "triplanar": (SPLAT_CASES["triplanar"], "mirror", "float16"),
    "triplanar, no heights": (SPLAT_CASES["triplanar, no heights"], "wrap", "srgb8"),
    "triplanar, face layers, height array": ({**SPLAT_CASES["triplanar, face layers, height array"], "tiling": [0.8, 1.2, 1.9, 0.6, 2.2]}, "clamp", "float32"),
}


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("filter", ["nearest", "bilinear", "trilinear", "anisotropic"])
@pytest.mark.parametrize("case", list(_TILING_CASES))
def test_splat_tiling_gradient_lanes_add_the_one_pixel_sums(rng, launched, case, filter, threads):
    """The tiling's gradient (the fit's), one tiling for every layer or one each, in every projection,
    address mode and texel format: the forward lane keeps each layer's slope from its own taps
    (``lane_saved``), and the gradient lane adds each pixel's layers into the tiling in the one-pixel
    kernel's order, so the output, the tiling's gradient and the texels' are the same bits. Height
    layers keep their heights and slopes beside the colours'."""
    options, address, texel_format = _TILING_CASES[case]
    g = _splat_gbuffer(rng, 3000)
    layers = wt.TextureArray(rng.random((5, 32, 64, 4), dtype=np.float32), requires_grad=True, format=texel_format)
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (2, 16, 16, 4)).astype(np.float32), mipmaps=False, requires_grad=True)
    kw = dict(options)
    textures = [layers, maps]
    if kw.pop("heights", False):
        kw["heights"] = wt.TextureArray(rng.random((5, 48, 24, 1), dtype=np.float32), requires_grad=True)
        textures.append(kw["heights"])
    tiling = wp.array(np.atleast_1d(np.asarray(kw.pop("tiling", 1.7), dtype=np.float32)), dtype=float, requires_grad=True)
    smp = wt.Sampler(filter=filter, address=address, lod_bias=-0.4, border=(0.1, 0.2, 0.3, 0.4), max_aniso=24)
    weights = rng.normal(size=(3000, 4)).astype(np.float32)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        both = []
        for one_pixel in (False, True):
            tiling.grad.zero_()
            outs = []
            grads = _texel_grads(lambda: outs.append(wt.splat(g, layers, maps, tiling=tiling, sampler=smp, **kw)) or outs[-1], textures, weights, one_pixel)
            both.append([outs[0].numpy()] + grads + [tiling.grad.numpy().copy()])
    finally:
        wt.set_num_threads(previous)
    for a, b in zip(*both):  # the forward (which keeps the slopes from its own taps), the texels' and the tiling's gradients
        _same_bits(a, b)
    assert filter == "nearest" or np.all(both[0][-1] != 0.0)  # every tiling was reached (a nearest read has no slope)
    assert threads > 1 or ("splat8_texel_grad_lanes", -(-3000 // LANES)) in launched


@pytest.mark.parametrize("stochastic", [None, "hash4"])
def test_splat_gradient_lanes_of_height_layers(rng, launched, stochastic):
    """Height layers whose gradient is the colour layers' own (``heights=`` the one-channel layers
    themselves: a pixel's colour and height adds interleave in the same texels) run the one-pixel
    kernel; separate height layers that need no gradient, beside colour layers that do, take the
    lanes. Both give the one-pixel kernel's bits."""
    g = _splat_gbuffer(rng, 3000)
    grey = wt.TextureArray(rng.random((5, 32, 64, 1), dtype=np.float32), requires_grad=True)
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (2, 16, 16, 4)).astype(np.float32), mipmaps=False, requires_grad=True)
    name = "splat8_stochastic_texel_grad_lanes" if stochastic else "splat8_texel_grad_lanes"
    _same_grads(lambda: wt.splat(g, grey, maps, heights=grey, height_blend=0.2, stochastic=stochastic), [grey, maps], rng, 1, 3000)
    assert not any(n == name for n, _ in launched)  # splat_lanes.grad_lanes_take
    layers = wt.TextureArray(rng.random((5, 32, 64, 4), dtype=np.float32), requires_grad=True)
    heights = wt.TextureArray(rng.random((5, 48, 24, 1), dtype=np.float32))
    _same_grads(lambda: wt.splat(g, layers, maps, heights=heights, height_blend=0.2, stochastic=stochastic), [layers, maps], rng, 4, 3000)
    assert (name, -(-3000 // LANES)) in launched


def test_splat_gradient_lanes_read_the_colours_their_own_forward_kept(rng, launched, monkeypatch):
    """A splat recorded with gradients keeps its layers' colours for its backward lane
    (``SplatPixels.saved``): two of one size on one tape each read their own, and one recorded after
    that tape is gone takes the kept block still holding their colours (``warptex._memory``), and
    overwrites every entry."""
    monkeypatch.setattr(_memory, "MIN_BYTES", 0)  # this small test's 240 kB of colours are kept too
    g = _splat_gbuffer(rng, 3000)
    layers = wt.TextureArray(rng.random((5, 32, 64, 4), dtype=np.float32), requires_grad=True)
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (2, 16, 16, 4)).astype(np.float32), mipmaps=False, requires_grad=True)
    weights = rng.normal(size=(3000, 4)).astype(np.float32)
    colours = 3000 * 20 * 4  # bytes: 5 layers of RGBA a pixel
    taken = []
    take = _memory._take
    monkeypatch.setattr(_memory, "_take", lambda nbytes: taken.append((nbytes, take(nbytes))) or taken[-1][1])

    def grads(one_pixel: bool, tilings) -> list:
        layers.zero_grad()
        maps.zero_grad()
        with one_pixel_kernels(one_pixel):
            tape = wp.Tape()
            with tape:
                outs = [wt.splat(g, layers, maps, tiling=t, height_blend=0.2) for t in tilings]
            for k, out in enumerate(outs):
                out.grad.assign(weights * (k + 1))
            tape.backward()
        return [layers.grad(k) for k in range(layers.num_levels)] + [maps.grad(0)]

    for a, b in zip(grads(False, (1.0, 2.5)), grads(True, (1.0, 2.5))):
        _same_bits(a, b)
    kept = {address for nbytes, address in _memory._spares if nbytes == colours}
    assert kept  # the first tape's, given back
    taken.clear()
    for a, b in zip(grads(False, (0.7,)), grads(True, (0.7,))):
        _same_bits(a, b)
    assert any(nbytes == colours and address in kept for nbytes, address in taken)
    assert sum(1 for name, _ in launched if name == "splat8_texel_grad_lanes") == 3


@pytest.mark.parametrize("case", list(SPLAT_CASES))
def test_splat_gradient_lanes_give_the_one_pixel_bits(rng, launched, case):
    """Every splat case's texel gradients (layers, maps, height layers) and its tiling's, given as a
    ``wp.array`` that takes gradients: the blend's and weights' backward of the lane
    (``blend_backward_lane8``: no height blend, a height channel, height layers; normalised or
    not) gives the one-pixel kernel's bits."""
    g, layers, maps, kw, textures = _splat_inputs(rng, case, 3000, requires_grad=True)
    mask = g.mask.numpy()
    mask[0, :15] = 0.0  # not the non-finite or huge normals, positions, derivatives and UVs, which make the tiling's gradient NaN
    g.mask.assign(mask)
    tiling = wp.array(np.asarray(kw.pop("tiling", [1.5]), dtype=np.float32), dtype=float, requires_grad=True)
    weights = rng.normal(size=(3000, 4)).astype(np.float32)
    grads = [_texel_grads(lambda: wt.splat(g, layers, maps, tiling=tiling, **kw), textures, weights, one_pixel, arrays=[tiling]) for one_pixel in (False, True)]
    for a, b in zip(*grads):
        _same_bits(a, b)
    assert np.abs(np.nan_to_num(grads[0][0])).sum() > 0 and np.abs(np.nan_to_num(grads[0][-1])).sum() > 0  # the tiling's and the maps' (or heights')
    assert ("splat8_texel_grad_lanes", -(-3000 // LANES)) in launched


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("case", ["uv, height channel", "uv, not normalized, tiling per layer", "triplanar"])
def test_splat_gradient_lanes_add_the_transition_gradient(rng, launched, case, threads):
    """A height blend's transition given as a ``wp.array`` that takes gradients: its gradient too is
    the one-pixel kernel's bits (each pixel adds its share in pixel order), beside the texels'."""
    g = _splat_gbuffer(rng, 3000)
    layers = wt.TextureArray(rng.random((5, 32, 64, 4), dtype=np.float32), requires_grad=True)
    maps = wt.TextureArray(rng.uniform(-0.2, 1.0, (2, 16, 16, 4)).astype(np.float32), mipmaps=False, requires_grad=True)
    transition = wp.array([0.15], dtype=float, requires_grad=True)
    kw = dict(SPLAT_CASES[case], height_blend=transition)
    weights = rng.normal(size=(3000, 4)).astype(np.float32)
    previous = wt.get_num_threads()
    wt.set_num_threads(threads)
    try:
        grads = []
        for one_pixel in (False, True):
            transition.grad.zero_()
            texels = _texel_grads(lambda: wt.splat(g, layers, maps, **kw), [layers, maps], weights, one_pixel)
            grads.append([*texels, transition.grad.numpy().copy()])
    finally:
        wt.set_num_threads(previous)
    for a, b in zip(*grads):
        _same_bits(a, b)
    assert grads[0][-1][0] != 0.0
    assert threads > 1 or ("splat8_texel_grad_lanes", -(-3000 // LANES)) in launched


def test_lane_kernels_live_in_cpu_only_modules():
    """A CPU job compiles the lane kernels instead of the one-pixel ones, a GPU job never: every lane
    kernel is in its one-pixel kernel's module + ``.lanes``, and ``launched`` picks it on the CPU."""
    from warptex.kernels import all_kernels
    from warptex.kernels.family import LANES_SUFFIX, cpu_only, registered_kernels
    from warptex.kernels.sampling import sample_kernels
    from warptex.kernels.splat import splat_kernels
    from warptex.kernels.triplanar import triplanar_kernels

    families = [sample_kernels(level=True), triplanar_kernels(normal=False, stochastic=False, faces=False), splat_kernels(capacity=8, stochastic=False)]
    for k in families:
        assert k.lanes is not None and cpu_only(k.lanes) and not cpu_only(k.forward)
        assert k.lanes.module.name == k.forward.module.name + LANES_SUFFIX
        assert k.launched("cpu") is k.lanes
        if k.texel_grad_lanes is not None:
            assert k.texel_grad_lanes.module.name == k.texel_grad.module.name + LANES_SUFFIX
            assert k.launched("cpu", grad=True) is k.texel_grad_lanes
    lanes = [k for k in all_kernels((4,)) if cpu_only(k)]
    assert len(lanes) >= 5 and all(k in registered_kernels({"layer_counts": (4,)}) for k in lanes)
    assert not any(cpu_only(k) for k in (sample_kernels(level=False).forward, triplanar_kernels(normal=False, stochastic=True, faces=False).forward))


@pytest.mark.parametrize("address", ["wrap", "border"])
def test_anisotropic_lanes_read_every_tap(rng, address):
    """Footprints stretched 100:1 along a random direction take ``max_aniso`` taps (others one, or
    a few), each lane its own count: the lanes' means of taps are the one-pixel kernel's bits."""
    count = 999
    g = _hand_gbuffer(rng, count)
    angle = rng.uniform(0.0, np.pi, count)
    major = np.stack([np.cos(angle), np.sin(angle), np.zeros(count)], -1).astype(np.float32)
    minor = np.stack([-np.sin(angle), np.cos(angle), np.zeros(count)], -1).astype(np.float32)
    stretch = rng.choice([1.0, 3.0, 100.0], count).astype(np.float32)[:, None]
    g.normal.assign(np.tile(np.float32([0.1, 0.2, 1.0]), (1, count, 1)))
    g.position.assign(rng.uniform(0.05, 0.45, (1, count, 3)).astype(np.float32))  # inside the texture, for the border mode
    g.position_dx.assign((major * 0.01 * stretch).reshape(1, count, 3))
    g.position_dy.assign((minor * 0.01).reshape(1, count, 3))
    tex = wt.Texture(rng.random((128, 128, 4), dtype=np.float32))
    smp = wt.Sampler(filter="anisotropic", address=address, max_aniso=8)
    lanes, scalar = _both(lambda: wt.triplanar(g, tex, tiling=2.0, sampler=smp))
    _same_bits(lanes, scalar)
    trilinear = wt.triplanar(g, tex, tiling=2.0, sampler=wt.Sampler(filter="trilinear", address=address)).numpy()
    stretched = (stretch[:, 0] == 100.0) & (g.mask.numpy()[0] > 0)
    assert (np.abs(lanes - trilinear)[0][stretched].max(-1) > 1e-3).mean() > 0.5  # those pixels read several taps


def test_one_lane_decision():
    """``lanes_for`` alone decides whether a launch runs lanes: CPU only, where the configuration has
    them and takes the launch's ``args``, not within ``one_pixel_kernels``, and a gradient lane that
    reads what the forward lane keeps only where that lane runs."""
    from warptex.kernels.family import Kernels, lanes_for

    forward, grad, lanes, grad_lanes = (object() for _ in range(4))
    plain = Kernels(forward, grad, lanes=lanes, texel_grad_lanes=grad_lanes)
    assert lanes_for(plain, "cpu") is lanes and lanes_for(plain, "cpu", grad=True) is grad_lanes
    assert plain.launched("cpu") is lanes and plain.launched("cpu", grad=True) is grad_lanes
    with one_pixel_kernels():
        assert lanes_for(plain, "cpu") is None and lanes_for(plain, "cpu", grad=True) is None
        assert plain.launched("cpu") is forward and plain.launched("cpu", grad=True) is grad
    assert lanes_for(Kernels(forward, grad), "cpu") is None
    picky = Kernels(forward, grad, lanes=lanes, texel_grad_lanes=grad_lanes, lanes_take=lambda args: args == "small", lane_saved=lambda args: 3)
    assert lanes_for(picky, "cpu", "small") is lanes and lanes_for(picky, "cpu", "small", grad=True) is grad_lanes
    assert lanes_for(picky, "cpu", "big") is None
    assert lanes_for(picky, "cpu", "big", grad=True) is None  # its forward lane keeps nothing to read
    assert lanes_for(picky, "cpu") is lanes  # no args: as compiled ahead, any launch
    if wp.is_cuda_available():
        assert lanes_for(plain, "cuda:0") is None and plain.launched("cuda:0") is forward


#: The tests run again at the width this host does not use: those that reach each of the lanes'
#: width-specific code (the transposes, the bilinear blend of rows, the 8-bit byte shuffle).
OTHER_WIDTH_TESTS = (
    "test_sample_lanes_give_the_one_pixel_bits or test_triplanar_normal_lanes_give_the_one_pixel_bits"
    " or test_splat_lanes_give_the_one_pixel_bits or test_sample_gradient_lanes_add_the_one_pixel_sums"
    " or test_a_compact_texture_samples_as_its_decoded_float_twin"
)


def test_lanes_of_the_other_width_give_the_one_pixel_bits():
    """The lanes are 16 pixels wide with AVX-512 and 8 without (``host_lanes``); every test above runs
    this host's width, and those of ``OTHER_WIDTH_TESTS`` run here at the other one (``WARPTEX_LANES``),
    in a process of their own (the width is fixed at import), so that both widths' C++ stays the
    scalar kernels' bits on any host."""
    other = 8 if LANES == 16 else 16
    here = os.path.dirname(os.path.abspath(__file__))
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-x", "-k", OTHER_WIDTH_TESTS,
         os.path.join(here, "test_lanes.py"), os.path.join(here, "test_formats.py")],
        env=dict(os.environ, WARPTEX_LANES=str(other)), capture_output=True, text=True, timeout=1800)
    tail = (run.stdout + run.stderr)[-6000:]
    assert run.returncode == 0, f"at lanes of {other}:\n{tail}"
    passed = re.search(r"(\d+) passed", run.stdout)
    assert passed and int(passed.group(1)) >= 100, f"at lanes of {other}, too few tests ran:\n{tail}"


def test_the_lane_width_is_the_hosts_or_asked(monkeypatch):
    """``WARPTEX_LANES`` picks 8 or 16 and nothing else; unset, the host's SIMD decides."""
    from warptex.kernels.lanes import host_lanes

    for width in (8, 16):
        monkeypatch.setenv("WARPTEX_LANES", str(width))
        assert host_lanes() == width
    for bad in ("4", "32", "sixteen"):
        monkeypatch.setenv("WARPTEX_LANES", bad)
        with pytest.raises(ValueError, match="8 or 16"):
            host_lanes()
    monkeypatch.delenv("WARPTEX_LANES")
    assert host_lanes() in (8, 16)
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            avx512 = any(line.startswith("flags") and "avx512f" in line.split() for line in f)
        assert host_lanes() == (16 if avx512 else 8)
