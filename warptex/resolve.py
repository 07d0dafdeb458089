"""Resolving supersampled renders: the stratified samples of each pixel (a supersampled G-buffer's
``s × s`` blocks, :func:`warptex.rasterize` with ``samples=``) averaged into one pixel, on the tape.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warptex._validate import as_float_array
from warptex._warp import active_tape
from warptex.kernels import raster as kr

__all__ = ["resolve"]


def resolve(image, samples, *, device=None) -> wp.array:
    """Average each pixel's ``s × s`` block of samples: a box filter over the pixel, what a
    renderer's multisample resolve does. Differentiable: inside a ``wp.Tape``, the gradient of the
    result reaches ``image`` (each sample gets ``1 / s²`` of its pixel's).

    Resolve the coverage mask (``g.mask``) for an anti-aliased alpha, and premultiplied colour
    (``colour * mask``) for colour that composites over any background.

    Args:
        image: ``(H·s, W·s)``, ``(H·s, W·s, C)`` or a batch ``(V, H·s, W·s, C)`` of float32: a
            ``wp.array`` (a technique's output over a supersampled G-buffer) or anything NumPy
            takes (copied to ``device``).
        samples: samples per pixel, ``s²`` (1, 4, 9, ...), or the supersampled :class:`GBuffer`
            the image was rendered over (its ``samples``).
        device: Warp device of the launch (default: the image's, or Warp's default for NumPy).

    Returns:
        ``wp.array`` of float32 ``(H, W)``, ``(H, W, C)`` or ``(V, H, W, C)``, as ``image`` is shaped.

    Raises:
        ValueError: ``samples`` not a square number, or a size that is not a multiple of ``s``.
        TypeError: ``image`` not a float32 ``wp.array`` or an array of numbers.
    """
    func = "resolve"
    count = getattr(samples, "samples", samples)
    s = math.isqrt(count) if isinstance(count, (int, np.integer)) and not isinstance(count, bool) and count > 0 else 0
    if s == 0 or s * s != count:
        raise ValueError(f"{func}(): samples must be a square number of samples per pixel (1, 4, 9, ...) or a supersampled GBuffer, got {samples!r}")
    if isinstance(image, wp.array):
        if image.dtype != wp.float32:
            raise TypeError(f"{func}(): image must be a wp.array of float32, got {wp.types.type_repr(image.dtype)}")
        device = image.device if device is None else wp.get_device(device)
        if image.device != device:
            raise ValueError(f"{func}(): image is on {image.device} but device is {device}")
        if not image.is_contiguous:
            raise ValueError(f"{func}(): image must be a contiguous wp.array")
    else:
        device = wp.get_device(device)
        image = wp.array(np.ascontiguousarray(as_float_array(func, "image", image), np.float32), dtype=float, device=device)
    shape = tuple(image.shape)
    if len(shape) not in (2, 3, 4) or 0 in shape:
        raise ValueError(f"{func}(): image must be (H*s, W*s), (H*s, W*s, C) or (V, H*s, W*s, C), got {shape}")
    height, width = shape[:2] if len(shape) == 2 else shape[-3:-1]
    if height % s or width % s:
        raise ValueError(f"{func}(): image must be {s}-times a pixel size for {s * s} samples per pixel, got {height}x{width}")
    channels = 1 if len(shape) == 2 else shape[-1]
    rows = math.prod(shape) // (width * channels)  # the rows of every view, one after the other
    flat = image.reshape((rows, width, channels))
    out = wp.zeros((rows // s, width // s, channels), dtype=float, device=device, requires_grad=image.requires_grad)
    wp.launch(kr.resolve_kernel, dim=out.shape, inputs=[flat, s], outputs=[out], device=device, record_tape=False)
    tape = active_tape()
    if tape is not None and image.requires_grad:

        def backward():
            wp.launch(kr.resolve_adjoint_kernel, dim=flat.shape, inputs=[out.grad, s], outputs=[flat.grad], device=device, record_tape=False)

        tape.record_func(backward, arrays=[flat, out])
    result = (height // s, width // s) if len(shape) == 2 else (*shape[:-3], height // s, width // s, channels)
    return out.reshape(result)
