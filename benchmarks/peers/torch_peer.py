"""PyTorch peers: every technique built on ``torch.nn.functional.grid_sample``, forward (under
``torch.inference_mode``) and forward + backward to the texture (each mip level a leaf tensor).

How warptex's sampling maps onto ``grid_sample`` (``align_corners=False``, bilinear):

- Wrap: ``grid_sample`` has no repeat mode, so coordinates are reduced with ``u - floor(u)`` and
  the texture is padded circularly by one texel per side (``F.pad(mode="circular")``); the grid
  then addresses texel ``x`` of the original at padded pixel ``x + 1``. Inference pads once in
  ``prepare``; the training path pads inside the timed call, so gradients reach the texels.
- Clamp (splat maps): ``padding_mode="border"``, which equals clamped texel indices for bilinear.
- UV convention: row 0 is the top (``v`` up), so the grid's ``y`` is ``1 - v``.
- Trilinear with a per-sample LOD: ``grid_sample`` reads one level per call, so the samples are
  grouped by level: level ``k`` is read (one call) by the samples whose LOD lies in ``[k-1, k+1)``
  with weight ``1 - f`` or ``f``, and results are accumulated with ``index_add``. Each sample is
  read on its two levels only, as in a trilinear texture unit.
- Zero-weight projections, layers and taps are skipped (rows compressed), as the kernels do.
- Half textures (``data["format"] = "float16"``): half tensors and a half grid (``grid_sample``
  takes one dtype), on CUDA only. On the CPU, torch 2.13's half ``grid_sample`` (added by
  pytorch PR #134812) is wrong from 256² images up: measured here, 42 of 1,000 random reads of a
  256² RGBA image came back NaN or huge, and the benchmark's scenes aborted the process with heap
  corruption. So on the CPU the peer stores float32 only.
"""

from __future__ import annotations

import numpy as np

from . import Peer, PeerUnavailable, common
from .common import SPLAT_LAYERS, layer_tiling, lod_kind, options, texel_format, uv_grads

try:
    import torch
    import torch.nn.functional as F
except ImportError as err:  # the peers are optional
    torch = F = None
    IMPORTED, UNAVAILABLE = False, f"torch is not installed ({err})"
else:
    IMPORTED, UNAVAILABLE = True, None

PLANES = ((2, 1), (0, 2), (0, 1))
TO_WORLD = ((2, 1, 0), (0, 2, 1), (0, 1, 2))
MASK32 = 0xFFFFFFFF


DEVICE = "cpu"  # where the tensors live (set_device)


def set_device(device: str) -> None:
    """Put every tensor on ``device``: the inputs explicitly, the rest through torch's default device."""
    global DEVICE
    if device != "cpu" and not torch.cuda.is_available():
        raise PeerUnavailable(f"this torch build has no CUDA (torch {torch.__version__})")
    DEVICE = device
    torch.set_default_device(device)


def synchronize() -> None:
    if DEVICE != "cpu":
        torch.cuda.synchronize()


def set_threads(count: int) -> None:
    torch.set_num_threads(count)


def _tensor(a: np.ndarray):
    """A float32 NumPy array as a tensor on :data:`DEVICE`."""
    return torch.from_numpy(np.ascontiguousarray(a, np.float32)).to(DEVICE)


def _numpy(t) -> np.ndarray:
    return t.detach().cpu().numpy()


# -- textures and the sampling core ---------------------------------------------------------------


def _leaves(levels, dtype=None):
    """Each level ``(h, w, C)`` or ``(L, h, w, C)`` as an ``(L, C, h, w)`` tensor (float32, or ``dtype``)."""
    out = []
    for a in levels:
        a = np.asarray(a, np.float32)
        a = a[None] if a.ndim == 3 else a
        out.append(_tensor(a.transpose(0, 3, 1, 2)).to(dtype or torch.float32))
    return out


def pad_wrap(levels):
    return [F.pad(t, (1, 1, 1, 1), mode="circular") for t in levels]


# Fewest grid points per batch: smaller reads stay one batch (one thread).
SPLIT_POINTS = 4096


