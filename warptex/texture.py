"""Textures and texture arrays with differentiable, box-filtered mip chains."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np
import warp as wp

from warptex import formats
from warptex._output import check_memory
from warptex._threads import zero
from warptex.formats import Format
from warptex.kernels import texels as kx
from warptex.texture_input import file_images, image_array, layers_array


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



#: Mip chains of this many bytes or more are checked against the memory there is before they are made.
LARGE_CHAIN_BYTES = 64 << 20


class TextureArray:
    """``L`` texture layers of one size and channel count, each with its own mip chain.

    Texels are linear, 1–4 channels, stored on a Warp device in a :class:`Format` (``format=``;
    float32 by default) as one flat buffer of four channels a texel (layout in
    :mod:`warptex.kernels.texels`). For float32 textures: Level 0 of every layer is exposed as
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
            :func:`warptex.io.read_image` decodes 8- and 16-bit data), except that ``uint8``
            values for an 8-bit ``format`` are the codes it stores (sRGB-encoded for ``srgb8``);
            other integer dtypes raise ``TypeError``.
        format: how the texels are stored (:class:`Format` or its name): ``float32`` (default),
            ``float16``, ``unorm8`` or ``srgb8``.
        mipmaps: ``True`` for the full chain down to ``1 × 1``, ``False`` for level 0 only, or an
            int: the maximum number of levels.
        requires_grad: allocate gradient buffers for the texels (float32, whatever the format).
        device: Warp device (``None``: Warp's default device).
    """

    _name = "TextureArray"

    def __init__(self, layers, *, format: Format | str = Format.FLOAT32, mipmaps: bool | int = True, requires_grad: bool = False, device=None):
        fmt = formats.texture_format(format, self._name)
        data = self._layers_to_array(layers, fmt)
        num_layers, height, width, channels = data.shape
        if isinstance(mipmaps, (bool, np.bool_)):
            max_levels = None if mipmaps else 1
        elif not isinstance(mipmaps, (int, np.integer)):
            raise TypeError(f"{self._name}(): mipmaps must be a bool or a positive int, got {mipmaps!r}")
        elif mipmaps >= 1:
            max_levels = int(mipmaps)
        else:
            raise ValueError(f"{self._name}(): mipmaps must be a bool or a positive int, got {mipmaps!r}")
        if fmt is Format.FLOAT16 and data.dtype != np.uint8 and np.abs(data).max() > np.finfo(np.float16).max:
            at = tuple(int(i) for i in np.argwhere(np.abs(data) > np.finfo(np.float16).max)[0])
            raise ValueError(f"{self._name}(): a float16 texture holds values up to 65504; texel {data[at]} at (layer, row, col, channel) {at} is beyond that")

        sizes = mip_sizes(height, width, max_levels)
        texels = sum(num_layers * h * w for h, w in sizes)
        nbytes = texels * formats.TEXEL_BYTES[fmt]
        if nbytes + texels * 16 * requires_grad >= LARGE_CHAIN_BYTES:  # the chain, its host copy and gradient, before NumPy's bare MemoryError part-way
            what = f"a {num_layers}x{height}x{width} {fmt.value} texture with {len(sizes)} level(s)"
            check_memory(self._name, what, 2 * nbytes + texels * 16 * requires_grad, device, hint="use a smaller texture, a compact format, or mipmaps=False")
        if fmt is Format.FLOAT32:
            padded = np.zeros((texels, 4), dtype=np.float32)
            padded[: num_layers * height * width, :channels] = data.reshape(-1, channels)
            self._wrap(wp.array(padded, dtype=wp.vec4, device=device, requires_grad=requires_grad), num_layers, sizes, channels)
            self.update()
            return
        store = formats.store_array(formats.packed(formats.mip_chain(formats.stored(data, fmt, channels), fmt, channels, sizes), fmt), fmt, device)
        self._wrap(formats.gradient_carrier(texels, requires_grad, store.device), num_layers, sizes, channels, fmt, store)

    @classmethod
    def around(cls, chain: wp.array, num_layers: int, sizes: Sequence[tuple[int, int]], channels: int) -> "TextureArray":
        """A texture array whose mip chain *is* ``chain`` (no copy), for buffers that another
        framework owns (the PyTorch bridge): a contiguous ``wp.array`` of ``vec4`` holding the levels of
        ``sizes`` (:func:`mip_sizes`) one after another, each ``num_layers`` layers of rows, with
        ``channels`` channels in use. Levels 1.. are as the buffer holds them: call :meth:`update`
        to build them from level 0."""
        if chain.dtype != wp.vec4 or chain.ndim != 1 or chain.shape[0] != sum(num_layers * h * w for h, w in sizes):
            raise ValueError(f"{cls._name}.around(): chain must be a 1-D wp.array of vec4 holding the levels {list(sizes)} of {num_layers} layer(s)")
        if not chain.is_contiguous:
            raise ValueError(f"{cls._name}.around(): chain must be contiguous (the CPU lanes read its texels 16 bytes apart), got strides {chain.strides}")
        if not 1 <= channels <= 4:
            raise ValueError(f"{cls._name}.around(): channels must be in [1, 4], got {channels}")
        texture = cls.__new__(cls)
        texture._wrap(chain, num_layers, [tuple(s) for s in sizes], channels)
        return texture

    def _wrap(self, chain: wp.array, num_layers: int, sizes: list[tuple[int, int]], channels: int, fmt: Format = Format.FLOAT32, store: wp.array | None = None) -> None:
        """Hold the chain: ``chain`` the float32 texels (``FLOAT32``), or else the carrier of their
        gradient (:func:`_gradient_carrier`), and ``store`` the texels as ``fmt`` packs them."""
        self._device = chain.device
        self._channels = channels
        self._sizes = sizes
        self._chain = chain
        self._format = fmt
        self._store = store
        view = kx.TextureView()
        view.texels = self._chain
        self._offsets, view.level_offset, view.level_height, view.level_width = kx.level_table(tuple(sizes), num_layers, self._device)
        view.num_levels = len(self._sizes)
        view.num_layers = num_layers
        view.texel_format = formats.KERNEL_FORMAT[fmt]
        self._decode = wp.array(formats.decode_table(fmt, channels), dtype=float, device=self._device) if fmt in formats.EIGHT_BIT else None
        view.packed = wp.uint64(store.ptr if store is not None else 0)  # the arrays live as long as the texture
        view.decode = wp.uint64(self._decode.ptr if self._decode is not None else 0)
        self._view = view

    # -- construction -----------------------------------------------------------------------------

    @classmethod
    def _layers_to_array(cls, layers, fmt: Format = Format.FLOAT32) -> np.ndarray:
        """``layers`` validated as ``[L, H, W, C]`` texels (:func:`warptex.texture_input.layers_array`)."""
        return layers_array(cls._name, layers, fmt)

    @classmethod
    def from_files(cls, paths: Sequence[str | os.PathLike], *, data: bool = False, channels=None, format: Format | str | None = None, mipmaps: bool | int = True, requires_grad: bool = False, device=None) -> "TextureArray":
        """Load one layer per file (PNG/JPG/EXR; see :func:`warptex.io.read_image`).

        ``data=True`` keeps PNG/JPG values as they are (normal, splat and height maps) instead of
        decoding sRGB. ``format=None`` keeps the files' precision (:meth:`Texture.from_file`) where
        they all share it, else stores float32. Files of different sizes or channel counts raise
        ``ValueError`` naming both.
        """
        if isinstance(paths, (str, bytes, os.PathLike)):
            raise TypeError(f"{cls._name}.from_files(): paths must be a sequence of paths, got the single path {paths!r}")
        paths = list(paths)
        if not paths:
            raise ValueError(f"{cls._name}.from_files(): needs at least one path")
        images, fmt = file_images(cls._name, "from_files", paths, data=data, channels=channels, format=format)
        for p, img in zip(paths[1:], images[1:]):
            if img.shape != images[0].shape:
                raise ValueError(
                    f"{cls._name}.from_files(): '{os.fspath(p)}' is {img.shape} (H, W, C) but "
                    f"'{os.fspath(paths[0])}' is {images[0].shape}; layers must match"
                )
        return cls(images, format=fmt, mipmaps=mipmaps, requires_grad=requires_grad, device=device)

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
    def format(self) -> Format:
        """How the texels are stored (:class:`Format`)."""
        return self._format

    @property
    def nbytes(self) -> int:
        """Bytes the texels of every level take on the device, with an 8-bit format's decode table
        (gradients not counted: float32, 16 bytes a texel, where ``requires_grad``)."""
        if self._format is Format.FLOAT32:
            return self._chain.capacity
        return self._store.capacity + (self._decode.capacity if self._decode is not None else 0)

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
        aliasing the start of the chain. ``FLOAT32`` textures only (others: :meth:`numpy`, :meth:`assign`)."""
        return self.level(0)

    def level(self, level: int) -> wp.array:
        """Mip ``level`` as a ``wp.array`` of ``vec4`` shaped ``(L, h, w)``: a view into the chain.

        Writing to a coarse level directly (rather than through :meth:`update`) is allowed, e.g.
        for hand-made mips; its gradient (``.grad``) is the view of that level's gradient.
        ``FLOAT32`` textures only: other formats pack their texels (:meth:`numpy` decodes them).
        """
        self._check_level("level", level)
        if self._format is not Format.FLOAT32:
            raise TypeError(
                f"{self._name}.level(): a {self._format.value} texture stores packed texels, not float32 vec4s; "
                "read them with numpy(), set level 0 with assign(), or make the texture with format='float32'"
            )
        return self._level_array(self._chain, level)

    # -- operations -------------------------------------------------------------------------------

    def update(self) -> None:
        """Rebuild levels 1.. from level 0 with the box filter.

        Call it after changing :attr:`texels`. Inside a ``wp.Tape`` the launches are recorded, so
        gradients reaching coarse levels flow back to level 0 in the backward pass. Textures of
        other formats than ``FLOAT32`` rebuild on the host (decoded, filtered in linear space,
        encoded); inside a tape their gradients are carried down the same way (the encoding taken as exact).
        """
        if self._format is not Format.FLOAT32:
            if self.num_levels > 1:
                levels = formats.mip_chain(self._stored_level(0), self._format, self._channels, self._sizes)
                self._store[self._offsets[1] :].assign(formats.packed(levels[1:], self._format))
                formats.carry_mip_gradients(self._view, self._chain, self._sizes, self.num_layers)
            return
        formats.build_mips(self._view, self._chain, self._sizes, self.num_layers)

    def numpy(self, level: int = 0) -> np.ndarray:
        """Texels of ``level`` as float32 ``[L, h, w, C]`` (decoded: as sampling reads them)."""
        self._check_level("numpy", level)
        if self._format is not Format.FLOAT32:
            return formats.decode(self._stored_level(level), self._format, self._channels)
        return self._level_numpy(self._chain, level)

    def assign(self, values) -> None:
        """Set level 0 to ``values`` and rebuild the coarser levels (:meth:`update`).

        ``values`` is what the constructor takes for this texture, of its size and channel count:
        ``[L, H, W, C]`` (``[H, W, C]`` for a :class:`Texture`) floats, linear, stored in this
        texture's format (an 8-bit one clips to ``[0, 1]`` and rounds), or a texture (its level 0).
        This is how a fit keeps a float32 master copy and stores it compactly: step the master with
        :meth:`grad`, then ``assign`` it.
        """
        data = self._layers_to_array(values, self._format)
        want = (self.num_layers, self.height, self.width, self._channels)
        if data.shape != want:
            raise ValueError(f"{self._name}.assign(): values must be shaped {want[1:] if isinstance(self, Texture) else want}, got {data.shape[1:] if isinstance(self, Texture) else data.shape}")
        count = self.num_layers * self.height * self.width
        if self._format is Format.FLOAT32:
            self._chain[:count].assign(formats.encode(data.reshape(-1, self._channels), Format.FLOAT32).reshape(-1, 4))
        else:
            self._store[:count].assign(formats.packed([formats.stored(data, self._format, self._channels)], self._format))
        self.update()

    def _stored_level(self, level: int) -> np.ndarray:
        """Level ``level`` as the store holds it, ``[L, h, w, 4]`` (uint8 codes or float16)."""
        h, w = self._sizes[level]
        start = self._offsets[level]
        return formats.unpacked(self._store[start : start + self.num_layers * h * w].numpy(), self._format).reshape(self.num_layers, h, w, 4)

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
            f"channels={self.channels}, format={self._format.value}, levels={self.num_levels}, device={self.device})"
        )


