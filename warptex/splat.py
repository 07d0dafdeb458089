"""Terrain texturing: texture-array layers blended by splat maps, with height-based blending.

Formulas: :mod:`warptex.kernels.splat_layers` and :mod:`warptex.kernels.splat`. The atlas + index-map variant is in :mod:`warptex.atlas`.
"""

from __future__ import annotations

import enum
from typing import Sequence

import numpy as np
import warp as wp

from warptex import _plan
from warptex._op import run
from warptex._pack import MAP_SAMPLER, SURFACE, footprints, empty_array, out_array, packed, projection_args, sampler_args, stochastic_args, struct_of
from warptex._validate import as_enum, as_on_device, check_layer_count, param_array, warn_renamed
from warptex.gbuffer import GBuffer, _gbuffer_device
from warptex.kernels import projection as kp
from warptex.kernels import splat as kl
from warptex.kernels import splat_layers as ksl
from warptex.kernels import stochastic as kst
from warptex.options import Sampler, Stochastic, _as_sampler, _as_stochastic
from warptex.texture import TextureArray


class LayerProjection(str, enum.Enum):
    """Where :func:`splat`'s layers are read.

    - ``UV``: the G-buffer's UV set (``uv_set``) × the layer's tiling.
    - ``WORLD_XZ``: world ``(-x, z)`` × tiling: the triplanar top projection (reads unmirrored
      from above), for ground without UVs.
    - ``TRIPLANAR``: every layer mapped triplanar (``sharpness``, ``offsets``, ``mirror_fix`` as in
      :func:`warptex.triplanar`), for cliffs.
    """

    UV = "uv"
    WORLD_XZ = "world_xz"
    TRIPLANAR = "triplanar"


_PROJECTION_IDS = {LayerProjection.UV: ksl.PROJECT_UV, LayerProjection.WORLD_XZ: ksl.PROJECT_WORLD_XZ, LayerProjection.TRIPLANAR: ksl.PROJECT_TRIPLANAR}


def _as_splat_maps(func: str, splat_maps, device) -> TextureArray:
    """``splat_maps`` as a :class:`TextureArray` (NumPy ``[H, W, C]`` or ``[M, H, W, C]`` arrays are
    wrapped without mips); weights are data, never sRGB-decoded."""
    if isinstance(splat_maps, TextureArray):
        if splat_maps.device != device:
            raise ValueError(f"{func}(): splat_maps are on {splat_maps.device} but the G-buffer on {device}")
        return splat_maps
    if isinstance(splat_maps, wp.array):
        raise TypeError(f"{func}(): pass splat maps as a TextureArray (or NumPy), not a bare wp.array")
    data = np.asarray(splat_maps)
    if data.ndim == 3:
        data = data[None]
    if data.ndim != 4:
        raise ValueError(f"{func}(): splat_maps must be a TextureArray or an array [H, W, C] / [M, H, W, C], got shape {data.shape}")
    try:
        return TextureArray(data, mipmaps=False, device=device)
    except (TypeError, ValueError) as err:  # said of the maps, not of "TextureArray(): layer 0"
        text = str(err).removeprefix("TextureArray(): ").replace("layer ", "map ", 1)
        raise type(err)(f"{func}(): splat_maps: {text}") from None


