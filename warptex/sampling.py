"""Public texture sampling: :func:`sample` and the filter and address modes."""

from __future__ import annotations

import enum
import math

import numpy as np
import warp as wp

from warptex._launch import per_pixel
from warptex._op import Kernels, needs_grad, run
from warptex._validate import as_enum, as_float, as_float_array, resolve_device
from warptex.kernels import sampling as ks
from warptex.texture import Texture, TextureArray


class Filter(str, enum.Enum):
    """Texture filtering.

    - ``NEAREST``: the texel containing the UV, on the mip level nearest the LOD (level 0 without one).
    - ``BILINEAR``: bilinear interpolation of the four nearest texel centres, on the nearest level.
    - ``TRILINEAR``: bilinear on the two levels around the LOD, blended linearly; needs a LOD.
    - ``AUTO``: ``TRILINEAR`` when a LOD or UV derivatives are given, ``BILINEAR`` otherwise.
    """

    NEAREST = "nearest"
    BILINEAR = "bilinear"
    TRILINEAR = "trilinear"
    AUTO = "auto"


class Address(str, enum.Enum):
    """What texel coordinates outside ``[0, 1]`` read.

    - ``WRAP``: repeat the texture (period 1 in UV).
    - ``CLAMP``: the nearest edge texel.
    - ``MIRROR``: repeat with every other copy mirrored (period 2), as OpenGL's ``MIRRORED_REPEAT``.
    - ``BORDER``: the constant ``border`` colour outside the texture (bilinear blends towards it).
    """

    WRAP = "wrap"
    CLAMP = "clamp"
    MIRROR = "mirror"
    BORDER = "border"


_KERNELS = Kernels(ks.sample_kernel, ks.sample_texel_grad_kernel, ks.sample_adjoint_kernel)
_LEVEL_KERNELS = Kernels(ks.sample_level_kernel, ks.sample_level_texel_grad_kernel, ks.sample_level_adjoint_kernel)

_FILTER_IDS = {Filter.NEAREST: ks.FILTER_NEAREST, Filter.BILINEAR: ks.FILTER_BILINEAR, Filter.TRILINEAR: ks.FILTER_TRILINEAR}
_ADDRESS_IDS = {
    Address.WRAP: ks.ADDRESS_WRAP,
    Address.CLAMP: ks.ADDRESS_CLAMP,
    Address.MIRROR: ks.ADDRESS_MIRROR,
    Address.BORDER: ks.ADDRESS_BORDER,
}


def make_sampler(
    func: str,
    *,
    filter: Filter,
    address: Address | str,
    border=(0.0, 0.0, 0.0, 0.0),
    lod_bias: float = 0.0,
    min_lod: float = 0.0,
    max_lod: float = float("inf"),
) -> ks.SamplerArgs:
    """Validate sampler options and pack them for kernels (``filter`` must already be resolved)."""
    smp = ks.SamplerArgs()
    smp.filter = _FILTER_IDS[filter]
    smp.address = _ADDRESS_IDS[as_enum(func, "address", address, Address)]
    colour = as_float_array(func, "border", border).reshape(-1)
    if not 1 <= colour.size <= 4 or not np.isfinite(colour).all():
        raise ValueError(f"{func}(): border must be 1 to 4 finite numbers, got {border!r}")
    smp.border = wp.vec4(*np.pad(colour, (0, 4 - colour.size)))
    smp.lod_bias = as_float(func, "lod_bias", lod_bias)
    smp.min_lod = as_float(func, "min_lod", min_lod, finite=False)
    smp.max_lod = as_float(func, "max_lod", max_lod, finite=False)
    if smp.min_lod > smp.max_lod:
        raise ValueError(f"{func}(): min_lod ({smp.min_lod}) must not exceed max_lod ({smp.max_lod})")
    return smp


def surface_sampler(func: str, *, filter, address, lod_bias=0.0, min_lod=0.0, max_lod=float("inf")) -> ks.SamplerArgs:
    """The sampler of a technique that reads textures over a G-buffer (which always has
    derivatives, so ``"auto"`` is trilinear)."""
    filt = as_enum(func, "filter", filter, Filter)
    filt = Filter.TRILINEAR if filt == Filter.AUTO else filt
    return make_sampler(func, filter=filt, address=address, lod_bias=lod_bias, min_lod=min_lod, max_lod=max_lod)


