"""warptex._op.run derives the gradient bookkeeping from a launch's inputs: every differentiable input
gets its gradient, whichever struct it sits in, with no list of them kept anywhere by hand."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import _op

RNG = np.random.default_rng(11)


def _gbuffer() -> wt.GBuffer:
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, :2] * 0.5 + 0.5)
    return wt.rasterize(mesh, wt.look_at((1.6, 1.2, 2.4), (0, 0, 0), fov_y=40.0, resolution=(24, 32)))


def _texture(channels=4, layers=None):
    shape = (16, 16, channels) if layers is None else (layers, 16, 16, channels)
    data = RNG.random(shape).astype(np.float32)
    return wt.Texture(data) if layers is None else wt.TextureArray(data)


G = _gbuffer()
UV = RNG.uniform(-1, 2, (300, 2)).astype(np.float32)
DX = (RNG.normal(size=(300, 2)) * 0.02).astype(np.float32)
DY = (RNG.normal(size=(300, 2)) * 0.02).astype(np.float32)
MAPS = RNG.random((1, 5, 5, 4)).astype(np.float32)

# Each technique, and the inputs its output does not depend on there (by path into its kernels'
# arguments): everything else must receive a non-zero gradient when it alone requires one.
CASES = {
    "sample, derivatives": (lambda: wt.sample(_texture(), UV, uv_dx=DX, uv_dy=DY, sampler=wt.Sampler(filter="anisotropic")), set()),
    "sample, per-sample LOD": (lambda: wt.sample(_texture(), UV, lod=RNG.uniform(0, 3, 300).astype(np.float32)), set()),
    "stochastic hex": (lambda: wt.stochastic(_texture(), UV, "hex", lod=RNG.uniform(0, 3, 300).astype(np.float32)), set()),
    "triplanar": (lambda: wt.triplanar(G, _texture(), tiling=3.0), {"pixels.mask"}),
    "triplanar per face, hash4": (lambda: wt.triplanar(G, textures_per_face=[_texture() for _ in range(6)], tiling=3.0, stochastic="hash4"), {"pixels.mask"}),
    "triplanar_normal": (lambda: wt.triplanar_normal(G, _texture(3), tiling=3.0), {"pixels.mask"}),
    "splat, triplanar": (
        lambda: wt.splat(G, _texture(layers=4), MAPS, tiling=[2.0, 3.0, 4.0, 5.0], projection="triplanar", height_blend=0.3),
        # UV0's derivatives give a LOD to UV-mapped layers only; the layers' tiling is args.reads.params.tiling
        {"pixels.surface.mask", "pixels.uv0_dx", "pixels.uv0_dy", "args.reads.proj.tiling"},
    ),
    "splat, uv": (
        lambda: wt.splat(G, _texture(layers=4), MAPS, tiling=3.0, projection="uv"),
        {"pixels.surface.mask", "pixels.surface.position", "pixels.surface.position_dx", "pixels.surface.position_dy", "pixels.surface.normal", "args.reads.proj.tiling", "args.reads.proj.sharpness",
         "args.reads.proj.offsets", "args.reads.params.transition"},
    ),
    "splat_atlas": (lambda: wt.splat_atlas(G, wt.pack_atlas(_texture(layers=4)), *wt.export_index_maps(MAPS, k=2), tiling=3.0), {"pixels.mask"}),
}


def _captured(monkeypatch, call):
    """The ``run`` calls (kernels, arguments) that ``call`` makes."""
    seen = []
    real = _op.run

    def spy(kernels, count, **kw):
        seen.append((kernels, count, kw))
        return real(kernels, count, **kw)

    for module in ("sampling", "stochastic", "triplanar", "splat", "atlas"):  # the modules (warptex.splat is also the function)
        monkeypatch.setattr(importlib.import_module(f"warptex.{module}"), "run", spy)  # imported here: alone, this test may run first
    call()
    assert len(seen) == 1
    return seen[0]


@pytest.mark.parametrize("case", list(CASES))
def test_every_differentiable_input_gets_its_gradient(case, monkeypatch):
    """For each float array among a technique's inputs (struct fields included), requiring a gradient
    on it alone makes the output require one and gives it a non-zero gradient, whichever backward
    pass that takes: a differentiable input that the bookkeeping missed would get nothing."""
    call, unused = CASES[case]
    kernels, count, kw = _captured(monkeypatch, call)
    inputs = {"args": kw["args"], "pixels": kw["pixels"]}
    paths = [(path, a) for path, a in _op.differentiable(inputs) if a.shape[0] > 0 and a.size > 0]
    assert {p for p, _ in paths} >= unused, "an input listed as unused is not an input"
    checked = []
    for path, array in paths:
        array.requires_grad = True
        _repack(inputs)  # a struct holds its arrays' gradients as they were when they were set
        try:
            tape = wp.Tape()
            with tape:
                out = _op.run(kernels, count, **kw)
            assert out.requires_grad, f"{path}: the output does not require a gradient"
            out.grad.assign(np.random.default_rng(1).random(out.shape).astype(np.float32))
            tape.backward()
            grad = array.grad.numpy()
            if path in unused:
                assert not np.any(grad), f"{path}: listed as unused, but has a gradient"
            else:
                assert np.isfinite(grad).all() and np.any(grad), f"{path}: no gradient reached it"
            checked.append(path)
        finally:
            array.requires_grad = False
            _repack(inputs)
    assert len(checked) == len(paths)


def _repack(value):
    """Set every field of ``value`` (a dict of structs, or a struct) again, nested structs first."""
    items = value.items() if isinstance(value, dict) else [(name, getattr(value, name)) for name in value._cls.vars]
    for name, field in items:
        if wp.types.is_struct(field):
            _repack(field)
        if not isinstance(value, dict):
            setattr(value, name, field)


def test_nothing_requiring_gradients_records_nothing(monkeypatch):
    """Without a differentiable input that requires a gradient, the output requires none and a tape
    records nothing."""
    kernels, count, kw = _captured(monkeypatch, CASES["triplanar"][0])
    tape = wp.Tape()
    with tape:
        out = _op.run(kernels, count, **kw)
    assert not out.requires_grad and not tape.launches
