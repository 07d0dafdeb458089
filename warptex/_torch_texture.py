"""The textures the PyTorch bridge (:mod:`warptex._torch_op`) makes around texture tensors.

A call's texture tensor is read through a :class:`~warptex.TextureArray` whose chain is the tensor
itself (level 0 alone, RGBA float32, contiguous) or a buffer level 0 is copied into, its mips built
on the call's tape. The texture made around a tensor is kept for the tensor's next calls
(:func:`texture_around`), and its gradient buffer handed to torch as the gradient where it has the
tensor's shape (:class:`Handed`). :func:`view` and :func:`zeros` are the bridge's tensor buffers
as Warp reads them, for these textures and the op's other tensors alike.
"""

from __future__ import annotations

import dataclasses
import threading
import weakref

import numpy as np
import torch
import warp as wp

from warptex.texture import Texture, TextureArray, mip_sizes


def zeros(shape: tuple, device: torch.device) -> torch.Tensor:
    """float32 zeros on ``device``; on the CPU from NumPy (see :func:`texture_around`)."""
    if device.type == "cpu":
        return torch.from_numpy(np.zeros(shape, np.float32))
    return torch.zeros(shape, dtype=torch.float32, device=device)


def texture_around(t: torch.Tensor, *, mipmaps: bool, index, grads: dict, leases: list) -> TextureArray:
    """A :class:`Texture` (``t`` ``[H, W, C]``) or :class:`TextureArray` (``[L, H, W, C]``) whose
    chain is a torch buffer holding ``t`` at level 0, its mips built here (on the active tape), or
    ``t`` itself where that is the whole chain (no mips, 4 float32 channels, contiguous);
    with ``index``, zeroed gradient buffers whose level 0 ``grads[index]`` returns shaped like ``t``.

    The texture is one kept for ``t`` (:func:`_kept_texture`), taken until the call is done with it
    (``leases``).

    On the CPU the buffers are filled and read through NumPy, not torch: torch runs CPU tensor ops
    on its OpenMP threads, which keep spinning a while after each op, and the Warp launch that
    followed a torch copy of a 256² texture ran 20% slower on 2 cores (measured:
    ``benchmarks/bench_torch.py``)."""
    kept = _kept_texture(t, mipmaps, gradient=index is not None)
    leases.append(kept)
    layers = t.unsqueeze(0) if t.dim() == 3 else t
    count, channels = kept.count, layers.shape[-1]
    cpu = t.device.type == "cpu"
    if kept.chain is not None:  # level 0 copied in, the mips built from it
        if cpu:
            kept.chain.numpy()[:count, :channels] = layers.detach().numpy().reshape(count, channels)
        else:
            kept.chain[:count, :channels] = layers.detach().reshape(count, channels)
    grad = kept.grad
    if grad is not None:
        kept.array.grad.zero_()  # Warp's memset (on the call's stream): NumPy's fill of 1 MB took twice as long
        if kept.array.shape[0] == count and channels == 4:  # the buffer is the gradient, shaped as t: handed to torch as it is
            grads[index] = Handed(grad, t.shape)
        elif cpu:
            grads[index] = lambda: torch.from_numpy(grad.numpy()[:count, :channels].reshape(t.shape).copy())
        else:
            grads[index] = lambda: grad[:count, :channels].reshape(t.shape).clone()
    kept.texture.update()
    return kept.texture


@dataclasses.dataclass(eq=False)
class _Kept:
    """A texture the bridge made around a tensor (:func:`_kept_texture`): ``chain``, the buffer each
    call copies level 0 into, with room for the mips (``None`` where the tensor itself is the chain),
    ``array`` the Warp view of the chain that the texture holds, ``grad`` its gradient buffer (or
    ``None``), ``count`` the level-0 texels, and ``shelf`` the list of free ones it goes back to
    (by weak reference: the shelf holds it while it is free, and no cycle keeps either alive)."""

    texture: TextureArray
    chain: torch.Tensor | None
    array: wp.array
    grad: torch.Tensor | None
    count: int
    shelf: weakref.ref

    @property
    def nbytes(self) -> int:
        """The bytes of its own buffers (not the tensor's)."""
        return 4 * sum(b.numel() for b in (self.chain, self.grad) if b is not None)

    def free(self) -> bool:
        """Whether nothing but this holds the gradient buffer: torch may still hold it where a
        call handed it over as the gradient (:class:`Handed`), and then it is not reused."""
        return self.grad is None or _holders(self.grad) <= 1


def _holders(buffer: torch.Tensor) -> int:
    """How many tensors share ``buffer``'s storage, beside ``buffer``'s own view of it (a large
    count where torch cannot say)."""
    count = getattr(torch._C, "_storage_Use_Count", None)
    return 1 << 30 if count is None else count(buffer.untyped_storage()._cdata) - 1


