"""Data-parallel fitting on ``torch.distributed``: every rank fits its own views, and the
parameters' gradients are summed over the ranks, so every rank takes the same Adam step.

:func:`warptex.fit.fit_splat` does this when given ``process_group=`` (a
``torch.distributed`` process group: gloo for a fit on the CPU, NCCL for one on CUDA, e.g.
``torch.distributed.group.WORLD`` after ``init_process_group``). PyTorch is imported only then:
the rest of :mod:`warptex.fit` runs without it.

- **Views.** Each rank passes only its own views, so that no rank loads, rasterises or holds the
  others'. :func:`shard` is the split warptex uses (``warptex fit``, ``examples/torch_fit.py``):
  item ``k`` goes to rank ``k mod world_size``, the order of ``DistributedSampler`` without
  shuffling. Apply it to the cameras or file names, before loading anything.
- **Start.** Before the first iteration the ranks exchange the result of their input checks and a
  digest of their settings (schedule, loss, prior, splat options, layers, parameter shapes): an
  error on one rank, or settings that differ, raise on every rank. Then rank 0's parameters are
  broadcast, so every rank starts from the same ones.
- **Iterations.** The loss is normalised by the pixel weight of *all* ranks' views, so the sum of
  the ranks' losses is the one-process loss; the entropy prior is added on rank 0 only. Every
  rank renders and differentiates its views; one ``all_reduce`` (sum, in float64) carries every
  parameter gradient and the loss and MSE of the iteration; the sums are rounded back to float32
  and every rank's Adam steps on them. A tiling scan evaluates each rank's views at every tiling
  and sums the losses in one ``all_reduce``.
- **End.** The ranks compare a digest of their parameters; ranks that disagree raise
  :class:`DistributedError`.

What the number of ranks does to the bits: a run is reproducible bit for bit at a given number of
ranks (gloo's all-reduce adds in an order fixed by the number of ranks, and every rank receives
the same sum). A different number of ranks groups the views' gradients differently (one
process sums every view's texel gradient before the softmax's backward pass; two ranks each
backpropagate their own and add the results), so the fit agrees with one process to float
rounding, not bit for bit (``tests/test_distributed.py`` measures both).

Failures: a rank that dies closes its connections and the others' next collective fails at once;
one that stops answering fails them after the group's timeout (``init_process_group(...,
timeout=)``; ``warptex fit`` sets 30 s). Either raises :class:`DistributedError` naming the rank
that saw it.
"""

from __future__ import annotations

import hashlib
from typing import Sequence

import numpy as np
import warp as wp

__all__ = ["DistributedError", "Reducer", "shard"]


class DistributedError(RuntimeError):
    """A collective of a distributed fit failed: another rank died, stopped answering (the
    group's timeout) or its parameters diverged."""


