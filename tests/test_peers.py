"""The benchmark peers (benchmarks/peers) compute what warptex computes, on small data.

NumPy peers agree with warptex to 1e-5; the PyTorch (grid_sample) and Dr.Jit (Texture2f) peers to
1e-4 forward, and their texture gradients of ``sum(output)`` to 1e-4 relative to the largest
gradient, level by level (warptex: ``wp.Tape``, ``out.grad`` = 1, ``tex.grad(k)``). The torch and
drjit parts skip when those packages are not installed.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex.scenes.terrain import terrain
from warptex.scenes import terrain_camera

BENCHMARKS = str(Path(__file__).resolve().parents[1] / "benchmarks")
if BENCHMARKS not in sys.path:
    sys.path.insert(0, BENCHMARKS)

import peers  # noqa: E402  (benchmarks/peers, found through the path above)
from peers import common  # noqa: E402

TECHNIQUES = peers.TECHNIQUES
FORWARD_ATOL = {"numpy": 1e-5, "torch": 1e-4, "drjit": 1e-4}
GRAD_RTOL = 1e-4


# -- data: small textures, the sphere and terrain G-buffers used elsewhere in the tests ---------------


def _image(seed, h, w, c=4):
    return np.random.default_rng(seed).random((h, w, c)).astype(np.float32)


def _normal_map(seed, h, w):
    """A tileable normal map with moderate slopes (3×3 box blur of noise)."""
    raw = np.random.default_rng(seed).random((h, w, 3))
    blur = sum(np.roll(np.roll(raw, i, 0), j, 1) for i in (-1, 0, 1) for j in (-1, 0, 1)) / 9
    return np.concatenate([blur[..., :2], 0.8 + 0.2 * raw[..., 2:]], axis=-1).astype(np.float32)


@functools.lru_cache(maxsize=None)
def _sphere():
    """The orthographic unit sphere at 64 × 64 (as in test_triplanar), positions × 4 as coordinates."""
    camera = wt.orthographic((0, 0, 5), (0, 0, 0), height=2.2, resolution=(64, 64))
    return wt.rasterize(trimesh.creation.icosphere(subdivisions=4), camera)


@functools.lru_cache(maxsize=None)
def _terrain():
    """The default terrain (coarse mesh) at 48 × 64 (as in test_layers), for the UV0 splat."""
    return wt.rasterize(terrain(resolution=(65, 65)), terrain_camera((48, 64)))


def _source(technique):
    """The images a technique reads (level 0 each) and its options."""
    if technique in ("splat4", "splat8"):
        count = common.SPLAT_LAYERS[technique]
        layers = np.stack([_image(10 + j, 24, 20) for j in range(count)])
        maps = np.stack([_image(30 + m, 9, 7) for m in range(count // 4)])
        return {"layers": layers, "maps": maps}, {"tiling": np.linspace(2.0, 9.0, count).astype(np.float32)}
    if technique == "triplanar_normal":
        return {"texture": _normal_map(3, 16, 20)}, {"tiling": 4.0, "strength": 0.8}
    if technique in ("triplanar", "biplanar"):
        return {"texture": _image(2, 32, 24)}, {"tiling": 4.0}
    if technique in ("hash4", "cheap2"):
        return {"texture": _image(4, 16, 12)}, {"seed": 7, "mirror": True}
    return {"texture": _image(5, 20, 24)}, {"seed": 3} if technique == "hex" else {}


def _uv(technique, count=3000):
    rng = np.random.default_rng(11)
    uv = rng.uniform(-3, 5, (count, 2)).astype(np.float32)
    lod = rng.uniform(-0.5, 5.5, count).astype(np.float32)
    return uv, (None if technique == "bilinear" else lod)


def _textures(images, requires_grad=False, fmt="float32"):
    """Warptex textures of ``images``; textures and layers in ``fmt`` (maps stay float32)."""
    out = {}
    for name, img in images.items():
        if name == "layers":
            out[name] = wt.TextureArray(img, requires_grad=requires_grad, format=fmt)
        elif name == "maps":
            out[name] = wt.TextureArray(img, mipmaps=False, requires_grad=requires_grad)
        else:
            out[name] = wt.Texture(img, requires_grad=requires_grad, format=fmt)
    return out


@functools.lru_cache(maxsize=None)
def case(technique, fmt="float32"):
    """``(data, warptex output (N, C), warptex gradients {name: [per level]})`` of a technique, its
    textures stored in ``fmt`` (the data's levels are their decoded texels, ``data["format"]`` the
    format a peer is to store them in)."""
    images, opts = _source(technique)
    texs = _textures(images, requires_grad=True, fmt=fmt)
    if fmt != "float32":
        opts = {**opts, "format": fmt}
    if technique in common.GBUFFER_TECHNIQUES:
        g = _terrain() if technique in common.SPLAT_LAYERS else _sphere()
        data = common.gbuffer_data(g, texture=texs.get("texture"), layers=texs.get("layers"), maps=texs.get("maps"), **opts)
        call = dict(gbuffer=g, **texs)
    else:
        uv, lod = _uv(technique)
        data = common.sample_data(texs["texture"], uv, lod=lod, **opts)
        call = dict(texture=texs["texture"])
    tape = wp.Tape()
    with tape:
        out = common.warptex_forward(technique, data, **call)
    out.grad.fill_(1.0)
    if technique != "hex" or fmt == "float32":  # hex's histogram blend takes float32 textures' gradients only
        tape.backward()
    grads = {name: [t.grad(k) for k in range(t.num_levels)] for name, t in texs.items()}
    return data, out.numpy().reshape(-1, out.shape[-1]), grads


# -- checks ---------------------------------------------------------------------------------------------


def _load(backend):
    if backend != "numpy":
        pytest.importorskip(backend)
    try:
        return peers.load(backend)
    except peers.PeerUnavailable as err:
        pytest.skip(f"{backend} peers unavailable: {err}")


def _check_forward(backend, technique):
    peer = _load(backend)[technique]
    data, want, _ = case(technique)
    got = peer.output(peer.forward(peer.prepare(data)))
    assert got.shape == want.shape
    assert np.abs(want).max() > 0.1  # the data exercise the technique
    np.testing.assert_allclose(got, want, atol=FORWARD_ATOL[backend], rtol=0)
    return peer, data


def _check_gradients(backend, technique):
    peer = _load(backend)[technique]
    data, want_out, want = case(technique)
    out, grads = peer.forward_backward(peer.prepare(data))
    np.testing.assert_allclose(peer.output(out), want_out, atol=FORWARD_ATOL[backend], rtol=0)
    got = peer.grads(grads)
    assert set(got) == set(want)
    for name in want:
        assert 1 <= len(got[name]) <= len(want[name])
        for extra in want[name][len(got[name]) :]:  # levels a peer does not hold are never read
            assert not extra.any()
        scale = max(np.abs(g).max() for g in want[name])
        assert scale > 0
        for k, (a, b) in enumerate(zip(got[name], want[name])):
            np.testing.assert_allclose(a, b, atol=GRAD_RTOL * scale, rtol=0, err_msg=f"{technique}: {name} level {k}")


@pytest.mark.parametrize("technique", TECHNIQUES)
def test_numpy_peer_matches_warptex(technique):
    _check_forward("numpy", technique)


@pytest.mark.parametrize("backend", ["torch", "drjit"])
@pytest.mark.parametrize("technique", TECHNIQUES)
def test_autodiff_peer_matches_warptex(backend, technique):
    _check_forward(backend, technique)
    _check_gradients(backend, technique)


@pytest.mark.parametrize("technique", TECHNIQUES)
def test_torch_peer_split_over_threads_computes_the_same(technique, monkeypatch):
    """The torch peer splits a ``grid_sample`` read into one batch per thread (ATen runs a batch on
    one thread); with 3 threads and tiny batches every read is split and padded, and the results
    and gradients still match warptex."""
    torch = pytest.importorskip("torch")
    torch_peer = pytest.importorskip("peers.torch_peer")
    monkeypatch.setattr(torch_peer, "SPLIT_POINTS", 5)
    threads = torch.get_num_threads()
    torch.set_num_threads(3)
    try:
        _check_forward("torch", technique)
        _check_gradients("torch", technique)
    finally:
        torch.set_num_threads(threads)


def test_every_backend_lists_every_technique_or_says_why_not():
    for backend in peers.BACKENDS:
        reason = peers.unavailable(backend)
        if reason is None:
            assert set(peers.load(backend)) == set(TECHNIQUES)
        else:
            assert reason.startswith(backend)  # e.g. "torch is not installed (...)"


@pytest.mark.parametrize("technique", TECHNIQUES)
def test_drjit_half_peer_reads_the_texels_of_warptex_float16(technique):
    """``data["format"] = "float16"``: Dr.Jit's ``Texture2f16`` on the texels of warptex's float16
    textures computes warptex's float16 output (the benchmark's float16 peer rows)."""
    peer = _load("drjit")[technique]
    assert "float16" in peer.formats
    data, want, _ = case(technique, "float16")
    got = peer.output(peer.forward(peer.prepare(data)))
    assert np.abs(want).max() > 0.1
    np.testing.assert_allclose(got, want, atol=FORWARD_ATOL["drjit"], rtol=0)


def test_torch_peer_stores_half_textures_on_cuda_only():
    """torch 2.13's CPU half ``grid_sample`` is wrong from 256² images up (peers/torch_peer.py), so
    the CPU peer offers float32 alone and the benchmark has no torch float16 rows there."""
    assert all(peer.formats == ("float32",) for peer in _load("torch").values())


def test_limit_loop_computes_warptex_bilinear():
    """``bench_samplers.py --limit``: the plain C loop reads what warptex's bilinear reads, wrapped
    UVs of both signs, on one thread and on several."""
    reason = peers.unavailable("limit")
    if reason is not None:
        pytest.skip(f"the C loop cannot be built here: {reason}")
    peer = peers.load("limit")["bilinear"]
    data, want, _ = case("bilinear")
    assert data["uv"].min() < 0 < 1 < data["uv"].max()
    for threads in (1, 3):
        peers.set_threads("limit", threads)
        got = peer.output(peer.forward(peer.prepare(data)))
        np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)


def _misaligned(a):
    """A copy of ``a`` that starts 16 bytes past a 64-byte boundary (as NumPy often hands one over):
    16 bytes into a buffer that the peer's own ``aligned`` starts on one."""
    from peers.drjit_peer import aligned

    out = aligned(np.empty(a.nbytes + 16, np.uint8), np.uint8)[16:].view(a.dtype).reshape(a.shape)
    out[...] = a
    return out