def grid_sample_points(image, grid):
    """Bilinear ``grid_sample`` of one image ``(1, C, h, w)`` at ``grid`` points ``(n, 2)``: ``(n, C)``.

    ATen's CPU ``grid_sample`` (forward and backward) runs its batches in parallel and each batch
    on one thread, so a single batch of points uses one core whatever ``torch.set_num_threads``
    says. The points are split into one batch per thread over the same image (an ``expand``, no
    copy), as a user who wants all cores would write it: that measured 1.5–2× faster on two
    threads than one batch, forward and backward.

    A half image takes a half grid (``grid_sample`` wants one dtype); its reads come back float32.
    """
    n = grid.shape[0]
    parts = max(1, min(torch.get_num_threads(), n // SPLIT_POINTS))
    pad = (-n) % parts
    if pad:
        grid = torch.cat([grid, grid[:pad]])
    out = F.grid_sample(image.expand(parts, -1, -1, -1), grid.to(image.dtype).view(parts, 1, -1, 2), mode="bilinear", padding_mode="border", align_corners=False)
    return out[:, :, 0].permute(0, 2, 1).reshape(-1, image.shape[1])[:n].float()


def read_level(padded, u, v, layer=0):
    """Bilinear, wrap: level ``padded`` (circularly padded ``(L, C, h+2, w+2)``) at reduced ``u, v``: ``(n, C)``."""
    h, w = padded.shape[-2] - 2, padded.shape[-1] - 2
    gx = (2.0 * w * u + 2.0) / (w + 2) - 1.0
    gy = (2.0 * h * (1.0 - v) + 2.0) / (h + 2) - 1.0
    return grid_sample_points(padded[layer : layer + 1], torch.stack([gx, gy], dim=-1))


def wrap(u):
    return u - torch.floor(u)


def sample(padded, u, v, lod, layer=0):
    """Wrap-addressed read: bilinear on level 0 when ``lod`` is None, else trilinear (grouped by level)."""
    u, v = wrap(u), wrap(v)
    if lod is None:
        return read_level(padded[0], u, v, layer)
    top = len(padded) - 1
    l = lod.clamp(0.0, float(top))
    base = torch.floor(l)
    f = l - base
    lo = base.long()
    out = torch.zeros((len(u), padded[0].shape[1]), dtype=torch.float32)
    if len(u) == 0:
        return out
    first, last = int(lo.min()), min(int(lo.max()) + 1, top)
    for k in range(first, last + 1):
        fine = lo == k
        rows = torch.nonzero(fine | ((lo == k - 1) & (f > 0))).squeeze(1)
        if rows.numel():
            weight = torch.where(fine[rows], 1.0 - f[rows], f[rows])
            out = out.index_add(0, rows, read_level(padded[k], u[rows], v[rows], layer) * weight[:, None])
    return out


def lod_from_derivatives(size, dx, dy):
    """``0.5 log2(max(|dx·size|², |dy·size|², 1e-30))``; ``size`` = level 0's ``(w, h)``."""
    s = torch.tensor(size, dtype=torch.float32)
    a, b = dx * s, dy * s
    return 0.5 * torch.log2(torch.clamp(torch.maximum((a * a).sum(-1), (b * b).sum(-1)), min=1e-30))


_sample_lod = common.sized_sample_lod(lod_from_derivatives)


def _tensors(data, keys):
    return {k: _tensor(data[k]) for k in keys if k in data}


# -- peers ----------------------------------------------------------------------------------------------


def _prepare(technique):
    def prepare(data):
        state = _tensors(data, ("uv", "lod", "uv_dx", "uv_dy", "position", "normal", "position_dx", "position_dy", "mask"))
        if uv_grads(data):
            state["uv"].requires_grad_(True)  # inference_mode's forward takes none
        state["options"] = options(data, technique)
        state["lod_kind"] = "none" if technique == "bilinear" else lod_kind(data)
        names = {"layers": "layer_levels", "maps": "maps"} if technique in SPLAT_LAYERS else {"texture": "levels"}
        state["leaves"] = {}
        half = texel_format(data) == "float16"  # textures and layers as half tensors; maps stay float32
        for name, key in names.items():
            levels = [data[key]] if key == "maps" else data[key][:1] if technique == "bilinear" else data[key]
            dtype = torch.float16 if half and name != "maps" else None
            state["leaves"][name] = [t.requires_grad_(True) for t in _leaves(levels, dtype)]
        if technique in SPLAT_LAYERS:
            state["tiling"] = [float(t) for t in layer_tiling(data, len(data["layer_levels"][0]))]
        with torch.no_grad():  # inference reads textures padded once
            state["padded"] = {n: pad_wrap(v) if n != "maps" else v for n, v in state["leaves"].items()}
        state["padded"] = {n: [t.detach() for t in v] for n, v in state["padded"].items()}
        return state

    return prepare


def _sign(x):
    return torch.where(x < 0, -1.0, 1.0)


def _power(r, exponent):
    if exponent == 0:
        return torch.ones_like(r)
    return torch.where(r > 0, torch.exp(exponent * torch.log(torch.clamp(r, min=1e-38))), 0.0)


def triplanar_weights(n, sharpness):
    a = n.abs()
    m = a.max(dim=1).values
    valid = torch.isfinite(n).all(dim=1) & (m > 0)
    w = _power(a / torch.where(valid, m, 1.0)[:, None], float(sharpness))
    w = w / torch.clamp(w.sum(dim=1, keepdim=True), min=1e-20)
    return torch.where(valid[:, None], w, 0.0)


def biplanar_weights(n, sharpness):
    length = torch.sqrt((n * n).sum(dim=1))
    valid = torch.isfinite(n).all(dim=1) & (length > 0)
    a = n.abs() / torch.where(valid, length, 1.0)[:, None]
    minor = torch.where((a[:, 2] <= a[:, 0]) & (a[:, 2] <= a[:, 1]), 2, torch.where(a[:, 1] <= a[:, 0], 1, 0))
    r = torch.clamp((a - 0.5773) / (1.0 - 0.5773), 0.0, 1.0)
    w = torch.where(torch.arange(3)[None, :] != minor[:, None], _power(r, float(sharpness) / 8.0), 0.0)
    w = w / torch.clamp(w.sum(dim=1, keepdim=True), min=1e-20)
    return torch.where(valid[:, None], w, 0.0)


def _u_sign(n, axis):
    s = _sign(n[:, axis])
    return s if axis == 2 else -s


def _project(state, axis, rows, tiling, size):
    plane = list(PLANES[axis])
    c = state["position"][rows][:, plane] * tiling
    u = c[:, 0] * _u_sign(state["normal"][rows], axis)
    lod = lod_from_derivatives(size, state["position_dx"][rows][:, plane] * tiling, state["position_dy"][rows][:, plane] * tiling)
    return u, c[:, 1], lod


def _planar(biplanar):
    def run(state, padded):
        opts = state["options"]
        n = state["normal"]
        w = (biplanar_weights if biplanar else triplanar_weights)(n, opts["sharpness"])
        tex = padded["texture"]
        size = (tex[0].shape[-1] - 2, tex[0].shape[-2] - 2)
        covered = state["mask"] != 0
        out = torch.zeros((len(n), tex[0].shape[1]))
        for axis in range(3):
            rows = torch.nonzero(covered & (w[:, axis] > 0)).squeeze(1)
            u, v, lod = _project(state, axis, rows, float(opts["tiling"]), size)
            out = out.index_add(0, rows, w[rows, axis, None] * sample(tex, u, v, lod))
        return out

    return run


def _normalize(v):
    length = torch.sqrt((v * v).sum(dim=-1, keepdim=True))
    return torch.where(length > 0, v / torch.clamp(length, min=1e-30), 0.0)


def _decode(texel, strength):
    x, y = texel[:, 0] * 2.0 - 1.0, texel[:, 1] * 2.0 - 1.0
    if texel.shape[1] >= 3:
        z = texel[:, 2] * 2.0 - 1.0
    else:
        z = torch.sqrt(torch.clamp(1.0 - x * x - y * y, min=0.0))
    return _normalize(torch.stack([x * strength, y * strength, z], dim=1))


def _blend(t, b, kind):
    if kind == "udn":
        return torch.stack([t[:, 0] + b[:, 0], t[:, 1] + b[:, 1], b[:, 2]], dim=1)
    if kind == "rnm":
        n1 = torch.stack([b[:, 0], b[:, 1], b[:, 2].abs() + 1.0], dim=1)
        n2 = t * torch.tensor([-1.0, -1.0, 1.0])
        r = n1 * ((n1 * n2).sum(dim=1, keepdim=True) / n1[:, 2:3]) - n2
        return torch.stack([r[:, 0], r[:, 1], r[:, 2] * _sign(b[:, 2])], dim=1)
    return torch.stack([t[:, 0] + b[:, 0], t[:, 1] + b[:, 1], t[:, 2] * b[:, 2]], dim=1)


def _triplanar_normal(state, padded):
    opts = state["options"]
    n = state["normal"]
    w = triplanar_weights(n, opts["sharpness"])
    unit = _normalize(n)
    tex = padded["texture"]
    size = (tex[0].shape[-1] - 2, tex[0].shape[-2] - 2)
    covered = state["mask"] != 0
    total = torch.zeros((len(n), 3))
    for axis in range(3):
        rows = torch.nonzero(covered & (w[:, axis] > 0)).squeeze(1)
        u, v, lod = _project(state, axis, rows, float(opts["tiling"]), size)
        t = _decode(sample(tex, u, v, lod), float(opts["strength"]))
        t = torch.stack([t[:, 0] * _u_sign(unit[rows], axis), t[:, 1], t[:, 2]], dim=1)
        b = unit[rows][:, list(PLANES[axis]) + [axis]]
        total = total.index_add(0, rows, w[rows, axis, None] * _blend(t, b, opts["blend"])[:, list(TO_WORLD[axis])])
    length = torch.sqrt((total * total).sum(dim=1, keepdim=True))
    out = torch.where(length > 1e-12, total / torch.clamp(length, min=1e-12), unit)
    keep = covered & torch.isfinite(n).all(dim=1) & (n.abs().max(dim=1).values > 0)
    return torch.where(keep[:, None], out, 0.0)


def _splat(state, padded):
    layers, maps = padded["layers"], padded["maps"][0]
    uv, dx, dy = state["uv"], state["uv_dx"], state["uv_dy"]
    covered = torch.nonzero(state["mask"] != 0).squeeze(1)
    cuv = uv[covered]
    count = layers[0].shape[0]
    # Splat maps: bilinear, clamp (border padding), level 0; all maps in one call.
    grid = torch.stack([2.0 * cuv[:, 0] - 1.0, 1.0 - 2.0 * cuv[:, 1]], dim=-1)
    w = torch.cat([grid_sample_points(maps[m : m + 1], grid) for m in range(maps.shape[0])], dim=1)  # (n, M·C)
    w = w[:, :count].clamp(min=0.0)
    w = w / torch.clamp(w.sum(dim=1, keepdim=True), min=1e-20)
    size = (layers[0].shape[-1] - 2, layers[0].shape[-2] - 2)
    colour = torch.zeros((len(covered), layers[0].shape[1]))
    for j in range(count):
        rows = torch.nonzero(w[:, j] > 0).squeeze(1)
        t = state["tiling"][j]
        px = covered[rows]
        lod = lod_from_derivatives(size, dx[px] * t, dy[px] * t)
        colour = colour.index_add(0, rows, w[rows, j, None] * sample(layers, uv[px, 0] * t, uv[px, 1] * t, lod, layer=j))
    out = torch.zeros((len(uv), layers[0].shape[1]))
    return out.index_add(0, covered, colour)


def _bilinear(state, padded):
    uv = state["uv"]
    return read_level(padded["texture"][0], wrap(uv[:, 0]), wrap(uv[:, 1]))


def _trilinear(state, padded):
    uv = state["uv"]
    tex = padded["texture"]
    return sample(tex, uv[:, 0], uv[:, 1], _sample_lod(state, (tex[0].shape[-1] - 2, tex[0].shape[-2] - 2)))


def _make(technique, body):
    def forward(state):
        with torch.inference_mode():
            return body(state, state["padded"])

    def forward_backward(state):
        leaves = state["leaves"]
        for levels in leaves.values():
            for t in levels:
                t.grad = None
        if "uv" in state:
            state["uv"].grad = None
        padded = {n: pad_wrap(v) if n != "maps" else v for n, v in leaves.items()}
        out = body(state, padded)
        out.sum().backward()
        return out, {n: [torch.zeros_like(t) if t.grad is None else t.grad for t in v] for n, v in leaves.items()}

    def grads(g):
        return {n: [_numpy(t).transpose(0, 2, 3, 1)[0 if n == "texture" else slice(None)].astype(np.float32) for t in v] for n, v in g.items()}

    note = "F.grid_sample, one call per mip level read (samples grouped by level, split into one batch per thread), wrap by circular padding"
    formats = ("float32",) if DEVICE == "cpu" else ("float32", "float16")  # see the module docstring
    return Peer("torch", technique, _prepare(technique), forward, forward_backward, lambda r: _numpy(r).astype(np.float32), grads, note, formats)


def peers() -> dict[str, Peer]:
    from .torch_stochastic import stochastic as _stochastic

    bodies = common.technique_bodies(bilinear=_bilinear, trilinear=_trilinear, planar=_planar, triplanar_normal=_triplanar_normal, splat=_splat, stochastic=_stochastic)
    return {t: _make(t, b) for t, b in bodies.items()}
