"""Texture sampling at UV coordinates: :func:`sample`."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import warp as wp

from warptex import _plan
from warptex._op import run
from warptex._pack import footprints, lod_inputs, mip_levels, out_array, packed, reshaped, resolve_layer, sample_args, struct_of, vec2_array
from warptex._validate import resolve_device
from warptex.kernels import sampling as ks
from warptex.kernels import texels as kx
from warptex.kernels.family import Kernels
from warptex.options import Sampler, _as_sampler
from warptex.texture import TextureArray


def sample(texture: TextureArray, uv, *, layer=None, lod=None, uv_dx=None, uv_dy=None, sampler: Sampler | None = None, device=None, out=None) -> wp.array:
    """Sample a texture (or a layer of a texture array) at UV coordinates.

    Args:
        texture: a :class:`Texture` or :class:`TextureArray` with ``C`` channels.
        uv: texture coordinates, shape ``(..., 2)``: a float NumPy array, or a ``wp.array`` of
            ``wp.vec2`` of any shape (receives gradients when it has ``requires_grad``). ``(0, 0)``
            is the image's bottom-left corner; non-finite UVs give NaN in every channel.
        layer: for a :class:`TextureArray`: an int, or an int array with one index per UV
            (out-of-range per-UV indices are clamped to the array). Must be ``None`` or 0 for a
            :class:`Texture`.
        lod: level of detail: a number, or one float per UV (a ``wp.array`` of float receives
            gradients). Exclusive with ``uv_dx``/``uv_dy``.
        uv_dx, uv_dy: screen-space derivatives of ``uv`` along x and y, same shape as ``uv``. The
            LOD is ``log2(max(|uv_dx * (W, H)|, |uv_dy * (W, H)|))``, the footprint in level-0 texels;
            the ``"anisotropic"`` filter reads their ellipse (:class:`~warptex.Filter`).
        sampler: a :class:`Sampler` (filtering, addressing, LOD bias and clamp); ``None``: the
            defaults, with ``"auto"`` filtering: trilinear when a LOD is given, else bilinear.
        device: Warp device; must be the texture's (``None``: the texture's).
        out: a float32 ``wp.array`` of the result's shape on the device, to fill in place and
            return (a loop's buffer, reused call after call); ``None``: a new array. It must not
            overlap an input.

    Returns:
        ``wp.array`` of float32 (``out`` when given), shape ``(..., C)`` (``uv``'s sample shape plus the channels),
        recorded on the active ``wp.Tape``: gradients reach the texels of every sampled level,
        ``uv``, and a per-UV ``lod`` or ``uv_dx``/``uv_dy`` arrays. Call ``.numpy()`` for NumPy.
    """
    func = "sample"
    plan = plan_key(func, texture, uv, lod, uv_dx, uv_dy, layer, sampler, device, out)
    done = _plan.rerun(plan, (texture,), uv.shape, out=out, uv=uv) if plan is not None else None
    if done is not None:  # this call's inputs again: its launch again
        return done
    if not isinstance(texture, TextureArray):
        raise TypeError(f"{func}(): texture must be a Texture or TextureArray, got {type(texture).__name__}")
    device = resolve_device(func, device, texture.device)
    uv, given = vec2_array(func, "uv", uv, device), uv
    single = not isinstance(given, wp.array) and np.ndim(given) == 1  # one UV, shape (2,): a result of shape (C,)
    shape, count = uv.shape, uv.size
    sampler = _as_sampler(func, sampler)
    lod_source, constant_lod, lods, dx, dy = lod_inputs(func, lod, uv_dx, uv_dy, shape, device)
    constant_layer, layers = resolve_layer(func, texture, layer, shape, device)
    into = out_array(func, out, (*(() if single else shape), texture.channels), device)
    key = ("sample", sampler, lod_source, constant_lod, constant_layer)
    setup = packed(texture, key, lambda: _setup(func, texture, sampler, lod_source, constant_lod, constant_layer))
    pixels = struct_of(ks.SamplePixels, device, uv=reshaped(uv, (count,)), uv_dx=dx, uv_dy=dy, lods=lods, layers=layers)
    with _plan.recording(plan, (texture,), out=out, uv=given, hold=(setup,)):
        result = run(setup.kernels, count, args=setup.args, pixels=pixels, out=((count, texture.channels), float) if into is None else into,
                     device=device, footprints=setup.footprints, touched=setup.touched)
    return out if into is not None else reshaped(result, (*(() if single else shape), texture.channels))


def plan_key(func: str, texture, uv, lod, uv_dx, uv_dy, layer, sampler, device, out, *options) -> tuple | None:
    """The key of a call of :func:`sample` or :func:`~warptex.stochastic` that a plan can repeat
    (``warptex._plan``): a UV array, ``out=`` an array or ``None``, a constant LOD and layer
    (plain numbers), no derivatives, and no recording tape; else ``None``. ``options``: the
    function's other options, hashable."""
    if (
        not (out is None or type(out) is wp.array)
        or type(uv) is not wp.array
        or uv_dx is not None
        or uv_dy is not None
        or type(lod) not in (type(None), int, float)
        or type(layer) not in (type(None), int)
        or not (sampler is None or type(sampler) is Sampler)
        or not _plan.usable()
    ):
        return None
    try:
        hash(options)
    except TypeError:  # an option that holds arrays: no plan
        return None
    return (func, lod, layer, sampler, None if device is None else str(device), *options)  # (a Warp device is not hashable)


class _Setup(NamedTuple):
    """What a :func:`sample` call on a texture needs beside its per-UV inputs (:func:`_setup`)."""

    kernels: Kernels
    args: ks.SampleArgs
    footprints: int
    touched: dict | None  # the texel entries the gradient can reach, when known (all levels otherwise)


def _setup(func: str, texture: TextureArray, sampler: Sampler, lod_source: int, constant_lod: float, constant_layer: int) -> _Setup:
    """The kernels and packed arguments of :func:`sample` on ``texture`` for these options: made once
    per texture and options (``warptex._pack.packed``), as a fit calls it again and again."""
    args = sample_args(func, texture, sampler, lod_source, constant_lod, constant_layer)
    touched = None
    level = lod_source in (kx.LOD_NONE, kx.LOD_CONSTANT)  # one LOD for all: its levels resolved here
    if level:
        args.level, args.fraction = mip_levels(constant_lod, args.smp, texture.num_levels)
        touched = {"args.tex": texture.level_entries(args.level, args.level + 1 if args.fraction > 0.0 else args.level)}  # trilinear reads the next level too
    return _Setup(ks.sample_kernels(level=level), args, footprints(args.smp), touched)
