"""Previews for pictures: Lambert lighting of any technique's output, normal maps from height, and
labelled side-by-side panels. Plain NumPy: these make images to look at, not gradients."""

from __future__ import annotations

import numpy as np
import warp as wp
from PIL import Image, ImageDraw

from warptex import io
from warptex.gbuffer import GBuffer

#: Linear RGB of the background where the G-buffer's mask is 0.
SKY = np.array([0.45, 0.62, 0.85], np.float32)


def _numpy(value) -> np.ndarray:
    return value.numpy() if isinstance(value, wp.array) else np.asarray(value, np.float32)


def to_rgb(colour) -> np.ndarray:
    """``[..., C]`` colour as ``[..., 3]`` RGB for display: gray (1-2 channels) is replicated, alpha dropped."""
    colour = _numpy(colour)
    return colour[..., :3] if colour.shape[-1] >= 3 else np.repeat(colour[..., :1], 3, axis=-1)


def lambert(gbuffer: GBuffer, albedo, *, normals=None, light_dir=(0.4, 0.8, 0.3), ambient: float = 0.2, background=SKY) -> np.ndarray:
    """Lambert shading ``albedo · (ambient + (1 - ambient) · max(0, n·l))``; ``background`` where
    the mask is 0.

    Args:
        gbuffer: supplies the mask and, unless ``normals`` is given, the shading normals.
        albedo: ``[H, W, C]`` linear colour (NumPy or ``wp.array``), e.g. a technique's output;
            1-2 channels are shown as gray.
        normals: ``[H, W, 3]`` world-space normals to light with instead, e.g. the output of
            :func:`warptex.triplanar.triplanar_normal`.
        light_dir: direction towards the light (normalised here).
        ambient: the fraction of light that reaches every surface, in ``[0, 1]``.
        background: linear RGB for uncovered pixels.

    Returns:
        ``[H, W, 3]`` float32 linear RGB.
    """
    if not 0.0 <= ambient <= 1.0:
        raise ValueError(f"lambert(): ambient must be in [0, 1], got {ambient!r}")
    light, rgb, n = _inputs("lambert", gbuffer, albedo, normals, light_dir)
    lit = rgb * (ambient + (1.0 - ambient) * np.clip(n @ light, 0.0, None)[..., None])
    return np.where(gbuffer.mask.numpy()[..., None] > 0, lit, background).astype(np.float32)


#: The preview's key light: the direction towards the sun (low, 32° up, from the left and behind
#: the default terrain view, so that slopes facing away from it fall into the sky's fill), and its
#: colour (warm, bright: sunlit ground reads near its albedo).
SUN_DIR = (-0.7, 0.5, -0.3)
SUN = np.array([1.35, 1.25, 1.06], np.float32)
#: The sky's fill: light from the sky dome (bluish) above, bounced from the ground (warm, dim) below.
SKY_FILL = np.array([0.16, 0.2, 0.28], np.float32)
GROUND_FILL = np.array([0.07, 0.06, 0.045], np.float32)


def sun_and_sky(gbuffer: GBuffer, albedo, *, normals=None, sun_dir=SUN_DIR, sun=SUN, sky=SKY_FILL, ground=GROUND_FILL, background=SKY) -> np.ndarray:
    """A preview's light: a key light with real contrast and a soft sky fill,
    ``albedo · (sun · max(0, n·l) + mix(ground, sky, (1 + n_y) / 2))``; ``background`` where the
    mask is 0. Faces turned from the sun keep the sky's cool fill (dim on overhangs, which see the
    ground), so relief reads as it does outdoors; no shadows are cast.

    Args:
        gbuffer: supplies the mask and, unless ``normals`` is given, the shading normals.
        albedo: ``[H, W, C]`` linear colour (NumPy or ``wp.array``); 1-2 channels are shown as gray.
        normals: ``[H, W, 3]`` world-space normals to light with instead.
        sun_dir: direction towards the key light (normalised here). sun, sky, ground: linear RGB
            of the key light, and of the fill from straight up and straight down.
        background: linear RGB for uncovered pixels.

    Returns:
        ``[H, W, 3]`` float32 linear RGB.
    """
    light, rgb, n = _inputs("sun_and_sky", gbuffer, albedo, normals, sun_dir)
    up = np.clip(0.5 + 0.5 * n[..., 1:2], 0.0, 1.0)
    fill = np.asarray(ground, np.float32) * (1.0 - up) + np.asarray(sky, np.float32) * up
    lit = rgb * (np.asarray(sun, np.float32) * np.clip(n @ light, 0.0, None)[..., None] + fill)
    return np.where(gbuffer.mask.numpy()[..., None] > 0, lit, background).astype(np.float32)


