"""Dr.Jit peers: every technique built on ``drjit.llvm.ad.Texture2f`` (LLVM backend, vectorised JIT),
forward and forward + backward to the texture tensors (``dr.enable_grad``, ``dr.backward``).

How warptex's sampling maps onto ``Texture2f`` (``FilterMode.Linear``):

- Wrap: ``WrapMode.Repeat``; coordinates are reduced with ``u - floor(u)`` first, as warptex does,
  so large UVs keep their fraction. Clamp (splat maps): ``WrapMode.Clamp``.
- UV convention: Dr.Jit's texel centres are at ``(j + 0.5) / W, (i + 0.5) / H`` with row 0 first,
  the same grid as warptex's with ``v`` flipped: the query is ``(u, 1 - v)``.
- Mips: Dr.Jit textures have none, so each level is its own ``Texture2f`` (and each layer of a
  splat its own texture) built from the same level arrays; trilinear with a per-sample LOD sends
  each lane to the pair of level textures around its LOD with ``dr.switch`` (a symbolic call)
  and blends them by ``1 - f`` / ``f``.
- Zero-weight projections, layers and taps are masked off (``active``), as the kernels skip them.
- Every timed call ends with ``dr.eval`` + ``dr.sync_thread``: Dr.Jit traces lazily, so this is
  what makes it run the fused kernel (and, for the backward, the scatter-adds into the texels).
- Every array is handed over 64-byte aligned (:func:`aligned`). The LLVM backend maps a NumPy
  array in place, and reads a texel's channels with one packet gather only where the texels
  start on a boundary of its vector width × 4 bytes (drjit-core's ``jitc_var_gather_packet``
  checks ``unaligned``); elsewhere it gathers each channel on its own. Where a NumPy array
  starts depends on the allocator's history, so without this a process drew Dr.Jit's pace at
  random: bilinear on the benchmark sphere took 2.0–2.5 ms aligned and 3.3–4.6 ms not.
"""

from __future__ import annotations

import numpy as np

from . import Peer, PeerUnavailable, common
from .common import SPLAT_LAYERS, layer_tiling, lod_kind, options, texel_format, uv_grads

MIN_LLVM = 17  # 15.0.6 and 16.0.6 fail as described below; 19.1.7 works

IMPORTED = False
try:
    import drjit as dr
    from drjit.llvm.ad import Array2f, Float, TensorXf, TensorXf16, Texture2f, Texture2f16, UInt32
except ImportError as err:  # the peers are optional
    dr = None
    UNAVAILABLE = f"drjit is not installed ({err})"
except Exception as err:  # noqa: BLE001 (the LLVM backend failed to start)
    dr = None
    UNAVAILABLE = f"drjit's LLVM backend is unavailable ({type(err).__name__}: {err}); install libLLVM (apt-get install llvm) or set DRJIT_LIBLLVM_PATH"
else:
    IMPORTED = True
    UNAVAILABLE = None


def _llvm_problem() -> str | None:
    """Why Dr.Jit's LLVM (CPU) backend cannot run here, or ``None``."""
    if not dr.has_backend(dr.JitBackend.LLVM):
        return "drjit's LLVM backend is unavailable (libLLVM not found): apt-get install libllvm19, or set DRJIT_LIBLLVM_PATH"
    if dr.detail.llvm_version()[0] < MIN_LLVM:
        # LLVM 15 and 16 abort the process ("LLVM ERROR: Cannot select: fminimum") on Dr.Jit's
        # float min/max on x86, so an older libLLVM must not be used at all.
        return (
            f"drjit loaded libLLVM {'.'.join(map(str, dr.detail.llvm_version()))}, whose x86 backend aborts on Dr.Jit's "
            f"float min/max; needs LLVM >= {MIN_LLVM}: apt-get install libllvm19 (Dr.Jit picks the newest), or set DRJIT_LIBLLVM_PATH"
        )
    return None


