"""Texture a mesh without UVs: planar projection vs triplanar, biplanar and triplanar normal mapping.

Renders the Stanford bunny (no UVs) with the brick texture from ``../shared/data`` six ways and
writes one labelled contact sheet, ``triplanar_bunny.png``:

1. a single world-XZ projection: what a mesh without UVs gets naively (stretched on steep faces);
2. triplanar colour, Lambert-lit with the surface normals;
3. biplanar colour (two taps at most);
4. triplanar colour lit with triplanar normal mapping (a normal map derived from the brick's
   luminance, whiteout blend);
5. the triplanar blend weights (red: X projection, green: Y, blue: Z);
6. the mapped normals, as colours.

Run: ``python examples/triplanar_bunny.py --out out`` (see ``--help``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import warp as wp

import warptex as wt
from warptex import io
from warptex.apps.render import default_camera
from warptex.apps.shade import height_to_normal_map, lambert, side_by_side, to_rgb
from warptex.triplanar import biplanar, triplanar, triplanar_normal

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
BRICK_TINT = np.array([1.0, 0.55, 0.42], np.float32)
LIGHT = (-0.75, 0.55, 0.35)  # from the upper left, low enough for the normal map to show


def render_bunny(
    out_dir="out",
    *,
    mesh_path=SHARED / "meshes" / "bunny.ply",
    texture_path=SHARED / "textures" / "brick.png",
    resolution=(512, 512),
    repeats: float = 3.0,
    sharpness: float = 4.0,
    bump: float = -20.0,
    device=None,
) -> Path:
    """Render the six panels and write ``<out_dir>/triplanar_bunny.png``.

    Args:
        out_dir: output folder (created if missing).
        mesh_path: a mesh; its UVs, if any, are ignored.
        texture_path: the colour texture (sRGB); a greyscale one is tinted brick red.
        resolution: ``(height, width)`` of each panel.
        repeats: texture repeats across the mesh's largest extent.
        sharpness: triplanar blend sharpness (biplanar uses ``2 × sharpness``, Quilez' scale).
        bump: strength of the normal map derived from the texture's luminance; negative makes
            dark texels high (the brick photo has light mortar between darker bricks).
        device: Warp device.

    Returns:
        The PNG's path.
    """
    mesh = wt.load_mesh(mesh_path)
    framing = default_camera(mesh, resolution, fov_y=35.0)  # frames the bounding sphere: move in
    centre = mesh.bounds.mean(axis=0)
    camera = wt.look_at(centre + 0.72 * (framing.eye - centre), centre, fov_y=35.0, resolution=resolution)
    g = wt.rasterize(mesh, camera, device=device)
    image = to_rgb(io.read_image(texture_path))
    if np.ptp(image, axis=-1).max() < 1e-3:  # a greyscale photo: tint it brick red for the picture
        image = image * BRICK_TINT
    brick = wt.Texture(image, device=device)
    normal_map = wt.Texture(height_to_normal_map(image, strength=bump), device=device)
    tiling = repeats / float(np.max(mesh.extents))

    start = time.perf_counter()
    planar_uv = g.position.numpy()[..., [0, 2]] * tiling
    planar_dx, planar_dy = (getattr(g, k).numpy()[..., [0, 2]] * tiling for k in ("position_dx", "position_dy"))
    planar = wt.sample(brick, planar_uv, uv_dx=planar_dx, uv_dy=planar_dy)
    colour = triplanar(g, brick, tiling=tiling, sharpness=sharpness)
    bi = biplanar(g, brick, tiling=tiling, sharpness=2 * sharpness)
    normals = triplanar_normal(g, normal_map, tiling=tiling, sharpness=sharpness, blend="whiteout")
    red, green, blue = (wt.Texture(np.full((1, 1, 3), c, np.float32), device=device) for c in np.eye(3))
    weights = triplanar(g, textures_per_axis=(red, green, blue), sharpness=sharpness)
    wp.synchronize_device(device)
    elapsed = time.perf_counter() - start

    covered = g.mask.numpy()[..., None] > 0
    panels = {
        "single world-XZ projection": lambert(g, planar.numpy() * covered, light_dir=LIGHT),
        "triplanar": lambert(g, colour, light_dir=LIGHT),
        "biplanar": lambert(g, bi, light_dir=LIGHT),
        "triplanar + normal map": lambert(g, colour, normals=normals, light_dir=LIGHT),
        "blend weights (X, Y, Z)": np.where(covered, weights.numpy(), 0.0),
        "mapped normals": np.where(covered, io.srgb_to_linear(normals.numpy() * 0.5 + 0.5), 0.0),
    }
    path = Path(out_dir) / "triplanar_bunny.png"
    io.write_png(path, side_by_side(panels, columns=3), data=True)
    pixels = int(covered.sum())
    print(f"{pixels:,} shaded pixels, 4 techniques + weights in {elapsed:.3f} s (a first run also compiles kernels)")
    return path


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--mesh", default=str(SHARED / "meshes" / "bunny.ply"), help="mesh file (default: the shared bunny)")
    parser.add_argument("--texture", default=str(SHARED / "textures" / "brick.png"), help="colour texture (default: the shared brick)")
    parser.add_argument("--resolution", default="512x512", help="panel size HxW (default: 512x512)")
    parser.add_argument("--repeats", type=float, default=3.0, help="texture repeats across the mesh (default: 3)")
    parser.add_argument("--sharpness", type=float, default=4.0, help="triplanar blend sharpness (default: 4)")
    parser.add_argument("--bump", type=float, default=-20.0, help="normal-map strength; negative: dark is high (default: -20)")
    parser.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0")
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.resolution.lower().split("x"))
    wt.init_quietly()  # no Warp banner, CUDA-driver warning or compile log between our lines
    path = render_bunny(
        args.out,
        mesh_path=args.mesh,
        texture_path=args.texture,
        resolution=(height, width),
        repeats=args.repeats,
        sharpness=args.sharpness,
        bump=args.bump,
        device=args.device,
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
