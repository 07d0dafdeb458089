"""Losses and image operations of fitting: the image loss, the Gaussian blur, the weight entropy
prior and PSNR.

:func:`image_loss` is the L2 or L1 distance of a render to a target in linear space, weighted
per pixel (the coverage mask), accumulated in float64; :func:`blur` is the separable Gaussian
used for coarse-to-fine fitting (applied to the render *and* the target). All are Warp kernels
(:mod:`warptex.kernels.fit`) recorded on an active ``wp.Tape``.
"""

from __future__ import annotations

import enum
import math

import numpy as np
import warp as wp

from typing import TYPE_CHECKING

from warptex._validate import as_enum, as_float
from warptex.kernels import fit as kf

if TYPE_CHECKING:
    from warptex.fit.parameters import SplatParameters

__all__ = ["Loss", "blur", "gaussian_taps", "image_loss", "psnr", "weight_entropy"]


class Loss(str, enum.Enum):
    """The per-channel penalty of :func:`image_loss`.

    - ``L2``: squared difference; with the default normalisation the loss is the mean squared
      error, so :func:`psnr` of it is the PSNR.
    - ``L1``: absolute difference (``sqrt(d² + 1e-12)``, smooth at 0); robust to outliers such as
      shadows or objects the layers cannot explain.
    """

    L2 = "l2"
    L1 = "l1"


_LOSS_IDS = {Loss.L2: kf.LOSS_L2, Loss.L1: kf.LOSS_L1}


def _image(func: str, name: str, value, device, *, ndim: int = 3) -> wp.array:
    """``value`` as a contiguous float32 ``wp.array`` of ``ndim`` dimensions on ``device``."""
    if isinstance(value, wp.array):
        if value.dtype != wp.float32 or value.ndim != ndim or not value.is_contiguous:
            raise ValueError(f"{func}(): {name} must be a contiguous float32 wp.array with {ndim} dimensions, got {wp.types.type_repr(value.dtype)} {value.shape}")
        if value.device != device:
            raise ValueError(f"{func}(): {name} is on {value.device}, expected {device}")
        return value
    arr = np.asarray(value)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{func}(): {name} must hold real numbers, got dtype {arr.dtype}")
    if arr.ndim != ndim:
        raise ValueError(f"{func}(): {name} must have {ndim} dimensions, got shape {arr.shape}")
    return wp.array(np.ascontiguousarray(arr, np.float32), dtype=float, device=device)


def gaussian_taps(sigma: float) -> np.ndarray:
    """Normalised Gaussian taps of standard deviation ``sigma`` pixels, radius ``ceil(3·sigma)``
    (float32, odd length; ``[1.0]`` for ``sigma == 0``)."""
    sigma = as_float("gaussian_taps", "sigma", sigma)
    if sigma < 0:
        raise ValueError(f"gaussian_taps(): sigma must be >= 0, got {sigma}")
    if sigma == 0:
        return np.ones(1, np.float32)
    x = np.arange(-math.ceil(3 * sigma), math.ceil(3 * sigma) + 1, dtype=np.float64)
    taps = np.exp(-0.5 * (x / sigma) ** 2)
    return (taps / taps.sum()).astype(np.float32)


def blur(image, sigma: float, *, channels: int | None = None, device=None) -> wp.array:
    """Separable Gaussian blur with zero padding (a masked image stays comparable to another masked
    image blurred the same way).

    Args:
        image: ``[H, W, C]`` float32 (``wp.array``, receives gradients on a ``wp.Tape``, or NumPy).
        sigma: standard deviation in pixels, ``>= 0``; 0 returns ``image`` itself (as a ``wp.array``).
        channels: blur only the first ``channels`` channels (default all).
        device: Warp device (default: the image's, or Warp's default for NumPy input).

    Returns:
        ``wp.array`` float32 ``[H, W, channels]``.
    """
    func = "blur"
    device = image.device if isinstance(image, wp.array) and device is None else wp.get_device(device)
    src = _image(func, "image", image, device)
    h, w, c = src.shape
    channels = c if channels is None else channels
    if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) or not 1 <= channels <= c:
        raise ValueError(f"{func}(): channels must be an int in [1, {c}], got {channels!r}")
    taps = gaussian_taps(sigma)
    if len(taps) == 1 and channels == c:
        return src
    taps_wp = wp.array(taps, dtype=float, device=device)
    rows = wp.zeros((h, w, channels), dtype=float, device=device, requires_grad=src.requires_grad)
    out = wp.zeros((h, w, channels), dtype=float, device=device, requires_grad=src.requires_grad)
    wp.launch(kf.blur_kernel, dim=(h, w, channels), inputs=[src, taps_wp, 0, 1], outputs=[rows], device=device)
    wp.launch(kf.blur_kernel, dim=(h, w, channels), inputs=[rows, taps_wp, 1, 0], outputs=[out], device=device)
    return out


