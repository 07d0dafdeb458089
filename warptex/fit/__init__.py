"""Fitting texturing to images: splat weights, tiling and sharpness recovered by gradient descent.

- :class:`SplatParameters` (:mod:`.parameters`): the optimisable parameters (per-texel logits,
  log-tiling, softplus sharpness) and the splat maps, tiling and sharpness they make;
- :mod:`.losses`: :func:`image_loss` (L2/L1 in linear space), :func:`blur`, :func:`weight_entropy`,
  :func:`psnr`;
- :class:`FitView` and :class:`Objective` (:mod:`.objective`): the views to fit, checked,
  subsampled and blurred, rendered with :func:`warptex.splat`;
- :func:`fit_splat` (:mod:`.loop`): Adam, coarse to fine, with a tiling scan (:func:`default_stages`);
  data-parallel over the ranks of a ``torch.distributed`` process group (:mod:`.distributed`:
  :func:`shard` splits the views, :class:`DistributedError` says a rank failed).
"""

from warptex.fit.distributed import DistributedError, shard
from warptex.fit.loop import FitResult, Stage, default_stages, fit_splat, render_views
from warptex.fit.losses import Loss, blur, gaussian_taps, image_loss, psnr, weight_entropy
from warptex.fit.objective import FitView, Objective, check_inputs, prepare_views
from warptex.fit.parameters import SplatParameters

__all__ = [
    "DistributedError",
    "FitResult",
    "FitView",
    "Loss",
    "Objective",
    "SplatParameters",
    "Stage",
    "blur",
    "check_inputs",
    "default_stages",
    "fit_splat",
    "gaussian_taps",
    "image_loss",
    "prepare_views",
    "psnr",
    "render_views",
    "shard",
    "weight_entropy",
]
