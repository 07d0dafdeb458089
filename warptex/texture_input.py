"""What a texture is made from: arrays and image files, validated and turned into the texels a
:class:`~warptex.texture.TextureArray` stores (float32, or the codes of an 8-bit format), with
errors that name the class (``owner``), the layer and the file."""

from __future__ import annotations

import os

import numpy as np

from warptex import io
from warptex._validate import as_float_array
from warptex.formats import (
    EIGHT_BIT,
    Format,
    as_format,
    decode,
    file_format,
    texture_format,
)

#: Integer texel dtypes accepted, and the value that maps to 1.
UNORM_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}


def layers_array(owner: str, layers, fmt: Format) -> np.ndarray:
    """Validate ``layers`` (a TextureArray's argument) and return them as ``[L, H, W, C]``: float32,
    or the uint8 codes an 8-bit ``fmt`` stores when every layer is given as such."""
    from warptex.texture import Texture, TextureArray  # the classes this validates for

    if isinstance(layers, TextureArray):
        return layers.numpy(0)[None] if isinstance(layers, Texture) else layers.numpy(0)
    if isinstance(layers, (list, tuple)):
        if not layers:
            raise ValueError(f"{owner}(): needs at least one layer, got an empty sequence")
        arrays = []
        for i, x in enumerate(layers):
            if isinstance(x, TextureArray) and not isinstance(x, Texture):
                raise TypeError(
                    f"{owner}(): layer {i} is a {type(x).__name__} of {x.num_layers} layers; pass "
                    "Textures or [H, W, C] arrays (a TextureArray's layers: its .numpy())"
                )
            arrays.append(x.numpy(0) if isinstance(x, Texture) else image_array(owner, f"layer {i}", x, fmt))
        for i, a in enumerate(arrays[1:], start=1):
            if a.shape != arrays[0].shape:
                raise ValueError(f"{owner}(): all layers must have the same (H, W, C); layer 0 is {arrays[0].shape} but layer {i} is {a.shape}")
        if len({a.dtype for a in arrays}) > 1:  # codes beside floats: all as the linear floats they stand for
            arrays = [decode(a, fmt, a.shape[-1]) if a.dtype == np.uint8 else a for a in arrays]
        return np.stack(arrays)
    data = texel_values(owner, "layers", layers, fmt)
    if data.ndim == 3:
        data = data[..., None]
    if data.ndim != 4:
        raise ValueError(f"{owner}(): layers must have shape (L, H, W, C) or (L, H, W), got {data.shape}")
    if data.shape[0] == 0:
        raise ValueError(f"{owner}(): needs at least one layer, got shape {data.shape}")
    return np.stack([image_array(owner, f"layer {i}", x, fmt) for i, x in enumerate(data)])


def image_array(owner: str, name: str, image, fmt: Format = Format.FLOAT32) -> np.ndarray:
    """Validate one ``[H, W]`` or ``[H, W, C]`` image and return it as ``[H, W, C]``: float32, or
    uint8 codes of an 8-bit ``fmt``."""
    data = texel_values(owner, name, image, fmt)
    if data.ndim == 2:
        data = data[..., None]
    if data.ndim != 3:
        raise ValueError(f"{owner}(): {name} must have shape (H, W, C) or (H, W), got {data.shape}")
    h, w, c = data.shape
    if h == 0 or w == 0:
        raise ValueError(f"{owner}(): {name} must not be empty, got shape {data.shape}")
    if not 1 <= c <= 4:
        raise ValueError(f"{owner}(): {name} must have 1 to 4 channels, got {c} (shape {data.shape})")
    if data.dtype == np.uint8:
        return np.ascontiguousarray(data)
    finite = np.isfinite(data)
    if not finite.all():
        where = tuple(int(i) for i in np.argwhere(~finite)[0])
        raise ValueError(f"{owner}(): {name} contains non-finite texels, first {data[where]} at (row, col, channel) {where}")
    return np.ascontiguousarray(data, dtype=np.float32)


def texel_values(owner: str, name: str, value, fmt: Format = Format.FLOAT32) -> np.ndarray:
    """``value`` as float32: floats as given, ``uint8``/``uint16`` scaled to ``[0, 1]`` (like
    :func:`warptex.io.read_image`), other integer dtypes refused (their range is ambiguous).
    ``uint8`` values for an 8-bit ``fmt`` stay the codes it stores (sRGB-encoded colour for ``SRGB8``)."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as err:  # ragged nesting
        raise ValueError(f"{owner}(): {name} must be a rectangular array of numbers, got {type(value).__name__}: {err}") from None
    if np.issubdtype(arr.dtype, np.integer):
        if arr.dtype == np.uint8 and fmt in EIGHT_BIT:
            return arr
        scale = UNORM_SCALE.get(arr.dtype)
        if scale is None:
            raise TypeError(
                f"{owner}(): {name} has integer dtype {arr.dtype}; pass floats (linear, usually in [0, 1]), "
                "or uint8 / uint16, which are divided by 255 / 65535"
            )
        return (arr / scale).astype(np.float32)
    return as_float_array(owner, name, arr.astype(np.float32) if arr.dtype == np.float16 else arr)


def file_images(owner: str, func: str, paths: list, *, data: bool, channels, layer=None, format=None) -> tuple[list[np.ndarray], Format]:
    """The images of ``paths`` (:func:`warptex.io.read_texels`) as a texture of the format they
    keep (``format=None``: the files' own where they share it, else float32) takes them, each
    checked as a layer, naming the file where it is not one; and that format."""
    fmt = None if format is None else texture_format(format, f"{owner}.{func}")
    images = [io.read_texels(p, data=data, channels=channels, layer=layer) for p in paths]
    kept = {file_format(img, data) for img in images}
    fmt = fmt or (kept.pop() if len(kept) == 1 else Format.FLOAT32)
    images = [as_format(img, data, fmt) for img in images]
    for path, image in zip(paths, images):
        try:
            image_array(owner, "image", image, fmt)
        except ValueError as err:
            raise ValueError(f"{owner}.{func}(): {os.fspath(path)!r}: {str(err).removeprefix(f'{owner}(): ')}") from None
    return images, fmt