def image_loss(render, target, *, weight=None, loss: Loss | str = Loss.L2, scale: float | None = None, out: wp.array | None = None, device=None) -> wp.array:
    """The distance of ``render`` to ``target`` in linear space: ``scale · Σ weight · Σ_c ρ(render - target)``.

    Args:
        render: ``[H, W, C_r]`` float32 ``wp.array`` (receives gradients) or NumPy.
        target: ``[H, W, C]`` with ``C <= C_r``: the channels compared (a render's extra height
            channel is ignored).
        weight: ``[H, W]`` per-pixel weights, e.g. the G-buffer's coverage mask (default 1).
        loss: :class:`Loss`: ``"l2"`` or ``"l1"``.
        scale: the normalisation; default ``1 / (C · Σ weight)``, so L2 gives the weighted mean
            squared error.
        out: a float64 ``wp.array`` of shape ``(1,)`` to add into (several views, one loss);
            default a new zeroed one with ``requires_grad`` when the render has it.
        device: Warp device (default: the render's).

    Returns:
        ``out``: float64 ``(1,)``. Seed ``out.grad`` with 1 (``tape.backward(loss=out)``).
    """
    func = "image_loss"
    device = render.device if isinstance(render, wp.array) and device is None else wp.get_device(device)
    kind = as_enum(func, "loss", loss, Loss)
    render = _image(func, "render", render, device)
    target = _image(func, "target", target, device)
    h, w, c = target.shape
    if render.shape[:2] != (h, w) or render.shape[2] < c:
        raise ValueError(f"{func}(): render {render.shape} must be (H, W, C_r) with the target's H, W = {h}, {w} and C_r >= {c}")
    if weight is None:
        weight = wp.full((h, w), 1.0, dtype=float, device=device)
    weight = _image(func, "weight", weight, device, ndim=2)
    if weight.shape != (h, w):
        raise ValueError(f"{func}(): weight must have shape {(h, w)}, got {weight.shape}")
    if scale is None:
        total = float(weight.numpy().astype(np.float64).sum())
        if total <= 0:
            raise ValueError(f"{func}(): the weights sum to {total}: no pixel to compare")
        scale = 1.0 / (c * total)
    scale = as_float(func, "scale", scale)
    if out is None:
        out = wp.zeros(1, dtype=wp.float64, device=device, requires_grad=render.requires_grad)
    elif not isinstance(out, wp.array) or out.dtype != wp.float64 or out.shape != (1,):
        raise ValueError(f"{func}(): out must be a float64 wp.array of shape (1,)")
    wp.launch(kf.image_loss_kernel, dim=(h, w), inputs=[render, target, weight, _LOSS_IDS[kind], scale], outputs=[out], device=device)
    return out


def weight_entropy(params: "SplatParameters", strength: float, *, out: wp.array | None = None) -> wp.array:
    """``strength ·`` the mean entropy ``-Σ_l w_l log w_l`` of the splat weights over the texels,
    added into ``out`` (float64 ``(1,)``; default a new one). Recorded on the tape, its gradient
    reaches the logits through the softmax.

    A prior, not a measurement: the images fix the weights only up to what the height blend hides
    (a layer whose ``height·w + t`` stays below the top layer's is invisible, and so gets no
    gradient); this term picks, among weights that render alike, the least mixed ones. It also
    biases genuinely mixed texels towards their dominant layer, by about ``strength /
    (data curvature)``, so keep it small.
    """
    strength = as_float("weight_entropy", "strength", strength)
    if strength < 0:
        raise ValueError(f"weight_entropy(): strength must be >= 0, got {strength}")
    maps = params.maps
    if out is None:
        out = wp.zeros(1, dtype=wp.float64, device=params.device, requires_grad=True)
    h, w = params.size
    wp.launch(kf.entropy_kernel, dim=(maps.num_layers, h, w), inputs=[maps.texels, params.num_layers, maps.channels, strength / (h * w)], outputs=[out], device=params.device)
    return out


def psnr(mse: float, peak: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB of a mean squared error (``inf`` for 0)."""
    return float("inf") if mse <= 0 else float(10.0 * math.log10(peak * peak / mse))
