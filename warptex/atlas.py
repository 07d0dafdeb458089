"""Splat-map terrain texturing through an atlas and index maps: a fixed number of layer reads per
pixel, however many layers the terrain has.

Three steps:

1. :func:`export_index_maps` (offline, NumPy): per splat texel, the ``k`` heaviest layers and their
   weights, as an index map and a weight map (``[H, W, k]``).
2. :func:`pack_atlas`: the layers as tiles of one :class:`Atlas` texture, each surrounded by a
   gutter of its own wrapped content, with a mip chain and the largest LOD that never bleeds.
3. :func:`splat_atlas`: per pixel, ``k`` atlas reads blended by weight (formulas and the LOD bound
   in :mod:`warptex.kernels.atlas`).

With ``k = L`` and the same LOD it reproduces :func:`warptex.splat` (``projection="uv"``)
wherever the splat weights are constant over a splat texel (e.g. at splat-texel centres): the splat
path reads weights bilinearly, the index-map path per texel (nearest).
"""

from __future__ import annotations

import math
import types

import numpy as np
import warp as wp

from warptex._op import run
from warptex._pack import footprints, out_array, sampler_args, struct_of
from warptex._validate import as_device_array, as_float_array, as_on_device, check_layer_count, param_array
from warptex.gbuffer import GBuffer, _gbuffer_device
from warptex.kernels import atlas as ka
from warptex.options import Address, Filter, Sampler, _as_sampler
from warptex.texture import Texture, TextureArray

MAX_K = 4  # ka.MAX_ENTRIES: an RGBA index map


def export_index_maps(splat_maps, k: int = 2, *, num_layers: int | None = None, normalize: bool = True):
    """The ``k`` heaviest layers of every splat texel, as index and weight maps.

    Weights are read as :func:`warptex.splat` reads them: map ``m`` channel ``c`` is layer
    ``m·C + c``; negative weights count as 0. Layers are ranked by weight, ties going to the lower
    layer index (a stable sort), so the export is deterministic. With ``normalize`` the kept
    weights are divided by their sum; the weight this drops, as a fraction of the texel's total, is
    ``1 - Σ kept / Σ all`` (0 when ``k = L``), and it bounds the colour error against the full
    splat: ``|err| <= dropped · (max - min)`` of the layer values. A texel whose weights are all 0
    gets weights 0 (indices ``0..k-1``), so :func:`splat_atlas` gives 0 there, like ``splat``.

    Args:
        splat_maps: a :class:`TextureArray` (level 0 is read) or an array ``[H, W, C]`` /
            ``[M, H, W, C]`` of finite weights.
        k: entries per texel, an int in ``[1, min(4, L)]`` (2 or 3 are usual: a terrain texel
            rarely mixes more layers).
        num_layers: ``L``; default every channel of every map, ``M·C``. With fewer, the spare
            channels of the last map are ignored (``(M - 1)·C < L <= M·C``).
        normalize: renormalise the kept weights to sum 1 (else keep them as read, clamped to >= 0).

    Returns:
        ``(indices, weights)``: int32 ``[H, W, k]`` layer indices, heaviest first, and float32
        ``[H, W, k]`` weights. NumPy arrays (an offline step; no gradients).
    """
    func = "export_index_maps"
    if isinstance(splat_maps, TextureArray):
        data = splat_maps.numpy(0)
    else:
        if isinstance(splat_maps, wp.array):
            raise TypeError(f"{func}(): pass splat maps as a TextureArray or NumPy array, not a bare wp.array")
        data = as_float_array(func, "splat_maps", splat_maps)
        if data.ndim == 3:
            data = data[None]
        if data.ndim != 4 or 0 in data.shape:
            raise ValueError(f"{func}(): splat_maps must have shape (H, W, C) or (M, H, W, C), got {data.shape}")
        if not np.isfinite(data).all():
            raise ValueError(f"{func}(): splat_maps must be finite")
    m, h, w, c = data.shape
    if num_layers is None:
        num_layers = m * c
    elif isinstance(num_layers, bool) or not isinstance(num_layers, (int, np.integer)) or num_layers < 1:
        raise ValueError(f"{func}(): num_layers must be a positive int or None, got {num_layers!r}")
    check_layer_count(func, int(num_layers), types.SimpleNamespace(num_layers=m, channels=c))
    top = min(MAX_K, num_layers)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= top:
        raise ValueError(f"{func}(): k must be an int in [1, {top}] (at most 4 and at most the {num_layers} layers), got {k!r}")

    layer_w = np.clip(data.transpose(1, 2, 0, 3).reshape(h, w, m * c)[..., :num_layers], 0.0, None)
    order = np.argsort(-layer_w, axis=-1, kind="stable")[..., :k]
    kept = np.take_along_axis(layer_w, order, axis=-1)
    if normalize:
        total = kept.sum(axis=-1, keepdims=True)
        kept = np.divide(kept, total, out=np.zeros_like(kept), where=total > 0)
    return order.astype(np.int32), kept.astype(np.float32)


