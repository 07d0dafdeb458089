"""Baked assets against their originals: quality, gutters, normal maps, and cost (issue 35).

For each mesh (default: the bunny and fandisk, which have no UVs, and the Duck, whose UVs are
mirrored (its two sides share texels), so all three get an xatlas atlas; plus the Duck with an
atlas of its own as UV0, which is kept):

- **quality**: the mesh is textured triplanar (brick, 8 repeats across it) and baked at ``--size``;
  the exported GLB is loaded back, rasterised with warptex's rasteriser from ``warptex render``'s
  default camera at ``--resolution``² and textured by a plain UV lookup of its base-colour PNG. The
  PSNR against the direct triplanar render of the original (sRGB-encoded values, over pixels both
  cover, eroded by one pixel away from silhouettes) is reported, both with the same filter;
- **gutters**: the same render with the texels outside every chart and gutter set to 0 and to 1:
  the largest difference and the share of pixels that differ say whether background reaches the
  render at all (0 when the gutters are wide enough for the mips the view reads); also with no
  gutter, for scale;
- **normal map**: ``triplanar_normal`` baked into a tangent-space map, decoded through the GLB's
  tangent frame, against the direct ``triplanar_normal`` render: mean and 99th-percentile angle;
- **cost** (``--cost``): ``warptex bake`` of the bunny at ``--size`` against ``warptex render`` of it
  at ``--size``², each a fresh process (interleaved, warm kernel cache, minimum of ``--repeats``).

    python benchmarks/bench_bake.py                                  # 2048² bakes, 512² renders, cost
    python benchmarks/bench_bake.py --size 1024 --resolution 256 --no-cost --json bake.json
"""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh
import warp as wp

import warptex as wt
from warptex.gltf import load_gltf
from warptex.scenes import framing_camera
from warptex.scenes.material import noise_texture

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
MESHES = ("bunny.ply", "fandisk.obj", "Duck.glb", "Duck.glb:own-uvs")


def load(name: str, size: int) -> trimesh.Trimesh:
    """A shared mesh; ``"<file>:own-uvs"``: the mesh with an xatlas atlas for ``size``² as its own
    UV0 (the Duck's authored UVs are mirrored, both sides sharing texels, so they cannot hold a
    bake: this is the Duck an artist would re-export, and its UVs are kept)."""
    path, _, part = name.partition(":")
    mesh = wt.load_mesh(DATA / "meshes" / path)
    if part:
        mesh = wt.unwrap(mesh, size=size, padding=16, force_atlas=True).trimesh()
    return mesh


def materials(texture: np.ndarray, mesh: trimesh.Trimesh, tiling: float, sampler: wt.Sampler):
    """Triplanar colour and normal mapping with ``tiling`` repeats across the mesh's largest extent;
    the normal map is the texture's luminance as a height (slopes of 20 per unit)."""
    scale = tiling / float(np.max(mesh.extents))
    height = texture.mean(axis=-1)
    slope_u, slope_v = np.gradient(height, axis=1) * 20.0, -np.gradient(height, axis=0) * 20.0
    tangent = np.stack([-slope_u, -slope_v, np.ones_like(height)], axis=-1)
    normal_map = tangent / np.linalg.norm(tangent, axis=-1, keepdims=True) * 0.5 + 0.5
    colour = functools.partial(wt.triplanar, texture=wt.Texture(texture), tiling=scale, sampler=sampler)
    normal = functools.partial(wt.triplanar_normal, normal_map=wt.Texture(normal_map.astype(np.float32)), tiling=scale, sampler=sampler)
    return colour, normal


def uv_lookup(texture: np.ndarray, g: wt.GBuffer, sampler: wt.Sampler) -> np.ndarray:
    """``texture`` read through the G-buffer's UV0 as an engine draws the asset (clamped to the
    edge, as the GLB's sampler says), ``[H, W, C]``."""
    uv = g.uv("uv0")
    flat = [np.ascontiguousarray(uv[k].numpy().reshape(-1, 2)) for k in ("uv", "uv_dx", "uv_dy")]
    clamped = sampler.replace(address="clamp")
    return wt.sample(wt.Texture(texture), flat[0], uv_dx=flat[1], uv_dy=flat[2], sampler=clamped).numpy().reshape(*g.resolution, -1)


