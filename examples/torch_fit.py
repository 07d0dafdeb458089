"""Recover a terrain's splat maps and tiling from pictures with PyTorch: ``torch.optim.Adam``
through ``warptex.torch``.

The problem of ``examples/fit_splat.py`` (the procedural terrain rendered with known splat maps and
a tiling of 1/6 per world unit; the fit starts from uniform weights and a tiling 20% off), solved
the way a PyTorch user would: the parameters are torch tensors (per-texel logits with a softmax
over the layers, a log-tiling), the render is ``warptex.torch.splat`` of all the views in one
call, the loss and the optimiser are torch's. The schedule is ``warptex.fit``'s: coarse to fine
(blurred, every second pixel), with a scan of the tiling, whose loss is not convex.

    python examples/torch_fit.py --out out/torch_fit          # about a minute on 2 CPU cores
    python examples/torch_fit.py --iters 12 --out out/quick   # a quick check
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

import warptex as wt
import warptex.torch as wtt
from warptex.scenes import terrain_cameras
from warptex.scenes import TERRAIN_GRID
from warptex.scenes.terrain import terrain
from warptex.scenes.material import terrain_layers, terrain_splat_maps
from warptex.fit import default_stages, psnr
from warptex.fit.losses import gaussian_taps

TRUE_TILING = 1.0 / 6.0
OPTIONS = {"projection": "triplanar", "height_blend": 0.2}  # of the targets and the fit
ENTROPY = 1e-4  # the weight-entropy prior of warptex.fit (see weight_entropy)


def views_at(gbuffers: dict, targets: torch.Tensor, stride: int):
    """The G-buffer tensors and targets of every ``stride``-th pixel (derivatives unchanged)."""
    if stride == 1:
        return gbuffers, targets
    return {k: v[:, ::stride, ::stride].contiguous() for k, v in gbuffers.items()}, targets[:, ::stride, ::stride].contiguous()


def blur(images: torch.Tensor, sigma: float) -> torch.Tensor:
    """Separable Gaussian blur of ``[V, H, W, C]`` with zero padding (``warptex.fit.blur``'s taps)."""
    if sigma == 0:
        return images
    taps = torch.tensor(gaussian_taps(sigma), dtype=images.dtype, device=images.device)
    x = images.permute(0, 3, 1, 2)
    c, r = x.shape[1], len(taps) // 2
    x = torch.nn.functional.conv2d(x, taps.view(1, 1, 1, -1).expand(c, 1, 1, -1), padding=(0, r), groups=c)
    x = torch.nn.functional.conv2d(x, taps.view(1, 1, -1, 1).expand(c, 1, -1, 1), padding=(r, 0), groups=c)
    return x.permute(0, 2, 3, 1)


def image_mse(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, sigma: float) -> torch.Tensor:
    """Mask-weighted mean squared error of all views, render and target blurred alike."""
    m = mask[..., None]
    weight = blur(m, sigma)
    diff = blur(render * m, sigma) - blur(target * m, sigma)
    return (weight * diff.square()).sum() / (weight.sum() * target.shape[-1])


def weight_entropy(weights: torch.Tensor) -> torch.Tensor:
    """Mean over texels of ``-Σ_l w log w``."""
    return -(weights * torch.log(weights.clamp_min(1e-12))).sum(0).mean()


def fit(out_dir="out/torch_fit", *, iters: int = 240, resolution=(192, 256), views: int = 2, progress: bool = True) -> dict:
    """Render the targets, fit, write ``target.png`` and ``fitted.png`` into ``out_dir``.

    Returns ``{"psnr": dB, "tiling": fitted, "tiling_error": relative, "weight_mae": mean |w - true|,
    "iterations": Adam steps}``.
    """
    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    cameras = terrain_cameras(resolution, views)
    # All views in one G-buffer (V, H, W): one call renders them all.
    gbuffers = wtt.gbuffer_tensors(wt.rasterize(mesh, cameras))
    layers = torch.tensor(terrain_layers().numpy())  # [L, 256, 256, 4]: RGB + height
    true_maps = torch.tensor(terrain_splat_maps(mesh, TERRAIN_GRID), dtype=torch.float32)  # [129, 129, 4]
    with torch.no_grad():
        targets = wtt.splat(gbuffers, layers, true_maps, tiling=TRUE_TILING, **OPTIONS)[..., :3]

    num_layers, size = layers.shape[0], TERRAIN_GRID
    logits = torch.zeros((num_layers, *size), requires_grad=True)  # uniform weights
    log_tiling = torch.tensor(math.log(1.2 * TRUE_TILING), requires_grad=True)  # 20% off

    def loss(g, target, sigma):
        weights = torch.softmax(logits, dim=0)
        render = wtt.splat(g, layers, weights.permute(1, 2, 0), tiling=log_tiling.exp(), **OPTIONS)[..., :3]
        return image_mse(render, target, g["mask"], sigma) + ENTROPY * weight_entropy(weights)

    steps = 0
    bar = tqdm(total=iters, desc="torch fit", unit="it", disable=not progress)
    for stage in default_stages(iters):
        g, target = views_at(gbuffers, targets, stage.stride)
        if stage.scan is not None:
            scan_tiling(functools.partial(loss, g, target, stage.sigma), log_tiling, *stage.scan)
        if stage.iters == 0:
            continue
        groups = [{"params": [logits], "lr": stage.lr_logits}, {"params": [log_tiling], "lr": stage.lr_tiling}]
        optimiser = torch.optim.Adam(groups)
        base = [group["lr"] for group in optimiser.param_groups]
        for k in range(stage.iters):
            cosine = stage.decay + (1 - stage.decay) * 0.5 * (1 + math.cos(math.pi * k / stage.iters))
            for group, lr in zip(optimiser.param_groups, base, strict=True):
                group["lr"] = lr * cosine
            optimiser.zero_grad()
            value = loss(g, target, stage.sigma)
            value.backward()
            optimiser.step()
            steps += 1
            bar.update(1)
            bar.set_postfix(loss=f"{value.item():.3g}", tiling=f"{log_tiling.exp().item():.5f}")
    bar.close()

    with torch.no_grad():
        weights = torch.softmax(logits, dim=0).permute(1, 2, 0)
        fitted = wtt.splat(gbuffers, layers, weights, tiling=log_tiling.exp(), **OPTIONS)[..., :3]
        mse = image_mse(fitted, targets, gbuffers["mask"], 0.0).item()
    out = Path(out_dir)
    wt.io.write_png(out / "target.png", np.concatenate(list(targets.numpy()), axis=1))
    wt.io.write_png(out / "fitted.png", np.concatenate(list(fitted.numpy()), axis=1))
    tiling = log_tiling.exp().item()
    return {
        "psnr": psnr(mse),
        "tiling": tiling,
        "tiling_error": abs(tiling / TRUE_TILING - 1.0),
        "weight_mae": float((weights - true_maps).abs().mean()),
        "iterations": steps,
    }


def scan_tiling(loss, log_tiling: torch.Tensor, half_range: float, count: int) -> None:
    """Set ``log_tiling`` to the best of ``count`` values in ``± half_range`` around it (by
    ``loss()``), refined by the vertex of the parabola through the best and its neighbours."""
    deltas = np.linspace(-half_range, half_range, count)
    start = log_tiling.item()
    values = []
    with torch.no_grad():
        for d in deltas:
            log_tiling.fill_(start + d)
            values.append(loss().item())
        best = int(np.argmin(values))
        chosen = start + deltas[best]
        if 0 < best < count - 1:
            a, b, c = values[best - 1], values[best], values[best + 1]
            curvature = a - 2 * b + c
            if curvature > 0:
                chosen += 0.5 * (a - c) / curvature * (deltas[1] - deltas[0])
        log_tiling.fill_(chosen)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out/torch_fit", help="output folder (default: %(default)s)")
    parser.add_argument("--iters", type=int, default=240, help="Adam iterations (default: %(default)s)")
    parser.add_argument("--views", type=int, default=2, choices=(1, 2, 3), help="camera views fitted together (default: %(default)s)")
    args = parser.parse_args(argv)
    wt.init_quietly()  # no Warp banner, CUDA-driver warning or compile log between the progress lines
    if args.iters < 0:
        parser.error("--iters must be >= 0")
    r = fit(args.out, iters=args.iters, views=args.views)
    print(f"PSNR {r['psnr']:.2f} dB, tiling {r['tiling']:.6f} ({100 * r['tiling_error']:.3f}% off), splat weights MAE {r['weight_mae']:.4f}")
    print(f"wrote {args.out}/target.png and {args.out}/fitted.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