def _two_adic(n: int) -> int:
    """How many times 2 divides ``n > 0``."""
    return (n & -n).bit_length() - 1




class _AtlasTexture(Texture):
    """A :class:`Texture` whose constructor leaves the (zero) mips alone: :func:`pack_atlas` writes
    level 0 and then builds them, so an active tape records exactly pack, then mips."""

    _name = "Atlas"

    def __init__(self, image, **kw):
        self._packing = True
        super().__init__(image, **kw)
        self._packing = False

    def update(self) -> None:
        if not self._packing:
            super().update()


class Atlas:
    """Layers packed as tiles of one texture, with wrapped gutters (layout in
    :mod:`warptex.kernels.atlas`). Made by :func:`pack_atlas`.

    Attributes:
        texture: the atlas, a :class:`Texture` of ``rows·(th + 2g)`` by ``columns·(tw + 2g)``
            texels with the layers' channel count and a box-filtered mip chain.
        layers: the source :class:`TextureArray` (level 0 is what was packed).
        tile_size: ``(th, tw)``, the layer size; gutter: ``g``; columns, rows: the grid.
        max_lod: the largest level that never bleeds across tiles, ``min(v2(g), v2(th), v2(tw))``
            capped by the chain (``v2(n)``: the exponent of the largest power of 2 dividing ``n``); 0 unless the sizes are
            even. :func:`splat_atlas` clamps every LOD to it.
    """

    def __init__(self, texture, layers, layout, rows):
        self.texture, self.layers, self.layout, self.rows = texture, layers, layout, rows
        self.tile_size = (layout.tile_height, layout.tile_width)
        self.gutter, self.columns, self.num_layers = layout.gutter, layout.columns, layout.num_tiles
        th, tw, g = layout.tile_height, layout.tile_width, layout.gutter
        self.max_lod = min(_two_adic(g), _two_adic(th), _two_adic(tw), texture.num_levels - 1)

    @property
    def device(self):
        return self.texture.device

    @property
    def channels(self) -> int:
        return self.texture.channels

    def cell_origin(self, layer: int) -> tuple[int, int]:
        """Level-0 ``(row, col)`` of the top-left texel of ``layer``'s tile (inside its gutter)."""
        th, tw = self.tile_size
        g = self.gutter
        r, c = divmod(int(layer), self.columns)
        return r * (th + 2 * g) + g, c * (tw + 2 * g) + g

    def uv(self, layer: int, uv) -> np.ndarray:
        """Atlas UVs (float64 ``[..., 2]``) of ``layer`` at layer UVs ``uv`` (wrapped into the tile),
        as the sampler computes them."""
        uv = np.asarray(uv, np.float64)
        th, tw = self.tile_size
        r0, c0 = self.cell_origin(layer)
        ah, aw = self.texture.height, self.texture.width
        x = c0 + np.mod(uv[..., 0], 1.0) * tw
        y = r0 + (1.0 - np.mod(uv[..., 1], 1.0)) * th
        return np.stack([x / aw, 1.0 - y / ah], axis=-1)

    def update(self) -> None:
        """Re-pack level 0 from :attr:`layers` and rebuild the mips (after changing the layers).
        Inside a ``wp.Tape`` gradients of the atlas flow back to the layers' level-0 texels."""
        _pack(self.layers, self.layout, self.texture)

    def __repr__(self) -> str:
        return (
            f"Atlas(layers={self.num_layers}, tile={self.tile_size[0]}x{self.tile_size[1]}, gutter={self.gutter}, "
            f"grid={self.rows}x{self.columns}, max_lod={self.max_lod}, device={self.device})"
        )