def splat(
    gbuffer: GBuffer,
    layers: TextureArray,
    splat_maps,
    *,
    tiling=1.0,
    projection: LayerProjection | str = LayerProjection.UV,
    normalize: bool = True,
    height_blend=None,
    heights: TextureArray | None = None,
    height_channel: int = 3,
    uv_set: str = "uv0",
    sharpness=4.0,
    offsets=None,
    mirror_fix: bool = True,
    layers_per_face=None,
    stochastic: Stochastic | str | None = None,
    sampler: Sampler | None = None,
    device=None,
    out=None,
    face_layers=None,
) -> wp.array:
    """Blend the ``L`` layers of a texture array by splat-map weights, per pixel of a G-buffer.

    Splat map ``m``'s channel ``c`` is the weight of layer ``m·C + c``; the maps are read in
    ``uv_set`` with bilinear filtering on level 0, clamped at the edges (a texel centre returns its
    texel exactly). Negative weights are clamped to 0; with ``normalize`` the weights are divided by
    their sum, and a pixel whose weights are all zero gets 0. Each layer with weight is sampled at
    its own tiling (trilinear, LOD from the G-buffer's derivatives) in ``projection``.

    Args:
        gbuffer: the G-buffer, ``(H, W)``; reads ``uv_set``, ``position``, ``normal``, their
            derivatives and ``mask``.
        layers: a :class:`TextureArray` of ``L`` layers (one size, ``C_out`` channels).
        splat_maps: a :class:`TextureArray` (or NumPy ``[H, W, C]`` / ``[M, H, W, C]``) of
            ``M = ceil(L / C)`` maps; spare channels of the last map are ignored.
        tiling: layer repeats per UV unit (or per world unit): a number, ``L`` numbers, or a float32
            ``wp.array`` of shape ``(1,)`` or ``(L,)`` (receives gradients). Non-zero.
        projection: :class:`LayerProjection`: ``"uv"``, ``"world_xz"`` or ``"triplanar"``.
        normalize: divide the weights by their sum.
        height_blend: ``None`` for a plain blend, or the transition ``t > 0`` of height-based
            blending (a number or a float32 ``wp.array`` of shape ``(1,)``, receives gradients):
            ``h = height·w; m = max h; w' = max(0, h + t - m)·w / sum``.
        heights: ``L`` one-channel height layers (any size), read like the colour layers; default:
            channel ``height_channel`` of ``layers``.
        height_channel: the channel of ``layers`` holding height when ``heights`` is ``None``.
        uv_set: the G-buffer UV set holding the splat-map UVs (and the layer UVs for ``"uv"``).
        sharpness, offsets, mirror_fix: the triplanar options, for ``projection="triplanar"``.
        layers_per_face: for ``projection="triplanar"``: which array layers a layer reads on each
            face of the cube of directions (grass on top, rock beneath), as
            :func:`~warptex.triplanar`'s ``textures_per_face`` picks a texture per face.
            ``None`` (every layer reads itself), or ``L`` entries (a sequence, or an int array ``(L, 6)``), one per layer
            ``l``: ``None`` (``l`` itself on every face) or 6 layer indices ``(+x, -x, +y, -y,
            +z, -z)``, where a ``None`` index means ``l`` itself. Projection ``a`` reads the
            ``+a`` face's layer where the normal has ``n[a] >= 0``, the ``-a`` face's where
            ``n[a] < 0``; the seam lies where projection ``a``'s weight is 0. The colour (and the
            height, from ``height_channel`` or ``heights``) is read from that layer at layer
            ``l``'s tiling; layer ``l``'s splat weight and its place in the height blend are
            unchanged. Gradients reach the texels of the layers read.
        stochastic: ``None`` (plain tiling), or anti-tiling for every layer: a
            :class:`~warptex.Stochastic` (or a method name), see :func:`warptex.stochastic`. A
            histogram must be built from ``layers``; ``heights`` are read with the same taps,
            blended linearly.
        sampler: a :class:`~warptex.Sampler` for the layers (and heights); its ``"auto"`` filter
            is trilinear. The splat maps have their own: bilinear on level 0, clamped.
        device: Warp device; must be the G-buffer's and the textures'.
        out: a float32 ``wp.array`` of shape ``(H, W, C_out)`` on the device, to fill in place and
            return (a loop's buffer, reused call after call); ``None``: a new array. It must not
            overlap an input.
        face_layers: the old name of ``layers_per_face`` (deprecated).

    Returns:
        ``wp.array`` of float32 (``out`` when given), shape ``(H, W, C_out)``; 0 where the mask is 0. Recorded on the
        active ``wp.Tape``: gradients reach the splat-map texels (every channel), the layer texels,
        ``heights``, and ``tiling`` / ``height_blend`` when given as arrays that require them.
    """
    func = "splat"
    if face_layers is not None:
        if layers_per_face is not None:
            raise TypeError(f"{func}(): got layers_per_face= and its old name face_layers=; pass layers_per_face= alone")
        warn_renamed("splat(face_layers=...)", "splat(layers_per_face=...), named as triplanar's textures_per_face")
        layers_per_face = face_layers
    device = _gbuffer_device(func, gbuffer, device)
    options = {"tiling": tiling, "projection": projection, "normalize": normalize, "height_blend": height_blend, "height_channel": height_channel, "sharpness": sharpness,
               "offsets": offsets, "mirror_fix": mirror_fix, "layers_per_face": layers_per_face, "stochastic": stochastic, "sampler": sampler}  # fmt: skip
    key = _args_key(gbuffer, layers, splat_maps, heights, uv_set=uv_set, device=device, **options)
    # A small call repeated on the same objects (and the same out=, or none; on the CPU, an out= of the same layout) reruns its launch (warptex._plan).
    plan = key if (out is None or type(out) is wp.array) and _plan.usable() else None
    objects = (gbuffer, layers, splat_maps, *(() if heights is None else (heights,)), *(getattr(gbuffer, n) for n in SURFACE), *gbuffer.uv_sets.get(uv_set, {}).values()) if plan else ()
    done = _plan.rerun(plan, objects, gbuffer.resolution, out=out) if plan is not None else None
    if done is not None:
        return done
    as_on_device(func, "layers", layers, TextureArray, "a TextureArray", device)
    maps = _as_splat_maps(func, splat_maps, device)
    check_layer_count(func, layers.num_layers, maps)
    gbuffer.require(func, "position", "position_dx", "position_dy", "normal", "mask", f"{uv_set}.uv", f"{uv_set}.uv_dx", f"{uv_set}.uv_dy")
    build = lambda: _packed_args(func, gbuffer.origin, layers, maps, heights, device, **options)  # noqa: E731
    # key: the same layers, maps, heights, options and origin, checked and packed by an earlier call.
    args, footprint, stochastic_on, linear = build() if key is None else packed(layers, key, build, weakly=(maps, heights))

    into = out_array(func, out, (*gbuffer.resolution, layers.channels), device)
    count = gbuffer.pixel_count
    uvs = gbuffer.uv_sets[uv_set]
    pixels = struct_of(kl.SplatPixels, device, uv0=uvs["uv"].reshape((count,)), uv0_dx=uvs["uv_dx"].reshape((count,)), uv0_dy=uvs["uv_dy"].reshape((count,)), saved=None)
    surface = struct_of(pixels.surface, device, **{name: getattr(gbuffer, name).reshape((count,)) for name in ("position", "position_dx", "position_dy", "normal", "mask")})
    kernels = kl.splat_kernels(capacity=kl.capacity(layers.num_layers), stochastic=stochastic_on)
    with _plan.recording(plan, objects, out=out, hold=(args,)):
        result = run(kernels, count, args=args, pixels=pixels, out=((count, layers.channels), float) if into is None else into, device=device, linear=linear, covered=surface.mask,
                     footprints=footprint)
    return out if into is not None else result.reshape((*gbuffer.resolution, layers.channels))


