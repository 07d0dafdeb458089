"""Stochastic sampling that breaks visible tiling: :func:`stochastic` (and, re-exported from
:mod:`warptex.histogram`, :func:`prepare_histogram` for the hex technique's histogram blend).

The techniques and their hashes are described in :mod:`warptex.kernels.stochastic` and
:mod:`warptex.kernels.hashing`; :func:`stochastic_params` packs the options for kernels so that
other techniques (triplanar, splat layers) can sample each projection or layer stochastically.
"""

from __future__ import annotations

import dataclasses
import enum

import numpy as np
import warp as wp

from warptex._launch import per_pixel
from warptex._op import Kernels, needs_grad, run
from warptex._validate import as_enum, as_float, as_float_array, resolve_device
from warptex.histogram import GAUSSIAN_MEAN, LUT_RANGE, Histogram, prepare_histogram
from warptex.kernels import stochastic as kst
from warptex.sampling import Address, Filter, _resolve_layer, _vec2_array, lod_inputs, make_sampler, resolve_filter
from warptex.texture import Texture, TextureArray

__all__ = ["Histogram", "Method", "Stochastic", "hex_taps", "prepare_histogram", "as_stochastic", "resolve_stochastic", "stochastic", "stochastic_params"]


class Method(str, enum.Enum):
    """Stochastic sampling technique.

    - ``NONE``: plain sampling (one tap), for comparisons.
    - ``HASH4``: per-cell hashed offset (and optional mirror) at the four cells around the UV,
      blended by ``smoothstep(blend[0], blend[1], frac(uv))`` (seed 000; Quilez technique 1). 4 taps
      at most, 1 in the cell interiors with the default window.
    - ``CHEAP2``: two taps whose offsets are chosen by a low-frequency value noise, blended by its
      fraction (Quilez technique 3). 2 taps at most.
    - ``HEX``: three taps on a triangle grid with per-vertex offsets (and optional rotation),
      barycentric weights with a contrast exponent; with a :class:`Histogram`, Heitz & Neyret's
      variance-preserving blend in Gaussianised space (Mikkelsen 2022; Heitz & Neyret 2018).
    """

    NONE = "none"
    HASH4 = "hash4"
    CHEAP2 = "cheap2"
    HEX = "hex"


_METHOD_IDS = {Method.NONE: kst.METHOD_NONE, Method.HASH4: kst.METHOD_HASH4, Method.CHEAP2: kst.METHOD_CHEAP2, Method.HEX: kst.METHOD_HEX}
_KERNELS = Kernels(kst.stochastic_kernel, kst.stochastic_texel_grad_kernel, kst.stochastic_adjoint_kernel)
_DEFAULT_BLEND = {Method.HASH4: (0.25, 0.75), Method.CHEAP2: (0.2, 0.8)}


@dataclasses.dataclass(frozen=True)
class Stochastic:
    """Stochastic sampling inside another technique: pass as ``stochastic=`` to
    :func:`~warptex.triplanar`, :func:`~warptex.biplanar`, :func:`~warptex.triplanar_normal` or
    :func:`~warptex.splat` (a bare method name, e.g. ``stochastic="hex"``, takes every default).

    Every projection (triplanar) or layer (splat) is then sampled with the technique, each with the
    LOD of its own unperturbed footprint. The fields mean what :func:`stochastic`'s arguments of the
    same names mean; ``histogram`` must be built from the texture (or layer array) being sampled,
    and gradients then reach ``histogram.texture``.
    """

    method: Method | str = Method.HASH4
    seed: int = 0
    blend: tuple[float, float] | None = None
    mirror: bool = False
    contrast: float = 1.0
    rotation: float = 0.0
    noise_frequency: float = 0.5
    noise_levels: float = 8.0
    histogram: Histogram | None = None


def as_stochastic(func: str, option) -> Stochastic:
    """``stochastic=`` of a technique (``None``, a :class:`Method` name, or :class:`Stochastic`) as
    :class:`Stochastic` (``None`` is method ``"none"``). Errors name ``func``."""
    if option is None:
        return Stochastic(method=Method.NONE)
    if isinstance(option, (str, Method)):
        return Stochastic(method=option)
    if not isinstance(option, Stochastic):
        raise TypeError(f"{func}(): stochastic must be None, a method name or a warptex.Stochastic, got {type(option).__name__}")
    return option