def test_drjit_peer_reads_texels_as_packets_from_any_numpy_array(capfd):
    """Dr.Jit's LLVM backend uses a NumPy array in place and reads a texel's four channels with one
    packet gather only where the array starts 64-byte aligned; otherwise it gathers channel by
    channel, 1.4–2× slower on the benchmark sphere (benchmarks/peers/drjit_peer.py). The peer
    hands over aligned copies, so it runs Dr.Jit's fast path whatever the allocator gave: a
    benchmark process used to draw Dr.Jit's pace at random."""
    peer = _load("drjit")["bilinear"]
    import drjit as dr

    data, want, _ = case("bilinear")
    data = {**data, "levels": [_misaligned(level) for level in data["levels"]], "uv": _misaligned(data["uv"])}
    assert data["levels"][0].ctypes.data % 64 == 16
    capfd.readouterr()
    dr.set_log_level(dr.LogLevel.Debug)
    try:
        got = peer.output(peer.forward(peer.prepare(data)))
    finally:
        dr.set_log_level(dr.LogLevel.Warn)
    captured = capfd.readouterr()
    log = captured.out + captured.err
    assert "jit_var_gather_packet()" in log
    assert "jit_var_gather()" not in log  # no texel read channel by channel
    np.testing.assert_allclose(got, want, atol=FORWARD_ATOL["drjit"], rtol=0)
