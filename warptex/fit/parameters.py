"""The optimisable parameters of a splat blend, and the splat maps, tiling and sharpness they make.

- Splat weights are per-texel **logits** ``z`` with a softmax over the ``L`` layers, written into
  the data of a splat-map :class:`~warptex.texture.TextureArray` (so every weight is positive and
  the weights of a texel sum to 1, whatever Adam does to the logits);
- the tiling is **log-scale**, ``tiling = exp(log_tiling)`` (positive, and a step means the same
  relative change at any scale);
- the triplanar sharpness is a **softplus**, ``sharpness = log(1 + exp(x))`` (positive, optional).

:meth:`SplatParameters.apply` launches those three maps (kernels in :mod:`warptex.kernels.fit`);
recorded on a ``wp.Tape``, the gradients that :func:`warptex.splat` gives the splat-map texels,
the tiling and the sharpness flow back to ``logits``, ``log_tiling`` and ``sharpness_raw``.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warptex._validate import as_float
from warptex.kernels import fit as kf
from warptex._validate import check_layer_count
from warptex.texture import TextureArray

__all__ = ["SplatParameters"]


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