def _pack(layers: TextureArray, layout, texture: Texture) -> None:
    wrap = sampler_args("pack_atlas", Sampler(filter=Filter.NEAREST), has_lod=False)
    g = layout.gutter
    dim = (layout.num_tiles, layout.tile_height + 2 * g, layout.tile_width + 2 * g)
    wp.launch(ka.pack_kernel, dim=dim, inputs=[layers.view, layout, wrap], outputs=[texture.texels], device=texture.device)
    texture.update()


def pack_atlas(
    layers, *, gutter: int = 4, columns: int | None = None, mipmaps: bool | int = True, requires_grad: bool = False, device=None
) -> Atlas:
    """Pack ``L`` layers into an atlas of tiles with wrapped gutters.

    Each layer becomes a cell of ``th + 2·gutter`` by ``tw + 2·gutter`` texels: the layer, framed
    by ``gutter`` texels of its own content wrapped around, so bilinear filtering at a tile edge
    reads what wrap addressing would. Cells fill a grid row by row from the top-left, ``columns``
    wide; cells beyond ``L`` are zero. Mips stay inside their tiles up to level
    ``min(v2(gutter), v2(th), v2(tw))``: use power-of-two gutters and tile sizes (e.g. 4 and 256
    allow level 2); other sizes are handled exactly by a lower :attr:`Atlas.max_lod` (0 for an odd
    gutter or tile side, i.e. no mips).

    Args:
        layers: a :class:`TextureArray` (level 0 is packed) or an array ``[L, H, W, C]`` /
            ``[L, H, W]`` or a sequence of ``[H, W, C]`` arrays of one size, 1 to 4 channels.
        gutter: border width in texels, an int >= 1 (bilinear filtering reads one texel past a tile).
        columns: cells per atlas row; default ``ceil(sqrt(L))``.
        mipmaps: the atlas chain, as for :class:`Texture` (``True``: down to 1 × 1; the sampler
            never reads past :attr:`Atlas.max_lod`).
        requires_grad: give the atlas texels gradients (implied by layers that require them).
        device: Warp device for NumPy layers (``None``: Warp's default); must be a
            :class:`TextureArray`'s own device.

    Returns:
        An :class:`Atlas`. Packed inside a ``wp.Tape``, the pack and the mip build are recorded, so
        gradients reaching any atlas level flow to the atlas' level 0 and on to the layer texels.
    """
    func = "pack_atlas"
    if isinstance(layers, TextureArray):
        if device is not None and wp.get_device(device) != layers.device:
            raise ValueError(f"{func}(): layers are on {layers.device} but device is {wp.get_device(device)}")
        source = layers
    else:
        if isinstance(layers, wp.array):
            raise TypeError(f"{func}(): pass layers as a TextureArray or NumPy array, not a bare wp.array")
        if isinstance(layers, (list, tuple)):
            shapes = [np.shape(x) for x in layers]
            for i, s in enumerate(shapes[1:], start=1):
                if s != shapes[0]:
                    raise ValueError(f"{func}(): layers must all have one size; layer 0 is {shapes[0]} but layer {i} is {s}")
        data = as_float_array(func, "layers", layers)
        if data.ndim not in (3, 4) or 0 in data.shape:
            raise ValueError(f"{func}(): layers must have shape (L, H, W, C) or (L, H, W), got {data.shape}")
        if data.ndim == 4 and not 1 <= data.shape[-1] <= 4:
            raise ValueError(f"{func}(): layers must have 1 to 4 channels, got shape {data.shape}")
        if not np.isfinite(data).all():
            raise ValueError(f"{func}(): layers must be finite")
        source = TextureArray(data, mipmaps=False, device=device)
    if isinstance(gutter, bool) or not isinstance(gutter, (int, np.integer)) or gutter < 1:
        raise ValueError(f"{func}(): gutter must be an int >= 1 (bilinear filtering reads one texel past a tile), got {gutter!r}")
    num = source.num_layers
    if columns is None:
        columns = math.ceil(math.sqrt(num))
    elif isinstance(columns, bool) or not isinstance(columns, (int, np.integer)) or columns < 1:
        raise ValueError(f"{func}(): columns must be a positive int or None, got {columns!r}")
    columns = min(int(columns), num)
    rows = -(-num // columns)

    layout = ka.AtlasLayout()
    layout.tile_height, layout.tile_width = source.height, source.width
    layout.gutter, layout.columns, layout.num_tiles = int(gutter), columns, num
    size = (rows * (source.height + 2 * gutter), columns * (source.width + 2 * gutter), source.channels)
    texture = _AtlasTexture(
        np.zeros(size, np.float32), mipmaps=mipmaps, requires_grad=requires_grad or source.requires_grad, device=source.device
    )
    _pack(source, layout, texture)
    return Atlas(texture, source, layout, rows)


def _map_array(func, name, value, dtype, shape, device) -> wp.array:
    """An index or weight map as a ``wp.array`` ``[H, W, k]`` (the caller's array, kept for gradients)."""
    np_dtype = np.int32 if dtype == wp.int32 else np.float32
    if isinstance(value, wp.array):
        if value.dtype != dtype or value.ndim != 3 or (shape is not None and value.shape != shape):
            want = "(H, W, k)" if shape is None else str(shape)
            got = f"{wp.types.type_repr(value.dtype)} {value.shape}"
            raise ValueError(f"{func}(): {name} must be a wp.array of {wp.types.type_repr(dtype)} with shape {want}, got {got}")
        return as_device_array(func, name, value, device, beside="the G-buffer")
    arr = np.asarray(value)
    if dtype == wp.int32 and not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{func}(): {name} must hold integers, got dtype {arr.dtype}")
    if dtype == wp.float32:
        arr = as_float_array(func, name, arr)
        if not np.isfinite(arr).all():
            raise ValueError(f"{func}(): {name} must be finite")
    if arr.ndim != 3 or (shape is not None and arr.shape != shape):
        want = "(H, W, k)" if shape is None else f"{shape}, the shape of indices"
        raise ValueError(f"{func}(): {name} must have shape {want}, got {arr.shape}")
    return wp.array(np.ascontiguousarray(arr, np_dtype), dtype=dtype, device=device)


def splat_atlas(
    gbuffer: GBuffer,
    atlas: Atlas,
    indices,
    weights,
    *,
    tiling=1.0,
    normalize: bool = False,
    uv_set: str = "uv0",
    sampler: Sampler | None = None,
    device=None,
    out=None,
) -> wp.array:
    """Blend ``k`` atlas layers per pixel by an index map and a weight map.

    Per covered pixel: the index and weight maps are read in ``uv_set`` with *nearest* filtering,
    clamped at the edges (the texel containing the UV; weights belong to the indices of their own
    texel, so blending weights bilinearly across texels of different indices would be wrong). Each
    of the ``k`` entries samples layer ``idx`` at ``uv · tiling[idx]``, wrapped into its tile,
    with the LOD of the pixel footprint in tile texels, clamped to ``[min_lod, min(max_lod,
    atlas.max_lod)]`` (of the ``sampler``) after its ``lod_bias`` so mips never bleed across tiles (at level ``ℓ`` the gutter
    is ``gutter / 2^ℓ`` texels and bilinear needs >= 1, hence ``ℓ <= log2(gutter)``; see
    :mod:`warptex.kernels.atlas`). The samples are summed with their weights.

    Args:
        gbuffer: the G-buffer, ``(H, W)``; reads ``uv_set`` (``uv``, ``uv_dx``, ``uv_dy``) and ``mask``.
        atlas: an :class:`Atlas` of ``L`` layers, ``C`` channels.
        indices: int ``[h, w, k]`` layer indices in ``[0, L)``, ``1 <= k <= 4`` (NumPy, or a
            ``wp.array`` of int32), e.g. from :func:`export_index_maps`.
        weights: float ``[h, w, k]`` (NumPy, or a float32 ``wp.array``: receives gradients).
        tiling: layer repeats per UV unit: a number, ``L`` numbers (indexed by layer), or a float32
            ``wp.array`` of shape ``(1,)`` or ``(L,)`` (receives gradients). Non-zero.
        normalize: clamp the weights to >= 0 and divide by their sum (all zero: output 0);
            default: use them as stored (:func:`export_index_maps` already normalises).
        uv_set: the G-buffer UV set of the maps and the layers.
        sampler: a :class:`~warptex.Sampler`: its filter (``"auto"`` is trilinear; bilinear and
            nearest read the nearest allowed level), LOD bias and clamp (``min_lod`` must not
            exceed ``atlas.max_lod``; ``max_lod=0`` turns mips off). Its address mode must be
            ``"wrap"``, the default: every tile wraps through its gutter.
        device: Warp device; must be the G-buffer's and the atlas'.
        out: a float32 ``wp.array`` of shape ``(H, W, C)`` on the device, to fill in place and
            return (a loop's buffer, reused call after call); ``None``: a new array. It must not
            overlap an input.

    Returns:
        ``wp.array`` of float32 (``out`` when given), shape ``(H, W, C)``, 0 where the mask is 0, NaN where the UV is
        not finite. Recorded on the active ``wp.Tape``: gradients reach the atlas texels (every
        level read; level 0 and the layers too when the atlas was packed or updated on the tape),
        ``weights``, ``tiling`` and the G-buffer's UVs and derivatives.
    """
    func = "splat_atlas"
    device = _gbuffer_device(func, gbuffer, device)
    as_on_device(func, "atlas", atlas, Atlas, "an Atlas (from pack_atlas)", device)
    gbuffer.require(func, "mask", f"{uv_set}.uv", f"{uv_set}.uv_dx", f"{uv_set}.uv_dy")
    idx = _map_array(func, "indices", indices, wp.int32, None, device)
    k = idx.shape[2]
    if not 1 <= k <= MAX_K or 0 in idx.shape:
        raise ValueError(f"{func}(): indices must have shape (h, w, k) with h, w >= 1 and 1 <= k <= {MAX_K}, got {idx.shape}")
    values = idx.numpy()
    if values.min() < 0 or values.max() >= atlas.num_layers:
        raise ValueError(
            f"{func}(): indices must be layers of the atlas, in [0, {atlas.num_layers - 1}], "
            f"got values in [{values.min()}, {values.max()}]"
        )
    wts = _map_array(func, "weights", weights, wp.float32, idx.shape, device)
    num = atlas.num_layers
    tiling = param_array(func, "tiling", tiling, ((1,), (num,)), device, nonzero=True)
    sampler = _as_sampler(func, sampler)
    if sampler.address != Address.WRAP:
        raise ValueError(f"{func}(): the atlas wraps every layer through its gutter; sampler.address must be 'wrap', got {sampler.address.value!r}")
    if sampler.min_lod > atlas.max_lod:
        raise ValueError(
            f"{func}(): sampler.min_lod ({sampler.min_lod}) must not exceed the atlas' max_lod ({atlas.max_lod}), past which mips bleed across tiles"
        )
    # The tile UV is wrapped in the kernel; the atlas itself is read clamped, up to its safe level.
    smp = sampler_args(func, sampler.replace(address=Address.CLAMP, max_lod=min(sampler.max_lod, float(atlas.max_lod))), has_lod=True)

    into = out_array(func, out, (*gbuffer.resolution, atlas.channels), device)
    count = gbuffer.pixel_count
    uvs = gbuffer.uv_sets[uv_set]
    pixels = struct_of(ka.AtlasPixels, device, uv0=uvs["uv"].reshape((count,)), uv0_dx=uvs["uv_dx"].reshape((count,)), uv0_dy=uvs["uv_dy"].reshape((count,)), mask=gbuffer.mask.reshape((count,)))
    args = struct_of(ka.AtlasArgs, device, atlas=atlas.texture.view, layout=atlas.layout, indices=idx, weights=wts, tiling=tiling, smp=smp, normalize=int(bool(normalize)))
    result = run(ka.atlas_kernels(), count, args=args, pixels=pixels, out=((count, atlas.channels), float) if into is None else into, device=device, covered=pixels.mask,
                 footprints=footprints(smp, lookups=k))
    return out if into is not None else result.reshape((*gbuffer.resolution, atlas.channels))
