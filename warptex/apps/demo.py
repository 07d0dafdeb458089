"""The texture-sampling demo: a ground plane to the horizon, sampled four ways, and the address modes.

A picture shows what the sampling core does better than numbers: nearest and bilinear filtering
of level 0 alias into moiré towards the horizon; trilinear filtering with the LOD taken from the
pixels' UV derivatives stays clean but blurs the distance to grey, because it takes the LOD of the
footprint's long axis; anisotropic filtering reads taps along that axis at the short axis' LOD
and keeps the far checks sharp. A quad with UVs in ``[-1, 2]`` shows each address mode.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

from warptex import io
from warptex._output import check_output_folder, output_set
from warptex.apps.shade import labelled, to_rgb
from warptex.options import Sampler
from warptex.sampling import sample
from warptex.texture import Texture

SKY = np.array([0.35, 0.55, 0.85], np.float32)


def checker_texture(size: int = 256, tiles: int = 8) -> np.ndarray:
    """A linear RGB checkerboard with thin grid lines: the classic aliasing test, ``[size, size, 3]``."""
    idx = np.arange(size) * tiles // size
    board = (idx[:, None] + idx[None, :]) % 2
    colours = np.array([[0.8, 0.25, 0.1], [0.9, 0.85, 0.7]], np.float32)
    img = colours[board]
    lines = (np.arange(size) % (size // tiles)) < max(1, size // 128)
    img[lines] = img[:, lines] = 0.02
    return img


def ground_plane(resolution: tuple[int, int], *, height=1.0, pitch_deg=12.0, fov_y_deg=60.0, tiling=0.25):
    """UVs and their screen-space derivatives of the plane ``y = 0`` seen from ``height``.

    Returns ``(uv, uv_dx, uv_dy, mask)``: three ``[H, W, 2]`` float32 arrays and the ``[H, W]``
    mask of pixels that see the plane. UV is the world ``(x, z)`` position times ``tiling``; the
    derivatives are the UV differences across one pixel (central, exact for the plane).
    """
    h, w = resolution
    f = 0.5 * h / math.tan(math.radians(fov_y_deg) / 2)
    pitch = math.radians(pitch_deg)

    def uv_at(rows, cols):
        x = (cols - 0.5 * w) / f
        y = (0.5 * h - rows) / f
        # Camera looks along -z, tilted down by `pitch` about the x axis.
        dy = y * math.cos(pitch) - math.sin(pitch)
        dz = -(y * math.sin(pitch) + math.cos(pitch))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(dy < -1e-6, height / -dy, np.nan)
        return np.stack([x * t, -dz * t], axis=-1) * tiling

    rows, cols = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    uv = uv_at(rows, cols)
    uv_dx = uv_at(rows, cols + 0.5) - uv_at(rows, cols - 0.5)
    uv_dy = uv_at(rows + 0.5, cols) - uv_at(rows - 0.5, cols)
    mask = np.isfinite(uv_dx).all(-1) & np.isfinite(uv_dy).all(-1)
    for a in (uv, uv_dx, uv_dy):
        a[~mask] = 0.0
    return uv.astype(np.float32), uv_dx.astype(np.float32), uv_dy.astype(np.float32), mask


def run_demo(out_dir: str | os.PathLike = "out", *, texture_path=None, resolution=(360, 480), device=None) -> list[Path]:
    """Render the demo and write ``demo.png`` (sRGB preview), ``demo_trilinear.exr`` and
    ``demo_anisotropic.exr`` (linear).

    Args:
        out_dir: folder for the outputs (created if missing).
        texture_path: an image file for the texture; ``None`` uses a procedural checkerboard.
        resolution: ``(height, width)`` of each ground-plane panel.
        device: Warp device for the launches.

    Returns:
        The paths written.
    """
    check_output_folder("run_demo", out_dir)
    image = checker_texture() if texture_path is None else io.read_image(texture_path)
    tex = Texture(image, device=device)
    h, w = resolution
    uv, uv_dx, uv_dy, mask = ground_plane(resolution)

    start = time.perf_counter()
    renders = {}
    for name, kw in (
        ("nearest, level 0", {"sampler": Sampler(filter="nearest")}),
        ("bilinear, level 0", {"sampler": Sampler(filter="bilinear")}),
        ("trilinear, LOD from derivatives", {"uv_dx": uv_dx, "uv_dy": uv_dy, "sampler": Sampler(filter="trilinear")}),
        ("anisotropic, 16 taps", {"uv_dx": uv_dx, "uv_dy": uv_dy, "sampler": Sampler(filter="anisotropic")}),
    ):
        colour = to_rgb(sample(tex, uv, device=device, **kw).numpy())
        renders[name] = np.where(mask[..., None], colour, SKY)
    panels = [labelled(colour, name) for name, colour in renders.items()]

    quad = w  # four address-mode panels span the four ground-plane panels
    cells = np.linspace(-1.0, 2.0, quad, endpoint=False) + 1.5 / quad
    quad_uv = np.stack(np.meshgrid(cells, cells[::-1]), axis=-1).astype(np.float32)
    modes = []
    for mode in ("wrap", "clamp", "mirror", "border"):
        colour = to_rgb(sample(tex, quad_uv, sampler=Sampler(address=mode, border=(0.1, 0.1, 0.1, 1.0)), device=device).numpy())
        modes.append(labelled(colour, mode))
    elapsed = time.perf_counter() - start

    top = np.concatenate(panels, axis=1)
    bottom = np.zeros((quad, top.shape[1], 3), np.uint8)
    row = np.concatenate(modes, axis=1)
    bottom[:, : row.shape[1]] = row
    with output_set(out_dir) as staging:
        io.write_png(staging / "demo.png", np.concatenate([top, bottom]).astype(np.float32) / 255.0, data=True)
        io.write_exr(staging / "demo_trilinear.exr", renders["trilinear, LOD from derivatives"])
        io.write_exr(staging / "demo_anisotropic.exr", renders["anisotropic, 16 taps"])
    paths = [Path(out_dir) / name for name in ("demo.png", "demo_trilinear.exr", "demo_anisotropic.exr")]
    samples = 4 * h * w + 4 * quad * quad
    print(f"sampled {samples:,} texels in {elapsed:.3f} s (a first run also compiles the kernels)")
    return paths