def _vec2_array(func: str, name: str, value, device) -> wp.array:
    """``value`` as a contiguous ``wp.array`` of ``vec2`` (a view when it already is one)."""
    if isinstance(value, wp.array):
        if value.dtype != wp.vec2:
            raise TypeError(f"{func}(): {name} must be a wp.array of wp.vec2, got dtype {wp.types.type_repr(value.dtype)}")
        if value.device != device:
            raise ValueError(f"{func}(): {name} is on {value.device} but the texture is on {device}")
        if not value.is_contiguous:
            raise ValueError(f"{func}(): {name} must be contiguous")
        return value
    arr = as_float_array(func, name, value)
    if arr.ndim < 1 or arr.shape[-1] != 2:
        raise ValueError(f"{func}(): {name} must have shape (..., 2), got {arr.shape}")
    return wp.array(np.ascontiguousarray(arr), dtype=wp.vec2, device=device)


def _per_sample(func: str, name: str, value, shape, dtype, device) -> wp.array:
    """A per-sample array of ``dtype`` matching the sample ``shape``."""
    if isinstance(value, wp.array):
        if value.dtype != dtype or value.shape != shape or value.device != device:
            raise ValueError(
                f"{func}(): {name} must be a wp.array of {wp.types.type_repr(dtype)} with shape {shape} "
                f"on {device}, got {wp.types.type_repr(value.dtype)} {value.shape} on {value.device}"
            )
        return value
    np_dtype = np.float32 if dtype == wp.float32 else np.int32
    arr = np.asarray(value)
    if dtype == wp.int32 and not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{func}(): {name} must hold integers, got dtype {arr.dtype}")
    if dtype == wp.float32:
        arr = as_float_array(func, name, arr)
    if arr.shape != shape:
        raise ValueError(f"{func}(): {name} must have shape {shape} (one per UV), got {arr.shape}")
    return wp.array(np.ascontiguousarray(arr, dtype=np_dtype), dtype=dtype, device=device)


