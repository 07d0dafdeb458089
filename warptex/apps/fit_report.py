"""Pictures and files of a splat fit: weights as colours, the loss/PSNR curve, the JSON summary.

Weights and errors are NumPy images; the curve is a :func:`warptex.plot.line_chart`.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
from warptex import io
from warptex.plot import line_chart

#: Display colours (linear RGB) of layers 0, 1, 2...: green, orange, brown, white, blue, magenta, cyan, yellow.
PALETTE = np.array(
    [(0.05, 0.45, 0.03), (0.9, 0.4, 0.03), (0.3, 0.12, 0.05), (0.95, 0.95, 0.95), (0.05, 0.15, 0.8), (0.7, 0.05, 0.6), (0.05, 0.6, 0.7), (0.85, 0.8, 0.05)],
    np.float32,
)
PALETTE_NAMES = ("green", "orange", "brown", "white", "blue", "magenta", "cyan", "yellow")


def weights_image(weights: np.ndarray, *, scale: int = 3) -> np.ndarray:
    """Splat weights ``[H, W, L]`` as a linear-RGB picture ``[H·scale, W·scale, 3]``: each layer's
    :data:`PALETTE` colour (cycled past 8 layers) mixed by its weight, texels enlarged ``scale``×."""
    weights = np.asarray(weights, np.float32)
    colours = PALETTE[np.arange(weights.shape[-1]) % len(PALETTE)]
    image = weights @ colours
    return np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)


def legend(layer_names) -> str:
    """``"grass=green gravel=orange ..."`` for the labels of :func:`weights_image` panels."""
    return " ".join(f"{n}={PALETTE_NAMES[k % len(PALETTE_NAMES)]}" for k, n in enumerate(layer_names))


def heat_image(values: np.ndarray, *, vmax: float, scale: int = 3) -> np.ndarray:
    """A ``[H, W]`` map as grey levels (0 black, ``vmax`` and above white), enlarged ``scale``×."""
    grey = np.clip(np.asarray(values, np.float32) / vmax, 0.0, 1.0)
    grey = io.srgb_to_linear(grey)  # even steps on screen
    return np.repeat(np.repeat(np.repeat(grey[..., None], 3, axis=-1), scale, axis=0), scale, axis=1)


def write_curve(path, history: dict, *, stages=()) -> None:
    """Write the fit's curves to ``path`` (PNG, atomically): PSNR (dB) per iteration and the stage's
    objective (``history["loss"]``, log scale); ``stages`` ``[(first iteration, name)]`` are marked
    by dashed lines."""
    its = list(range(len(history["loss"])))
    psnr = [v if math.isfinite(v) else None for v in history["psnr"]]
    loss = [v if v > 0 and math.isfinite(v) else None for v in history["loss"]]
    line_chart(
        path,
        [
            {"series": {"PSNR": (its, psnr)}, "xlabel": "iteration", "ylabel": "dB", "title": "PSNR of the sharp render vs the target", "marks": stages},
            {"series": {"objective": (its, loss)}, "xlabel": "iteration", "ylabel": "objective", "title": "the stage's objective (blurred, + prior)", "logy": True, "marks": stages},
        ],
    )


def write_json(path, data: dict) -> None:
    """Write ``data`` as indented JSON, atomically (temporary file, then rename)."""
    text = json.dumps(data, indent=2, allow_nan=True) + "\n"
    with io._atomic_output(os.fspath(path)) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)


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
