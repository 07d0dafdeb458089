"""Compiling warptex's kernels ahead of their first launch, side by side on every core."""

from __future__ import annotations

import warp as wp

from warptex._threads import cpu_count, interruptible


def preload(kernels, device=None) -> None:
    """Compile (or load from Warp's kernel cache) the Warp modules of ``kernels`` for ``device``,
    side by side on every core.

    Warp compiles a module the first time one of its kernels runs, one module after another. A job
    that knows which kernels it will run calls this first, so that a cold start compiles them in
    parallel (each compile is single-threaded, on the CPU and with NVRTC alike).
    """
    from warptex.kernels.family import cpu_only

    device = wp.get_device(device)
    modules = list({id(k.module): k.module for k in kernels if device.is_cpu or not cpu_only(k)}.values())
    if not modules:
        return
    # Waited for interruptibly: Warp's compile pool would first finish every compile under way
    # (seconds each); what is under way then finishes in the background.
    # A CPU launch loads a module's block_dim=1 variant. Given no block_dim, Warp 1.17's force_load
    # compiled the module's default one (256) there, another hash: every kernel compiled twice, the
    # second time on the main thread at its first launch.
    block_dim = 1 if device.is_cpu else None
    interruptible("warptex-preload", wp.force_load, device=device, modules=modules, block_dim=block_dim, max_workers=min(len(modules), cpu_count()))


def precompile(device=None, *, layer_counts=(4,)) -> None:
    """Compile every warptex kernel for ``device`` now, side by side on every core, into Warp's
    kernel cache (the first run of each kernel then starts at once; on a GPU, every kernel but the
    CPU's lane kernels).

    Args:
        device: Warp device (``None``: Warp's default).
        layer_counts: the layer counts whose splat kernels to compile (they come in sizes of 8,
            16, 32... layers).
    """
    from warptex.kernels import all_kernels

    preload(all_kernels(layer_counts), device)