def resolve_stochastic(func: str, option, texture: TextureArray, address, *, histogram_allowed: bool = True) -> tuple[kst.StochasticArgs, TextureArray]:
    """``stochastic=`` of a technique (see :func:`as_stochastic`) as ``(params, sampled)`` for its
    kernels (see :func:`stochastic_params`). ``address`` must be periodic for any method but
    ``"none"``. Errors name ``func``."""
    option = as_stochastic(func, option)
    if option.histogram is not None and not histogram_allowed:
        raise ValueError(f"{func}(): a stochastic histogram needs one texture for every projection (textures_per_axis differ)")
    fields = {f.name: getattr(option, f.name) for f in dataclasses.fields(option)}  # shallow: the histogram is shared
    params, sampled = stochastic_params(func, texture, **fields)
    addr = as_enum(func, "address", address, Address)
    if params.method != kst.METHOD_NONE and addr not in (Address.WRAP, Address.MIRROR):
        raise ValueError(f"{func}(): stochastic sampling needs address 'wrap' or 'mirror' (a periodic texture), got {addr.value!r}")
    return params, sampled


def stochastic_params(
    func: str,
    texture: TextureArray,
    *,
    method: Method | str = Method.HASH4,
    seed: int = 0,
    blend=None,
    mirror: bool = False,
    contrast: float = 1.0,
    rotation: float = 0.0,
    noise_frequency: float = 0.5,
    noise_levels: float = 8.0,
    histogram: Histogram | None = None,
) -> tuple[kst.StochasticArgs, TextureArray]:
    """Validate stochastic options (see :func:`stochastic`) and pack them for kernels.

    Returns ``(params, sampled)``: the :class:`~warptex.kernels.stochastic.StochasticArgs` and the
    texture the kernel must sample, ``histogram.texture`` when a histogram is given, else ``texture``.
    Errors name ``func``.
    """
    m = as_enum(func, "method", method, Method)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{func}(): seed must be an int, got {type(seed).__name__}")
    if not 0 <= seed < 1 << 32:
        raise ValueError(f"{func}(): seed must be in [0, 2**32), got {seed}")
    if blend is None:
        blend = _DEFAULT_BLEND.get(m, (0.25, 0.75))
    window = as_float_array(func, "blend", blend).reshape(-1)
    if window.size != 2 or not np.isfinite(window).all() or not 0.0 <= window[0] < window[1] <= 1.0:
        raise ValueError(f"{func}(): blend must be two numbers (lo, hi) with 0 <= lo < hi <= 1, got {blend!r}")
    if not isinstance(mirror, (bool, np.bool_)):
        raise TypeError(f"{func}(): mirror must be a bool, got {type(mirror).__name__}")
    gain = as_float(func, "contrast", contrast)
    if gain < 1.0:
        raise ValueError(f"{func}(): contrast must be >= 1 (1: plain barycentric weights), got {gain}")
    rot = float(rotation) if isinstance(rotation, (bool, np.bool_)) else as_float(func, "rotation", rotation)
    if not 0.0 <= rot <= 1.0:
        raise ValueError(f"{func}(): rotation must be a bool or a strength in [0, 1], got {rotation!r}")
    freq = as_float(func, "noise_frequency", noise_frequency)
    levels = as_float(func, "noise_levels", noise_levels)
    if freq <= 0.0 or levels <= 0.0:
        raise ValueError(f"{func}(): noise_frequency and noise_levels must be positive, got {freq} and {levels}")

    params = kst.StochasticArgs()
    params.method = _METHOD_IDS[m]
    params.seed = wp.uint32(int(seed))
    params.blend_lo, params.blend_hi = float(window[0]), float(window[1])
    params.mirror = int(bool(mirror))
    params.noise_frequency, params.noise_levels = freq, levels
    params.contrast, params.rotation = gain, rot
    params.histogram, params.mean, params.lut_size, params.lut_levels, params.decorrelate = 0, GAUSSIAN_MEAN, 0, 0, 0
    params.lut_lo, params.lut_hi = LUT_RANGE
    params.channels = texture.channels
    # Unused arrays are empty rather than null: wp.Tape walks every array field of a struct.
    params.lut = wp.empty(0, dtype=float, device=texture.device)
    params.basis = wp.empty(0, dtype=wp.mat33, device=texture.device)
    params.centre = wp.empty(0, dtype=wp.vec3, device=texture.device)
    sampled = texture
    if histogram is not None:
        if not isinstance(histogram, Histogram):
            raise TypeError(f"{func}(): histogram must be a Histogram from prepare_histogram(), got {type(histogram).__name__}")
        if m != Method.HEX:
            raise ValueError(f"{func}(): histogram= is used by method='hex' only, got method={m.value!r}")
        h = histogram.texture
        have = (h.num_layers, h.height, h.width, h.channels)
        want = (texture.num_layers, texture.height, texture.width, texture.channels)
        if have != want:
            raise ValueError(f"{func}(): histogram was built for (layers, H, W, C) = {have}, the texture is {want}")
        if h.device != texture.device:
            raise ValueError(f"{func}(): histogram is on {h.device} but the texture is on {texture.device}")
        params.histogram, params.lut, params.lut_size = 1, histogram.lut, histogram.lut_size
        params.lut_levels = histogram.levels
        if histogram.decorrelate:
            params.decorrelate, params.basis, params.centre = 1, histogram.basis, histogram.centre
        sampled = h
    return params, sampled