def _packed_args(func, origin, layers, maps, heights, device, *, tiling, projection, normalize, height_blend, height_channel, sharpness, offsets, mirror_fix, layers_per_face,
                 stochastic, sampler) -> tuple:  # fmt: skip
    """``(args, footprints, stochastic, linear)``: the checked options packed for the kernels,
    the footprints a pixel reads (``warptex._pack.footprints``), whether the stochastic kernels
    run, and whether the blend is linear in the texels (a histogram's is not)."""
    num_layers = layers.num_layers
    args = ksl.SplatArgs()
    reads = args.reads  # filled in place: assigning a struct copies it field by field (Python time per call)
    params = reads.params
    params.num_layers, params.map_channels = num_layers, maps.channels
    params.tiling = param_array(func, "tiling", tiling, ((1,), (num_layers,)), device, nonzero=True)
    params.projection = _PROJECTION_IDS[as_enum(func, "projection", projection, LayerProjection)]
    params.normalize = int(bool(normalize))
    params.height_channel = 0
    height_tex = layers
    if height_blend is None:
        if heights is not None:
            raise ValueError(f"{func}(): heights are only used with height_blend=<transition>")
        params.height_mode = ksl.HEIGHT_NONE
        params.transition = param_array(func, "height_blend", 0.0, ((1,),), device)  # not read
    else:
        params.transition = param_array(func, "height_blend", height_blend, ((1,),), device)
        if float(params.transition.numpy()[0]) <= 0:
            raise ValueError(f"{func}(): height_blend (the transition) must be > 0, got {params.transition.numpy()[0]}")
        if heights is None:
            if isinstance(height_channel, bool) or not isinstance(height_channel, (int, np.integer)) or not 0 <= height_channel < layers.channels:
                raise ValueError(
                    f"{func}(): height_channel must be a channel of the layers (0 to {layers.channels - 1}), got {height_channel!r}; "
                    "pass heights= for layers without a height channel"
                )
            params.height_mode, params.height_channel = ksl.HEIGHT_CHANNEL, int(height_channel)
        else:
            if not isinstance(heights, TextureArray):
                raise TypeError(f"{func}(): heights must be a TextureArray, got {type(heights).__name__}")
            if heights.num_layers != num_layers or heights.channels != 1 or heights.device != device:
                raise ValueError(
                    f"{func}(): heights must have {num_layers} one-channel layers on {device}, "
                    f"got {heights.num_layers} layer(s) of {heights.channels} channel(s) on {heights.device}"
                )
            params.height_mode, height_tex = ksl.HEIGHT_ARRAY, heights

    option, sampler = _as_stochastic(func, stochastic), _as_sampler(func, sampler)
    stoch, layers_read = stochastic_args(func, option, layers, sampler)
    if height_tex is layers:
        height_tex, height_stoch = layers_read, stoch  # heights from a channel of the same (decoded) sample
    else:  # a separate height array: the same taps, without the layers' histogram
        height_stoch, _ = stochastic_args(func, option.replace(histogram=None), height_tex, sampler)

    params.face_layers = _face_layers(func, layers_per_face, num_layers, params.projection, device)

    reads.proj = projection_args(func, tiling=1.0, sharpness=sharpness, offsets=offsets, mirror_fix=mirror_fix, weights=kp.WEIGHTS_TRIPLANAR,
                                 origin=origin, address=sampler.address, device=device)  # fmt: skip
    reads.smp = sampler_args(func, sampler, has_lod=True)
    args.layers, args.heights, args.maps = layers_read.view, height_tex.view, maps.view
    args.map_smp, args.stoch, args.height_stoch = sampler_args(func, MAP_SAMPLER, has_lod=False), stoch, height_stoch

    linear = stoch.histogram == 0 and height_stoch.histogram == 0  # the histogram blend is not linear in the texels
    # A layer's lookup costs about two footprints: its share of the blend (weights, heights,
    # normalising) as much as its filtering (44 ns a footprint in a splat's backward against 20 for bilinear).
    lookups = 2 * num_layers * (3 if params.projection == ksl.PROJECT_TRIPLANAR else 1)
    return args, footprints(reads.smp, stoch, lookups=lookups), stoch.method != kst.METHOD_NONE, linear


