"""The default terrain's material: four layers (grass, gravel, rock, snow) and splat maps from
height and slope rules, for :func:`warptex.splat`.

The layers are the shared greyscale photographs (``../shared/data/textures``) tinted, with the
photo's luminance as a height channel for height blending; without the shared folder they are
procedural noise of the same character, so the main job runs anywhere.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from warptex import io
from warptex.apps.terrain import terrain_slope_height
from warptex.texture import TextureArray

LAYER_NAMES = ("grass", "gravel", "rock", "snow")
#: Linear RGB tints of the greyscale photos (grass.png, gravel.png, brick.png as rock).
TINTS = {"grass": (0.55, 0.8, 0.32), "gravel": (0.95, 0.82, 0.62), "rock": (0.85, 0.8, 0.74), "snow": (0.95, 0.97, 1.0)}
SHARED_TEXTURES = Path(__file__).resolve().parents[2] / "shared" / "data" / "textures"


def noise_texture(size: int = 256, *, seed: int = 0, octaves: int = 6) -> np.ndarray:
    """A tileable, earthy ground texture ``[size, size, 3]`` (linear RGB): fBm of wrapped value noise."""
    rng = np.random.default_rng(seed)
    value = np.zeros((size, size))
    for octave in range(octaves):
        cells = 4 * 2**octave
        value += 0.55**octave * _wrapped_bilinear(rng.random((cells, cells), dtype=np.float32), size)
    value = (value - value.min()) / (value.max() - value.min())
    dark, mid, light = np.array([0.09, 0.07, 0.04]), np.array([0.16, 0.2, 0.07]), np.array([0.32, 0.29, 0.2])
    t = value[..., None]
    return np.where(t < 0.5, dark + (mid - dark) * (2 * t), mid + (light - mid) * (2 * t - 1)).astype(np.float32)


def _wrapped_bilinear(grid: np.ndarray, size: int) -> np.ndarray:
    """``grid`` ``[n, n]`` magnified to ``[size, size]``: bilinear between texel centres, wrapping
    at the edges (texture-sampling conventions), so the result tiles."""
    n = grid.shape[0]
    x = (np.arange(size) + 0.5) * (n / size) - 0.5
    i0 = np.floor(x).astype(int)
    f = (x - i0).astype(np.float32)
    i0, i1 = i0 % n, (i0 + 1) % n
    rows = grid[i0] * (1 - f)[:, None] + grid[i1] * f[:, None]
    return rows[:, i0] * (1 - f)[None, :] + rows[:, i1] * f[None, :]


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def terrain_splat_maps(mesh: trimesh.Trimesh, grid: tuple[int, int]) -> np.ndarray:
    """RGBA splat weights ``[rows, cols, 4]`` (grass, gravel, rock, snow; sum 1) of a
    :func:`warptex.terrain` mesh with ``grid = (rows, cols)`` vertices, one texel per vertex (the
    terrain's UV0 puts vertex ``(r, c)`` at texel ``(r, c)`` of a ``rows × cols`` map, up to half a
    texel at the borders).

    Rules: rock on slopes past ~35°, snow on high, gentle ground, gravel on low, flat ground
    (valley floors) and as a band below the rock, grass elsewhere; transitions are smoothsteps.
    """
    height, slope = terrain_slope_height(mesh)
    rows, cols = grid
    if height.size != rows * cols:
        raise ValueError(f"terrain_splat_maps(): the mesh has {height.size} vertices, not a {rows}x{cols} grid")
    rock = _smoothstep(30.0, 42.0, slope)
    snow = _smoothstep(0.68, 0.8, height) * (1 - rock)
    gravel = np.maximum(_smoothstep(0.12, 0.03, height), _smoothstep(22.0, 32.0, slope)) * (1 - rock) * (1 - snow)
    grass = np.clip(1 - rock - snow - gravel, 0.0, 1.0)
    weights = np.stack([grass, gravel, rock, snow], axis=-1)
    weights /= weights.sum(axis=-1, keepdims=True)
    return weights.reshape(rows, cols, 4).astype(np.float32)


def terrain_layers(*, size: int = 256, textures_dir=SHARED_TEXTURES, seed: int = 0, device=None) -> TextureArray:
    """The four layers as a ``TextureArray`` of ``[4, size, size, 4]``: linear RGB + height (alpha)."""
    layers = []
    for k, name in enumerate(LAYER_NAMES):
        photo = Path(textures_dir) / {"grass": "grass.png", "gravel": "gravel.png", "rock": "brick.png"}.get(name, "")
        if name != "snow" and photo.is_file():
            grey = io.read_image(photo)[..., :1]
            grey = _resize(grey, size)
        else:
            grey = noise_texture(size, seed=seed + 17 * k).mean(axis=-1, keepdims=True)
            grey = 0.6 + 0.4 * (grey - grey.min()) / max(float(np.ptp(grey)), 1e-6) if name == "snow" else grey * 3.0
        grey = np.clip(grey, 0.0, 1.0)
        rgb = grey * np.asarray(TINTS[name], np.float32)
        height = (grey - grey.min()) / max(float(np.ptp(grey)), 1e-6)
        layers.append(np.concatenate([rgb, height], axis=-1))
    return TextureArray(np.stack(layers).astype(np.float32), device=device)


def _resize(image: np.ndarray, size: int) -> np.ndarray:
    """Box-downsample ``[H, W, C]`` to ``[size, size, C]`` (sizes must divide; else crop)."""
    h, w, c = image.shape
    fh, fw = max(1, h // size), max(1, w // size)
    image = image[: size * fh, : size * fw]
    return image.reshape(size, fh, size, fw, c).mean(axis=(1, 3))
