"""Histogram transforms for the hex technique's variance-preserving blend (Heitz & Neyret 2018).

:func:`prepare_histogram` Gaussianises a texture per channel and builds the inverse LUTs, one per
mip level, that ``warptex.stochastic(..., method="hex", histogram=...)`` maps its blend back with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
import warp as wp

from warptex.texture import Texture, TextureArray

#: Mean and standard deviation of the Gaussianised values (Heitz & Neyret: most of them in [0, 1]).
GAUSSIAN_MEAN = 0.5
GAUSSIAN_STD = 1.0 / 6.0
#: Gaussianised values the inverse LUT spans, mean ± 6 std (the extremes of a 4k² texture are ±5.3 std).
LUT_RANGE = (GAUSSIAN_MEAN - 6.0 * GAUSSIAN_STD, GAUSSIAN_MEAN + 6.0 * GAUSSIAN_STD)


@dataclass(frozen=True)
class Histogram:
    """A texture's Gaussianised copy and the inverse transform, built by :func:`prepare_histogram`.

    Attributes:
        texture: the Gaussianised texture (same class, size, layers, channels and mip levels as the
            source): every channel has mean :data:`GAUSSIAN_MEAN` and std :data:`GAUSSIAN_STD`.
            ``stochastic(..., histogram=h)`` samples it, so texel gradients land here.
        lut: inverse LUTs, ``wp.array`` of float32 flattened from ``[L, levels, C, lut_size]``: entry
            ``i`` of channel ``c`` at mip level ``k`` is the (decorrelated) value for the Gaussianised
            value ``lo + (i + 0.5) / lut_size * (hi - lo)``, ``(lo, hi) =`` :data:`LUT_RANGE`, read at
            level ``k`` (prefiltered, see :func:`prepare_histogram`).
        lut_size: entries per channel and level.
        levels: mip levels with a LUT (those of ``texture``).
        basis, centre: per layer, ``wp.array`` of ``mat33`` / ``vec3`` undoing the decorrelation
            (``rgb = basis @ y + centre``); ``None`` unless ``decorrelate``.
        decorrelate: whether the first three channels were rotated onto their principal axes.
    """

    texture: TextureArray
    lut: wp.array
    lut_size: int
    levels: int
    basis: wp.array | None
    centre: wp.array | None
    decorrelate: bool

    def lut_numpy(self) -> np.ndarray:
        """The inverse LUTs as float32 ``[L, levels, C, lut_size]``."""
        t = self.texture
        return self.lut.numpy().reshape(t.num_layers, self.levels, t.channels, self.lut_size)


def _gaussianise(values: np.ndarray, lut_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Histogram transform of one channel (float64 ``[N]``): Gaussian values and the inverse LUT.

    Equal values share their mid-rank ``u`` (so a flat region stays flat), mapped to
    ``μ + σ Φ⁻¹(u)``. The LUT maps its grid ``g_i`` over :data:`LUT_RANGE` back by interpolating the sorted
    distinct values at ``Φ((g_i - μ) / σ)`` between their mid-ranks (ends clamped).
    """
    distinct, inverse, counts = np.unique(values, return_inverse=True, return_counts=True)
    mid_rank = (np.cumsum(counts) - 0.5 * counts) / values.size
    normal = NormalDist(GAUSSIAN_MEAN, GAUSSIAN_STD)
    gauss = np.frompyfunc(normal.inv_cdf, 1, 1)(mid_rank).astype(np.float64)
    g = LUT_RANGE[0] + (np.arange(lut_size) + 0.5) / lut_size * (LUT_RANGE[1] - LUT_RANGE[0])
    u = np.frompyfunc(normal.cdf, 1, 1)(g).astype(np.float64)
    return gauss[inverse], np.interp(u, mid_rank, distinct)


def _prefiltered(lut: np.ndarray, lost_variance: float) -> np.ndarray:
    """``E[lut(g + ε)]`` with ``ε ~ N(0, lost_variance)`` on the LUT grid (values beyond it clamped)."""
    step = (LUT_RANGE[1] - LUT_RANGE[0]) / lut.size
    sd = math.sqrt(max(lost_variance, 0.0)) / step
    if sd < 0.25:
        return lut.copy()
    radius = int(math.ceil(4.0 * sd))
    kernel = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sd) ** 2)
    return np.convolve(np.pad(lut, radius, mode="edge"), kernel / kernel.sum(), mode="valid")


