"""Views to fit: a G-buffer and its target image, checked, subsampled and blurred, and the
objective that renders them all (:class:`Objective`), for :func:`warptex.fit.fit_splat`.

Subsampled stages read every ``stride``-th pixel of the G-buffer and of the target (the
derivatives, hence the texture LOD, are the full-resolution ones), so a subsampled render of the
true parameters is exactly the subsampled target. Blurred stages blur the masked render and the
masked target with the same Gaussian, and weight each pixel by the blurred mask.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warptex._warp import paused_tape
from warptex.fit.losses import Loss, blur, gaussian_taps, image_loss, weight_entropy
from warptex.fit.parameters import SplatParameters
from warptex.gbuffer import FIELDS, GBuffer, _gbuffer_device
from warptex.kernels import fit as kf
from warptex._validate import check_layer_count
from warptex.splat import splat
from warptex.texture import TextureArray
from warptex.tiles import checked_memory, tile_rows

__all__ = ["FitView", "Objective", "check_inputs", "prepare_views", "render_view", "subsample_gbuffer", "views_device"]


@dataclass
class FitView:
    """One camera view to fit: a G-buffer and the target image it should render to; or a batch of
    views of one size, rendered in one call per iteration.

    Attributes:
        gbuffer: the view's :class:`GBuffer` ``(H, W)``, or a batch ``(V, H, W)`` (from
            :func:`~warptex.rasterize` with ``V`` cameras).
        target: ``[H, W, C]`` linear colour (``[V, H, W, C]`` for a batch; finite where the mask
            is non-zero); compared with the first ``C`` channels of the render.
        mask: ``[H, W]`` (``[V, H, W]``) per-pixel loss weights (>= 0); default the G-buffer's
            coverage mask. Pixels the G-buffer does not cover are never fitted.
    """

    gbuffer: GBuffer
    target: np.ndarray
    mask: np.ndarray | None = None


#: A target is sharper along its G-buffer's silhouette than elsewhere by this much, or less, only
#: when they are of different views: matching renders here measure 7-25, mismatched ones 0.2-5.5.
LINED_UP_CONTRAST = 3.0


def silhouette_contrast(image: np.ndarray, mask: np.ndarray) -> float | None:
    """How much sharper ``image`` ``[H, W, C]`` is along the silhouette of ``mask`` ``[H, W]`` (the
    pixels either side of its edges) than on average: the mean of the largest difference to a
    neighbour there, over the image's. Far above 1 for a target and its own G-buffer (the object
    against its background); about 1 for a G-buffer of another view. ``None`` where the mask has
    too little silhouette to tell (under 32 pixels) or the image is flat."""
    covered = np.asarray(mask) > 0.5
    lum = np.asarray(image, np.float64).reshape(*covered.shape, -1).mean(axis=-1)
    edge, sharp = np.zeros_like(covered), np.zeros_like(lum)
    for axis in (0, 1):
        step = [slice(None)] * 2
        ahead, behind = tuple(step[:axis] + [slice(1, None)]), tuple(step[:axis] + [slice(None, -1)])
        change = covered[ahead] != covered[behind]
        edge[ahead] |= change
        edge[behind] |= change
        diff = np.abs(lum[ahead] - lum[behind])
        sharp[ahead] = np.maximum(sharp[ahead], diff)
        sharp[behind] = np.maximum(sharp[behind], diff)
    if edge.sum() < 32 or sharp.mean() <= 0.0:
        return None
    return float(sharp[edge].mean() / sharp.mean())


def subsample_gbuffer(gbuffer: GBuffer, stride: int) -> GBuffer:
    """Every ``stride``-th pixel of ``gbuffer`` (rows and columns from 0, of every view of a
    batch), derivatives unchanged."""
    if stride == 1:
        return gbuffer
    pixels = (slice(None),) * (len(gbuffer.resolution) - 2) + (slice(None, None, stride),) * 2

    def sub(a: wp.array) -> wp.array:
        return wp.array(np.ascontiguousarray(a.numpy()[pixels]), dtype=a.dtype, device=a.device)

    arrays = {name: sub(getattr(gbuffer, name)) for name in FIELDS}
    sets = {s: {k: sub(v) for k, v in arrays_.items()} for s, arrays_ in gbuffer.uv_sets.items()}
    return GBuffer(**arrays, uv_sets=sets, camera=None, origin=gbuffer.origin)


@dataclass
class _Prepared:
    """A validated view on the device, with its subsampled versions and its blurred targets."""

    gbuffer: GBuffer
    mask: wp.array  # [H, W]
    target: wp.array  # [H, W, C], 0 where the mask is 0
    batch: "_Batch | None" = None  # the batch this view is view ``index`` of, rendered with it
    index: int = 0
    _strided: dict = field(default_factory=dict)
    _levels: dict = field(default_factory=dict)

    def at(self, stride: int) -> "_Prepared":
        if stride == 1:
            return self
        if stride not in self._strided:
            sub = lambda a: wp.array(np.ascontiguousarray(a.numpy()[::stride, ::stride]), dtype=float, device=a.device)  # noqa: E731
            gbuffer = self.batch.at(stride).view(self.index) if self.batch is not None else subsample_gbuffer(self.gbuffer, stride)
            self._strided[stride] = _Prepared(gbuffer, sub(self.mask), sub(self.target), self.batch, self.index)
        return self._strided[stride]

    def level(self, sigma: float) -> tuple[wp.array, wp.array]:
        """The target and the loss weights at blur ``sigma``: sharp, the target and the mask;
        blurred, ``blur(target · mask)`` (to compare with ``blur(render · mask)``) and ``blur(mask)``."""
        if sigma not in self._levels:
            if sigma == 0:
                self._levels[sigma] = (self.target, self.mask)
            else:
                mask = self.mask.numpy()
                masked = wp.array(self.target.numpy() * mask[..., None], dtype=float, device=self.mask.device)
                weight = blur(mask[..., None], sigma, device=self.mask.device)
                self._levels[sigma] = (blur(masked, sigma), weight.reshape(mask.shape))
        return self._levels[sigma]


@dataclass
class _Batch:
    """A batched G-buffer ``(V, H, W)`` whose views are fitted together, with its subsampled versions."""

    gbuffer: GBuffer
    _strided: dict = field(default_factory=dict)

    def at(self, stride: int) -> GBuffer:
        if stride not in self._strided:
            self._strided[stride] = subsample_gbuffer(self.gbuffer, stride)
        return self._strided[stride]


def views_device(func: str, views, device):
    """The Warp device of a fit: ``device``, which must be the first view's G-buffer's, or that
    G-buffer's device."""
    first = views if isinstance(views, FitView) else next(iter(views), None)
    return _gbuffer_device(func, first.gbuffer, device) if isinstance(first, FitView) else wp.get_device(device)