def _inputs(func: str, gbuffer: GBuffer, albedo, normals, light_dir) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The unit light direction, the ``(H, W, 3)`` albedo and the normals, checked."""
    light = np.asarray(light_dir, np.float64)
    if light.shape != (3,) or not np.isfinite(light).all() or np.linalg.norm(light) == 0:
        raise ValueError(f"{func}(): light direction must be 3 finite numbers, not all zero, got {light_dir!r}")
    rgb = to_rgb(albedo)
    n = gbuffer.normal.numpy() if normals is None else _numpy(normals)
    shape = (*gbuffer.resolution, 3)
    for name, arr in (("albedo", rgb), ("normals", n)):
        if arr.shape != shape:
            raise ValueError(f"{func}(): {name} must have shape {shape} (H, W, 3), got {arr.shape}")
    return (light / np.linalg.norm(light)).astype(np.float32), rgb, n


def height_to_normal_map(height, *, strength: float = 1.0) -> np.ndarray:
    """A tangent-space normal map (``[0, 1]`` data, OpenGL style: green up) from a tileable height map.

    Slopes are central differences with wrap-around, in height units per texel, scaled by
    ``strength``: ``n = normalize(-strength · dh/dx, -strength · dh/dy, 1)`` with ``x`` to the
    right and ``y`` up the image, encoded as ``n · 0.5 + 0.5``.

    Args:
        height: ``[H, W]`` or ``[H, W, C]`` (the channel mean is used), e.g. a texture's luminance.
        strength: slope scale; larger is bumpier.

    Returns:
        ``[H, W, 3]`` float32 in ``[0, 1]``.
    """
    h = _numpy(height).astype(np.float64)
    if h.ndim == 3:
        h = h.mean(axis=-1)
    if h.ndim != 2 or min(h.shape) < 2:
        raise ValueError(f"height_to_normal_map(): height must be [H, W] or [H, W, C] with H, W >= 2, got {h.shape}")
    if not np.isfinite(h).all():
        raise ValueError("height_to_normal_map(): height must be finite")
    dx = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) * 0.5
    dy = (np.roll(h, 1, axis=0) - np.roll(h, -1, axis=0)) * 0.5  # row 0 is the top: up is -row
    n = np.stack([-strength * dx, -strength * dy, np.ones_like(h)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return (n * 0.5 + 0.5).astype(np.float32)


def labelled(linear_rgb, text: str) -> np.ndarray:
    """``[H, W, 3]`` linear RGB as sRGB-encoded uint8 with ``text`` in its top-left corner."""
    pil = Image.fromarray(np.round(io.linear_to_srgb(np.clip(to_rgb(linear_rgb), 0.0, 1.0)) * 255).astype(np.uint8))
    draw = ImageDraw.Draw(pil)
    draw.rectangle((0, 0, 8 + 7 * len(text), 18), fill=(0, 0, 0))
    draw.text((4, 3), text, fill=(255, 255, 255))
    return np.asarray(pil)


def side_by_side(panels: dict[str, np.ndarray], *, columns: int | None = None) -> np.ndarray:
    """Labelled linear-RGB panels of one size in a grid (``columns`` per row, default all in one
    row), as float32 sRGB-encoded values in ``[0, 1]`` for :func:`warptex.io.write_png` with
    ``data=True``."""
    images = [labelled(image, name) for name, image in panels.items()]
    if not images or any(i.shape != images[0].shape for i in images):
        raise ValueError("side_by_side(): needs one or more panels of one size")
    columns = len(images) if columns is None else columns
    blank = np.zeros_like(images[0])
    rows = [images[i : i + columns] for i in range(0, len(images), columns)]
    rows[-1] = rows[-1] + [blank] * (columns - len(rows[-1]))
    return np.concatenate([np.concatenate(r, axis=1) for r in rows]).astype(np.float32) / 255.0
