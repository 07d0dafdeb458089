"""Fitting texturing parameters to images: parameterisations, the image loss, blur and metrics.

The optimisable parameters of a splat blend live in :class:`SplatParameters`:

- splat weights as per-texel **logits** ``z`` with a softmax over the ``L`` layers, written into
  the data of a splat-map :class:`~warptex.texture.TextureArray` (so every weight is positive and
  the weights of a texel sum to 1, whatever Adam does to the logits);
- tiling as **log-scale**, ``tiling = exp(log_tiling)`` (positive, and a step means the same
  relative change at any scale);
- triplanar sharpness as **softplus**, ``sharpness = log(1 + exp(x))`` (positive, optional).

:meth:`SplatParameters.apply` launches those three maps (kernels in :mod:`warptex.kernels.fit`);
recorded on a ``wp.Tape``, the gradients that :func:`warptex.splat` gives the splat-map texels,
the tiling and the sharpness flow back to ``logits``, ``log_tiling`` and ``sharpness_raw``.

:func:`image_loss` is the L2 or L1 distance of a render to a target in linear space, weighted
per pixel (the coverage mask), accumulated in float64; :func:`blur` is the separable Gaussian
used for coarse-to-fine fitting (applied to the render *and* the target). The optimisation loop is
:func:`warptex.fit_loop.fit_splat`.
"""

from __future__ import annotations

import enum
import math

import numpy as np
import warp as wp

from warptex._validate import as_enum, as_float
from warptex.kernels import fit as kf
from warptex.layers import check_layer_count
from warptex.texture import TextureArray

__all__ = ["Loss", "SplatParameters", "blur", "gaussian_taps", "image_loss", "psnr", "splat_coverage", "weight_entropy"]


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


def splat_coverage(uvs, size) -> np.ndarray:
    """How much each splat-map texel is seen: the sum, over pixels, of the bilinear weight the
    pixel's lookup gives the texel (the same clamped bilinear read :func:`warptex.splat` makes).

    A texel's coverage is the number of pixel-equivalents whose colour depends on it; 0 means no
    view constrains it at all (its gradient is exactly 0).

    Args:
        uvs: one ``[N, 2]`` (or ``[H, W, 2]``) array of splat-map UVs per view, covered pixels only.
        size: ``(H, W)`` of the splat map.

    Returns:
        float64 ``[H, W]``.
    """
    h, w = size
    cover = np.zeros(h * w, np.float64)
    for uv in uvs:
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        uv = uv[np.isfinite(uv).all(axis=1)]
        x = uv[:, 0] * w - 0.5
        y = (1.0 - uv[:, 1]) * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        for dy, wy in ((0, 1 - fy), (1, fy)):
            for dx, wx in ((0, 1 - fx), (1, fx)):
                i = np.clip(y0 + dy, 0, h - 1).astype(np.int64)
                j = np.clip(x0 + dx, 0, w - 1).astype(np.int64)
                np.add.at(cover, i * w + j, wy * wx)
    return cover.reshape(h, w)