def prepare_histogram(texture: TextureArray, *, lut_size: int = 4096, decorrelate: bool = False, requires_grad: bool = False) -> Histogram:
    """Gaussianise a texture per channel for ``stochastic(..., method="hex", histogram=...)``.

    Heitz & Neyret (2018): each channel's values are replaced by Gaussian values of the same rank
    (mean 0.5, std 1/6), so that the variance-preserving blend of independent taps stays Gaussian;
    the inverse LUT maps the blend back to the texture's own histogram. Built once, in NumPy, from
    level 0 of every layer; the Gaussianised copy gets its own box-filtered mip chain.

    Prefiltering (Heitz & Neyret §1.5): filtering the Gaussianised texture at mip level ``k`` leaves
    values of a smaller variance ``σ_k²``, and the level-0 LUT would map them towards the median, so a
    distant surface would drift darker or lighter than the texture's mean. Each level gets its own
    LUT, ``lut_k(g) = E[lut_0(g + ε)]`` with ``ε ~ N(0, σ_0² - σ_k²)`` (the variance filtered away),
    so the mean is kept at every distance and the coarsest level reads the texture's mean.

    Args:
        texture: a :class:`Texture` or :class:`TextureArray` (1-4 channels).
        lut_size: inverse-LUT entries per channel, at least 16.
        decorrelate: rotate the first three channels onto their principal axes (PCA of the colours)
            before the per-channel transform, so that colour correlations survive; needs 3 or 4
            channels. Alpha (a fourth channel) is transformed on its own.
        requires_grad: give the Gaussianised texture gradient buffers.

    Returns:
        A :class:`Histogram`. The transform itself is not differentiable.
    """
    func = "prepare_histogram"
    if not isinstance(texture, TextureArray):
        raise TypeError(f"{func}(): texture must be a Texture or TextureArray, got {type(texture).__name__}")
    if isinstance(lut_size, bool) or not isinstance(lut_size, (int, np.integer)) or not 16 <= lut_size <= 1 << 20:
        raise ValueError(f"{func}(): lut_size must be an int in [16, 1048576], got {lut_size!r}")
    if not isinstance(decorrelate, (bool, np.bool_)):
        raise TypeError(f"{func}(): decorrelate must be a bool, got {type(decorrelate).__name__}")
    channels = texture.channels
    if decorrelate and channels < 3:
        raise ValueError(f"{func}(): decorrelate=True needs 3 or 4 channels, the texture has {channels}")

    data = TextureArray.numpy(texture, 0).astype(np.float64)  # [L, H, W, C] for both classes
    gauss = np.empty_like(data)
    luts = np.empty((texture.num_layers, channels, lut_size))
    bases, centres = [], []
    for layer, image in enumerate(data):
        flat = image.reshape(-1, channels).copy()
        if decorrelate:
            centre = flat[:, :3].mean(axis=0)
            basis = np.eye(3)  # one texel has no covariance: nothing to decorrelate
            if len(flat) > 1:
                _, basis = np.linalg.eigh(np.cov(flat[:, :3] - centre, rowvar=False))
            flat[:, :3] = (flat[:, :3] - centre) @ basis
            bases.append(basis)
            centres.append(centre)
        for c in range(channels):
            values, luts[layer, c] = _gaussianise(flat[:, c], lut_size)
            gauss[layer, ..., c] = values.reshape(image.shape[:2])

    device = texture.device
    kwargs = {"mipmaps": texture.num_levels, "requires_grad": requires_grad, "device": device}
    gauss_texture = Texture(gauss[0], **kwargs) if isinstance(texture, Texture) else TextureArray(gauss, **kwargs)
    levels = texture.num_levels
    variance = [TextureArray.numpy(gauss_texture, k).astype(np.float64).var(axis=(1, 2)) for k in range(levels)]  # [L, C] each
    prefiltered = np.empty((texture.num_layers, levels, channels, lut_size))
    for layer in range(texture.num_layers):
        for k in range(levels):
            for c in range(channels):
                lost = variance[0][layer, c] - variance[k][layer, c]
                prefiltered[layer, k, c] = _prefiltered(luts[layer, c], lost)
    lut = wp.array(prefiltered.astype(np.float32).reshape(-1), dtype=float, device=device)
    basis = centre = None
    if decorrelate:
        basis = wp.array(np.asarray(bases, np.float32), dtype=wp.mat33, device=device)
        centre = wp.array(np.asarray(centres, np.float32), dtype=wp.vec3, device=device)
    return Histogram(gauss_texture, lut, int(lut_size), levels, basis, centre, bool(decorrelate))
