"""Fit splat maps and tiling to images: the reason the samplers are differentiable.

The default run builds the default terrain (``warptex.terrain``) and rasterises it from two cameras
(the default three-quarter view and a top-down view), renders the target with the true splat maps
(height and slope rules, ``warptex.terrain_material``) and the true tiling (1/6) with the real
layer textures, then starts from uniform splat weights and a tiling 20% off and fits both with
Adam, coarse to fine (a blurred, subsampled weights-only stage; a brute-force scan of the tiling;
then weights and tiling jointly, sharp). It writes into ``--out``:

- ``target.png``, ``initial.png``, ``fitted.png`` (every view side by side) and ``comparison.png``
  (per view: target, initial, fitted, |fitted - target| × 8);
- ``splat_true.png``, ``splat_fitted.png`` (weights shown as layer colours), ``splat_maps.png``
  (true, fitted, coverage, error) and ``splat_fitted.exr`` (the fitted weights as data);
- ``curve.png`` (PSNR and loss per iteration) and ``summary.json`` (final PSNR, splat MAE on
  covered texels, tiling error, iterations, time).

With ``--target img.png --gbuffer gbuffer.exr [--layers a.png b.png ...]`` it fits splat maps to
your images instead (repeat ``--target``/``--gbuffer`` for several views). ``warptex fit`` is the
same command.

Run: ``python examples/fit_splat.py --out out/fit`` (``--iters 5`` for a quick check; ``--help``).
"""

from __future__ import annotations

import argparse
import sys

from warptex.cli import add_fit_arguments, fit_arguments, fit_report
from warptex.fit_demo import run_fit


def fit_splat_example(
    out_dir="out/fit",
    *,
    iters: int = 240,
    resolution=(192, 256),
    views: int = 2,
    seed: int = 0,
    tiling_error: float = 0.2,
    entropy: float = 1e-4,
    **options,
) -> dict:
    """Fit the default terrain's splat maps and tiling from rendered views; write the results.

    Args:
        out_dir: output folder (created if missing).
        iters: Adam iterations of the coarse-to-fine schedule (240: about 25 s on 2 CPU cores).
        resolution: ``(height, width)`` of each view (192×256).
        views: 1 (three-quarter view), 2 (+ top-down, the default) or 3 (+ the opposite corner).
        seed: terrain and layer seed.
        tiling_error: the fit starts at ``(1 + tiling_error) ×`` the true tiling of 1/6.
        entropy: strength of the weight-entropy prior (``warptex.fit.weight_entropy``); 0 for none.
        **options: any other keyword of :func:`warptex.fit_demo.run_fit`, e.g. ``targets=``,
            ``gbuffers=`` and ``layers=`` to fit your own images.

    Returns:
        The summary also written to ``summary.json``.
    """
    return run_fit(out_dir, iters=iters, resolution=resolution, views=views, seed=seed, tiling_error=tiling_error, entropy=entropy, **options)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_fit_arguments(parser)
    args = parser.parse_args(argv)
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    kwargs = fit_arguments(args)
    summary = fit_splat_example(args.out, **kwargs)
    print(fit_report(summary))
    for path in summary["files"]:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