if IMPORTED:
    UNAVAILABLE = _llvm_problem()


def set_device(device: str) -> None:
    """The LLVM backend on the CPU, the CUDA backend on a GPU (the types of both modules rebound)."""
    global Array2f, Float, TensorXf, TensorXf16, Texture2f, Texture2f16, UInt32, UNAVAILABLE
    from . import drjit_stochastic

    if device == "cpu":
        UNAVAILABLE = _llvm_problem()
        if UNAVAILABLE:
            raise PeerUnavailable(UNAVAILABLE)
        import drjit.llvm.ad as backend
    else:
        if not dr.has_backend(dr.JitBackend.CUDA):
            raise PeerUnavailable("drjit's CUDA backend is unavailable (no CUDA driver or GPU)")
        import drjit.cuda.ad as backend
        UNAVAILABLE = None
    Array2f, Float, TensorXf, Texture2f, UInt32 = backend.Array2f, backend.Float, backend.TensorXf, backend.Texture2f, backend.UInt32
    TensorXf16, Texture2f16 = backend.TensorXf16, backend.Texture2f16
    drjit_stochastic.Float, drjit_stochastic.Float64, drjit_stochastic.Int32, drjit_stochastic.UInt32 = backend.Float, backend.Float64, backend.Int32, backend.UInt32


def synchronize() -> None:
    dr.sync_thread()


PLANES = ((2, 1), (0, 2), (0, 1))
TO_WORLD = ((2, 1, 0), (0, 2, 1), (0, 1, 2))


def set_threads(count: int) -> None:
    dr.set_thread_count(count)


# -- textures and the sampling core ---------------------------------------------------------------

ALIGN = 64  # bytes: the widest LLVM vector Dr.Jit uses (16 floats) and a cache line


def aligned(a, dtype=np.float32) -> np.ndarray:
    """A C-contiguous copy of ``a`` in ``dtype`` that starts on an ``ALIGN``-byte boundary (see the
    module's docstring: Dr.Jit uses its arrays in place and gathers packets only from aligned ones)."""
    a = np.asarray(a, dtype)
    buffer = np.empty(a.nbytes + ALIGN, np.uint8)
    start = -buffer.ctypes.data % ALIGN
    out = buffer[start : start + a.nbytes].view(dtype).reshape(a.shape)
    out[...] = a
    return out


class Chain:
    """One ``Texture2f`` per mip level of one image; ``tensors`` are the AD leaves when trained.
    ``half``: ``Texture2f16`` on half texels instead (lookups still return float32)."""

    def __init__(self, levels, *, grad: bool, wrap_mode=None, half: bool = False):
        tensor, texture = (TensorXf16, Texture2f16) if half else (TensorXf, Texture2f)
        self.tensors = [tensor(aligned(a, np.float16 if half else np.float32)) for a in levels]
        if grad:
            for t in self.tensors:
                dr.enable_grad(t)
        mode = dr.WrapMode.Repeat if wrap_mode is None else wrap_mode
        self.textures = [texture(t, filter_mode=dr.FilterMode.Linear, wrap_mode=mode) for t in self.tensors]
        self.size = (levels[0].shape[1], levels[0].shape[0])
        self.channels = levels[0].shape[2]
        self.top = len(levels) - 1
        self.targets = [self._level_pair(k) for k in range(len(levels))]

    def _level_pair(self, k):
        """Target ``k`` of the trilinear ``dr.switch``: level ``k`` blended with ``k + 1`` by ``f``."""
        fine = self.textures[k]
        coarse = self.textures[k + 1] if k < self.top else None

        def target(pos, f, active=True):
            value = fine.eval(pos, active)
            if coarse is None:  # the LOD is clamped to the chain, so f = 0 here
                return value
            return value * (1.0 - f) + coarse.eval(pos, active) * f

        return target


