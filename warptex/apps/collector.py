"""Python's cycle collector in a command's own process: paused through the imports, then back on
with what they made frozen.

The imports make hundreds of thousands of objects that live as long as the process (Warp's parsed
kernels and functions above all), and the collector went over them again and again while they were
made, and over all of them in every full pass of the run after. A warm ``warptex render`` takes
0.74-0.78x the time with them frozen (medians of 3 runs of 6 alternated pairs; docs/performance.md).
Paused alone, without the freeze, the collector only went over them later. Only the process's own
entry (``warptex.apps.cli.entry``) does this: ``main`` called from a user's program leaves their
collector alone.
"""

from __future__ import annotations

import gc

_paused = False  # pause() turned the collector off


def pause() -> None:
    """Turn the collector off until :func:`resume` (where it is on)."""
    global _paused
    _paused = gc.isenabled()
    gc.disable()


def resume() -> None:
    """Where :func:`pause` turned the collector off: every object made so far out of its passes
    (``gc.freeze``), and the collector back on, so that a fit's loop still collects its own cycles."""
    global _paused
    if _paused:
        _paused = False
        gc.freeze()
        gc.enable()
