"""Compiling warptex's kernels ahead of their first launch, side by side on every core."""

from __future__ import annotations

import warp as wp

from warptex._threads import cpu_count, interruptible


def preload(kernels, device=None, *, here: bool = False) -> None:
    """Compile (or load from Warp's kernel cache) the Warp modules of ``kernels`` for ``device``,
    side by side on every core.

    Warp compiles a module the first time one of its kernels runs, one module after another. A job
    that knows which kernels it will run calls this first, so that a cold start compiles them in
    parallel (each compile is single-threaded, on the CPU and with NVRTC alike).

    ``here``: one after another on this thread instead. Warp 1.19 builds a precompiled header of
    its own in each thread that compiles (3 s here), so a new thread for a module or two would
    spend more on that header than on the modules.
    """
    from warptex.kernels.family import cpu_only

    device = wp.get_device(device)
    modules = list({id(k.module): k.module for k in kernels if device.is_cpu or not cpu_only(k)}.values())
    if not modules:
        return
    # A CPU launch loads a module's block_dim=1 variant. Given no block_dim, Warp 1.17's force_load
    # compiled the module's default one (256) there, another hash: every kernel compiled twice, the
    # second time on the main thread at its first launch.
    block_dim = 1 if device.is_cpu else None
    if here:  # max_workers=1: Warp loads them one after another on this thread
        wp.force_load(device=device, modules=modules, block_dim=block_dim, max_workers=1)
    else:  # waited for interruptibly: Warp's compile pool would first finish every compile under
        # way (seconds each); what is under way then finishes in the background
        interruptible("warptex-preload", wp.force_load, device=device, modules=modules, block_dim=block_dim, max_workers=min(len(modules), cpu_count()))


# The (module, device) pairs load_first has loaded, by id: Warp's modules live as long as the process.
_LOADED: set[tuple[int, str]] = set()


def load_first(kernels, device) -> None:
    """Load the Warp modules of ``kernels`` for ``device`` here, compiling those the kernel cache
    lacks, before threads launch them.

    Warp loads a module at the first launch of one of its kernels, and nothing stops two threads
    from doing so at once: each then compiles it. A launch split over threads would compile a
    module as many times as it has threads, side by side (two threads compiled ``warptex.raster``
    twice on a first ``rasterize``; a pool of 16 would hold 16 compilers' memory). After the first
    call for a module and device, a set lookup.
    """
    device = wp.get_device(device)
    todo = [k for k in kernels if (id(k.module), device.alias) not in _LOADED]
    if todo:
        preload(todo, device, here=True)
        _LOADED.update((id(k.module), device.alias) for k in todo)


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