def _chains(levels, grad, layered=False, half=False):
    """A :class:`Chain` (or, for ``(L, h, w, C)`` levels, one per layer)."""
    if not layered:
        return Chain(levels, grad=grad, half=half)
    return [Chain([lv[j] for lv in levels], grad=grad, half=half) for j in range(levels[0].shape[0])]


def wrap(u):
    return u - dr.floor(u)


def _zeros(count):
    return [Float(0.0) for _ in range(count)]


def _add(out, active, weight, value):
    """``out += weight · value`` on the ``active`` lanes (channel lists)."""
    return [o + dr.select(active, weight * c, 0.0) for o, c in zip(out, value)]


def sample(chain: Chain, u, v, lod, active=True):
    """Wrap-addressed read: bilinear on level 0 when ``lod`` is None, else trilinear; list of channels.

    Trilinear dispatches each lane to its level pair with ``dr.switch`` (symbolic call: per SIMD
    packet, one call per distinct level among its active lanes), the idiomatic Dr.Jit way to pick
    one of several textures per lane; it was 2-4x faster here than masked lookups of every level.
    """
    pos = Array2f(wrap(u), 1.0 - wrap(v))
    if lod is None:
        return list(chain.textures[0].eval(pos, active))
    l = dr.clip(lod, 0.0, float(chain.top))
    base = dr.floor(l)
    return list(dr.switch(UInt32(base), chain.targets, pos, l - base, active=active))


def lod_from_derivatives(size, dx, dy):
    """``0.5 log2(max(|dx·size|², |dy·size|², 1e-30))`` for ``dx, dy`` = (x, y) pairs of Floats."""
    a = (dx[0] * size[0], dx[1] * size[1])
    b = (dy[0] * size[0], dy[1] * size[1])
    return 0.5 * dr.log2(dr.maximum(dr.maximum(a[0] * a[0] + a[1] * a[1], b[0] * b[0] + b[1] * b[1]), 1e-30))


_sample_lod = common.sized_sample_lod(lod_from_derivatives)


def _columns(a):
    a = np.asarray(a, np.float32)
    return [Float(aligned(a[:, c])) for c in range(a.shape[1])] if a.ndim == 2 else Float(aligned(a))


# -- peers ----------------------------------------------------------------------------------------------


def _prepare(technique):
    def prepare(data):
        state = {k: _columns(data[k]) for k in ("uv", "lod", "uv_dx", "uv_dy", "position", "normal", "position_dx", "position_dy", "mask") if k in data}
        state["options"] = options(data, technique)
        state["lod_kind"] = "none" if technique == "bilinear" else lod_kind(data)
        if uv_grads(data):  # forward_backward's own UV columns, which take gradients
            state["train_uv"] = _columns(data["uv"])
            for c in state["train_uv"]:
                dr.enable_grad(c)
        half = texel_format(data) == "float16"  # textures and layers; splat maps stay float32
        for mode, grad in (("infer", False), ("train", True)):
            if technique in SPLAT_LAYERS:
                maps = np.asarray(data["maps"], np.float32)
                state[mode] = {
                    "layers": _chains(data["layer_levels"], grad, layered=True, half=half),
                    "maps": [Chain([m], grad=grad, wrap_mode=dr.WrapMode.Clamp) for m in maps],
                }
            else:
                state[mode] = {"texture": _chains(data["levels"][:1] if technique == "bilinear" else data["levels"], grad, half=half)}
        if technique in SPLAT_LAYERS:
            state["tiling"] = [float(t) for t in layer_tiling(data, len(data["layer_levels"][0]))]
        return state

    return prepare


def _sign(x):
    return dr.select(x < 0.0, -1.0, 1.0)


def _power(r, exponent):
    if exponent == 0:
        return Float(1.0) + 0.0 * r
    return dr.select(r > 0.0, dr.exp(exponent * dr.log(dr.maximum(r, 1e-38))), 0.0)