class SplatParameters:
    """The optimisable parameters of a splat blend, and the splat maps they produce.

    Args:
        num_layers: ``L``, the number of layers the weights are for.
        size: ``(H, W)`` of the splat maps.
        channels: channels per splat map (1–4; 4 = RGBA).
        num_maps: ``M``; default ``ceil(L / channels)``. ``M`` maps of ``C`` channels hold weights
            for ``(M-1)·C < L <= M·C`` layers, else ``ValueError``.
        weights: initial weights ``[H, W, L]`` (non-negative, not all zero per texel; normalised
            here); default uniform ``1/L``. Logits are ``log(max(w, 1e-4))``.
        tiling: initial tiling, positive: a number (one for all layers) or ``L`` numbers.
        sharpness: initial triplanar sharpness (> 0) to optimise through softplus, or ``None`` to
            leave sharpness out of the parameters.
        device: Warp device.

    Attributes:
        logits: float32 ``wp.array`` of ``L·H·W`` (layer-major ``[L, H, W]``), ``requires_grad``.
        log_tiling: float32 ``(1,)`` or ``(L,)``, ``requires_grad``.
        sharpness_raw: float32 ``(1,)`` (softplus⁻¹ of the sharpness) or ``None``.
        maps: the splat maps, a :class:`TextureArray` ``[M, H, W, C]`` without mips, ``requires_grad``:
            pass it to :func:`warptex.splat`.
        tiling, sharpness: float32 arrays for :func:`warptex.splat` (``tiling=``, ``sharpness=``).
    """

    def __init__(self, num_layers: int, size, *, channels: int = 4, num_maps: int | None = None, weights=None, tiling=1.0, sharpness=None, device=None):
        func = "SplatParameters"
        for name, value, low in (("num_layers", num_layers, 1), ("channels", channels, 1)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f"{func}(): {name} must be a positive int, got {value!r}")
        if channels > 4:
            raise ValueError(f"{func}(): channels must be 1 to 4, got {channels}")
        try:
            h, w = (int(v) for v in size)
        except (TypeError, ValueError):
            raise ValueError(f"{func}(): size must be (height, width), got {size!r}") from None
        if h < 1 or w < 1:
            raise ValueError(f"{func}(): size must be positive, got {size!r}")
        num_maps = -(-num_layers // channels) if num_maps is None else num_maps
        if isinstance(num_maps, bool) or not isinstance(num_maps, (int, np.integer)) or num_maps < 1:
            raise ValueError(f"{func}(): num_maps must be a positive int, got {num_maps!r}")
        device = wp.get_device(device)
        self.maps = TextureArray(np.zeros((num_maps, h, w, channels), np.float32), mipmaps=False, requires_grad=True, device=device)
        check_layer_count(func, num_layers, self.maps)
        self.num_layers = int(num_layers)
        self.size = (h, w)
        self.device = device

        if weights is None:
            logits = np.zeros((num_layers, h, w), np.float32)
        else:
            weights = np.asarray(weights, np.float64)
            if weights.shape != (h, w, num_layers):
                raise ValueError(f"{func}(): weights must have shape {(h, w, num_layers)} (H, W, L), got {weights.shape}")
            if not np.isfinite(weights).all() or (weights < 0).any() or (weights.sum(axis=-1) <= 0).any():
                raise ValueError(f"{func}(): weights must be finite, >= 0, and not all 0 at any texel")
            weights = weights / weights.sum(axis=-1, keepdims=True)
            logits = np.log(np.maximum(weights, 1e-4)).transpose(2, 0, 1).astype(np.float32)
        self.logits = wp.array(logits.reshape(-1), dtype=float, device=device, requires_grad=True)
        self._top = wp.zeros(h * w, dtype=float, device=device)  # the softmax shift, no gradient
        self._total = wp.zeros(h * w, dtype=float, device=device, requires_grad=True)  # its denominator

        tiling = np.asarray(tiling, np.float64).reshape(-1)
        if tiling.shape not in ((1,), (num_layers,)) or not np.isfinite(tiling).all() or (tiling <= 0).any():
            raise ValueError(f"{func}(): tiling must be one or {num_layers} positive numbers (log-scale parameter), got {tiling.tolist()}")
        self.log_tiling = wp.array(np.log(tiling).astype(np.float32), dtype=float, device=device, requires_grad=True)
        self.tiling = wp.zeros(len(tiling), dtype=float, device=device, requires_grad=True)

        self.sharpness_raw = self.sharpness = None
        if sharpness is not None:
            s = as_float(func, "sharpness", sharpness)
            if s <= 0:
                raise ValueError(f"{func}(): sharpness must be > 0 (softplus parameter), got {s}")
            raw = s + math.log(-math.expm1(-s))  # softplus⁻¹, stable for large s
            self.sharpness_raw = wp.array([raw], dtype=float, device=device, requires_grad=True)
            self.sharpness = wp.zeros(1, dtype=float, device=device, requires_grad=True)
        self.apply()

    @property
    def arrays(self) -> list[wp.array]:
        """The raw parameters: ``logits``, ``log_tiling`` and (if optimised) ``sharpness_raw``."""
        return [a for a in (self.logits, self.log_tiling, self.sharpness_raw) if a is not None]

    def apply(self) -> None:
        """Write the splat maps (softmax), ``tiling`` (exp) and ``sharpness`` (softplus) from the raw
        parameters; recorded on the active ``wp.Tape``, so gradients flow back to them."""
        h, w = self.size
        d = self.device
        wp.launch(kf.logit_max_kernel, dim=h * w, inputs=[self.logits, self.num_layers], outputs=[self._top], device=d, record_tape=False)
        wp.launch(kf.softmax_total_kernel, dim=h * w, inputs=[self.logits, self._top, self.num_layers], outputs=[self._total], device=d)
        wp.launch(kf.softmax_kernel, dim=(self.maps.num_layers, h, w), inputs=[self.logits, self._top, self._total, self.num_layers, self.maps.channels], outputs=[self.maps.texels], device=d)
        wp.launch(kf.exp_kernel, dim=self.tiling.shape[0], inputs=[self.log_tiling], outputs=[self.tiling], device=d)
        if self.sharpness is not None:
            wp.launch(kf.softplus_kernel, dim=1, inputs=[self.sharpness_raw], outputs=[self.sharpness], device=d)

    def weights(self) -> np.ndarray:
        """The current weights ``[H, W, L]`` (softmax of the logits, computed in NumPy)."""
        z = self.logits.numpy().reshape(self.num_layers, *self.size).astype(np.float64)
        e = np.exp(z - z.max(axis=0))
        return (e / e.sum(axis=0)).transpose(1, 2, 0).astype(np.float32)

    def tiling_values(self) -> np.ndarray:
        """The current tiling, ``exp(log_tiling)`` (float64, 1 or ``L`` values)."""
        return np.exp(self.log_tiling.numpy().astype(np.float64))

    def zero_grad(self) -> None:
        for a in (*self.arrays, self.tiling, self.sharpness):
            if a is not None and a.grad is not None:
                a.grad.zero_()
        self.maps.zero_grad()
