"""Ctrl-C held back over a block that must not be cut: a set of renames, the libraries' imports,
or the one line that reports how a run ended.

Light on purpose (the standard library only): the command line enters it before importing Warp.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Within the block, a SIGINT (Ctrl-C) waits: it is raised as ``KeyboardInterrupt`` once the
    block is done. Only the main thread can change a signal's handler; elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    pending = []
    signal.signal(signal.SIGINT, lambda number, frame: pending.append(number))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if pending:
        raise KeyboardInterrupt


@contextmanager
def interrupts_ignored() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM are dropped. For the report of a run that already
    failed: torchrun sends SIGTERM to every rank once one fails, which may be while this rank is
    saying why it failed. A handler the block installs itself is kept: that is how a block hands a
    signal on with no moment in between in which the old handler is back. Only the main thread can
    change a signal's handler; elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    kept = {number: signal.signal(number, signal.SIG_IGN) for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for number, handler in kept.items():
            if signal.getsignal(number) is signal.SIG_IGN:
                signal.signal(number, handler)