def _weights(n, sharpness, biplanar):
    a = [dr.abs(c) for c in n]
    finite = dr.isfinite(n[0]) & dr.isfinite(n[1]) & dr.isfinite(n[2])
    if biplanar:
        length = dr.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        valid = finite & (length > 0.0)
        a = [c / dr.select(valid, length, 1.0) for c in a]
        minor2 = (a[2] <= a[0]) & (a[2] <= a[1])
        minor1 = ~minor2 & (a[1] <= a[0])
        minor = (~(minor1 | minor2), minor1, minor2)
        w = [dr.select(minor[i], 0.0, _power(dr.clip((a[i] - 0.5773) / (1.0 - 0.5773), 0.0, 1.0), float(sharpness) / 8.0)) for i in range(3)]
    else:
        m = dr.maximum(dr.maximum(a[0], a[1]), a[2])
        valid = finite & (m > 0.0)
        w = [_power(c / dr.select(valid, m, 1.0), float(sharpness)) for c in a]
    total = dr.maximum(w[0] + w[1] + w[2], 1e-20)
    return [dr.select(valid, c / total, 0.0) for c in w]


def _u_sign(n, axis):
    s = _sign(n[axis])
    return s if axis == 2 else -s


def _project(state, axis, tiling, size):
    i, j = PLANES[axis]
    p = state["position"]
    u = p[i] * tiling * _u_sign(state["normal"], axis)
    dx, dy = state["position_dx"], state["position_dy"]
    lod = lod_from_derivatives(size, (dx[i] * tiling, dx[j] * tiling), (dy[i] * tiling, dy[j] * tiling))
    return u, p[j] * tiling, lod


def _planar(biplanar):
    def run(state, tex):
        opts = state["options"]
        chain = tex["texture"]
        w = _weights(state["normal"], opts["sharpness"], biplanar)
        covered = state["mask"] != 0.0
        out = _zeros(chain.channels)
        for axis in range(3):
            active = covered & (w[axis] > 0.0)
            u, v, lod = _project(state, axis, float(opts["tiling"]), chain.size)
            out = _add(out, active, w[axis], sample(chain, u, v, lod, active))
        return out

    return run


def _normalize(v):
    length = dr.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return [dr.select(length > 0.0, c / dr.maximum(length, 1e-30), 0.0) for c in v]


def _blend(t, b, kind):
    if kind == "udn":
        return [t[0] + b[0], t[1] + b[1], b[2]]
    if kind == "rnm":
        n1 = [b[0], b[1], dr.abs(b[2]) + 1.0]
        n2 = [-t[0], -t[1], t[2]]
        s = (n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]) / n1[2]
        r = [n1[k] * s - n2[k] for k in range(3)]
        return [r[0], r[1], r[2] * _sign(b[2])]
    return [t[0] + b[0], t[1] + b[1], t[2] * b[2]]


def _triplanar_normal(state, tex):
    opts = state["options"]
    chain = tex["texture"]
    n = state["normal"]
    w = _weights(n, opts["sharpness"], False)
    unit = _normalize(n)
    covered = state["mask"] != 0.0
    total = _zeros(3)
    strength = float(opts["strength"])
    for axis in range(3):
        active = covered & (w[axis] > 0.0)
        u, v, lod = _project(state, axis, float(opts["tiling"]), chain.size)
        texel = sample(chain, u, v, lod, active)
        x, y = texel[0] * 2.0 - 1.0, texel[1] * 2.0 - 1.0
        z = texel[2] * 2.0 - 1.0 if chain.channels >= 3 else dr.sqrt(dr.maximum(1.0 - x * x - y * y, 0.0))
        t = _normalize([x * strength, y * strength, z])
        t = [t[0] * _u_sign(unit, axis), t[1], t[2]]
        i, j = PLANES[axis]
        r = _blend(t, [unit[i], unit[j], unit[axis]], opts["blend"])
        total = _add(total, active, w[axis], [r[c] for c in TO_WORLD[axis]])
    length = dr.sqrt(total[0] * total[0] + total[1] * total[1] + total[2] * total[2])
    keep = covered & (w[0] + w[1] + w[2] > 0.0)
    return [dr.select(keep, dr.select(length > 1e-12, c / dr.maximum(length, 1e-12), s), 0.0) for c, s in zip(total, unit)]


