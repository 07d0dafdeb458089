"""Textures and texture arrays with differentiable, box-filtered mip chains."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np
import warp as wp

from warptex import io
from warptex._output import check_memory
from warptex._threads import zero
from warptex._validate import as_float_array
from warptex.kernels import sampling as ks
from warptex.kernels import texels as kx


def mip_sizes(height: int, width: int, max_levels: int | None = None) -> list[tuple[int, int]]:
    """Sizes ``(h, w)`` of a mip chain: each level halves both sides (rounding down, at least 1).

    The chain runs down to ``1 × 1`` unless ``max_levels`` cuts it short. Non-power-of-two sizes are
    fine: a ``5 × 3`` texture has levels ``5×3, 2×1, 1×1``.
    """
    for name, value in (("height", height), ("width", width)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"mip_sizes(): {name} must be a positive int, got {value!r}")
    if max_levels is not None and (isinstance(max_levels, bool) or not isinstance(max_levels, (int, np.integer)) or max_levels < 1):
        raise ValueError(f"mip_sizes(): max_levels must be a positive int or None, got {max_levels!r}")
    sizes = [(int(height), int(width))]
    while sizes[-1] != (1, 1) and (max_levels is None or len(sizes) < max_levels):
        h, w = sizes[-1]
        sizes.append((max(1, h // 2), max(1, w // 2)))
    return sizes


#: Integer texel dtypes accepted by :class:`Texture` and :class:`TextureArray`, and the value that maps to 1.
_UNORM_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}
#: Mip chains of this many bytes or more are checked against the memory there is before they are made.
LARGE_CHAIN_BYTES = 64 << 20


class TextureArray:
    """``L`` texture layers of one size and channel count, each with its own mip chain.

    Texels are float32, linear, 1–4 channels, stored on a Warp device as one flat ``vec4`` buffer
    (layout in :mod:`warptex.kernels.sampling`). Level 0 of every layer is exposed as
    :attr:`texels`, a ``wp.array`` of ``vec4`` shaped ``(L, H, W)`` that *is* the start of that
    buffer: optimise it directly, then call :meth:`update` to rebuild the coarser levels.

    Gradients: with ``requires_grad=True`` every level receives gradients from sampling kernels
    recorded on a ``wp.Tape``. If :meth:`update` was called inside the same tape, the backward pass
    also carries the gradients of the coarse levels down to level 0, so ``grad(0)`` is the full
    derivative with respect to the texels the user owns.

    Args:
        layers: ``[L, H, W, C]`` or ``[L, H, W]`` array, or a sequence of ``[H, W, C]`` / ``[H, W]``
            arrays or :class:`Texture` objects of equal size and channel count (a Texture contributes its
            level-0 texels, copied: gradients do not flow back to it), or a :class:`TextureArray`
            (copied); ``1 <= C <= 4``. Float values are used as given (finite, linear); ``uint8``
            and ``uint16`` values are scaled to ``[0, 1]`` (divided by 255 and 65535, as
            :func:`warptex.io.read_image` decodes 8- and 16-bit data); other integer dtypes raise
            ``TypeError``.
        mipmaps: ``True`` for the full chain down to ``1 × 1``, ``False`` for level 0 only, or an
            int: the maximum number of levels.
        requires_grad: allocate gradient buffers for the texels.
        device: Warp device (``None``: Warp's default device).
    """

    _name = "TextureArray"

    def __init__(self, layers, *, mipmaps: bool | int = True, requires_grad: bool = False, device=None):
        data = self._layers_to_array(layers)
        num_layers, height, width, channels = data.shape
        if isinstance(mipmaps, (bool, np.bool_)):
            max_levels = None if mipmaps else 1
        elif not isinstance(mipmaps, (int, np.integer)):
            raise TypeError(f"{self._name}(): mipmaps must be a bool or a positive int, got {mipmaps!r}")
        elif mipmaps >= 1:
            max_levels = int(mipmaps)
        else:
            raise ValueError(f"{self._name}(): mipmaps must be a bool or a positive int, got {mipmaps!r}")

        sizes = mip_sizes(height, width, max_levels)
        texels = sum(num_layers * h * w for h, w in sizes)
        if texels * 16 >= LARGE_CHAIN_BYTES:  # the chain, its device copy and gradient, before NumPy's bare MemoryError part-way
            what, needed = f"a {num_layers}x{height}x{width} texture with {len(sizes)} level(s)", texels * 16 * (3 if requires_grad else 2)
            check_memory(self._name, what, needed, device, hint="use a smaller texture, or mipmaps=False")
        padded = np.zeros((texels, 4), dtype=np.float32)
        padded[: num_layers * height * width, :channels] = data.reshape(-1, channels)
        self._wrap(wp.array(padded, dtype=wp.vec4, device=device, requires_grad=requires_grad), num_layers, sizes, channels)
        self.update()

    @classmethod
    def around(cls, chain: wp.array, num_layers: int, sizes: Sequence[tuple[int, int]], channels: int) -> "TextureArray":
        """A texture array whose mip chain *is* ``chain`` (no copy), for buffers that another
        framework owns (the PyTorch bridge): a ``wp.array`` of ``vec4`` holding the levels of
        ``sizes`` (:func:`mip_sizes`) one after another, each ``num_layers`` layers of rows, with
        ``channels`` channels in use. Levels 1.. are as the buffer holds them: call :meth:`update`
        to build them from level 0."""
        if chain.dtype != wp.vec4 or chain.ndim != 1 or chain.shape[0] != sum(num_layers * h * w for h, w in sizes):
            raise ValueError(f"{cls._name}.around(): chain must be a 1-D wp.array of vec4 holding the levels {list(sizes)} of {num_layers} layer(s)")
        if not 1 <= channels <= 4:
            raise ValueError(f"{cls._name}.around(): channels must be in [1, 4], got {channels}")
        texture = cls.__new__(cls)
        texture._wrap(chain, num_layers, [tuple(s) for s in sizes], channels)
        return texture

    def _wrap(self, chain: wp.array, num_layers: int, sizes: list[tuple[int, int]], channels: int) -> None:
        self._device = chain.device
        self._channels = channels
        self._sizes = sizes
        self._chain = chain
        self._offsets = [int(o) for o in np.cumsum([0] + [num_layers * h * w for h, w in sizes])[:-1]]
        view = kx.TextureView()
        view.texels = self._chain
        view.level_offset = wp.array(self._offsets, dtype=wp.int32, device=self._device)
        view.level_height = wp.array([h for h, _ in self._sizes], dtype=wp.int32, device=self._device)
        view.level_width = wp.array([w for _, w in self._sizes], dtype=wp.int32, device=self._device)
        view.num_levels = len(self._sizes)
        view.num_layers = num_layers
        self._view = view

    # -- construction -----------------------------------------------------------------------------

    @classmethod
    def _layers_to_array(cls, layers) -> np.ndarray:
        """Validate ``layers`` and return them as a float32 ``[L, H, W, C]`` array."""
        if isinstance(layers, TextureArray):
            if isinstance(layers, Texture):
                return layers.numpy(0)[None]
            return layers.numpy(0)
        if isinstance(layers, (list, tuple)):
            if not layers:
                raise ValueError(f"{cls._name}(): needs at least one layer, got an empty sequence")
            arrays = []
            for i, x in enumerate(layers):
                if isinstance(x, TextureArray) and not isinstance(x, Texture):
                    raise TypeError(
                        f"{cls._name}(): layer {i} is a {type(x).__name__} of {x.num_layers} layers; pass "
                        "Textures or [H, W, C] arrays (a TextureArray's layers: its .numpy())"
                    )
                arrays.append(x.numpy(0) if isinstance(x, Texture) else cls._image_to_array(f"layer {i}", x))
            for i, a in enumerate(arrays[1:], start=1):
                if a.shape != arrays[0].shape:
                    raise ValueError(
                        f"{cls._name}(): all layers must have the same (H, W, C); layer 0 is "
                        f"{arrays[0].shape} but layer {i} is {a.shape}"
                    )
            return np.stack(arrays)
        data = cls._texel_values("layers", layers)
        if data.ndim == 3:
            data = data[..., None]
        if data.ndim != 4:
            raise ValueError(f"{cls._name}(): layers must have shape (L, H, W, C) or (L, H, W), got {data.shape}")
        if data.shape[0] == 0:
            raise ValueError(f"{cls._name}(): needs at least one layer, got shape {data.shape}")
        return np.stack([cls._image_to_array(f"layer {i}", x) for i, x in enumerate(data)])

    @classmethod
    def _image_to_array(cls, name: str, image) -> np.ndarray:
        """Validate one ``[H, W]`` or ``[H, W, C]`` image and return it as float32 ``[H, W, C]``."""
        data = cls._texel_values(name, image)
        if data.ndim == 2:
            data = data[..., None]
        if data.ndim != 3:
            raise ValueError(f"{cls._name}(): {name} must have shape (H, W, C) or (H, W), got {data.shape}")
        h, w, c = data.shape
        if h == 0 or w == 0:
            raise ValueError(f"{cls._name}(): {name} must not be empty, got shape {data.shape}")
        if not 1 <= c <= 4:
            raise ValueError(f"{cls._name}(): {name} must have 1 to 4 channels, got {c} (shape {data.shape})")
        finite = np.isfinite(data)
        if not finite.all():
            where = tuple(int(i) for i in np.argwhere(~finite)[0])
            raise ValueError(
                f"{cls._name}(): {name} contains non-finite texels, first {data[where]} at (row, col, channel) {where}"
            )
        return np.ascontiguousarray(data, dtype=np.float32)

    @classmethod
    def _texel_values(cls, name: str, value) -> np.ndarray:
        """``value`` as float32: floats as given, ``uint8``/``uint16`` scaled to ``[0, 1]`` (like
        :func:`warptex.io.read_image`), other integer dtypes refused (their range is ambiguous)."""
        try:
            arr = np.asarray(value)
        except (ValueError, TypeError) as err:  # ragged nesting
            raise ValueError(f"{cls._name}(): {name} must be a rectangular array of numbers, got {type(value).__name__}: {err}") from None
        if np.issubdtype(arr.dtype, np.integer):
            scale = _UNORM_SCALE.get(arr.dtype)
            if scale is None:
                raise TypeError(
                    f"{cls._name}(): {name} has integer dtype {arr.dtype}; pass floats (linear, usually in [0, 1]), "
                    "or uint8 / uint16, which are divided by 255 / 65535"
                )
            return (arr / scale).astype(np.float32)
        return as_float_array(cls._name, name, arr)

    @classmethod
    def from_files(cls, paths: Sequence[str | os.PathLike], *, data: bool = False, channels=None, mipmaps: bool | int = True, requires_grad: bool = False, device=None) -> "TextureArray":
        """Load one layer per file (PNG/JPG/EXR; see :func:`warptex.io.read_image`).

        ``data=True`` keeps PNG/JPG values as they are (normal, splat and height maps) instead of
        decoding sRGB. Files of different sizes or channel counts raise ``ValueError`` naming both.
        """
        if isinstance(paths, (str, bytes, os.PathLike)):
            raise TypeError(f"{cls._name}.from_files(): paths must be a sequence of paths, got the single path {paths!r}")
        paths = list(paths)
        images = [cls._checked_file("from_files", p, io.read_image(p, data=data, channels=channels)) for p in paths]
        if not images:
            raise ValueError(f"{cls._name}.from_files(): needs at least one path")
        for p, img in zip(paths[1:], images[1:]):
            if img.shape != images[0].shape:
                raise ValueError(
                    f"{cls._name}.from_files(): '{os.fspath(p)}' is {img.shape} (H, W, C) but "
                    f"'{os.fspath(paths[0])}' is {images[0].shape}; layers must match"
                )
        return cls(images, mipmaps=mipmaps, requires_grad=requires_grad, device=device)

    @classmethod
    def _checked_file(cls, func: str, path, image: np.ndarray) -> np.ndarray:
        """``image``, read from ``path``, checked as a layer, naming the file where it is not one."""
        try:
            cls._image_to_array("image", image)
        except ValueError as err:
            raise ValueError(f"{cls._name}.{func}(): {os.fspath(path)!r}: {str(err).removeprefix(f'{cls._name}(): ')}") from None
        return image

    # -- properties ---------------------------------------------------------------------------------

    @property
    def num_layers(self) -> int:
        return self._view.num_layers

    @property
    def height(self) -> int:
        return self._sizes[0][0]

    @property
    def width(self) -> int:
        return self._sizes[0][1]

    @property
    def channels(self) -> int:
        return self._channels

    @property
    def num_levels(self) -> int:
        return len(self._sizes)

    @property
    def level_sizes(self) -> list[tuple[int, int]]:
        """``(height, width)`` of every mip level, finest first."""
        return list(self._sizes)

    @property
    def device(self):
        return self._device

    @property
    def requires_grad(self) -> bool:
        return self._chain.requires_grad

    @property
    def view(self) -> kx.TextureView:
        """The texture as kernels take it (:class:`warptex.kernels.sampling.TextureView`)."""
        return self._view

    @property
    def texels(self) -> wp.array:
        """Level 0: ``wp.array`` of ``vec4``, shape ``(L, H, W)`` (``(H, W)`` for a :class:`Texture`),
        aliasing the start of the chain."""
        return self.level(0)

    def level(self, level: int) -> wp.array:
        """Mip ``level`` as a ``wp.array`` of ``vec4`` shaped ``(L, h, w)``: a view into the chain.

        Writing to a coarse level directly (rather than through :meth:`update`) is allowed, e.g.
        for hand-made mips; its gradient (``.grad``) is the view of that level's gradient.
        """
        self._check_level("level", level)
        return self._level_array(self._chain, level)

    # -- operations -------------------------------------------------------------------------------

    def update(self) -> None:
        """Rebuild levels 1.. from level 0 with the box filter.

        Call it after changing :attr:`texels`. Inside a ``wp.Tape`` the launches are recorded, so
        gradients reaching coarse levels flow back to level 0 in the backward pass.
        """
        for k in range(self.num_levels - 1):
            h, w = self._sizes[k + 1]
            wp.launch(
                ks.downsample_kernel,
                dim=(self.num_layers, h, w),
                inputs=[self._view, k],
                outputs=[self._chain],
                device=self._device,
            )

    def numpy(self, level: int = 0) -> np.ndarray:
        """Texels of ``level`` as float32 ``[L, h, w, C]``."""
        self._check_level("numpy", level)
        return self._level_numpy(self._chain, level)

    def grad(self, level: int = 0) -> np.ndarray | None:
        """Gradient with respect to the texels of ``level``, float32 ``[L, h, w, C]`` (``None`` without grads)."""
        self._check_level("grad", level)
        if self._chain.grad is None:
            return None
        return self._level_numpy(self._chain.grad, level)

    def zero_grad(self) -> None:
        """Reset the texel gradients of every level to zero (on the CPU, on warptex's threads)."""
        if self._chain.grad is not None:
            zero(self._chain.grad)

    def _check_level(self, method: str, level) -> None:
        if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= level < self.num_levels:
            raise ValueError(f"{self._name}.{method}(): level must be an int in [0, {self.num_levels - 1}], got {level!r}")

    def level_entries(self, first: int, last: int) -> tuple[int, int]:
        """``(start, stop)``: the entries of the texel chain (``view.texels``) that levels ``first``
        to ``last`` (inclusive) occupy, every layer."""
        h, w = self._sizes[last]
        return self._offsets[first], self._offsets[last] + self.num_layers * h * w

    def _level_array(self, buffer: wp.array, level: int) -> wp.array:
        h, w = self._sizes[level]
        start = self._offsets[level]
        return buffer[start : start + self.num_layers * h * w].reshape((self.num_layers, h, w))

    def _level_numpy(self, buffer: wp.array, level: int) -> np.ndarray:
        return self._level_array(buffer, level).numpy()[..., : self._channels].copy()

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(layers={self.num_layers}, size={self.height}x{self.width}, "
            f"channels={self.channels}, levels={self.num_levels}, device={self.device})"
        )


class Texture(TextureArray):
    """One image (1–4 channels, float32 linear) with an optional mip chain.

    A :class:`TextureArray` with a single layer; the array accessors drop the layer axis, so
    :meth:`numpy` and :meth:`grad` return ``[h, w, C]`` and :attr:`texels` has shape ``(H, W)``.

    Args:
        image: ``[H, W, C]`` or ``[H, W]`` array, ``1 <= C <= 4``. Float values are used as given
            (finite, linear); ``uint8`` and ``uint16`` values are scaled to ``[0, 1]`` (divided by
            255 and 65535, as :func:`warptex.io.read_image` decodes 8- and 16-bit data, without
            its sRGB decoding); other integer dtypes raise ``TypeError``. A :class:`Texture` is
            copied (level 0).
        mipmaps: ``True`` for the full chain, ``False`` for level 0 only, or the maximum number of levels.
        requires_grad: allocate gradient buffers for the texels.
        device: Warp device (``None``: Warp's default device).
    """

    _name = "Texture"

    def __init__(self, image, *, mipmaps: bool | int = True, requires_grad: bool = False, device=None):
        super().__init__(image, mipmaps=mipmaps, requires_grad=requires_grad, device=device)

    @classmethod
    def _layers_to_array(cls, image) -> np.ndarray:
        if isinstance(image, Texture):
            return image.numpy(0)[None]
        return cls._image_to_array("image", image)[None]

    @classmethod
    def from_file(cls, path: str | os.PathLike, *, data: bool = False, channels=None, layer: str | None = None, mipmaps: bool | int = True, requires_grad: bool = False, device=None) -> "Texture":
        """Load an image file (PNG/JPG decoded from sRGB unless ``data=True``; EXR as stored).

        ``channels`` selects EXR channels by name, or forces a channel count for PNG/JPG; ``layer``
        picks a layer of a multi-layer EXR; see :func:`warptex.io.read_image`. An image that is no
        texture (NaN or infinite texels, too many channels) is refused naming the file.
        """
        image = cls._checked_file("from_file", path, io.read_image(path, data=data, channels=channels, layer=layer))
        return cls(image, mipmaps=mipmaps, requires_grad=requires_grad, device=device)

    def level(self, level: int) -> wp.array:
        """Mip ``level`` as a ``wp.array`` of ``vec4`` shaped ``(h, w)``: a view into the chain."""
        return super().level(level).reshape(self._sizes[level])

    def numpy(self, level: int = 0) -> np.ndarray:
        """Texels of ``level`` as float32 ``[h, w, C]``."""
        return super().numpy(level)[0]

    def grad(self, level: int = 0) -> np.ndarray | None:
        """Gradient with respect to the texels of ``level``, float32 ``[h, w, C]`` (``None`` without grads)."""
        g = super().grad(level)
        return None if g is None else g[0]
