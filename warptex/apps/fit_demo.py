"""``warptex fit`` and ``examples/fit_splat.py``: recover splat maps and tiling from images.

Default (synthetic) run: the default terrain seen from several cameras; the target is rendered
with the true splat maps (:func:`warptex.scenes.material.terrain_splat_maps`: height and slope
rules) and the true tiling (1/6) with the real layer textures; the fit starts from uniform weights
and a tiling 20% off, and its result is compared with the truth.

With ``targets`` and ``gbuffers`` (and optionally ``layers``), it fits splat maps to your images:
one G-buffer EXR per target image (:func:`warptex.load_gbuffer`), the same splat options as the
default scene unless you change them.
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import warp as wp
import warp.optim

from warptex import io
from warptex._compile import preload
from warptex.kernels import fit as kfit
from warptex.kernels import sampling as ks
from warptex.kernels import raster as kr
from warptex.kernels import splat as kl
from warptex.camera import checked_resolution
from warptex.fit import FitView, SplatParameters, check_inputs, default_stages, fit_splat, psnr, render_views, shard
from warptex.fit.objective import LINED_UP_CONTRAST, silhouette_contrast
from warptex.apps.fit_report import heat_image, legend, splat_coverage, weights_image, write_curve, write_json
from warptex.raster import rasterize
from warptex.gbuffer_io import load_gbuffer
from warptex._validate import check_layer_count
from warptex.splat import splat
from warptex.options import Sampler
from warptex._output import check_memory, check_output_folder, output_set
from warptex.scenes import TERRAIN_GRID, terrain_cameras
from warptex.apps.shade import side_by_side
from warptex.scenes.terrain import terrain
from warptex.scenes.material import LAYER_NAMES, terrain_layers, terrain_splat_maps
from warptex.texture import TextureArray

#: Peak memory of a fit, measured (peak RSS, 2 views of 192x256 to 768x1024): ~300 MB plus ~630 B
#: per view pixel (G-buffers, renders, per-thread gradients); with a margin.
FIT_BYTES = (400e6, 800.0)
TRUE_TILING = 1.0 / 6.0  # the default scene's layer repeats per world unit
#: A texel counts as covered when the views' bilinear lookups give it at least this much weight
#: in all (about one pixel's worth): such a texel's weights change the images.
COVERED = 1.0


def _kernels(num_layers: int, synthetic: bool, device) -> list:
    """The kernels a fit runs: the synthetic scene's rasteriser, the splat's forward and the
    gradient lanes it keeps layers for, the layers' mip chains, the objective's and Adam's steps.
    Compiled in the main thread at their first launch, a module took the whole of its compile
    (seconds cold) to hear a Ctrl-C."""
    kernels = kl.splat_kernels(capacity=kl.capacity(num_layers), stochastic=False)  # the fit samples plainly
    adam = sys.modules[wp.optim.Adam.__module__]
    used = [kernels.launched(device), kernels.launched(device, grad=True), kernels.kept_lanes, ks.downsample_kernel, kfit.softmax_kernel]
    used += [kr.raster_kernel] if synthetic else []
    return [k for k in used if k is not None] + [k for k in vars(adam).values() if isinstance(k, wp.Kernel)]


def _panels(images, prefix: str) -> np.ndarray:
    return side_by_side({f"{prefix} view {k}": img[..., :3] for k, img in enumerate(images)})


def run_fit(
    out_dir: str | os.PathLike = "out/fit",
    *,
    iters: int = 240,
    resolution=(192, 256),
    views: int = 2,
    seed: int = 0,
    tiling_error: float = 0.2,
    entropy: float = 1e-4,
    loss: str = "l2",
    targets=None,
    gbuffers=None,
    layers=None,
    initial_maps=None,
    map_size=TERRAIN_GRID,
    map_channels: int = 4,
    num_maps: int | None = None,
    tiling: float | None = None,
    fit_tiling: bool = True,
    projection: str = "triplanar",
    height_blend: float | None = 0.2,
    sharpness: float = 4.0,
    filter: str = "anisotropic",
    report_every: int = 20,
    progress: bool | None = None,
    job=None,
    dist_timeout: float = 30.0,
    memory: int | None = None,
    device=None,
) -> dict:
    """Fit splat maps (and tiling) to images and write the results into ``out_dir``.

    Args:
        out_dir: output folder (created if missing).
        iters: Adam iterations of the default coarse-to-fine schedule
            (:func:`warptex.fit.default_stages`); 240 takes about 25 s on 2 CPU cores.
        resolution: ``(height, width)`` of each synthetic view (192×256).
        views: synthetic views, 1–3 (:func:`terrain_cameras`); 2 = three-quarter + top-down.
        seed: terrain and layer seed of the synthetic scene.
        tiling_error: the synthetic fit starts at ``(1 + tiling_error) ×`` the true tiling (0.2).
        entropy: strength of the weight-entropy prior (:func:`warptex.fit.weight_entropy`),
            1e-4: the images leave weights that the height blend hides undetermined; the prior
            takes the least mixed ones. 0 turns it off.
        loss: ``"l2"`` or ``"l1"``.
        targets, gbuffers: your images and their G-buffer EXRs (paths, one G-buffer per target)
            instead of the synthetic scene. Images are linear (PNG/JPG decoded from sRGB); RGB is
            fitted.
        layers: layer image paths (RGBA: colour + height in alpha for height blending); default
            the default scene's four layers.
        initial_maps: splat-map image paths to start from (data, not sRGB; their size sets the
            map size); default uniform weights of ``map_size``.
        map_size: ``(height, width)`` of the fitted splat maps (default 129×129, the default
            terrain's one texel per vertex).
        map_channels, num_maps: channels per splat map and map count (default ``ceil(L/4)`` RGBA).
        tiling: initial tiling (your images; default 1/6, the default scene's).
        fit_tiling: fit the tiling too (scan + Adam) or keep it.
        projection, height_blend, sharpness: the :func:`warptex.splat` options of the targets
            (default: the default scene's: triplanar, 0.2, 4); ``height_blend=None`` for a plain blend.
        filter: the layers' texture filter (:class:`~warptex.Filter`) for the targets and the
            fit; default anisotropic, as ``warptex render`` uses.
        report_every: print ``iter, stage, objective, psnr, tiling`` every this many iterations
            (0: never).
        progress: tqdm progress bar (``None``: only on a terminal).
        job: the torchrun job (:class:`warptex.apps.distributed.Job`, started) this process is a
            rank of, or ``None``: rank ``r`` fits views ``r, r + world_size, ...``
            (:func:`warptex.fit.shard`) and loads only those; rank 0 loads all of them for the
            pictures and alone writes the outputs.
        dist_timeout: with ``job``, the seconds a rank waits for the others in a collective.
        memory: bytes the work on one band of a view may take (:func:`warptex.fit.fit_splat`;
            default 256 MiB).
        device: Warp device.

    Returns:
        The summary written to ``summary.json`` (with ``"files"``: the paths written, and
        ``"world_size"``); on ranks other than 0, which write nothing, ``{"files": [], ...}``.

    Raises:
        ValueError: bad input, before any iteration: a target and its G-buffer of different
            sizes, NaNs in a target, splat maps that cannot hold the layers...
    """
    func = "run_fit"
    start = time.perf_counter()
    check_output_folder(func, out_dir)
    if isinstance(iters, bool) or not isinstance(iters, (int, np.integer)) or iters < 1:
        raise ValueError(f"{func}(): iters must be an int >= 1, got {iters!r}")
    if targets is None and gbuffers is None:
        h, w = resolution = checked_resolution(func, resolution)
        count = views if isinstance(views, (int, np.integer)) else 1  # terrain_cameras() checks it
        check_memory(func, f"a fit of {count} {h}x{w} view(s)", FIT_BYTES[0] + FIT_BYTES[1] * count * h * w)
    if isinstance(report_every, bool) or not isinstance(report_every, (int, np.integer)) or report_every < 0:
        raise ValueError(f"{func}(): report_every must be an int >= 0 (0: never), got {report_every!r}")
    device = wp.get_device(device)
    rank, world = (0, 1) if job is None else (job.rank, job.world_size)
    options = {"projection": projection, "height_blend": height_blend, "sharpness": sharpness, "sampler": Sampler(filter=filter)}
    synthetic = targets is None and gbuffers is None
    # Before anything is loaded or launched (as render and bake do): a cold start compiles every
    # module side by side, and a Ctrl-C is heard during the compiles. The first compile in a
    # process also pays the compiler's own start-up, seconds.
    preload(_kernels(len(layers) if layers is not None else len(LAYER_NAMES), synthetic, device), device)
    if not synthetic:
        problem = user_problem(func, targets, gbuffers, layers=layers, tiling=tiling, options=options, rank=rank, world_size=world, device=device)
    else:
        problem = synthetic_problem(func, resolution=resolution, views=views, seed=seed, tiling_error=tiling_error, layers=layers, options=options, rank=rank, world_size=world, device=device)
    params = initial_parameters(func, problem, initial_maps=initial_maps, map_size=map_size, map_channels=map_channels, num_maps=num_maps, device=device)
    if problem.synthetic and tuple(params.size) != problem.true_maps.shape[:2]:
        raise ValueError(
            f"{func}(): the synthetic fit is scored against the true {problem.true_maps.shape[0]}x{problem.true_maps.shape[1]} splat maps, "
            f"so the fitted maps must be that size too, got {params.size[0]}x{params.size[1]} (map_size or initial_maps)"
        )
    stages = default_stages(iters, fit_tiling=fit_tiling)

    check_inputs(problem.views, problem.layers, params, device=device)  # fit_splat's checks, before anything renders
    mine = problem.views if rank else shard(problem.views, rank=0, world_size=world)
    initial = render_views(problem.views, problem.layers, params, splat_options=options)
    group = None if job is None else job.ready(dist_timeout)
    result = fit_splat(mine, problem.layers, params, stages=stages, loss=loss, entropy=entropy, splat_options=options, progress=progress, report_every=report_every, process_group=group, memory=memory, device=device)
    if rank:
        return {"rank": rank, "world_size": world, "iterations": result.iterations, "files": []}
    fitted = render_views(problem.views, problem.layers, params, splat_options=options)

    summary = measure(problem, params, result, entropy=entropy, loss=loss)
    with output_set(out_dir) as staging:  # every file appears together, or none does
        names = write_outputs(staging, problem, params, result, initial, fitted, summary, stages) + ["summary.json"]
        summary["seconds_total"] = time.perf_counter() - start
        summary["files"] = [str(Path(out_dir) / name) for name in names]
        write_json(staging / "summary.json", summary)
    return summary


@dataclass
class Problem:
    """What a fit fits: the views (G-buffers and target images), the layers and their names, the
    splat options and the starting tiling; for the synthetic scene also the truth."""

    views: list[FitView]
    layers: TextureArray
    names: list[str]
    options: dict
    initial_tiling: float
    true_maps: np.ndarray | None = None
    true_tiling: float | None = None

    @property
    def synthetic(self) -> bool:
        return self.true_maps is not None


def _layers(func: str, layers, options: dict, seed: int, device) -> tuple[TextureArray, list[str]]:
    """The layers (image paths, or the default terrain's) and their names."""
    if layers is None:
        tex, names = terrain_layers(seed=seed, device=device), list(LAYER_NAMES)
    else:
        tex, names = TextureArray.from_files(list(layers), device=device), [Path(p).stem for p in layers]
    if options["height_blend"] is not None and tex.channels < 4:
        raise ValueError(f"{func}(): height blending reads the height from the layers' alpha, but they have {tex.channels} channels; pass RGBA layers, or turn the height blend off (--height-blend none; height_blend=None in Python)")
    return tex, names


def _wanted(items: list, rank: int, world_size: int) -> list:
    """The items rank ``rank`` loads: all on rank 0 (it draws every view), else its shard."""
    mine = shard(items, rank=rank, world_size=world_size)  # fewer views than ranks fail on every rank
    return items if rank == 0 else mine


def synthetic_problem(func: str, *, resolution, views: int, seed: int, tiling_error: float, layers, options: dict, rank: int = 0, world_size: int = 1, device) -> Problem:
    """The default terrain from ``views`` cameras, rendered with its true splat maps and tiling
    (of a job's rank ``rank``: the views :func:`_wanted`)."""
    if not -1.0 < float(tiling_error) < 10.0:
        raise ValueError(f"{func}(): tiling_error must be in (-1, 10), got {tiling_error!r}")
    mesh = terrain(resolution=TERRAIN_GRID, seed=seed)
    gbuffers = [rasterize(mesh, cam, device=device) for cam in _wanted(terrain_cameras(resolution, views), rank, world_size)]
    layer_tex, names = _layers(func, layers, options, seed, device)
    true_maps = layer_weights(terrain_splat_maps(mesh, TERRAIN_GRID), layer_tex.num_layers)
    truth = TextureArray(packed_maps(true_maps), mipmaps=False, device=device)
    targets = [splat(g, layer_tex, truth, tiling=TRUE_TILING, device=device, **options).numpy()[..., :3] for g in gbuffers]
    return Problem([FitView(g, t) for g, t in zip(gbuffers, targets)], layer_tex, names, options, TRUE_TILING * (1.0 + float(tiling_error)), true_maps, TRUE_TILING)


def layer_weights(rules: np.ndarray, num_layers: int) -> np.ndarray:
    """The terrain's four weights (grass, gravel, rock, snow; ``[H, W, 4]``) for ``num_layers``
    layers in that order, ``[H, W, L]``, still summing to 1: with fewer layers, the last one also
    takes the weights of those left out (three layers: rock where there would be snow); past four,
    the extra layers weigh nothing (the fit may still use them)."""
    if num_layers <= rules.shape[-1]:
        weights = rules[..., :num_layers].copy()
        weights[..., -1] += rules[..., num_layers:].sum(axis=-1)
        return weights
    return np.concatenate([rules, np.zeros((*rules.shape[:-1], num_layers - rules.shape[-1]), rules.dtype)], axis=-1)


def packed_maps(weights: np.ndarray, channels: int = 4) -> np.ndarray:
    """Per-layer weights ``[H, W, L]`` as ``ceil(L / channels)`` splat maps ``[M, H, W, channels]``
    (layer ``m·channels + c`` in map ``m``'s channel ``c``; the last map's unused channels 0)."""
    h, w, num_layers = weights.shape
    maps = np.zeros((-(-num_layers // channels) * channels, h, w), np.float32)
    maps[:num_layers] = np.moveaxis(weights, -1, 0)
    return np.ascontiguousarray(maps.reshape(-1, channels, h, w).transpose(0, 2, 3, 1))


def user_problem(func: str, targets, gbuffers, *, layers, tiling, options: dict, rank: int = 0, world_size: int = 1, device) -> Problem:
    """Your target images and their G-buffer EXRs (one per target; of a job's rank ``rank``: the
    views :func:`_wanted`)."""
    targets = [targets] if isinstance(targets, (str, os.PathLike)) else list(targets or [])
    gbuffers = [gbuffers] if isinstance(gbuffers, (str, os.PathLike)) else list(gbuffers or [])
    if not targets or len(targets) != len(gbuffers):
        raise ValueError(f"{func}(): give one G-buffer per target image, got {len(targets)} target(s) and {len(gbuffers)} G-buffer(s)")
    targets, gbuffers = _wanted(targets, rank, world_size), _wanted(gbuffers, rank, world_size)
    gbufs = [load_gbuffer(p, device=device) for p in gbuffers]
    images = [io.read_image(p) for p in targets]
    images = [img[..., :3] if img.shape[-1] >= 3 else img[..., :1] for img in images]
    for target, gbuffer, image, g in zip(targets, gbuffers, images, gbufs):
        contrast = silhouette_contrast(image, g.mask.numpy()) if image.shape[:2] == tuple(g.resolution[-2:]) else None
        if contrast is not None and contrast < LINED_UP_CONTRAST:
            warnings.warn(f"{func}(): the target {os.fspath(target)!r} does not seem to show the view of its G-buffer {os.fspath(gbuffer)!r}: it is no sharper along "
                          f"the G-buffer's silhouette than elsewhere ({contrast:.1f}x its mean contrast; a matching pair gives 7x or more). Check that each "
                          "target has its own G-buffer, in the same order", UserWarning, stacklevel=3)  # fmt: skip
    layer_tex, names = _layers(func, layers, options, 0, device)
    return Problem([FitView(g, t) for g, t in zip(gbufs, images)], layer_tex, names, options, TRUE_TILING if tiling is None else float(tiling))


def initial_parameters(func: str, problem: Problem, *, initial_maps, map_size, map_channels: int, num_maps, device) -> SplatParameters:
    """Uniform weights of ``map_size``, or the splat maps of the ``initial_maps`` images."""
    count = problem.layers.num_layers
    if initial_maps is None:
        return SplatParameters(count, map_size, channels=map_channels, num_maps=num_maps, tiling=problem.initial_tiling, device=device)
    images = [io.read_image(p, data=True) for p in initial_maps]
    if len({image.shape for image in images}) > 1:
        shapes = ", ".join(f"{Path(p).name}: {image.shape[0]}x{image.shape[1]}x{image.shape[2]}" for p, image in zip(initial_maps, images))
        raise ValueError(f"{func}(): the initial splat maps must share one size and channel count, got {shapes}")
    maps = np.stack(images)
    check_layer_count(func, count, TextureArray(maps, mipmaps=False, device=device))
    weights = maps.transpose(1, 2, 0, 3).reshape(*maps.shape[1:3], -1)[..., :count]
    weights = np.maximum(weights, 0.0) + 1e-6  # no all-zero texel
    return SplatParameters(count, maps.shape[1:3], channels=maps.shape[-1], num_maps=maps.shape[0], weights=weights, tiling=problem.initial_tiling, device=device)


def _coverage(problem: Problem, params: SplatParameters) -> np.ndarray:
    return splat_coverage([v.gbuffer.uv_sets["uv0"]["uv"].numpy()[v.gbuffer.mask.numpy() > 0] for v in problem.views if "uv0" in v.gbuffer.uv_sets], params.size)


def measure(problem: Problem, params: SplatParameters, result, *, entropy: float, loss: str) -> dict:
    """The summary: PSNR and tiling; against the truth, the tiling error and the weights' MAE on
    the texels the views cover."""
    fitted_tiling = params.tiling_values().tolist()
    summary = {
        "mode": "synthetic" if problem.synthetic else "user",
        "iterations": result.iterations,
        "initial_psnr_db": psnr(result.initial_mse),
        "final_psnr_db": result.final_psnr,
        "final_mse": result.final_mse,
        "psnr_space": "linear RGB in [0, 1], covered pixels of all views",
        "initial_tiling": problem.initial_tiling,
        "fitted_tiling": fitted_tiling,
        "tiling_scans": [{"stage": s["stage"], "chosen": s["chosen"]} for s in result.scans],
        "entropy_prior": entropy,
        "loss": loss,
        "views": len(problem.views),
        "resolutions": [list(v.gbuffer.resolution) for v in problem.views],
        "map_size": list(params.size),
        "splat_options": {**{k: v for k, v in problem.options.items() if k != "sampler"}, "filter": problem.options["sampler"].filter.value},
        "fit_seconds": result.seconds,
        "world_size": result.world_size,
    }
    if problem.synthetic:
        coverage = _coverage(problem, params)
        err = np.abs(params.weights() - problem.true_maps)
        covered = coverage >= COVERED
        summary.update(
            {
                "true_tiling": problem.true_tiling,
                "tiling_error_percent": 100.0 * abs(fitted_tiling[0] / problem.true_tiling - 1.0),
                "covered_definition": f"texels whose summed bilinear lookup weight over all covered pixels of all views is >= {COVERED} (about one pixel's worth)",
                "covered_texels": int(covered.sum()),
                "covered_fraction": float(covered.mean()),
                "splat_mae_covered": float(err[covered].mean()),
                "splat_mae_by_coverage": {f">={t:g}": float(err[coverage >= t].mean()) for t in (1e-6, 0.25, 1.0, 4.0) if (coverage >= t).any()},
                "splat_mae_all_texels": float(err.mean()),
                "splat_mae_uniform_start": float(np.abs(1.0 / problem.layers.num_layers - problem.true_maps)[covered].mean()),
            }
        )
    return summary


def write_outputs(out: Path, problem: Problem, params: SplatParameters, result, initial, fitted, summary: dict, stages) -> list[str]:
    """The pictures, the fitted maps and the curve (module docstring of ``warptex fit``) in the
    folder ``out``; the names of the files written."""
    files = []

    def png(name, image, data=False):
        io.write_png(out / name, image, data=data)
        files.append(name)

    gbufs = [v.gbuffer for v in problem.views]
    images = [v.target for v in problem.views]
    sky = lambda img, g: np.where(g.mask.numpy()[..., None] > 0, img[..., :3], 0.0)  # noqa: E731
    png("target.png", _panels([sky(i, g) for i, g in zip(images, gbufs)], "target"), data=True)
    png("initial.png", _panels([sky(i, g) for i, g in zip(initial, gbufs)], "initial"), data=True)
    png("fitted.png", _panels([sky(i, g) for i, g in zip(fitted, gbufs)], "fitted"), data=True)
    rows = {}
    for k, (t, i, f, g) in enumerate(zip(images, initial, fitted, gbufs)):
        covered_px = g.mask.numpy() > 0
        t, i, f = sky(t, g), sky(i, g), sky(f, g)
        rows[f"view {k}: target"] = t
        rows[f"view {k}: initial, {psnr(float(np.mean((i - t)[covered_px] ** 2))):.1f} dB"] = i
        rows[f"view {k}: fitted, {psnr(float(np.mean((f - t)[covered_px] ** 2))):.1f} dB"] = f
        rows[f"view {k}: |fitted - target| x 8"] = np.clip(8 * np.abs(f - t), 0, 1)
    png("comparison.png", side_by_side(rows, columns=4), data=True)
    weights = params.weights()
    png("splat_fitted.png", weights_image(weights))
    for m, data in enumerate(params.maps.numpy()):  # the fitted maps as data, e.g. for initial_maps
        name = "splat_fitted.exr" if params.maps.num_layers == 1 else f"splat_fitted_{m}.exr"
        io.write_exr(out / name, data)
        files.append(name)
    panels = {f"fitted ({legend(problem.names)})": weights_image(weights), "coverage (white: >= 4 px)": heat_image(_coverage(problem, params), vmax=4.0)}
    if problem.synthetic:
        png("splat_true.png", weights_image(problem.true_maps))
        err = np.abs(weights - problem.true_maps)
        panels = {"true": weights_image(problem.true_maps), **panels, f"|fitted - true| (white: 0.5), MAE {summary['splat_mae_covered']:.3f}": heat_image(err.mean(axis=-1), vmax=0.5)}
    png("splat_maps.png", side_by_side(panels, columns=2), data=True)
    marks, at = [], 0
    for stage in stages:
        name = "tiling scan" if stage.scan is not None else f"sigma {stage.sigma:g}" + (f", stride {stage.stride}" if stage.stride > 1 else "")
        marks.append((at, name))
        at += stage.iters
    write_curve(out / "curve.png", result.history, stages=marks)
    files.append("curve.png")
    return files
