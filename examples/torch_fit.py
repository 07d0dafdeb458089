"""Recover a terrain's splat maps and tiling from pictures with PyTorch: ``torch.optim.Adam``
through ``warptex.torch``, in one process or data-parallel on ``torch.distributed``.

The problem of ``examples/fit_splat.py`` (the procedural terrain rendered with known splat maps and
a tiling of 1/6 per world unit; the fit starts from uniform weights and a tiling 20% off), solved
the way a PyTorch user would: the parameters are torch tensors (per-texel logits with a softmax
over the layers, a log-tiling), the render is ``warptex.torch.splat`` of all the views in one
call, the loss and the optimiser are torch's. The schedule is ``warptex.fit``'s: coarse to fine
(blurred, every second pixel), with a scan of the tiling, whose loss is not convex.

Under ``torchrun`` it is an ordinary ``all_reduce`` loop (gloo on the CPU): each process renders
its share of the views (camera ``k`` on rank ``k mod N``, :func:`warptex.fit.shard`), the loss is
normalised by the pixels of all of them, the gradients are summed after ``backward()``, and every
rank's Adam takes the same step from the same (broadcast) start; rank 0 writes the outputs.

    python examples/torch_fit.py --out out/torch_fit          # about a minute on 2 CPU cores
    python examples/torch_fit.py --iters 12 --out out/quick   # a quick check
    torchrun --standalone --nproc-per-node 2 examples/torch_fit.py --out out/torch_fit   # the views split over 2 processes
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import sys
from datetime import timedelta
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
from tqdm import tqdm

import warptex as wt
import warptex.torch as wtt
from warptex.scenes import terrain_cameras
from warptex.scenes import TERRAIN_GRID
from warptex.scenes.terrain import terrain
from warptex.scenes.material import terrain_layers, terrain_splat_maps
from warptex.fit import default_stages, psnr, shard
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


def weighted_sse(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The mask-weighted sum of squared errors of the views, render and target blurred alike, and
    the sum of the weights times the channels (``sse / count`` is the mean squared error)."""
    m = mask[..., None]
    weight = blur(m, sigma)
    diff = blur(render * m, sigma) - blur(target * m, sigma)
    return (weight * diff.square()).sum(), weight.sum() * target.shape[-1]


def weight_entropy(weights: torch.Tensor) -> torch.Tensor:
    """Mean over texels of ``-Σ_l w log w``."""
    return -(weights * torch.log(weights.clamp_min(1e-12))).sum(0).mean()


