"""``warptex fit`` under ``torchrun``: one process per rank, each fitting its share of the views.

``torchrun --nproc-per-node N -m warptex fit ...`` (or ``torchrun ... $(which warptex) fit``)
starts N processes and gives each ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK``,
``LOCAL_WORLD_SIZE``, ``MASTER_ADDR`` and ``MASTER_PORT``; :func:`from_environment` reads them
(``WORLD_SIZE`` above 1 makes a distributed fit). Then:

- :meth:`Job.start` joins the job (``init_process_group``: gloo for a CPU device, NCCL for CUDA,
  each rank on ``cuda:LOCAL_RANK`` unless ``--device`` names an index), with a long timeout
  (:data:`STARTUP_TIMEOUT`) for the start, where ranks may be far apart (loading, compiling
  kernels). Without ``WARPTEX_NUM_THREADS`` each rank runs ``cores / LOCAL_WORLD_SIZE`` threads.
  SIGTERM (torchrun sends it to the other ranks when one fails) raises :class:`Terminated`, so
  that a run's staged output is removed and the error says why.
- :meth:`Job.ready`, once a rank has built its views and compiled its kernels: a barrier, then a
  second process group whose timeout is the fit's (``--dist-timeout``, 30 s by default): a rank
  that stops answering during the fit fails the others after that long; one that dies, at once.
- :meth:`Job.finish`: every rank waits for rank 0, which alone writes the outputs, so every
  process of the job ends with the run's outcome; :meth:`Job.close` leaves the job, also after
  an error.
"""

from __future__ import annotations

import os
import signal
from dataclasses import dataclass
from datetime import timedelta

import warp as wp

from warptex._threads import cpu_count, interruptible

#: Seconds the ranks wait for each other while starting and finishing (loading, compiling, writing).
STARTUP_TIMEOUT = 600.0
#: Default seconds a rank waits for the others in a collective of the fit.
DEFAULT_TIMEOUT = 30.0


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived (torchrun stops the other ranks so when one fails): unwinds like Ctrl-C."""

    status = 143

    def __str__(self) -> str:
        return "terminated (SIGTERM: another process of the job failed, or the job was stopped)"


def _terminate(signum, frame):
    raise Terminated()


@dataclass
class Job:
    """This process's place in a torchrun job."""

    rank: int
    world_size: int
    local_rank: int
    local_world_size: int
    backend: str = "gloo"
    group: object = None  # the fit's process group, from ready()

    def device(self, device):
        """The Warp device of this rank: ``device``; ``cuda`` (or Warp's default when it is a CUDA
        device) becomes ``cuda:LOCAL_RANK``, one GPU per rank."""
        chosen = wp.get_device(device)
        if chosen.is_cuda and (device is None or str(device) == "cuda"):
            chosen = wp.get_device(f"cuda:{self.local_rank}")
        return chosen

    def start(self, device) -> None:
        """Join the job's default process group on ``device`` (a Warp device)."""
        try:
            import torch
            import torch.distributed as dist
        except ImportError:
            from warptex._validate import TORCH_HINT

            raise ValueError(f"fit: torchrun started {self.world_size} processes (WORLD_SIZE={self.world_size}), which needs PyTorch, not installed: {TORCH_HINT}") from None
        self.backend = "nccl" if device.is_cuda else "gloo"
        if device.is_cuda:
            torch.cuda.set_device(device.ordinal)
        signal.signal(signal.SIGTERM, _terminate)
        if not os.environ.get("WARPTEX_NUM_THREADS", "").strip():
            from warptex import set_num_threads

            set_num_threads(max(1, cpu_count() // self.local_world_size))
        def join() -> None:
            if device.is_cuda:  # the current CUDA device is the thread's own
                torch.cuda.set_device(device.ordinal)
            self._collective(dist.init_process_group, self.backend, timeout=timedelta(seconds=STARTUP_TIMEOUT))

        # The rendezvous waits in native code for every rank (up to STARTUP_TIMEOUT): waited for
        # interruptibly, so that a Ctrl-C meanwhile stops the rank at once.
        interruptible("warptex-rendezvous", join)

    def ready(self, timeout: float):
        """Wait for every rank, then return the fit's process group (collective ``timeout`` s)."""
        import torch.distributed as dist

        self._collective(dist.barrier)
        self.group = self._collective(dist.new_group, backend=self.backend, timeout=timedelta(seconds=timeout))
        return self.group

    def finish(self) -> None:
        """Wait for every rank (rank 0 writes the outputs first)."""
        import torch.distributed as dist

        self._collective(dist.barrier)

    def close(self) -> None:
        """Leave the job, whatever happened (a process group left open aborts the process at exit);
        nothing to leave where it never started (PyTorch missing: :meth:`start` said so)."""
        try:
            import torch.distributed as dist
        except ImportError:
            return

        if dist.is_initialized():
            dist.destroy_process_group()

    def _collective(self, run, *args, **kwargs):
        from warptex.fit.distributed import DistributedError

        try:
            return run(*args, **kwargs)
        except RuntimeError as err:  # gloo and NCCL raise RuntimeError subclasses
            text = " ".join(str(err).split())
            raise DistributedError(f"fit: rank {self.rank} of {self.world_size}: another process of the job failed or stopped answering ({text})") from err


def from_environment() -> Job | None:
    """The torchrun job this process belongs to, from its environment variables; ``None`` when
    it is not one of several (no ``WORLD_SIZE``, or 1)."""
    if not os.environ.get("WORLD_SIZE", "").strip():
        return None
    values = {}
    for name, default in (("WORLD_SIZE", None), ("RANK", None), ("LOCAL_RANK", "0"), ("LOCAL_WORLD_SIZE", "1")):
        text = os.environ.get(name, default)
        try:
            values[name] = int(text)
        except (TypeError, ValueError):
            raise ValueError(f"fit: WORLD_SIZE is set, so this is a torchrun job, but {name}={text!r} is not a whole number") from None
    world, rank = values["WORLD_SIZE"], values["RANK"]
    if world < 1 or not 0 <= rank < world:
        raise ValueError(f"fit: torchrun gave RANK={rank} and WORLD_SIZE={world}; expected 0 <= RANK < WORLD_SIZE")
    if world == 1:
        return None
    return Job(rank, world, values["LOCAL_RANK"], max(1, values["LOCAL_WORLD_SIZE"]))