# The textures the bridge made around a tensor, kept while it lives: a loop passes the same texture
# tensor every step, and a new texture each call (its Warp arrays, and the kernel arguments packed
# once per texture: warptex._pack.packed) was a fifth of a 1,024-UV call. A kept texture serves one
# call at a time: taken for it, and given back (:func:`give_back`) when the call's recorded pass
# is gone, or at the end of a call that records none. Its gradient buffer is its own, as the
# packed arguments hold its address (Warp's generated adjoints add into a struct's arrays' .grad).
_kept: "torch.utils.weak.WeakIdKeyDictionary" = torch.utils.weak.WeakIdKeyDictionary()
_kept_lock = threading.RLock()  # re-entrant: a call's finaliser (give_back) can run in a collection under it
#: Layouts kept per tensor (a tensor whose storage is swapped gets a new one), and free textures per layout.
MAX_KEPT_LAYOUTS, MAX_KEPT_FREE = 4, 2
#: The most bytes of buffers a kept texture may hold while no call uses it: past that, making one
#: anew (two allocations) is a small part of a call that copies that many texels and builds their mips.
MAX_KEPT_BYTES = 16 << 20


def _kept_texture(t: torch.Tensor, mipmaps: bool, gradient: bool) -> _Kept:
    """A free texture kept for ``t`` in its current layout (storage address, shape, strides, dtype;
    with a gradient buffer or not), taken off its shelf, or a new one. Its texels are addressed,
    not referenced: ``t`` keeps none of its kept textures alive (they go with it), and they are used
    only while its storage is the one the layout names."""
    layout = (t.data_ptr(), tuple(t.shape), t.stride(), t.dtype, t.device, mipmaps, gradient)
    with _kept_lock:
        layouts = _kept.get(t)
        if layouts is None:
            layouts = _kept[t] = {}
        shelf = layouts.get(layout)
        if shelf is None:
            if len(layouts) >= MAX_KEPT_LAYOUTS:
                del layouts[next(iter(layouts))]
            shelf = layouts[layout] = _Shelf()
        while shelf:
            kept = shelf.pop()
            if kept.free():
                return kept
    layers = t.unsqueeze(0) if t.dim() == 3 else t
    num_layers, height, width, channels = layers.shape
    sizes = mip_sizes(height, width, None if mipmaps else 1)
    texels = sum(num_layers * h * w for h, w in sizes)
    count = num_layers * height * width
    in_place = texels == count and channels == 4 and layers.dtype == torch.float32 and layers.is_contiguous()
    chain = None if in_place else zeros((texels, 4), t.device)  # in place: level 0 alone, as the chain stores it, read only
    grad = zeros((texels, 4), t.device) if gradient else None
    device = wp.device_from_torch(t.device)
    array = view(layers.reshape(texels, 4) if in_place else chain, device, wp.vec4)
    if grad is not None:
        array.grad = view(grad, device, wp.vec4)
    texture = (Texture if t.dim() == 3 else TextureArray).around(array, num_layers, sizes, channels)
    return _Kept(texture, chain, array, grad, count, weakref.ref(shelf))


class _Shelf(list):
    """The free textures kept for one layout of a tensor (a list that can be weakly referenced)."""


def view(buffer: torch.Tensor, device, dtype=wp.float32) -> wp.array:
    """A Warp array of ``dtype`` (a scalar, or a vector: the tensor's last axis) over the contiguous
    tensor ``buffer`` of its scalars, holding no reference to it (the caller keeps it alive: the
    op's saved tensors and state, a kept texture's buffers): ``wp.from_torch`` took twice as long.
    Every tensor the bridge hands to Warp goes through here."""
    shape = tuple(buffer.shape[:-1]) if getattr(dtype, "_length_", 1) > 1 else tuple(buffer.shape)
    if buffer.numel() == 0:
        return wp.empty(shape, dtype=dtype, device=device)
    return wp.array(ptr=buffer.data_ptr(), dtype=dtype, shape=shape, device=device)


def give_back(leases: list) -> None:
    """Put the textures of ``leases`` back on their shelves (those of at most :data:`MAX_KEPT_BYTES`)."""
    with _kept_lock:
        for kept in leases:
            shelf = kept.shelf()
            if shelf is not None and len(shelf) < MAX_KEPT_FREE and kept.nbytes <= MAX_KEPT_BYTES:
                shelf.append(kept)
    leases.clear()


class Handed:
    """A texture's gradient buffer handed to torch as the gradient itself, with no copy (a 1 MB
    copy was 5% of a 1,024-UV bridge call). Only the first backward pass hands it out: the
    recorded launches add into this buffer, so a second pass of the same tape (``retain_graph``)
    uses it again, returns a copy, and gives the buffer back as torch held it (``warptex._torch_op._backward_pass``)."""

    def __init__(self, buffer: torch.Tensor, shape):
        self.buffer, self.shape, self.handed = buffer, tuple(shape), False

    def __call__(self) -> torch.Tensor:
        if self.handed:
            return self.buffer.reshape(self.shape).clone()
        self.handed = True
        return self.buffer.reshape(self.shape)