def _args_key(gbuffer, layers, splat_maps, heights, *, tiling, projection, normalize, height_blend, height_channel, uv_set, sharpness, offsets, mirror_fix, layers_per_face,
              stochastic, sampler, device) -> tuple | None:  # fmt: skip
    """The key of a call's packed arguments (``warptex._pack.packed``, which adds the maps and
    heights weakly) and plan (``warptex._plan``), or ``None`` where they are not kept: textures given as such,
    options as plain values of their exact types (an array option may receive gradients and may
    change in place; a ``True`` that a call refuses never matches a ``1``), no offsets, layers
    per face or histogram, hashable option objects."""
    if not isinstance(layers, TextureArray) or not isinstance(splat_maps, TextureArray) or offsets is not None or layers_per_face is not None:
        return None
    numbers = (tiling, sharpness) if height_blend is None else (tiling, sharpness, height_blend)
    if not all(type(v) in (int, float) or isinstance(v, (np.floating, np.integer)) for v in numbers) or getattr(stochastic, "histogram", None) is not None:
        return None
    try:
        key = ("splat", *((type(v), v) for v in (tiling, sharpness, height_blend, height_channel, projection, uv_set, normalize, mirror_fix)), heights is None, stochastic, sampler,
               tuple(gbuffer.origin.tolist()), str(device))  # fmt: skip
        hash(key)
    except TypeError:  # an unhashable option: no plan
        return None
    return key


