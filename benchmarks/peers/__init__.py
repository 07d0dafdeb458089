"""Peers of warptex's samplers: the same techniques built on NumPy, PyTorch and Dr.Jit.

``benchmarks/bench_samplers.py`` times these against warptex in the same process, on the same
data (the level arrays of a :class:`warptex.Texture`'s own mip chain, so every peer reads the same
texels), computing the same thing. Each peer is a :class:`Peer`: ``prepare(data)`` converts the
inputs once (untimed), then ``forward(state)`` and ``forward_backward(state)`` are the timed calls;
they return framework objects that :meth:`Peer.output` / :meth:`Peer.grads` turn into NumPy
(untimed). Dr.Jit peers evaluate inside the timed call (``dr.eval`` + ``dr.sync_thread``), so the
time is kernel execution, not lazy graph building.

Usage::

    from peers import load, TECHNIQUES
    peers = load("torch")            # raises PeerUnavailable(reason) without torch
    peer = peers["triplanar"]
    state = peer.prepare(data)       # data: see peers.common (gbuffer_data, sample_data, ...)
    out = peer.output(peer.forward(state))          # (N, C) float32
    out, grads = peer.forward_backward(state)       # grads of sum(out) w.r.t. every texel

``data`` dicts (NumPy, float32, N samples; built by :mod:`peers.common`):

- ``levels``: the texture's mip chain, a list of ``(h_k, w_k, C)`` arrays (level 0 first).
- sample techniques (bilinear, trilinear, hash4, cheap2, hex): ``uv`` ``(N, 2)``, and for a LOD
  either ``lod`` ``(N,)`` or ``uv_dx``/``uv_dy`` ``(N, 2)`` (then trilinear; without, bilinear on
  level 0), plus the stochastic options (``seed``, ``blend``, ``mirror``, ...).
- G-buffer techniques (triplanar, biplanar, triplanar_normal, splat4, splat8): ``position``,
  ``normal``, ``position_dx``, ``position_dy`` ``(N, 3)``, ``mask`` ``(N,)``; splat also ``uv``,
  ``uv_dx``, ``uv_dy``, ``layer_levels`` (list of ``(L, h_k, w_k, C)``) and ``maps``
  ``(M, hm, wm, 4)``; options ``tiling``, ``sharpness``, ``strength``.

With ``data["uv_grads"]`` (bilinear and trilinear; ``bench_samplers.py --uv-grads``),
``forward_backward`` also takes the gradients of the UVs (``common.uv_grads``); a peer without
autodiff has no ``forward_backward`` either way.

Gradients (``forward_backward``, loss = sum of every output value) are returned per texture name
(``"texture"``, or ``"layers"`` and ``"maps"`` for splat) as one array per mip level: every level is
its own leaf, as in warptex when the chain is built outside the ``wp.Tape``
(``tex.grad(k)`` for every ``k``).

:func:`common.warptex_forward` is the warptex call each technique corresponds to. Modules:
``numpy_peer``, ``torch_peer``, ``drjit_peer`` (sampling core, triplanar family, splat) and their
``*_stochastic`` companions (hash4, cheap2, hex); torch and drjit are imported only by theirs.

``limit`` (``limit_peer``) is not a peer but a yardstick: a plain C loop of the bilinear lookup,
compiled at run time, that ``bench_samplers.py --limit`` times beside the peers.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable

BACKENDS = ("numpy", "torch", "drjit")
TECHNIQUES = ("bilinear", "trilinear", "triplanar", "biplanar", "triplanar_normal", "splat4", "splat8", "hash4", "cheap2", "hex")


class PeerUnavailable(RuntimeError):
    """A backend cannot run here; ``str(err)`` says why (e.g. "torch is not installed")."""


@dataclass(frozen=True)
class Peer:
    """One technique on one backend.

    Attributes:
        backend, technique: names from :data:`BACKENDS` and :data:`TECHNIQUES`.
        prepare: ``data -> state``: converts the inputs to the backend's arrays (not timed).
        forward: ``state -> result``: the technique's output (timed).
        forward_backward: ``state -> (result, grads)``: output and the texture gradients of
            ``sum(output)`` (timed); ``None`` when the backend has no autodiff (NumPy).
        output: ``result -> (N, C) float32 NumPy``.
        grads: ``grads -> {texture name: [per-level float32 NumPy arrays]}``.
        note: how the peer is built, in a few words (every peer computes warptex's result; a
            difference in semantics would be stated here).
        formats: the texel formats its textures can be stored in (``data["format"]``, see
            :func:`common.texel_format`): float32, and float16 for torch's half tensors and
            Dr.Jit's ``Texture2f16``.
    """

    backend: str
    technique: str
    prepare: Callable[[dict], Any]
    forward: Callable[[Any], Any]
    forward_backward: Callable[[Any], Any] | None
    output: Callable[[Any], Any]
    grads: Callable[[Any], dict] | None
    note: str = ""
    formats: tuple[str, ...] = ("float32",)


REFERENCES = ("limit",)  # yardsticks, not peers a user would pick
_MODULES = {"numpy": "numpy_peer", "torch": "torch_peer", "drjit": "drjit_peer", "limit": "limit_peer"}


def _module(backend: str):
    if backend not in _MODULES:
        raise ValueError(f"peers.load(): backend must be one of {BACKENDS + REFERENCES}, got {backend!r}")
    module = importlib.import_module(f"{__name__}.{_MODULES[backend]}")
    if module.UNAVAILABLE:
        raise PeerUnavailable(module.UNAVAILABLE)
    return module


def load(backend: str) -> dict[str, Peer]:
    """The peers of ``backend`` by technique name; ``PeerUnavailable`` (with the reason) if it cannot run."""
    return _module(backend).peers()


def unavailable(backend: str) -> str | None:
    """Why ``backend`` cannot run here, or ``None`` when it can."""
    try:
        _module(backend)
    except PeerUnavailable as err:
        return str(err)
    return None


def set_device(backend: str, device: str) -> None:
    """Run ``backend``'s peers on ``device`` (``"cpu"`` or ``"cuda:N"``): torch on that device, Dr.Jit
    on its LLVM or CUDA backend; ``PeerUnavailable`` (with the reason) where the backend cannot."""
    if backend not in _MODULES:
        raise ValueError(f"peers.set_device(): backend must be one of {BACKENDS + REFERENCES}, got {backend!r}")
    module = importlib.import_module(f"{__name__}.{_MODULES[backend]}")
    if not module.IMPORTED:
        raise PeerUnavailable(module.UNAVAILABLE)
    module.set_device(str(device))


def synchronize(backend: str) -> None:
    """Wait for ``backend``'s queued GPU work (timed calls end with it)."""
    _module(backend).synchronize()


def set_threads(backend: str, count: int) -> None:
    """Use ``count`` CPU threads in ``backend`` (``torch.set_num_threads``, ``dr.set_thread_count``;
    NumPy's element-wise work is single-threaded, so this is a no-op there)."""
    _module(backend).set_threads(int(count))