def eroded(mask: np.ndarray) -> np.ndarray:
    """``mask`` without the pixels next to an uncovered one (8-neighbourhood)."""
    padded = np.pad(mask, 1)
    out = mask.copy()
    for dy in range(3):
        for dx in range(3):
            out &= padded[dy : dy + mask.shape[0], dx : dx + mask.shape[1]]
    return out


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of sRGB-encoded values in [0, 1]."""
    a, b = (wt.io.linear_to_srgb(np.clip(x, 0.0, 1.0)) for x in (a, b))
    return float(-10 * np.log10(max(np.mean((a - b) ** 2), 1e-20)))


def compare(name: str, texture: np.ndarray, *, size: int, resolution: int, tiling: float, sampler: wt.Sampler, folder: Path) -> dict:
    """Bake, export, reload and render one mesh; the quality figures (module docstring)."""
    mesh = load(name, size)
    camera = framing_camera(mesh, (resolution, resolution))
    colour, normal = materials(texture, mesh, tiling, sampler)
    g0 = wt.rasterize(mesh, camera)
    start = time.perf_counter()
    baked = wt.bake(mesh, colour, normal=normal, size=size, view_size=resolution)
    paths = wt.export_gltf(baked, folder / f"{name.replace(':', '_').replace('.', '_')}.glb")
    seconds = time.perf_counter() - start
    asset, textures = load_gltf(paths[0])
    g1 = wt.rasterize(asset, camera)
    pixels = eroded((g0.mask.numpy() > 0) & (g1.mask.numpy() > 0))
    direct, through_glb = colour(g0).numpy(), uv_lookup(textures["color"], g1, sampler)

    background = baked.gbuffer.mask.numpy()[..., None] > 0
    own = baked.color.numpy()
    lookups = {v: uv_lookup(np.where(background, own, v).astype(np.float32), g1, sampler) for v in (0.0, 1.0)}
    bleed = np.abs(lookups[1.0] - lookups[0.0]).max(axis=-1)[pixels]
    coverage = baked.coverage.numpy() > 0
    no_gutter = {v: uv_lookup(np.where(coverage[..., None], own, v).astype(np.float32), g1, sampler) for v in (0.0, 1.0)}
    bleed_without = np.abs(no_gutter[1.0] - no_gutter[0.0]).max(axis=-1)[pixels]

    tangent = uv_lookup(textures["normal"], g1, sampler) * 2.0 - 1.0
    world = wt.tangent_space(g1, wp.array(np.ascontiguousarray(tangent, np.float32)), uv_set="uv0", to_world=True).numpy()
    cosine = np.clip((world * normal(g0).numpy()).sum(-1)[pixels], -1.0, 1.0)
    angles = np.degrees(np.arccos(cosine))
    return {
        "mesh": name,
        "faces": len(mesh.faces),
        "uv": baked.layout.source,
        "why_atlas": baked.layout.reason,
        "size": size,
        "resolution": resolution,
        "gutter": baked.gutter,
        "padding": baked.layout.padding,
        "chart_texels": float(coverage.mean()),
        "pixels_compared": int(pixels.sum()),
        "psnr_db": psnr(direct[pixels], through_glb[pixels]),
        "background_max_diff": float(bleed.max()),
        "background_pixels": float((bleed > 1e-6).mean()),
        "no_gutter_background_pixels": float((bleed_without > 1e-6).mean()),
        "normal_mean_deg": float(angles.mean()),
        "normal_p99_deg": float(np.percentile(angles, 99)),
        "bake_export_s": seconds,
    }


def cost(mesh: Path, texture: Path, size: int, repeats: int, folder: Path) -> dict:
    """``warptex bake`` against ``warptex render`` at ``size``, fresh processes, interleaved."""
    jobs = {
        "render": ["render", "--mesh", str(mesh), "--texture", str(texture), "--resolution", f"{size}x{size}", "--out", str(folder / "render")],
        "bake": ["bake", "--mesh", str(mesh), "--texture", str(texture), "--size", str(size), "--out", str(folder / "bake" / "asset.glb")],
    }
    times = {name: [] for name in jobs}
    for _ in range(repeats + 1):  # the first round warms the kernel cache and the file cache
        for name, argv in jobs.items():
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "warptex", *argv], check=True, capture_output=True)
            times[name].append(time.perf_counter() - start)
    best = {name: min(t[1:]) for name, t in times.items()}
    return {"size": size, "render_s": best["render"], "bake_s": best["bake"], "ratio": best["bake"] / best["render"], "repeats": repeats}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--meshes", nargs="+", default=list(MESHES), help="shared meshes (default: %(default)s)")
    p.add_argument("--size", type=int, default=2048, help="bake size (default: %(default)s)")
    p.add_argument("--resolution", type=int, default=512, help="render size (default: %(default)s)")
    p.add_argument("--tiling", type=float, default=8.0, help="texture repeats across each mesh (default: %(default)s)")
    p.add_argument("--filter", default="anisotropic", help="texture filter of both renders (default: %(default)s)")
    p.add_argument("--no-cost", dest="cost", action="store_false", help="skip the bake-against-render timing")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats of each job (default: %(default)s)")
    p.add_argument("--json", type=Path, help="write the results here")
    args = p.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    if not DATA.is_dir():
        print(f"bench_bake: the shared data folder {DATA} is missing", file=sys.stderr)
        return 1
    brick = DATA / "textures" / "brick.png"
    texture = wt.io.read_image(brick, channels=3) if brick.exists() else noise_texture()
    sampler = wt.Sampler(filter=args.filter)
    result = {"quality": [], "cost": None}
    with tempfile.TemporaryDirectory(prefix="warptex_bake_") as tmp:
        for name in args.meshes:
            row = compare(name, texture, size=args.size, resolution=args.resolution, tiling=args.tiling, sampler=sampler, folder=Path(tmp))
            result["quality"].append(row)
            print(
                f"{name:22s} {row['uv']:6s} gutter {row['gutter']:3d} padding {str(row['padding']):4s} charts {row['chart_texels']:5.1%}  "
                f"PSNR {row['psnr_db']:5.2f} dB  background in {row['background_pixels']:.2%} of pixels "
                f"(max {row['background_max_diff']:.2g}; {row['no_gutter_background_pixels']:.1%} without gutters)  "
                f"normals {row['normal_mean_deg']:.2f}° mean, {row['normal_p99_deg']:.1f}° p99",
                flush=True,
            )
        if args.cost:
            result["cost"] = cost(DATA / "meshes" / "bunny.ply", brick, args.size, args.repeats, Path(tmp))
            c = result["cost"]
            print(f"cost: bake {c['bake_s']:.2f} s, render {c['render_s']:.2f} s at {args.size}²: bake / render = {c['ratio']:.2f}x")
    if args.json:
        from warptex.io import _atomic_output

        with _atomic_output(str(args.json)) as tmp_path:
            Path(tmp_path).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
