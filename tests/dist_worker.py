"""One rank of the distributed tests of ``warptex.fit.fit_splat`` (tests/test_distributed.py runs it
under ``torchrun``; with no ``WORLD_SIZE`` it is the one-process fit they are compared with).

``python tests/dist_worker.py OUT``: fits the small scene (3 views of a coarse terrain, smooth
layers, 9 × 9 maps, a short schedule with a tiling scan and the entropy prior) twice, each rank its
share of the views, and once more with a different start on every rank but 0, and writes
``OUT/rank{r}.npz`` (raw parameters, history, world size). Under
torchrun it also provokes the failures every rank must report alike and writes their messages to
``OUT/rank{r}.json``: one rank's bad view, ranks with different settings, diverged parameters.
"""

from __future__ import annotations

import json
import os
import sys
from datetime import timedelta
from pathlib import Path

import numpy as np
import warp as wp

import warptex as wt
from warptex.fit import DistributedError, FitView, SplatParameters, Stage, fit_splat, shard
from warptex.fit.distributed import Reducer
from warptex.scenes import terrain_camera
from warptex.scenes.terrain import terrain

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_fit import smooth_layers  # noqa: E402  (the layers of the one-process fit tests)

OPTIONS = {"projection": "triplanar", "height_blend": 0.2}
STAGES = [Stage(4, sigma=1.0, lr_logits=0.2), Stage(0, scan=(0.35, 21)), Stage(5, lr_logits=0.1, lr_tiling=0.005, decay=0.2)]


def scene():
    """Three views of a coarse terrain with targets rendered from random true weights at tiling 0.2."""
    mesh = terrain(resolution=(33, 33))
    cameras = [terrain_camera((24, 32)), wt.look_at((20.0, 30.0, 25.0), (0.0, 3.0, 0.0), resolution=(20, 24)), wt.look_at((-25.0, 28.0, -20.0), (0.0, 2.0, 0.0), resolution=(24, 24))]
    layers = wt.TextureArray(smooth_layers(4))
    true = np.random.default_rng(5).dirichlet(np.full(4, 0.7), size=(9, 9)).astype(np.float32)
    truth = wt.TextureArray(true[None], mipmaps=False)
    views = []
    for camera in cameras:
        g = wt.rasterize(mesh, camera)
        views.append(FitView(g, wt.splat(g, layers, truth, tiling=0.2, **OPTIONS).numpy()[..., :3]))
    return views, layers


def fit(views, layers, group, tiling=0.24, **kw):
    params = SplatParameters(4, (9, 9), tiling=tiling)
    result = fit_splat(views, layers, params, stages=STAGES, entropy=1e-3, splat_options=OPTIONS, progress=False, process_group=group, **kw)
    return params, result


def _message(run) -> str:
    try:
        run()
    except (ValueError, TypeError, DistributedError) as err:
        return f"{type(err).__name__}: {err}"
    return "no error"


def main(out: Path) -> None:
    wp.config.log_level = wp.LOG_WARNING
    views, layers = scene()
    group, rank, world = None, 0, 1
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        import torch.distributed as dist

        dist.init_process_group("gloo", timeout=timedelta(seconds=30))
        group, rank, world = dist.group.WORLD, dist.get_rank(), dist.get_world_size()
    mine = shard(views, rank=rank, world_size=world)
    params, result = fit(mine, layers, group)
    again, _ = fit(mine, layers, group)  # reproducible within a rank count
    moved, _ = fit(mine, layers, group, tiling=0.24 + 0.05 * rank)  # ranks above 0 start elsewhere: rank 0's start is broadcast
    arrays = {f"{k}{suffix}": getattr(p, k).numpy() for suffix, p in (("", params), ("_again", again), ("_moved", moved)) for k in ("logits", "log_tiling")}
    np.savez(out / f"rank{rank}.npz", **arrays, loss=result.history["loss"], mse=result.history["mse"], final_mse=result.final_mse, world_size=result.world_size)
    if group is None:
        return
    bad = [FitView(v.gbuffer, v.target[:, :-1]) for v in mine] if rank == 1 else mine  # rank 1's targets are a column short
    messages = {
        "bad view on rank 1": _message(lambda: fit(bad, layers, group)),
        "entropy differs": _message(lambda: fit_splat(mine, layers, SplatParameters(4, (9, 9), tiling=0.24), stages=STAGES, entropy=1e-3 * (1 + rank), splat_options=OPTIONS, progress=False, process_group=group)),
        "parameters differ": _message(lambda: Reducer("check", group).check_same([wp.array([float(rank == 1)], dtype=float)])),
        "works after the errors": _message(lambda: fit(mine, layers, group)),
    }
    (out / f"rank{rank}.json").write_text(json.dumps(messages, indent=1))
    import torch.distributed as dist

    dist.destroy_process_group()


if __name__ == "__main__":
    main(Path(sys.argv[1]))
