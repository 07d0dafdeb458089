"""Recover a terrain's splat maps and tiling from two pictures of it, with ``warptex.fit``.

The targets are the procedural terrain rendered with known splat maps (height and slope rules)
and a known tiling (1/6 repeats per world unit); the fit starts from uniform weights and a tiling
20% off. ``warptex fit`` runs the same problem and writes more pictures (``warptex/apps/fit_demo.py``).

    python examples/fit_splat.py --out out/fit_example            # about 30 s on 2 CPU cores
    python examples/fit_splat.py --iters 10 --out out/fit_quick   # a quick check
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import warptex as wt
from warptex.scenes import terrain_cameras
from warptex.scenes import TERRAIN_GRID
from warptex.scenes.terrain import terrain
from warptex.scenes.material import terrain_layers, terrain_splat_maps

TRUE_TILING = 1.0 / 6.0


def fit_example(out_dir="out/fit_example", *, iters: int = 240, resolution=(192, 256), device=None) -> dict:
    """Render the targets, fit, and write ``target.png`` and ``fitted.png`` into ``out_dir``.

    Returns ``{"psnr": dB, "tiling": fitted, "tiling_error": relative, "weight_mae": mean |w - true|}``.
    """
    # The scene: the terrain seen from above and from a three-quarter view, and its four layers
    # (RGB and a height in alpha), blended by height and mapped triplanar.
    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    gbuffers = [wt.rasterize(mesh, camera, device=device) for camera in terrain_cameras(resolution, 2)]
    layers = terrain_layers(device=device)
    options = {"projection": "triplanar", "height_blend": 0.2}

    # The targets, rendered with the true splat maps (one RGBA map: a weight per layer) and tiling.
    true_maps = terrain_splat_maps(mesh, TERRAIN_GRID)
    truth = wt.TextureArray(true_maps[None], mipmaps=False, device=device)
    targets = [wt.splat(g, layers, truth, tiling=TRUE_TILING, **options).numpy()[..., :3] for g in gbuffers]

    # The parameters: per-texel logits (a softmax over the layers gives the weights) and a
    # log-tiling, starting uniform and 20% off. fit_splat runs Adam coarse to fine, with a scan
    # of the tiling, whose loss is not convex.
    params = wt.fit.SplatParameters(layers.num_layers, TERRAIN_GRID, tiling=1.2 * TRUE_TILING, device=device)
    views = [wt.fit.FitView(g, target) for g, target in zip(gbuffers, targets)]
    result = wt.fit.fit_splat(views, layers, params, iters=iters, entropy=1e-4, splat_options=options, report_every=max(1, iters // 8))

    fitted = wt.fit.render_views(views, layers, params, splat_options=options)
    out = Path(out_dir)
    wt.io.write_png(out / "target.png", np.concatenate(targets, axis=1))
    wt.io.write_png(out / "fitted.png", np.concatenate([f[..., :3] for f in fitted], axis=1))
    tiling = float(params.tiling_values()[0])
    return {
        "psnr": result.final_psnr,
        "tiling": tiling,
        "tiling_error": abs(tiling / TRUE_TILING - 1.0),
        "weight_mae": float(np.abs(params.weights() - true_maps).mean()),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out/fit_example", help="output folder (default: %(default)s)")
    parser.add_argument("--iters", type=int, default=240, help="Adam iterations (default: %(default)s)")
    parser.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0")
    args = parser.parse_args(argv)
    wt.init_quietly()  # no Warp banner, CUDA-driver warning or compile log between the progress lines
    r = fit_example(args.out, iters=args.iters, device=args.device)
    print(f"PSNR {r['psnr']:.2f} dB, tiling {r['tiling']:.6f} ({100 * r['tiling_error']:.3f}% off), splat weights MAE {r['weight_mae']:.4f}")
    print(f"wrote {args.out}/target.png and {args.out}/fitted.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
