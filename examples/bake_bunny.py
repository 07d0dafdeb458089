"""From fit to asset: bake the bunny's triplanar texturing into a UV atlas and export a glTF.

The Stanford bunny (no UVs) is textured triplanar with the brick texture from ``../shared/data``
and a normal map from its luminance, as ``examples/triplanar_bunny.py`` does. ``wt.bake`` gives it
an xatlas atlas and bakes colour and a tangent-space normal map into it; ``wt.export_gltf`` writes
``bunny.glb`` with ``bunny_color.png`` and ``bunny_normal.png``. The GLB is then loaded back and
drawn as an engine draws it, with warptex's rasteriser and a plain UV lookup of its textures, and
``bake_bunny.png`` shows, side by side:

1. the original: triplanar colour lit with triplanar normal mapping;
2. the baked asset: the GLB's base colour lit with its normal texture, from the same camera;
3. the baked colour texture (the atlas);
4. the baked normal texture.

Run: ``python examples/bake_bunny.py --out out`` (see ``--help``).
"""

from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path

import numpy as np
import warp as wp

import warptex as wt
from warptex import io
from warptex.apps.render import default_camera
from warptex.apps.shade import height_to_normal_map, lambert, side_by_side, to_rgb
from warptex.gltf import load_gltf

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
BRICK_TINT = np.array([1.0, 0.55, 0.42], np.float32)
LIGHT = (-0.75, 0.55, 0.35)


def bake_bunny(out_dir="out", *, mesh_path=SHARED / "meshes" / "bunny.ply", texture_path=SHARED / "textures" / "brick.png", size: int = 2048,
               resolution: int = 512, repeats: float = 3.0, bump: float = -20.0, device=None) -> Path:  # fmt: skip
    """Bake, export, reload and render; write ``<out_dir>/bake_bunny/bunny.glb`` (and its PNGs)
    and ``<out_dir>/bake_bunny.png``; the picture's path."""
    mesh = wt.load_mesh(mesh_path)
    image = to_rgb(io.read_image(texture_path))
    if np.ptp(image, axis=-1).max() < 1e-3:  # a greyscale photo: tint it brick red for the picture
        image = image * BRICK_TINT
    tiling = repeats / float(np.max(mesh.extents))
    sampler = wt.Sampler(filter="anisotropic")
    colour = functools.partial(wt.triplanar, texture=wt.Texture(image, device=device), tiling=tiling, sampler=sampler)
    normal = functools.partial(wt.triplanar_normal, normal_map=wt.Texture(height_to_normal_map(image, strength=bump), device=device), tiling=tiling, sampler=sampler)

    start = time.perf_counter()
    baked = wt.bake(mesh, colour, normal=normal, size=size, view_size=resolution, device=device)
    paths = wt.export_gltf(baked, Path(out_dir) / "bake_bunny" / "bunny.glb")
    elapsed = time.perf_counter() - start

    camera = default_camera(mesh, (resolution, resolution))
    g = wt.rasterize(mesh, camera, device=device)
    original = lambert(g, colour(g), normals=normal(g), light_dir=LIGHT)
    asset, textures = load_gltf(paths[0])
    h = wt.rasterize(asset, camera, device=device)
    uv = {k: np.ascontiguousarray(v.numpy().reshape(-1, 2)) for k, v in h.uv("uv0").items() if k != "tangent"}

    def lookup(texels):
        clamped = sampler.replace(address="clamp")  # the GLB's sampler
        return wt.sample(wt.Texture(texels, device=device), uv["uv"], uv_dx=uv["uv_dx"], uv_dy=uv["uv_dy"], sampler=clamped).numpy().reshape(resolution, resolution, -1)

    normals = wt.tangent_space(h, wp.array(lookup(textures["normal"]) * 2.0 - 1.0, dtype=float, device=device), uv_set="uv0", to_world=True)
    drawn = lambert(h, lookup(textures["color"]), normals=normals, light_dir=LIGHT)
    panels = {
        "original: triplanar + normal map": original,
        "baked asset (bunny.glb), as engines draw it": drawn,
        f"baked colour ({size}x{size})": _shrunk(textures["color"], resolution),
        "baked normal map": io.srgb_to_linear(_shrunk(textures["normal"], resolution)),  # shown as its PNG looks
    }
    path = Path(out_dir) / "bake_bunny.png"
    io.write_png(path, side_by_side(panels, columns=4), data=True)
    print(f"baked {len(mesh.faces):,} faces into {size}x{size} ({baked.layout.source}: {baked.layout.reason}; gutter {baked.gutter}) and exported in {elapsed:.1f} s")
    for p in paths:
        print(f"wrote {p}")
    return path


def _shrunk(image: np.ndarray, resolution: int) -> np.ndarray:
    """``image`` ``[S, S, C]`` box-filtered to ``[resolution, resolution, C]`` (a texture in a panel)."""
    step = max(1, image.shape[0] // resolution)
    image = image[: step * resolution, : step * resolution]
    return image.reshape(resolution, step, resolution, step, -1).mean(axis=(1, 3)) if step * resolution == image.shape[0] else image[::step, ::step]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--mesh", default=str(SHARED / "meshes" / "bunny.ply"), help="mesh file (default: the shared bunny)")
    parser.add_argument("--texture", default=str(SHARED / "textures" / "brick.png"), help="colour texture (default: the shared brick)")
    parser.add_argument("--size", type=int, default=2048, help="bake size (default: 2048)")
    parser.add_argument("--resolution", type=int, default=512, help="panel size (default: 512)")
    parser.add_argument("--repeats", type=float, default=3.0, help="texture repeats across the mesh (default: 3)")
    parser.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    path = bake_bunny(args.out, mesh_path=args.mesh, texture_path=args.texture, size=args.size, resolution=args.resolution, repeats=args.repeats, device=args.device)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