def sample(
    texture: TextureArray,
    uv,
    *,
    layer=None,
    lod=None,
    uv_dx=None,
    uv_dy=None,
    filter: Filter | str = Filter.AUTO,
    address: Address | str = Address.WRAP,
    border=(0.0, 0.0, 0.0, 0.0),
    lod_bias: float = 0.0,
    min_lod: float = 0.0,
    max_lod: float = float("inf"),
    device=None,
) -> wp.array:
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
            LOD is ``log2(max(|uv_dx * (W, H)|, |uv_dy * (W, H)|))``, the footprint in level-0 texels.
        filter: a :class:`Filter`; ``"auto"`` picks trilinear when a LOD is given, else bilinear.
        address: an :class:`Address` mode for both axes.
        border: the colour read outside the texture in ``"border"`` mode, 1 to 4 numbers.
        lod_bias: added to every LOD before clamping.
        min_lod, max_lod: clamp of the biased LOD (then clamped to the chain, ``[0, levels - 1]``).
        device: Warp device; must be the texture's (``None``: the texture's).

    Returns:
        ``wp.array`` of float32, shape ``(..., C)`` (``uv``'s sample shape plus the channels),
        recorded on the active ``wp.Tape``: gradients reach the texels of every sampled level,
        ``uv``, and a per-UV ``lod`` or ``uv_dx``/``uv_dy`` arrays. Call ``.numpy()`` for NumPy.
    """
    func = "sample"
    if not isinstance(texture, TextureArray):
        raise TypeError(f"{func}(): texture must be a Texture or TextureArray, got {type(texture).__name__}")
    device = resolve_device(func, device, texture.device)
    uv = _vec2_array(func, "uv", uv, device)
    shape = uv.shape
    count = uv.size

    filt = resolve_filter(func, filter, has_lod=lod is not None or uv_dx is not None or uv_dy is not None)
    smp = make_sampler(func, filter=filt, address=address, border=border, lod_bias=lod_bias, min_lod=min_lod, max_lod=max_lod)

    flat = uv.reshape((count,))
    lod_source, constant_lod, lods, dx, dy = lod_inputs(func, lod, uv_dx, uv_dy, shape, device)

    constant_layer, layers = _resolve_layer(func, texture, layer, shape, device)

    others = [uv, dx, dy, lods]
    out = wp.zeros((count, texture.channels), dtype=float, device=device, requires_grad=texture.requires_grad or needs_grad(*others))
    if lod_source in (ks.LOD_NONE, ks.LOD_CONSTANT):  # one LOD for all: its levels resolved here
        level, fraction = mip_levels(constant_lod, smp, texture.num_levels)
        inputs = [texture.view, *per_pixel(flat, layers), smp, level, fraction, constant_layer]
        kernels = _LEVEL_KERNELS
    else:
        inputs = [texture.view, *per_pixel(flat, dx, dy, lods, layers), smp, lod_source, constant_lod, constant_layer]
        kernels = _KERNELS
    run(kernels, count, inputs=inputs, outputs=[out], device=device, by_hand=[texture.view.texels], others=others)
    return out.reshape((*shape, texture.channels))


def mip_levels(lod: float, smp: ks.SamplerArgs, num_levels: int) -> tuple[int, float]:
    """``(level, fraction)`` that ``lod`` reads through ``smp``: the kernels' ``mip_levels`` in the
    same float32 arithmetic, so a uniform LOD reads exactly the levels the per-sample kernel would."""
    f32 = np.float32
    l = f32(lod) + f32(smp.lod_bias)
    l = min(max(f32(smp.min_lod), l), f32(smp.max_lod))  # wp.clamp(x, a, b) = fmin(fmax(a, x), b)
    l = min(max(f32(0.0), l), f32(num_levels - 1))
    if smp.filter == ks.FILTER_TRILINEAR:
        base = np.floor(l)
        return int(base), float(f32(l - base))
    return int(np.floor(l + f32(0.5))), 0.0


def resolve_filter(func: str, filter, *, has_lod: bool) -> Filter:
    """``filter`` resolved for a lookup with or without a LOD source (``"auto"``: trilinear with one)."""
    filt = as_enum(func, "filter", filter, Filter)
    if filt == Filter.AUTO:
        filt = Filter.TRILINEAR if has_lod else Filter.BILINEAR
    if filt == Filter.TRILINEAR and not has_lod:
        raise ValueError(f"{func}(): filter='trilinear' needs lod= or uv_dx=/uv_dy=")
    return filt


def lod_inputs(func: str, lod, uv_dx, uv_dy, shape, device):
    """``(lod_source, constant_lod, lods, uv_dx, uv_dy)`` for a kernel, flattened, validated."""
    count = math.prod(shape)
    if lod is not None and (uv_dx is not None or uv_dy is not None):
        raise ValueError(f"{func}(): pass either lod= or uv_dx=/uv_dy=, not both")
    if (uv_dx is None) != (uv_dy is None):
        raise ValueError(f"{func}(): uv_dx and uv_dy must be given together")
    if uv_dx is not None:
        dx = _vec2_array(func, "uv_dx", uv_dx, device)
        dy = _vec2_array(func, "uv_dy", uv_dy, device)
        for name, d in (("uv_dx", dx), ("uv_dy", dy)):
            if d.shape != shape:
                raise ValueError(f"{func}(): {name} must have the shape of uv {shape}, got {d.shape}")
        return ks.LOD_DERIVATIVES, 0.0, None, dx.reshape((count,)), dy.reshape((count,))
    if isinstance(lod, (int, float, np.integer, np.floating)) and not isinstance(lod, bool):
        return ks.LOD_CONSTANT, as_float(func, "lod", lod), None, None, None
    if lod is not None:
        lods = _per_sample(func, "lod", lod, shape, wp.float32, device).reshape((count,))
        return ks.LOD_PER_SAMPLE, 0.0, lods, None, None
    return ks.LOD_NONE, 0.0, None, None, None


def _resolve_layer(func: str, texture: TextureArray, layer, shape, device):
    """``(constant_layer, per_sample_layers_or_None)`` for ``layer``, validated against ``texture``;
    per-sample layers come flattened to one entry per UV, as the kernels read them."""
    if layer is None:
        if isinstance(texture, Texture) or texture.num_layers == 1:
            return 0, None
        raise ValueError(f"{func}(): layer is required for a TextureArray of {texture.num_layers} layers")
    if isinstance(layer, (int, np.integer)) and not isinstance(layer, bool):
        if not 0 <= layer < texture.num_layers:
            raise ValueError(f"{func}(): layer must be in [0, {texture.num_layers - 1}], got {layer}")
        return int(layer), None
    return 0, _per_sample(func, "layer", layer, shape, wp.int32, device).reshape((math.prod(shape),))