def check_inputs(views, layers: TextureArray, params: SplatParameters, *, device=None) -> None:
    """The input checks :func:`fit_splat` runs before its first iteration (call it to fail before
    other work): target and G-buffer sizes, non-finite targets, layer counts, devices."""
    prepare_views("fit_splat", views, layers, params, views_device("fit_splat", views, device))


def render_view(gbuffer: GBuffer, layers: TextureArray, params: SplatParameters, options: dict, device=None) -> wp.array:
    """:func:`warptex.splat` of ``gbuffer`` with the current maps, tiling and (when fitted)
    sharpness of ``params`` and the other splat ``options``."""
    kw = dict(options)
    kw["tiling"] = params.tiling
    if params.sharpness is not None:
        kw["sharpness"] = params.sharpness
    return splat(gbuffer, layers, params.maps, device=device, **kw)


def prepare_views(func: str, views, layers: TextureArray, params: SplatParameters, device) -> list[_Prepared]:
    """Every input check, before anything runs (sizes, finiteness, layer counts, devices); the
    views on the device, targets zeroed where the mask is 0."""
    if not isinstance(layers, TextureArray):
        raise TypeError(f"{func}(): layers must be a TextureArray, got {type(layers).__name__}")
    if not isinstance(params, SplatParameters):
        raise TypeError(f"{func}(): params must be SplatParameters, got {type(params).__name__}")
    check_layer_count(func, layers.num_layers, params.maps)
    if params.num_layers != layers.num_layers:
        raise ValueError(f"{func}(): params hold weights for {params.num_layers} layers but there are {layers.num_layers} layers")
    if layers.device != device or params.device != device:
        raise ValueError(f"{func}(): layers ({layers.device}) and params ({params.device}) must be on {device}")
    views = [views] if isinstance(views, FitView) else list(views)
    if not views:
        raise ValueError(f"{func}(): needs at least one view")
    flat = []  # (label, FitView of one (H, W) view, its batch, its index there)
    for k, view in enumerate(views):
        if not isinstance(view, FitView):
            raise TypeError(f"{func}(): view {k} must be a FitView, got {type(view).__name__}")
        if view.gbuffer.samples > 1:
            raise ValueError(
                f"{func}(): view {k}'s G-buffer is supersampled ({view.gbuffer.samples} samples a pixel); a fit compares one "
                "sample a pixel with its target: rasterize the view with the camera itself, not camera.supersampled()"
            )
        _gbuffer_device(func, view.gbuffer, device)
        count = view.gbuffer.num_views
        if count is None:
            flat.append((f"view {k}", view, None, 0))
            continue
        target = np.asarray(view.target, np.float32)
        if target.ndim not in (3, 4) or target.shape[0] != count:
            raise ValueError(f"{func}(): view {k} is a batch of {count} views: its target must be [V, H, W, C] with V = {count}, got shape {target.shape}")
        mask = None if view.mask is None else np.asarray(view.mask, np.float32)
        if mask is not None and (mask.ndim != 3 or mask.shape[0] != count):
            raise ValueError(f"{func}(): view {k} is a batch of {count} views: its mask must be [V, H, W], got shape {mask.shape}")
        batch = _Batch(view.gbuffer)
        flat += [(f"view {k}[{j}]", FitView(view.gbuffer.view(j), target[j], None if mask is None else mask[j]), batch, j) for j in range(count)]
    prepared = []
    for k, (label, view, batch, index) in enumerate(flat):
        hw = view.gbuffer.resolution
        target = np.asarray(view.target, np.float32)
        if target.ndim == 2:
            target = target[..., None]
        if target.ndim != 3 or target.shape[:2] != hw:
            raise ValueError(f"{func}(): {label}: the target is {target.shape[:2]} (H, W) but its G-buffer is {hw}; they must match")
        if not 1 <= target.shape[2] <= layers.channels:
            raise ValueError(f"{func}(): {label}: the target has {target.shape[2]} channels but the layers only {layers.channels}")
        if k and target.shape[2] != prepared[0].target.shape[2]:
            raise ValueError(f"{func}(): {label}: the target has {target.shape[2]} channels, view 0's {prepared[0].target.shape[2]}")
        mask = view.gbuffer.mask.numpy() if view.mask is None else np.asarray(view.mask, np.float32)
        if mask.shape != hw:
            raise ValueError(f"{func}(): {label}: mask must have shape {hw}, got {mask.shape}")
        if not np.isfinite(mask).all() or (mask < 0).any():
            raise ValueError(f"{func}(): {label}: mask must be finite and >= 0")
        mask = mask * (view.gbuffer.mask.numpy() > 0)  # pixels without a surface cannot be fitted
        bad = ~np.isfinite(target) & (mask[..., None] > 0)
        if bad.any():
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"{func}(): {label}: the target has {int(bad.sum())} non-finite value(s) on covered pixels, "
                f"first {target[where]} at (row, col, channel) {where}"
            )
        if mask.sum() <= 0:
            raise ValueError(f"{func}(): {label}: no covered pixel to fit (the mask is all 0)")
        target = np.where(mask[..., None] > 0, target, 0.0).astype(np.float32)
        prepared.append(_Prepared(view.gbuffer, wp.array(mask, dtype=float, device=device), wp.array(target, dtype=float, device=device), batch, index))
    return prepared