def shard(items: Sequence, *, rank: int, world_size: int) -> list:
    """The items of rank ``rank`` of ``world_size``: item ``k`` goes to rank ``k mod world_size``
    (``items[rank::world_size]``).

    Args:
        items: anything in a fixed order (cameras, file names, :class:`~warptex.fit.FitView` s).
        rank: this process's rank, ``0 <= rank < world_size``.
        world_size: the number of ranks, ``>= 1``.

    Raises:
        ValueError: a bad rank or world size, or fewer items than ranks (a rank without a view
            has nothing to fit).
    """
    items = list(items)
    for name, value, low in (("world_size", world_size, 1), ("rank", rank, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"shard(): {name} must be an int >= {low}, got {value!r}")
    if rank >= world_size:
        raise ValueError(f"shard(): rank must be < world_size = {world_size}, got {rank}")
    if len(items) < world_size:
        raise ValueError(f"shard(): {world_size} ranks need at least {world_size} views (one each), got {len(items)}")
    return items[rank::world_size]


def digest(*arrays) -> str:
    """A SHA-1 of the bytes, shapes and dtypes of NumPy or Warp arrays."""
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a.numpy() if isinstance(a, wp.array) else np.asarray(a))
        h.update(f"{a.shape}{a.dtype}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def describe(value) -> str:
    """A value of a setting for :meth:`Reducer.agree`: arrays by shape, dtype and digest."""
    if isinstance(value, (wp.array, np.ndarray)):
        return f"array{tuple(value.shape)} {digest(value)[:12]}"
    return repr(value)


class Reducer:
    """The collectives of one distributed fit on ``group`` (see the module docstring).

    Args:
        func: the calling function's name, for messages.
        group: a ``torch.distributed`` process group.

    Attributes:
        rank, world_size: this process's rank in ``group`` and the group's size.
    """

    def __init__(self, func: str, group):
        try:
            import torch
            import torch.distributed as dist
        except ImportError:
            from warptex._validate import TORCH_HINT

            raise TypeError(f"{func}(): process_group needs PyTorch, which is not installed: {TORCH_HINT}") from None
        if not dist.is_available() or not isinstance(group, dist.ProcessGroup):
            raise TypeError(f"{func}(): process_group must be a torch.distributed ProcessGroup (e.g. torch.distributed.group.WORLD), got {type(group).__name__}")
        if not dist.is_initialized():
            raise ValueError(f"{func}(): torch.distributed is not initialised; call torch.distributed.init_process_group() first")
        self.func, self.group, self.torch, self.dist = func, group, torch, dist
        self.rank, self.world_size = dist.get_rank(group), dist.get_world_size(group)
        self.backend = str(dist.get_backend(group)).lower()
        self.device = None
        self.buffer_device = None

    def _collective(self, what: str, run, *args, **kwargs):
        try:
            return run(*args, group=self.group, **kwargs)
        except RuntimeError as err:  # gloo and NCCL raise RuntimeError subclasses (DistBackendError...)
            text = " ".join(str(err).split())
            raise DistributedError(
                f"{self.func}(): rank {self.rank} of {self.world_size}: the {what} failed: another rank of the "
                f"process group died, failed or stopped answering within the group's timeout ({text})"
            ) from err

    def agree(self, error: BaseException | None, settings: dict, device) -> None:
        """Exchange the input checks' outcome and the settings; raise on every rank when a rank's
        checks failed (that rank its own ``error``) or the settings differ."""
        outcomes = [None] * self.world_size
        mine = (None if error is None else f"{type(error).__name__}: {error}", {k: describe(v) for k, v in settings.items()})
        self._collective("exchange of the input checks", self.dist.all_gather_object, outcomes, mine)
        if error is not None:
            raise error
        for rank, (message, _) in enumerate(outcomes):
            if message is not None:
                raise ValueError(f"{self.func}(): rank {rank} of {self.world_size} failed its input checks: {message}")
        differ = [k for k in settings if len({o[1].get(k) for o in outcomes}) > 1]
        if differ:
            values = "; ".join(f"{k}: " + ", ".join(f"rank {r} {o[1].get(k)}" for r, o in enumerate(outcomes)) for k in differ)
            raise ValueError(f"{self.func}(): the ranks must fit with the same settings, but they differ in {values}")
        self.device = wp.get_device(device)
        cuda_buffer = self.backend == "nccl"
        if cuda_buffer and not self.device.is_cuda:
            raise ValueError(f"{self.func}(): a NCCL process group needs the fit on a CUDA device, got {self.device}; use gloo on the CPU")
        self.buffer_device = self.torch.device(wp.device_to_torch(self.device) if cuda_buffer else "cpu")

    def _pack(self, arrays: list[wp.array], values=()):
        wp.synchronize_device(self.device)
        parts = [wp.to_torch(a, requires_grad=False).reshape(-1).to(self.buffer_device, self.torch.float64) for a in arrays]
        parts.append(self.torch.tensor(np.asarray(values, np.float64), device=self.buffer_device))
        return self.torch.cat(parts)

    def _unpack(self, buffer, arrays: list[wp.array]) -> np.ndarray:
        at = 0
        for a in arrays:
            t = wp.to_torch(a, requires_grad=False)
            t.copy_(buffer[at : at + t.numel()].view(t.shape))  # float64 sum -> float32, rounded to nearest
            at += t.numel()
        if self.buffer_device.type == "cuda":
            self.torch.cuda.synchronize(self.buffer_device)
        return buffer[at:].cpu().numpy()

    def sum(self, values) -> np.ndarray:
        """The float64 sum over the ranks of ``values`` (a vector of the same length on every rank)."""
        buffer = self.torch.tensor(np.asarray(values, np.float64).reshape(-1), device=self.buffer_device)
        self._collective("all-reduce", self.dist.all_reduce, buffer)
        return buffer.cpu().numpy()

    def sum_gradients(self, arrays: list[wp.array], values) -> np.ndarray:
        """Replace the float32 ``arrays`` (the parameters' gradients) with their sums over the ranks,
        in one all-reduce with ``values``; the sums of ``values``."""
        buffer = self._pack(arrays, values)
        self._collective("all-reduce of the gradients", self.dist.all_reduce, buffer)
        return self._unpack(buffer, arrays)

    def broadcast(self, arrays: list[wp.array]) -> None:
        """Overwrite ``arrays`` with rank 0's."""
        buffer = self._pack(arrays)
        self._collective("broadcast of the initial parameters", self.dist.broadcast, buffer, src=self.dist.get_global_rank(self.group, 0))
        self._unpack(buffer, arrays)

    def check_same(self, arrays: list[wp.array]) -> None:
        """Raise :class:`DistributedError` on every rank unless every rank holds the same bits."""
        digests = [None] * self.world_size
        self._collective("comparison of the fitted parameters", self.dist.all_gather_object, digests, digest(*arrays))
        if len(set(digests)) > 1:
            raise DistributedError(f"{self.func}(): the ranks' parameters differ after the fit (digests {digests}); every rank must receive the same sums")