class Texture(TextureArray):
    """One image (1–4 channels, linear, stored in a :class:`Format`) with an optional mip chain.

    A :class:`TextureArray` with a single layer; the array accessors drop the layer axis, so
    :meth:`numpy` and :meth:`grad` return ``[h, w, C]`` and :attr:`texels` has shape ``(H, W)``.

    Args:
        image: ``[H, W, C]`` or ``[H, W]`` array, ``1 <= C <= 4``. Float values are used as given
            (finite, linear); ``uint8`` and ``uint16`` values are scaled to ``[0, 1]`` (divided by
            255 and 65535, as :func:`warptex.io.read_image` decodes 8- and 16-bit data, without
            its sRGB decoding), or, for an 8-bit ``format``, the codes it stores; other integer
            dtypes raise ``TypeError``. A :class:`Texture` is copied (level 0).
        format: how the texels are stored (:class:`Format`): ``float32`` (default), ``float16``,
            ``unorm8`` or ``srgb8``.
        mipmaps: ``True`` for the full chain, ``False`` for level 0 only, or the maximum number of levels.
        requires_grad: allocate gradient buffers for the texels.
        device: Warp device (``None``: Warp's default device).
    """

    _name = "Texture"

    def __init__(self, image, *, format: Format | str = Format.FLOAT32, mipmaps: bool | int = True, requires_grad: bool = False, device=None):
        super().__init__(image, format=format, mipmaps=mipmaps, requires_grad=requires_grad, device=device)

    @classmethod
    def _layers_to_array(cls, image, fmt: Format = Format.FLOAT32) -> np.ndarray:
        return image.numpy(0)[None] if isinstance(image, Texture) else image_array(cls._name, "image", image, fmt)[None]

    @classmethod
    def from_file(cls, path: str | os.PathLike, *, data: bool = False, channels=None, layer: str | None = None, format: Format | str | None = None, mipmaps: bool | int = True, requires_grad: bool = False, device=None) -> "Texture":
        """Load an image file (PNG/JPG decoded from sRGB unless ``data=True``; EXR as stored).

        ``channels`` selects EXR channels by name, or forces a channel count for PNG/JPG; ``layer``
        picks a layer of a multi-layer EXR; see :func:`warptex.io.read_image`. An image that is no
        texture (NaN or infinite texels, too many channels) is refused naming the file.

        ``format=None`` keeps the file's precision (:func:`warptex.io.read_texels`): an 8-bit
        PNG/JPG is stored ``SRGB8`` (``UNORM8`` with ``data=True``), a half EXR ``FLOAT16``, the
        rest ``FLOAT32``. The texels sample as :func:`warptex.io.read_image`'s values of the file
        do, in a quarter (8-bit) or half the memory; their mips differ by the rounding of the
        stored format. Another ``format`` converts.
        """
        (image,), fmt = file_images(cls._name, "from_file", [path], data=data, channels=channels, layer=layer, format=format)
        return cls(image, format=fmt, mipmaps=mipmaps, requires_grad=requires_grad, device=device)

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
