"""Break visible tiling: one large ground plane, plain tiling next to hash4, cheap2 and hex.

Rasterises a big flat quad seen from head height towards the horizon, maps it with world XZ ×
``tiling`` as UV (the LOD comes from the G-buffer's position derivatives, so it is the same for
every technique), and writes a labelled 2 × 2 contact sheet, ``stochastic_plane.png``:

1. plain tiling: the repeat is obvious as a grid of identical tiles;
2. ``hash4``: per-cell random offsets, 4 taps blended in a window around the cell borders;
3. ``cheap2``: 2 taps whose offsets follow a low-frequency noise;
4. ``hex``: triangle-grid tiles with random offsets, histogram-preserving blend.

Run: ``python examples/stochastic_plane.py --out out`` (see ``--help``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import trimesh

import warptex as wt
from warptex import io
from warptex.apps.shade import lambert, side_by_side

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def ground_quad(half_size: float) -> trimesh.Trimesh:
    """The square ``|x|, |z| <= half_size`` of the plane ``y = 0``, two triangles facing up."""
    s = half_size
    vertices = np.array([[-s, 0, -s], [s, 0, -s], [s, 0, s], [-s, 0, s]], np.float64)
    return trimesh.Trimesh(vertices, np.array([[0, 2, 1], [0, 3, 2]]), process=False)


def render_plane(
    out_dir="out",
    *,
    texture_path=SHARED / "textures" / "grass.png",
    resolution=(360, 480),
    tiling: float = 0.5,
    eye_height: float = 1.7,
    seed: int = 0,
    contrast: float = 2.0,
    device=None,
) -> Path:
    """Render the four panels and write ``<out_dir>/stochastic_plane.png``.

    Args:
        out_dir: output folder (created if missing).
        texture_path: a tileable colour texture (sRGB); stochastic textures (grass, gravel) hide
            their cells best, regular ones (bricks) show broken rows where cells blend.
        resolution: ``(height, width)`` of each panel.
        tiling: texture repeats per world unit (the plane is 400 units across; one repeat is 2 units
            by default, about a step at the camera's feet).
        eye_height: camera height above the plane, in world units.
        seed: the stochastic techniques' seed.
        contrast: hex blend contrast exponent (1: Heitz & Neyret's linear weights).
        device: Warp device.

    Returns:
        The PNG's path.
    """
    camera = wt.look_at((0.0, eye_height, 0.0), (0.0, 0.0, -3.5 * eye_height), fov_y=60.0, resolution=resolution)
    g = wt.rasterize(ground_quad(200.0), camera, device=device)
    tex = wt.Texture.from_file(texture_path, device=device)
    hist = wt.prepare_histogram(tex)

    # UV = world (x, -z) × tiling: "up" in the texture points away from the camera.
    axes, signs = [0, 2], np.array([1.0, -1.0], np.float32) * tiling
    uv, uv_dx, uv_dy = (getattr(g, k).numpy()[..., axes] * signs for k in ("position", "position_dx", "position_dy"))
    covered = g.mask.numpy() > 0
    options = {
        "plain tiling": wt.Stochastic("none", seed=seed),
        "hash4 (4 taps, per-cell offsets)": wt.Stochastic("hash4", seed=seed),
        "cheap2 (2 taps, noise-driven)": wt.Stochastic("cheap2", seed=seed),
        f"hex (3 taps, histogram-preserving, contrast {contrast:g})": wt.Stochastic("hex", seed=seed, histogram=hist, contrast=contrast),
    }
    start = time.perf_counter()
    panels = {}
    for name, option in options.items():
        colour = wt.stochastic(tex, uv, option, uv_dx=uv_dx, uv_dy=uv_dy, device=device).numpy()
        panels[name] = lambert(g, np.where(covered[..., None], colour, 0.0), light_dir=(0.3, 1.0, 0.2), ambient=0.35)
    elapsed = time.perf_counter() - start

    path = Path(out_dir) / "stochastic_plane.png"
    io.write_png(path, side_by_side(panels, columns=2), data=True)
    print(f"{len(options)} techniques x {int(covered.sum()):,} pixels in {elapsed:.3f} s (a first run also compiles kernels)")
    return path


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--texture", default=str(SHARED / "textures" / "grass.png"), help="tileable texture (default: the shared grass)")
    parser.add_argument("--resolution", default="360x480", help="panel size HxW (default: 360x480)")
    parser.add_argument("--tiling", type=float, default=0.5, help="repeats per world unit (default: 0.5)")
    parser.add_argument("--seed", type=int, default=0, help="stochastic seed (default: 0)")
    parser.add_argument("--contrast", type=float, default=2.0, help="hex blend contrast exponent (default: 2)")
    parser.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0")
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.resolution.lower().split("x"))
    wt.init_quietly()  # no Warp banner, CUDA-driver warning or compile log between our lines
    path = render_plane(
        args.out, texture_path=args.texture, resolution=(height, width), tiling=args.tiling, seed=args.seed,
        contrast=args.contrast, device=args.device,
    )  # fmt: skip
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