def fit(out_dir="out/torch_fit", *, iters: int = 240, resolution=(192, 256), views: int = 2, progress: bool = True, group=None) -> dict:
    """Render the targets, fit, and (on rank 0) write ``target.png``, ``fitted.png``,
    ``splat_fitted.exr`` (the fitted weights, data) and ``summary.json`` into ``out_dir``.

    ``group``: a ``torch.distributed`` process group to fit data-parallel on (each rank its share
    of the views), or ``None`` for one process.

    Returns ``{"psnr": dB, "tiling": fitted, "tiling_error": relative, "weight_mae": mean |w - true|,
    "iterations": Adam steps, "world_size": processes}``.
    """
    rank, world = (0, 1) if group is None else (dist.get_rank(group), dist.get_world_size(group))

    def all_sum(t: torch.Tensor) -> torch.Tensor:  # in place, over the ranks
        if group is not None:
            dist.all_reduce(t, group=group)
        return t

    mesh = terrain(resolution=TERRAIN_GRID, seed=0)
    cameras = terrain_cameras(resolution, views)
    # This rank's views in one G-buffer (V, H, W): one call renders them all.
    gbuffers = wtt.gbuffer_tensors(wt.rasterize(mesh, shard(cameras, rank=rank, world_size=world)))
    layers = torch.tensor(terrain_layers().numpy())  # [L, 256, 256, 4]: RGB + height
    true_maps = torch.tensor(terrain_splat_maps(mesh, TERRAIN_GRID), dtype=torch.float32)  # [129, 129, 4]
    with torch.no_grad():
        targets = wtt.splat(gbuffers, layers, true_maps, tiling=TRUE_TILING, **OPTIONS)[..., :3]

    num_layers, size = layers.shape[0], TERRAIN_GRID
    logits = torch.zeros((num_layers, *size), requires_grad=True)  # uniform weights
    log_tiling = torch.tensor(math.log(1.2 * TRUE_TILING), requires_grad=True)  # 20% off
    if group is not None:  # every rank starts from rank 0's parameters, as DistributedDataParallel does
        for p in (logits, log_tiling):
            dist.broadcast(p.data, src=dist.get_global_rank(group, 0), group=group)

    def loss(g, target, sigma, count):
        """This rank's share of the loss: its views' squared errors over the weight of all ranks'
        views, and (on rank 0 only) the prior."""
        weights = torch.softmax(logits, dim=0)
        render = wtt.splat(g, layers, weights.permute(1, 2, 0), tiling=log_tiling.exp(), **OPTIONS)[..., :3]
        value = weighted_sse(render, target, g["mask"], sigma)[0] / count
        return value + ENTROPY * weight_entropy(weights) if rank == 0 else value

    steps = 0
    bar = tqdm(total=iters, desc="torch fit", unit="it", disable=None if progress and rank == 0 else True)  # None: only on a terminal
    for stage in default_stages(iters):
        g, target = views_at(gbuffers, targets, stage.stride)
        with torch.no_grad():
            count = all_sum(weighted_sse(target, target, g["mask"], stage.sigma)[1])
        if stage.scan is not None:
            scan_tiling(functools.partial(loss, g, target, stage.sigma, count), log_tiling, *stage.scan, reduce=all_sum)
        if stage.iters == 0:
            continue
        groups = [{"params": [logits], "lr": stage.lr_logits}, {"params": [log_tiling], "lr": stage.lr_tiling}]
        optimiser = torch.optim.Adam(groups)
        base = [group["lr"] for group in optimiser.param_groups]
        for k in range(stage.iters):
            cosine = stage.decay + (1 - stage.decay) * 0.5 * (1 + math.cos(math.pi * k / stage.iters))
            for param_group, lr in zip(optimiser.param_groups, base, strict=True):
                param_group["lr"] = lr * cosine
            optimiser.zero_grad()
            value = loss(g, target, stage.sigma, count)
            value.backward()
            for p in (logits, log_tiling):  # the gradients of all ranks' views
                all_sum(p.grad)
            optimiser.step()
            steps += 1
            bar.update(1)
            bar.set_postfix(objective=f"{all_sum(value.detach()).item():.3g}", tiling=f"{log_tiling.exp().item():.5f}")
    bar.close()

    with torch.no_grad():
        weights = torch.softmax(logits, dim=0).permute(1, 2, 0)
        fitted = wtt.splat(gbuffers, layers, weights, tiling=log_tiling.exp(), **OPTIONS)[..., :3]
        sse, count = weighted_sse(fitted, targets, gbuffers["mask"], 0.0)
        mse = (all_sum(sse) / all_sum(count)).item()
    tiling = log_tiling.exp().item()
    result = {
        "psnr": psnr(mse),
        "tiling": tiling,
        "tiling_error": abs(tiling / TRUE_TILING - 1.0),
        "weight_mae": float((weights - true_maps).abs().mean()),
        "iterations": steps,
        "world_size": world,
    }
    if rank == 0:  # the pictures show every view: rank 0 renders the others' too
        every = gbuffers if world == 1 else wtt.gbuffer_tensors(wt.rasterize(mesh, cameras))
        with torch.no_grad():
            targets = wtt.splat(every, layers, true_maps, tiling=TRUE_TILING, **OPTIONS)[..., :3]
            fitted = wtt.splat(every, layers, weights, tiling=log_tiling.exp(), **OPTIONS)[..., :3]
        out = Path(out_dir)
        wt.io.write_png(out / "target.png", np.concatenate(list(targets.numpy()), axis=1))
        wt.io.write_png(out / "fitted.png", np.concatenate(list(fitted.numpy()), axis=1))
        wt.io.write_exr(out / "splat_fitted.exr", weights.numpy())
        (out / "summary.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def scan_tiling(loss, log_tiling: torch.Tensor, half_range: float, count: int, *, reduce=lambda t: t) -> None:
    """Set ``log_tiling`` to the best of ``count`` values in ``± half_range`` around it (by
    ``loss()``, summed over the ranks by ``reduce``), refined by the vertex of the parabola through
    the best and its neighbours."""
    deltas = np.linspace(-half_range, half_range, count)
    start = log_tiling.item()
    values = []
    with torch.no_grad():
        for d in deltas:
            log_tiling.fill_(start + d)
            values.append(loss())
        values = reduce(torch.stack(values)).tolist()
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
    parser.add_argument("--resolution", default="192x256", help="view size HxW (default: %(default)s)")
    args = parser.parse_args(argv)
    wt.init_quietly()  # no Warp banner, CUDA-driver warning or compile log between the progress lines
    if args.iters < 0:
        parser.error("--iters must be >= 0")
    resolution = tuple(int(v) for v in args.resolution.split("x"))
    group = None
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:  # started by torchrun: join its job
        dist.init_process_group("gloo", timeout=timedelta(seconds=60))
        group = dist.group.WORLD
    r = fit(args.out, iters=args.iters, resolution=resolution, views=args.views, group=group)
    if group is not None:
        dist.barrier()  # leave together: a rank that destroys its group while a peer still talks to it can abort at exit
        dist.destroy_process_group()
    if r["world_size"] == 1 or int(os.environ["RANK"]) == 0:
        print(f"PSNR {r['psnr']:.2f} dB, tiling {r['tiling']:.6f} ({100 * r['tiling_error']:.3f}% off), splat weights MAE {r['weight_mae']:.4f}")
        print(f"wrote {args.out}/target.png, fitted.png, splat_fitted.exr and summary.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
