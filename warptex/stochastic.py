"""Stochastic sampling that breaks visible tiling: :func:`stochastic`, and :func:`hex_taps` to
inspect the hex technique's taps.

The techniques and their hashes are described in :mod:`warptex.kernels.stochastic` and
:mod:`warptex.kernels.hashing`; their options are a :class:`~warptex.Stochastic`, which the
surface techniques (triplanar, splat layers) take too, to sample each projection or layer
stochastically.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import warp as wp

from warptex import _plan
from warptex._op import run
from warptex._pack import footprints, lod_inputs, out_array, packed, reshaped, resolve_layer, sample_args, stochastic_args, struct_of, vec2_array
from warptex._validate import resolve_device, warn_renamed
from warptex.kernels import sampling as ks
from warptex.kernels import stochastic_sample as kss
from warptex.options import Method, Sampler, Stochastic, _as_sampler, _as_stochastic
from warptex.sampling import plan_key
from warptex.texture import Texture, TextureArray



def stochastic(
    texture: TextureArray,
    uv,
    stochastic: Stochastic | Method | str = Method.HASH4,
    *,
    layer=None,
    lod=None,
    uv_dx=None,
    uv_dy=None,
    sampler: Sampler | None = None,
    device=None,
    out=None,
    method: Stochastic | Method | str | None = None,
) -> wp.array:
    """Sample a tiled texture with randomised tiles, so that the repetition is not visible.

    Every tap of a sample reads the same level of detail, computed from the *unperturbed* UV (or
    given), so mip selection never jumps at cell borders. The output is continuous in ``uv``:
    offsets change only where their blend weight is zero. Results are deterministic for a seed on
    every device (integer hashes, see :mod:`warptex.kernels.hashing`).

    Args:
        texture: a :class:`Texture` or :class:`TextureArray` with ``C`` channels.
        uv: texture coordinates, shape ``(..., 2)``: a float NumPy array, or a ``wp.array`` of
            ``wp.vec2`` of any shape (receives gradients when it has ``requires_grad``). One unit is
            one texture repeat, so ``uv = s * uv0`` tiles ``s`` times; its gradient gives the
            gradient to ``s`` as ``Σ uv0 · ∂L/∂uv``. Non-finite UVs give NaN in every channel.
        stochastic: a :class:`Stochastic` (the technique and its options: seed, blend window,
            mirror, contrast, rotation, noise, histogram), or just a :class:`Method` name with the
            defaults: the ``stochastic=`` every technique takes.
        layer: as for :func:`warptex.sample`: an int, or one int per UV, for a texture array.
        lod: level of detail: a number, or one float per UV (a ``wp.array`` of float receives
            gradients). Exclusive with ``uv_dx``/``uv_dy``.
        uv_dx, uv_dy: screen-space derivatives of ``uv``, same shape as ``uv``: the LOD is
            ``log2(max(|uv_dx * (W, H)|, |uv_dy * (W, H)|))``. Mirrored and rotated taps have the same
            isotropic footprint, so this one LOD serves every tap.
        sampler: a :class:`Sampler`; its address mode must be ``"wrap"`` (the default) or
            ``"mirror"``: stochastic tiling needs a periodic texture.
        device: Warp device; must be the texture's (``None``: the texture's).
        out: a float32 ``wp.array`` of the result's shape on the device, to fill in place and
            return (a loop's buffer, reused call after call); ``None``: a new array. It must not
            overlap an input.
        method: the old name of ``stochastic`` (deprecated).

    Returns:
        ``wp.array`` of float32 (``out`` when given), shape ``(..., C)``, recorded on the active ``wp.Tape``: gradients
        reach the texels of every sampled level (of ``histogram.texture`` when a histogram is
        given), ``uv``, and a per-UV ``lod`` or ``uv_dx``/``uv_dy`` arrays.
    """
    func = "stochastic"
    plain = method is None and (type(stochastic) in (str, Method) or (type(stochastic) is Stochastic and stochastic.histogram is None))
    plan = plan_key(func, texture, uv, lod, uv_dx, uv_dy, layer, sampler, device, out, stochastic) if plain else None
    done = _plan.rerun(plan, (texture,), uv.shape, out=out, uv=uv) if plan is not None else None
    if done is not None:  # this call's inputs again: its launch again
        return done
    if not isinstance(texture, TextureArray):
        raise TypeError(f"{func}(): texture must be a Texture or TextureArray, got {type(texture).__name__}")
    device = resolve_device(func, device, texture.device)
    if method is not None:
        if stochastic is not Method.HASH4:
            raise TypeError(f"{func}(): got stochastic= and its old name method=; pass stochastic= alone")
        warn_renamed("stochastic(method=...)", "stochastic(stochastic=...), the name every technique gives it")
        stochastic = method
    option = _as_stochastic(func, stochastic)
    sampler = _as_sampler(func, sampler)
    uv, given = vec2_array(func, "uv", uv, device), uv
    single = not isinstance(given, wp.array) and np.ndim(given) == 1  # one UV, shape (2,): a result of shape (C,)
    shape, count = uv.shape, uv.size
    lod_source, constant_lod, lods, dx, dy = lod_inputs(func, lod, uv_dx, uv_dy, shape, device)
    constant_layer, layers = resolve_layer(func, texture, layer, shape, device)
    into = out_array(func, out, (*(() if single else shape), texture.channels), device)

    def build() -> _Setup:
        return _setup(func, texture, option, sampler, lod_source, constant_lod, constant_layer)

    # Packed once per texture and options, but not with a histogram: the key would keep it, and a
    # histogram's Gaussianised texture is as large as the texture.
    setup = build() if option.histogram is not None else packed(texture, ("stochastic", option, sampler, lod_source, constant_lod, constant_layer), build)
    pixels = struct_of(ks.SamplePixels, device, uv=reshaped(uv, (count,)), uv_dx=dx, uv_dy=dy, lods=lods, layers=layers)
    with _plan.recording(plan, (texture,), out=out, uv=given, hold=(setup,)):
        result = run(kss.stochastic_kernels(), count, args=setup.args, pixels=pixels, out=((count, texture.channels), float) if into is None else into, device=device,
                     linear=setup.linear, footprints=setup.footprints)
    return out if into is not None else reshaped(result, (*(() if single else shape), texture.channels))


class _Setup(NamedTuple):
    """What a :func:`stochastic` call on a texture needs beside its per-UV inputs (:func:`_setup`)."""

    args: kss.StochasticSampleArgs
    footprints: int
    linear: bool  # the histogram blend is not linear in the texels


def _setup(func: str, texture: TextureArray, option: Stochastic, sampler: Sampler, lod_source: int, constant_lod: float, constant_layer: int) -> _Setup:
    """The packed arguments of :func:`stochastic` on ``texture`` for these options, checked."""
    params, sampled = stochastic_args(func, option, texture, sampler)
    args = kss.StochasticSampleArgs()
    args.sample, args.params = sample_args(func, sampled, sampler, lod_source, constant_lod, constant_layer), params  # nested structs are set whole: Warp copies their values in
    return _Setup(args, footprints(args.sample.smp, params), params.histogram == 0)


def hex_taps(uv, *, seed: int = 0, contrast: float = 1.0, rotation: float = 0.0, device=None):
    """The hex technique's three taps at each UV, for inspection and tests.

    Args:
        uv: shape ``(..., 2)`` float array (or ``wp.array`` of ``vec2``).
        seed, contrast, rotation: as for :class:`~warptex.Stochastic`.
        device: Warp device (``None``: Warp's default).

    Returns:
        ``(weights, vertices, taps)`` as NumPy: the normalised weights ``(..., 3)`` float32 (they sum
        to 1), the triangle-grid vertex ids ``(..., 3, 2)`` int32, and the tap UVs ``(..., 3, 2)``
        float32, reduced to ``[0, 2)`` plus the offset (texels repeat with period 1 under wrap).
    """
    func = "hex_taps"
    device = wp.get_device(device)
    uv = vec2_array(func, "uv", uv, device)
    probe = Texture(np.zeros((1, 1, 1), np.float32), device=device)
    try:
        option = Stochastic(Method.HEX, seed=seed, contrast=contrast, rotation=rotation)
    except (TypeError, ValueError) as err:
        raise type(err)(f"{func}(): {str(err).removeprefix('Stochastic(): ')}") from None
    params, _ = stochastic_args(func, option, probe, Sampler())
    n = uv.size
    weights = wp.zeros(n, dtype=wp.vec3, device=device)
    vertices = wp.zeros((n, 3), dtype=wp.vec2i, device=device)
    taps = wp.zeros((n, 3), dtype=wp.vec2, device=device)
    if n:
        wp.launch(kss.hex_taps_kernel, dim=n, inputs=[uv.reshape((n,)), params], outputs=[weights, vertices, taps], device=device, record_tape=False)
    shape = uv.shape
    return weights.numpy().reshape(*shape, 3), vertices.numpy().reshape(*shape, 3, 2), taps.numpy().reshape(*shape, 3, 2)