def _splat(state, tex):
    layers, maps = tex["layers"], tex["maps"]
    uv, dx, dy = state["uv"], state["uv_dx"], state["uv_dy"]
    covered = state["mask"] != 0.0
    count = len(layers)
    pos = Array2f(dr.clip(uv[0], -1.0, 2.0), 1.0 - dr.clip(uv[1], -1.0, 2.0))
    w = []
    for m in maps:
        w.extend(m.textures[0].eval(pos, covered))
    w = [dr.maximum(c, 0.0) for c in w[:count]]
    total = w[0]
    for c in w[1:]:
        total = total + c
    total = dr.maximum(total, 1e-20)
    w = [c / total for c in w]
    out = _zeros(layers[0].channels)
    for j, chain in enumerate(layers):
        t = state["tiling"][j]
        active = covered & (w[j] > 0.0)
        lod = lod_from_derivatives(chain.size, (dx[0] * t, dx[1] * t), (dy[0] * t, dy[1] * t))
        out = _add(out, active, w[j], sample(chain, uv[0] * t, uv[1] * t, lod, active))
    return out


def _bilinear(state, tex):
    u, v = state["uv"]
    return sample(tex["texture"], u, v, None)


def _trilinear(state, tex):
    u, v = state["uv"]
    chain = tex["texture"]
    return sample(chain, u, v, _sample_lod(state, chain.size))


def _leaves(textures):
    """``{name: [[per-level leaf tensors] per layer or map]}``."""
    out = {}
    for name, value in textures.items():
        chains = value if isinstance(value, list) else [value]
        out[name] = [c.tensors for c in chains]
    return out


def _make(technique, body):
    def forward(state):
        out = body(state, state["infer"])
        dr.eval(out)
        dr.sync_thread()
        return out

    def forward_backward(state):
        leaves = _leaves(state["train"])
        for chains in leaves.values():
            for tensors in chains:
                for t in tensors:
                    dr.clear_grad(t)
        train_uv = state.get("train_uv", [])
        for c in train_uv:
            dr.clear_grad(c)
        out = body({**state, "uv": train_uv} if train_uv else state, state["train"])
        total = out[0]
        for c in out[1:]:
            total = total + c
        dr.backward(dr.sum(total))
        grads = {n: [[dr.grad(t) for t in tensors] for tensors in chains] for n, chains in leaves.items()}
        dr.eval(out, grads, [dr.grad(c) for c in train_uv])
        dr.sync_thread()
        return out, grads

    def output(out):
        return np.stack([np.asarray(c, np.float32) for c in out], axis=1)

    def grads(g):
        result = {}
        for name, chains in g.items():
            per_level = [[np.asarray(chain[k], np.float32) for chain in chains] for k in range(len(chains[0]))]
            result[name] = [levels[0] if name == "texture" else np.stack(levels) for levels in per_level]
        return result

    note = "drjit.llvm.ad.Texture2f per mip level, level pair per lane by dr.switch; dr.eval + sync in the call"
    return Peer("drjit", technique, _prepare(technique), forward, forward_backward, output, grads, note, ("float32", "float16"))


def peers() -> dict[str, Peer]:
    from .drjit_stochastic import stochastic as _stochastic

    bodies = common.technique_bodies(bilinear=_bilinear, trilinear=_trilinear, planar=_planar, triplanar_normal=_triplanar_normal, splat=_splat, stochastic=_stochastic)
    return {t: _make(t, b) for t, b in bodies.items()}