FACE_NAMES = ("+x", "-x", "+y", "-y", "+z", "-z")


def _face_layers(func: str, layers_per_face, num_layers: int, projection: int, device) -> wp.array:
    """``layers_per_face`` checked, as the kernels' int32 array of ``6 L`` indices (``SplatArgs``);
    empty when not given or when every layer reads itself on every face (the default path)."""
    empty = empty_array(wp.int32, 1, device)
    if layers_per_face is None:
        return empty
    if projection != ksl.PROJECT_TRIPLANAR:
        raise ValueError(f"{func}(): layers_per_face needs projection='triplanar' (the faces are those of the triplanar projections)")
    if isinstance(layers_per_face, np.ndarray):
        if layers_per_face.ndim != 2 or layers_per_face.shape[1] != 6:
            raise ValueError(f"{func}(): layers_per_face as an array must have shape ({num_layers}, 6), got {layers_per_face.shape}")
        layers_per_face = [list(row) for row in layers_per_face]
    if isinstance(layers_per_face, (str, bytes)) or not isinstance(layers_per_face, Sequence) or len(layers_per_face) != num_layers:
        raise ValueError(
            f"{func}(): layers_per_face must be a sequence of {num_layers} entries (one per layer), each None or 6 layer indices "
            f"(+x, -x, +y, -y, +z, -z), got {layers_per_face!r}"
        )
    table = np.arange(num_layers, dtype=np.int32).repeat(6).reshape(num_layers, 6)
    for layer, entry in enumerate(layers_per_face):
        if entry is None:
            continue
        if isinstance(entry, (str, bytes)) or not isinstance(entry, (Sequence, np.ndarray)) or len(entry) != 6:
            raise ValueError(f"{func}(): layers_per_face[{layer}] must be None or 6 layer indices (+x, -x, +y, -y, +z, -z), got {entry!r}")
        for f, index in enumerate(entry):
            if index is None:
                continue
            if isinstance(index, (bool, np.bool_)) or not isinstance(index, (int, np.integer)):
                raise TypeError(f"{func}(): layers_per_face[{layer}][{f}] (the {FACE_NAMES[f]} face) must be a layer index or None, got {index!r}")
            if not 0 <= index < num_layers:
                raise ValueError(f"{func}(): layers_per_face[{layer}][{f}] (the {FACE_NAMES[f]} face) must be a layer in [0, {num_layers - 1}], got {index}")
            table[layer, f] = index
    if (table == np.arange(num_layers)[:, None]).all():
        return empty
    return wp.array(table.reshape(-1), dtype=wp.int32, device=device)


_RENAMED = {'as_splat_maps': '_as_splat_maps'}  # old public spellings, kept for one release


def __getattr__(name: str):
    from warptex._validate import renamed_attribute

    return renamed_attribute(__name__, name, _RENAMED, globals())