#: What a fit's work takes per pixel of a band (the render, its gradient, the blur's buffers, the
#: backward pass's per-pixel arrays), measured; :class:`Objective` cuts views into bands of rows
#: whose pixels take at most its ``memory``.
FIT_PIXEL_BYTES = 450


@dataclass
class _Band:
    """Rows of one or more views rendered in one call: ``gbuffer`` (a band of one view, or a
    whole batch), and for each view ``(prepared view, index in the batch or None, lo, r0, r1)``:
    the band's first row ``lo`` and the rows ``r0 <= r < r1`` it scores (the rest, up to a blur's
    radius on each side, only feeds the blur)."""

    gbuffer: GBuffer
    parts: list


class Objective:
    """The loss of every view's render against its target: masked, blurred, summed over the views
    (one normalisation for all), and the entropy prior; in bands of rows whose work takes at most
    ``memory`` bytes (default :data:`warptex.tiles.DEFAULT_MEMORY`), so views of any size fit.

    ``objective(sigma, stride)`` records the loss on the active tape (every band is kept until its
    backward); :meth:`gradient` takes each band's gradient on a tape of its own before the next
    band, so a fit holds one band's work at a time. Bands never change the loss beyond float
    rounding: a blurred band is rendered with a halo of the blur's radius above and below, and
    scores only its own rows.
    """

    def __init__(self, views: list[_Prepared], layers: TextureArray, params: SplatParameters, options: dict, loss: Loss, entropy: float, device, *, reduce=None, memory: int | None = None):
        self.views, self.layers, self.params, self.options = views, layers, params, options
        self.loss, self.entropy, self.device = loss, entropy, device
        self.reduce = reduce  # sums float64 vectors over the ranks of a distributed fit (None: one process)
        self.memory = checked_memory("fit_splat", memory)
        self.channels = views[0].target.shape[2]
        self._scales = {}

    def normalise(self, keys) -> None:
        """Compute the normalisations of the ``(sigma, stride)`` keys now (one sum over the ranks
        for all of them)."""
        keys = [k for k in dict.fromkeys(keys) if k not in self._scales]
        totals = [sum(float(v.at(stride).level(sigma)[1].numpy().astype(np.float64).sum()) for v in self.views) for sigma, stride in keys]
        if self.reduce is not None and keys:
            totals = self.reduce(totals)
        for key, total in zip(keys, totals):
            self._scales[key] = 1.0 / (float(total) * self.channels)

    def _scale(self, sigma: float, stride: int) -> float:
        """One normalisation for all views (of all ranks), ``1 / (C · Σ weight)``: views count by their pixels."""
        self.normalise([(sigma, stride)])
        return self._scales[(sigma, stride)]

    def __call__(self, sigma: float, stride: int = 1) -> tuple[wp.array, float]:
        """``(loss, mse)``: the loss (float64 ``(1,)``, ``requires_grad``, recorded on the active
        tape, the prior included) and this rank's share of the sharp renders' mean squared error."""
        total = wp.zeros(1, dtype=wp.float64, device=self.device, requires_grad=True)
        mse = wp.zeros(1, dtype=wp.float64, device=self.device)
        for band in self._bands(sigma, stride):
            self._band_loss(band, sigma, stride, total, mse)
        if self.entropy > 0:
            weight_entropy(self.params, self.entropy, out=total)
        return total, float(mse.numpy()[0])

    def gradient(self, sigma: float, stride: int = 1) -> tuple[float, float]:
        """``(loss, mse)`` of the renders (without the prior) as :meth:`__call__`, each band's
        gradient added into the arrays its render reads (the splat maps' texels, ``tiling``,
        ``sharpness``) before the next band is made. The caller takes the rest on its own tape:
        :meth:`~warptex.fit.SplatParameters.apply` and :meth:`prior`."""
        loss = 0.0
        mse = wp.zeros(1, dtype=wp.float64, device=self.device)
        for band in self._bands(sigma, stride):
            part = wp.zeros(1, dtype=wp.float64, device=self.device, requires_grad=True)
            tape = wp.Tape()
            with tape:
                self._band_loss(band, sigma, stride, part, mse)
            tape.backward(loss=part)
            loss += float(part.numpy()[0])
            del tape, part  # the band's arrays go before the next band's are made
        return loss, float(mse.numpy()[0])

    def prior(self) -> wp.array | None:
        """The entropy prior of the current splat maps (float64 ``(1,)``, recorded on the active
        tape), or ``None`` without one."""
        return weight_entropy(self.params, self.entropy) if self.entropy > 0 else None

    def mse(self, stride: int = 1, *, local: bool = False) -> float:
        """The sharp renders' mean squared error over all views (of all ranks; ``local``: this
        rank's share), at the current parameters."""
        with paused_tape():
            value = self(0.0, stride)[1]
        return value if local or self.reduce is None else float(self.reduce([value])[0])

    def _bands(self, sigma: float, stride: int):
        """The bands of every view (:class:`_Band`), each view's rows cut so that a band's pixels,
        its blur halo included, take at most ``memory`` of work; a batch of views whole when all
        of it fits."""
        halo = len(gaussian_taps(sigma)) // 2
        batches = set()
        for full in self.views:
            view = full.at(stride)
            if view.batch is not None:
                batch = view.batch.at(stride)
                if FIT_PIXEL_BYTES * batch.pixel_count <= self.memory:
                    if id(view.batch) not in batches:
                        batches.add(id(view.batch))
                        members = [v.at(stride) for v in self.views if v.batch is view.batch]
                        yield _Band(batch, [(v, v.index, 0, 0, v.mask.shape[0]) for v in members])
                    continue
            height, width = view.mask.shape
            for r0, r1 in tile_rows(height, FIT_PIXEL_BYTES * width, self.memory):
                lo, hi = max(0, r0 - halo), min(height, r1 + halo)
                yield _Band(view.gbuffer.rows(lo, hi), [(view, None, lo, r0, r1)])

    def _band_loss(self, band: _Band, sigma: float, stride: int, out: wp.array, mse: wp.array) -> None:
        """Render ``band`` and add its rows' losses into ``out`` (on the active tape) and their
        sharp squared errors into ``mse`` (off it)."""
        render = render_view(band.gbuffer, self.layers, self.params, self.options, self.device)
        for view, index, lo, r0, r1 in band.parts:
            image = render[index] if index is not None else render  # a view of a batch: its gradient lands in the batch's
            hi = lo + image.shape[0]
            inner = slice(r0 - lo, r1 - lo)
            target, weight = view.level(sigma)
            if sigma > 0:  # the render is 0 off the G-buffer; the user's mask may hide more
                masked = wp.zeros((hi - lo, image.shape[1], self.channels), dtype=float, device=self.device, requires_grad=image.requires_grad)
                wp.launch(kf.mask_kernel, dim=masked.shape, inputs=[image, view.mask[lo:hi]], outputs=[masked], device=self.device)
                scored = blur(masked, sigma)[inner]
            else:
                scored = image[inner]
            image_loss(scored, target[r0:r1], weight=weight[r0:r1], loss=self.loss, scale=self._scale(sigma, stride), out=out, device=self.device)
            with paused_tape():
                image_loss(image[inner], view.target[r0:r1], weight=view.mask[r0:r1], loss=Loss.L2, scale=self._scale(0.0, stride), out=mse, device=self.device)