def stochastic(
    texture: TextureArray,
    uv,
    *,
    method: Method | str = Method.HASH4,
    seed: int = 0,
    layer=None,
    lod=None,
    uv_dx=None,
    uv_dy=None,
    blend=None,
    mirror: bool = False,
    contrast: float = 1.0,
    rotation: float = 0.0,
    noise_frequency: float = 0.5,
    noise_levels: float = 8.0,
    histogram: Histogram | None = None,
    filter: Filter | str = Filter.AUTO,
    address: Address | str = Address.WRAP,
    lod_bias: float = 0.0,
    min_lod: float = 0.0,
    max_lod: float = float("inf"),
    device=None,
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
        method: a :class:`Method`: ``"hash4"``, ``"cheap2"``, ``"hex"`` or ``"none"``.
        seed: an int in ``[0, 2**32)``; every seed gives a different, reproducible arrangement.
        layer: as for :func:`warptex.sample`: an int, or one int per UV, for a texture array.
        lod: level of detail: a number, or one float per UV (a ``wp.array`` of float receives
            gradients). Exclusive with ``uv_dx``/``uv_dy``.
        uv_dx, uv_dy: screen-space derivatives of ``uv``, same shape as ``uv``: the LOD is
            ``log2(max(|uv_dx * (W, H)|, |uv_dy * (W, H)|))``. Mirrored and rotated taps have the same
            isotropic footprint, so this one LOD serves every tap.
        blend: hash4 and cheap2: the smoothstep window ``(lo, hi)``, ``0 <= lo < hi <= 1``; ``None``:
            ``(0.25, 0.75)`` for hash4, ``(0.2, 0.8)`` for cheap2. Wider blends more (softer, blurrier
            seams), narrower blends less (sharper, more visible seams).
        mirror: hash4 and cheap2: mirror each tap randomly per axis (more variety; wrong for
            directional textures such as bricks or lit relief).
        contrast: hex: exponent of the barycentric weights (>= 1); 1 is Heitz & Neyret's linear
            weights, larger values (Mikkelsen suggests up to 7) shrink the blend zones between tiles.
        rotation: hex: random rotation of each tile about its centre, a strength in ``[0, 1]``
            (``True`` = 1: any angle); 0 disables it. Only for isotropic textures.
        noise_frequency: cheap2: cells of the value noise per UV unit; lower changes offsets less often.
        noise_levels: cheap2: how many offsets the noise sweeps through, ``l = noise * noise_levels``.
        histogram: hex: a :class:`Histogram` from :func:`prepare_histogram` of this texture; the
            blend then preserves the texture's histogram (mean, contrast). Without it the three taps
            are blended linearly, which loses contrast where they mix.
        filter: a :class:`Filter`; ``"auto"`` picks trilinear when a LOD is given, else bilinear.
        address: ``"wrap"`` or ``"mirror"`` (stochastic tiling needs a periodic texture).
        lod_bias: added to every LOD before clamping.
        min_lod, max_lod: clamp of the biased LOD (then clamped to the chain).
        device: Warp device; must be the texture's (``None``: the texture's).

    Returns:
        ``wp.array`` of float32, shape ``(..., C)``, recorded on the active ``wp.Tape``: gradients
        reach the texels of every sampled level (of ``histogram.texture`` when a histogram is
        given), ``uv``, and a per-UV ``lod`` or ``uv_dx``/``uv_dy`` arrays.
    """
    func = "stochastic"
    if not isinstance(texture, TextureArray):
        raise TypeError(f"{func}(): texture must be a Texture or TextureArray, got {type(texture).__name__}")
    device = resolve_device(func, device, texture.device)
    params, sampled = stochastic_params(
        func, texture, method=method, seed=seed, blend=blend, mirror=mirror, contrast=contrast, rotation=rotation,
        noise_frequency=noise_frequency, noise_levels=noise_levels, histogram=histogram,
    )  # fmt: skip
    uv = _vec2_array(func, "uv", uv, device)
    shape, count = uv.shape, uv.size

    addr = as_enum(func, "address", address, Address)
    if addr not in (Address.WRAP, Address.MIRROR):
        raise ValueError(f"{func}(): address must be 'wrap' or 'mirror' (a periodic texture), got {addr.value!r}")
    filt = resolve_filter(func, filter, has_lod=lod is not None or uv_dx is not None or uv_dy is not None)
    smp = make_sampler(func, filter=filt, address=addr, lod_bias=lod_bias, min_lod=min_lod, max_lod=max_lod)

    lod_source, constant_lod, lods, dx, dy = lod_inputs(func, lod, uv_dx, uv_dy, shape, device)
    constant_layer, layers = _resolve_layer(func, texture, layer, shape, device)

    others = [uv, dx, dy, lods]
    out = wp.zeros((count, texture.channels), dtype=float, device=device, requires_grad=sampled.requires_grad or needs_grad(*others))
    inputs = [sampled.view, *per_pixel(uv.reshape((count,)), dx, dy, lods, layers), smp, params, lod_source, constant_lod, constant_layer]
    run(_KERNELS, count, inputs=inputs, outputs=[out], device=device, by_hand=[sampled.view.texels], others=others, linear=params.histogram == 0)
    return out.reshape((*shape, texture.channels))


def hex_taps(uv, *, seed: int = 0, contrast: float = 1.0, rotation: float = 0.0, device=None):
    """The hex technique's three taps at each UV, for inspection and tests.

    Args:
        uv: shape ``(..., 2)`` float array (or ``wp.array`` of ``vec2``).
        seed, contrast, rotation: as for :func:`stochastic`.
        device: Warp device (``None``: Warp's default).

    Returns:
        ``(weights, vertices, taps)`` as NumPy: the normalised weights ``(..., 3)`` float32 (they sum
        to 1), the triangle-grid vertex ids ``(..., 3, 2)`` int32, and the tap UVs ``(..., 3, 2)``
        float32, reduced to ``[0, 2)`` plus the offset (texels repeat with period 1 under wrap).
    """
    func = "hex_taps"
    device = wp.get_device(device)
    uv = _vec2_array(func, "uv", uv, device)
    probe = Texture(np.zeros((1, 1, 1), np.float32), device=device)
    params, _ = stochastic_params(func, probe, method=Method.HEX, seed=seed, contrast=contrast, rotation=rotation)
    n = uv.size
    weights = wp.zeros(n, dtype=wp.vec3, device=device)
    vertices = wp.zeros((n, 3), dtype=wp.vec2i, device=device)
    taps = wp.zeros((n, 3), dtype=wp.vec2, device=device)
    if n:
        wp.launch(kst.hex_taps_kernel, dim=n, inputs=[uv.reshape((n,)), params], outputs=[weights, vertices, taps], device=device, record_tape=False)
    shape = uv.shape
    return weights.numpy().reshape(*shape, 3), vertices.numpy().reshape(*shape, 3, 2), taps.numpy().reshape(*shape, 3, 2)
