"""The splat-map fitting loop: Adam over :class:`~warptex.fit.SplatParameters`, coarse to fine.

Why coarse to fine: the splat weights are close to a convex problem (a pixel's colour is nearly a
weighted sum of layer colours), but the tiling is not: texture content is periodic, so a render
at the wrong tiling is decorrelated from the target everywhere but near the origin of the
projection, and the loss as a function of tiling is a plateau with a narrow basin around the
truth (about ±8% wide on the default terrain) plus ripples. A tiling that starts 20% off sits on
the plateau, where its gradient points nowhere useful; blurring does not widen the basin enough,
because weights fitted at the wrong tiling absorb part of the blurred texture. The default
schedule (:func:`default_stages`) therefore

1. fits the weights alone against a blurred render and target, on every second pixel (``sigma =
   2`` at stride 2, about 4 px at full resolution: the layers look like their mean colours,
   almost whatever the tiling);
2. **scans** log-tiling over a grid, sharp (a common factor of ``exp(±0.35)``, i.e. 0.70–1.42×
   the current tiling, in 1% steps, on every second pixel), keeps the best and refines it with a
   parabola through its neighbours: a brute-force global search, not gradient descent;
3. fits weights and tiling jointly with Adam at full resolution, the blur shrinking to none and
   the learning rates decaying along a cosine.

The scan is what makes the tiling converge from 20% off; Adam only polishes it. Its range is an
assumption: a tiling outside 0.70–1.42× its initial value is not found by the default schedule
(pass your own ``stages``).

Subsampled and blurred stages: see :mod:`warptex.fit.objective`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp
import warp.optim

from warptex._validate import as_enum, as_float
from warptex._warp import paused_tape
from warptex.fit.losses import Loss, psnr
from warptex.fit.objective import FitView, Objective, prepare_views, render_view, views_device
from warptex.fit.parameters import SplatParameters
from warptex.texture import TextureArray
from warptex.tiles import checked_memory

__all__ = ["FitResult", "Stage", "default_stages", "fit_splat", "render_views"]


@dataclass(frozen=True)
class Stage:
    """One stage of the schedule.

    Attributes:
        iters: Adam iterations (0: only the scan).
        sigma: blur of render and target in pixels of this stage (0: sharp).
        stride: fit every ``stride``-th pixel in both directions (1: all).
        lr_logits, lr_tiling, lr_sharpness: Adam learning rates at the stage start (0 freezes
            that parameter); they decay along a cosine to ``decay ×`` themselves at its end.
        decay: final learning-rate factor.
        scan: ``(half_range, steps)``: before the iterations, scan ``log_tiling`` over
            ``current ± half_range`` in ``steps`` values (one common factor for per-layer
            tiling); ``None``: no scan.
    """

    iters: int
    sigma: float = 0.0
    stride: int = 1
    lr_logits: float = 0.1
    lr_tiling: float = 0.0
    lr_sharpness: float = 0.0
    decay: float = 1.0
    scan: tuple[float, int] | None = None


def default_stages(iters: int = 240, *, fit_tiling: bool = True, fit_sharpness: bool = False) -> list[Stage]:
    """The default coarse-to-fine schedule for ``iters`` Adam iterations in all (see the module
    docstring): 30% weights only, ``sigma = 2`` at stride 2; a sharp tiling scan at stride 2
    (when ``fit_tiling``); 20% joint at ``sigma = 1``; 50% joint and sharp, learning rates
    decaying to 10%."""
    if isinstance(iters, bool) or not isinstance(iters, (int, np.integer)) or iters < 0:
        raise ValueError(f"default_stages(): iters must be an int >= 0, got {iters!r}")
    coarse = (3 * iters) // 10
    middle = iters // 5
    fine = iters - coarse - middle
    lr_t = 0.005 if fit_tiling else 0.0
    lr_s = 0.05 if fit_sharpness else 0.0
    stages = [Stage(coarse, sigma=2.0, stride=2, lr_logits=0.15)]
    if fit_tiling:
        stages.append(Stage(0, sigma=0.0, stride=2, scan=(0.35, 71)))
    stages += [
        Stage(middle, sigma=1.0, lr_logits=0.1, lr_tiling=lr_t, lr_sharpness=lr_s),
        Stage(fine, sigma=0.0, lr_logits=0.1, lr_tiling=lr_t, lr_sharpness=lr_s, decay=0.1),
    ]
    return stages


@dataclass
class FitResult:
    """What :func:`fit_splat` did.

    Attributes:
        history: per Adam iteration: ``loss`` (the stage's objective: blurred, plus the entropy
            prior), ``mse`` and ``psnr`` (the sharp render against the target, all views, on the
            stage's pixels), ``tiling`` (first value), ``stage`` (index into ``stages``).
        scans: per scan: ``{"stage": k, "tiling": [...], "loss": [...], "chosen": t}``.
        stages: the schedule that ran.
        initial_mse, final_mse, final_psnr: of the initial and fitted parameters (sharp, all
            views, every pixel).
        iterations: Adam iterations run.
        seconds: wall time of the call (checks and target preparation included).
        world_size: the number of ranks that fitted (1 without a process group); the history and
            the errors are of all ranks' views, the same on every rank.
    """

    history: dict = field(default_factory=lambda: {"loss": [], "mse": [], "psnr": [], "tiling": [], "stage": []})
    scans: list = field(default_factory=list)
    stages: list = field(default_factory=list)
    initial_mse: float = float("nan")
    final_mse: float = float("nan")
    final_psnr: float = float("nan")
    iterations: int = 0
    seconds: float = 0.0
    world_size: int = 1


def _scan_tiling(objective: Objective, stage: Stage) -> dict:
    """Evaluate the loss at ``log_tiling + δ`` for ``steps`` values of ``δ`` in ``±half_range``
    (of all ranks' views: one sum over the ranks); set ``log_tiling`` to the best, refined by the
    vertex of a parabola through its neighbours."""
    half_range, steps = stage.scan
    params = objective.params
    base = params.log_tiling.numpy().astype(np.float64)
    deltas = np.linspace(-half_range, half_range, int(steps))
    losses = []
    for d in deltas:
        params.log_tiling.assign((base + d).astype(np.float32))
        params.apply()
        with paused_tape():
            losses.append(float(objective(stage.sigma, stage.stride)[0].numpy()[0]))
    losses = np.asarray(losses if objective.reduce is None else objective.reduce(losses))
    k = int(np.argmin(losses))
    best = deltas[k]
    if 0 < k < len(deltas) - 1:
        lm, l0, lp = losses[k - 1 : k + 2]
        curvature = lm - 2 * l0 + lp
        if curvature > 0:
            best += 0.5 * (lm - lp) / curvature * (deltas[1] - deltas[0])
    params.log_tiling.assign((base + best).astype(np.float32))
    params.apply()
    return {"tiling": np.exp(base[0] + deltas).tolist(), "loss": losses.tolist(), "chosen": float(np.exp(base[0] + best))}


def _optimisers(params: SplatParameters, stage: Stage) -> list:
    pairs = ((params.logits, stage.lr_logits), (params.log_tiling, stage.lr_tiling), (params.sharpness_raw, stage.lr_sharpness))
    return [(warp.optim.Adam([a], lr=lr), lr) for a, lr in pairs if a is not None and lr > 0]


def fit_splat(
    views,
    layers: TextureArray,
    params: SplatParameters,
    *,
    stages: list[Stage] | None = None,
    iters: int = 240,
    loss: Loss | str = Loss.L2,
    entropy: float = 0.0,
    splat_options: dict | None = None,
    progress: bool | None = None,
    report_every: int = 0,
    process_group=None,
    memory: int | None = None,
    device=None,
) -> FitResult:
    """Fit splat weights (and tiling, and sharpness) so that the views render like their targets.

    Every input is checked before the first iteration. Each Adam iteration renders every view with
    :func:`warptex.splat`, blurs render and target by the stage's ``sigma``, sums the losses (one
    normalisation over all views, so views count by their pixels), and steps Adam
    (``warp.optim.Adam``; its state is reset at each stage) on the raw parameters.

    Args:
        views: a :class:`FitView` or a list of them; several views constrain the splat maps
            wherever any of them sees the surface. With ``process_group``: this rank's views.
        layers: the ``L`` layers (:class:`TextureArray`), as for :func:`warptex.splat`.
        params: the parameters to fit, updated in place.
        stages: the schedule; default :func:`default_stages` of ``iters`` (with sharpness when
            ``params`` has it).
        iters: total Adam iterations of the default schedule.
        loss: :class:`~warptex.fit.Loss`, ``"l2"`` or ``"l1"``.
        entropy: strength of the weight-entropy prior (:func:`~warptex.fit.weight_entropy`),
            added to every stage's loss; 0 (default) for none.
        splat_options: keyword arguments for :func:`warptex.splat` (``projection``,
            ``height_blend``, ``sharpness``...), the same as the target's; ``tiling`` and, when
            optimised, ``sharpness`` come from ``params``.
        progress: show a tqdm progress bar (``None``: only on a terminal).
        report_every: also print ``iter, stage, objective, psnr, tiling`` every this many
            iterations, and a line where each stage starts (0: never). The objective is the
            stage's loss (blurred, on its pixels, plus the prior), so it jumps where a stage
            starts; the PSNR is of the sharp render.
        process_group: fit data-parallel on a ``torch.distributed`` process group (gloo on the
            CPU, NCCL on CUDA; PyTorch is imported only then): every rank calls ``fit_splat``
            with its own ``views`` (split them with :func:`~warptex.fit.shard`) and the same
            settings; rank 0's ``params`` are broadcast, the gradients are summed over the ranks
            and every rank ends with the same parameters; only rank 0 prints.
            :mod:`warptex.fit.distributed` says how. ``None`` (default): one process.
        memory: bytes the work on one band of a view may take (:class:`~warptex.fit.Objective`,
            default 256 MiB): views are rendered and differentiated in bands of rows, so their
            size is bounded by what their G-buffers and targets take, not by the work.
        device: Warp device (default the first G-buffer's).

    Returns:
        :class:`FitResult`.

    Raises:
        ValueError, TypeError: bad input, before any iteration: a target and its G-buffer of
            different sizes, non-finite target values on covered pixels, splat maps that cannot
            hold the layers, a bad schedule... With a process group, on every rank when one
            rank's input is bad or the ranks' settings differ.
        DistributedError: another rank died, failed or stopped answering during the fit.
    """
    from tqdm import tqdm

    func = "fit_splat"
    start = time.perf_counter()
    reducer = None
    if process_group is not None:
        from warptex.fit.distributed import Reducer

        reducer = Reducer(func, process_group)
    error, settings = None, {}
    try:
        device, kind, entropy, options, prepared, stages = _checked(func, views, layers, params, stages, iters, loss, entropy, splat_options, memory, device)
        if reducer is not None:
            shape = (params.num_layers, params.size, params.maps.texels.shape, params.log_tiling.shape, params.sharpness is not None)
            settings = {"stages": stages, "loss": kind, "entropy": entropy, "parameters": shape, "layers": layers.texels, "target channels": prepared[0].target.shape[2]}
            settings.update({f"splat_options[{k!r}]": v for k, v in sorted(options.items())})
    except (ValueError, TypeError) as err:
        if reducer is None:
            raise
        error, device = err, None
    if reducer is not None:
        reducer.agree(error, settings, device)
        reducer.broadcast(params.arrays)
        if reducer.rank != 0:
            progress, report_every = False, 0

    objective = Objective(prepared, layers, params, options, kind, entropy if reducer is None or reducer.rank == 0 else 0.0, device, reduce=None if reducer is None else reducer.sum, memory=memory)
    objective.normalise([(0.0, 1)] + [key for s in stages for key in ((s.sigma, s.stride), (0.0, s.stride))])
    params.apply()
    result = FitResult(stages=stages, initial_mse=objective.mse(), world_size=1 if reducer is None else reducer.world_size)
    total = sum(s.iters for s in stages)
    bar = tqdm(total=total, desc="fit", unit="it", disable=False if progress else None if progress is None else True)
    if report_every:
        bar.write("fit: 'objective' is the stage's loss (blurred, on the stage's pixels, + prior), so it jumps where a stage starts; 'psnr' is the sharp render's")
    it = 0
    for index, stage in enumerate(stages):
        if report_every:
            bar.write(f"stage {index}: " + _describe(stage))
        if stage.scan is not None:
            bar.set_postfix_str(f"stage {index}: tiling scan")
            result.scans.append({"stage": index, **_scan_tiling(objective, stage)})
            if report_every:
                bar.write(f"stage {index}: tiling scan chose {result.scans[-1]['chosen']:.6f}")
        optimisers = _optimisers(params, stage)
        for k in range(stage.iters):
            factor = stage.decay + (1 - stage.decay) * 0.5 * (1 + math.cos(math.pi * k / max(stage.iters - 1, 1)))
            tape = wp.Tape()  # the parameters' maps and the prior; the renders' bands take tapes of their own
            with tape:
                params.apply()
                prior = objective.prior()
            loss_value, mse = objective.gradient(stage.sigma, stage.stride)
            tape.backward(loss=prior)  # the bands' gradients of the maps, and the prior's, back to the raw parameters
            loss_value += float(prior.numpy()[0]) if prior is not None else 0.0
            if reducer is not None:  # every rank's gradients summed, and its share of loss and MSE
                loss_value, mse = (float(v) for v in reducer.sum_gradients([a.grad for a in params.arrays], [loss_value, mse]))
            for opt, lr in optimisers:
                opt.lr = lr * factor
                opt.step([opt.params[0].grad])
            tape.zero()
            params.zero_grad()
            h = result.history
            for key, v in (("loss", loss_value), ("mse", mse), ("psnr", psnr(mse)), ("tiling", float(params.tiling.numpy()[0])), ("stage", index)):
                h[key].append(v)
            it += 1
            bar.update()
            bar.set_postfix(objective=f"{loss_value:.3e}", psnr=f"{psnr(mse):.2f}", tiling=f"{h['tiling'][-1]:.5f}")
            if report_every and (it % report_every == 0 or it == total):
                bar.write(f"iter {it:4d}/{total}  stage {index}  objective {loss_value:.4e}  psnr {psnr(mse):6.2f} dB  tiling {h['tiling'][-1]:.6f}")
    bar.close()
    params.apply()
    result.final_mse = objective.mse()
    result.final_psnr = psnr(result.final_mse)
    result.iterations = it
    if reducer is not None:
        reducer.check_same(params.arrays)
    result.seconds = time.perf_counter() - start
    return result


def _describe(stage: Stage) -> str:
    """What a stage does, for the report."""
    pixels = "" if stage.stride == 1 else f", every {stage.stride}{'nd' if stage.stride == 2 else 'rd' if stage.stride == 3 else 'th'} pixel"
    scan = "" if stage.scan is None else f"tiling scan of {int(stage.scan[1])} tilings within exp(±{stage.scan[0]:g})"
    if stage.iters == 0:
        return scan + pixels
    return (scan + ", then " if scan else "") + f"{stage.iters} iteration{'s' if stage.iters != 1 else ''}, " + (f"blur {stage.sigma:g} px" if stage.sigma > 0 else "sharp") + pixels


def _checked(func, views, layers, params, stages, iters, loss, entropy, splat_options, memory, device):
    """:func:`fit_splat`'s checks: the device, loss, prior, memory, splat options, prepared views and schedule."""
    device = views_device(func, views, device)
    checked_memory(func, memory)
    kind = as_enum(func, "loss", loss, Loss)
    entropy = as_float(func, "entropy", entropy)
    if entropy < 0:
        raise ValueError(f"{func}(): entropy must be >= 0, got {entropy}")
    if not isinstance(params, SplatParameters):
        raise TypeError(f"{func}(): params must be SplatParameters, got {type(params).__name__}")
    options = dict(splat_options or {})
    for key in ("tiling", "device") + (("sharpness",) if params.sharpness is not None else ()):
        if key in options:
            raise ValueError(f"{func}(): splat_options must not set {key!r}; it comes from params")
    prepared = prepare_views(func, views, layers, params, device)
    stages = default_stages(iters, fit_sharpness=params.sharpness is not None) if stages is None else list(stages)
    for s in stages:
        if not isinstance(s, Stage) or s.iters < 0 or s.sigma < 0 or s.stride < 1 or min(s.lr_logits, s.lr_tiling, s.lr_sharpness, s.decay) < 0:
            raise ValueError(f"{func}(): stages must be Stage objects with iters >= 0, sigma >= 0, stride >= 1 and learning rates >= 0, got {s!r}")
        if s.scan is not None and (len(s.scan) != 2 or not s.scan[0] > 0 or int(s.scan[1]) < 3):
            raise ValueError(f"{func}(): a stage's scan must be (half_range > 0, steps >= 3), got {s.scan!r}")
    return device, kind, entropy, options, prepared, stages


def render_views(views, layers: TextureArray, params: SplatParameters, *, splat_options: dict | None = None) -> list[np.ndarray]:
    """The renders of the views' G-buffers with the current parameters, ``[H, W, C_layers]`` NumPy each
    (``[V, H, W, C_layers]`` for a batch of views)."""
    params.apply()
    return [render_view(view.gbuffer, layers, params, dict(splat_options or {})).numpy() for view in ([views] if isinstance(views, FitView) else views)]
