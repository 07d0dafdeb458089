"""The few things warptex needs from Warp that its public API does not offer, in one place.

Everything else warptex does with Warp goes through the public API (``wp.*``, ``wp.types``,
``wp.Tape``). These three reach into Warp's internals, so they live here, each with the reason,
and ``tests/test_warp_adapter.py`` checks them against the installed Warp (CI runs it against the
oldest Warp release warptex supports as well):

- :func:`active_tape`: the ``wp.Tape`` being recorded. Warp records its own launches on it but does
  not say which it is; warptex records its threaded launches and hand-written gradients there too.
- :func:`struct_fields` and :func:`struct_like`: the fields of a ``@wp.struct`` instance, and a new
  instance of the same struct. A threaded backward pass gives each worker copies of the kernel's
  struct arguments whose arrays accumulate their gradients privately.
"""

from __future__ import annotations

from typing import Any

import warp as wp


def _runtime():
    src = getattr(wp, "_src", None)  # Warp 1.10 moved its implementation into warp._src
    return (src.context if src is not None else wp.context).runtime


def active_tape() -> wp.Tape | None:
    """The ``wp.Tape`` being recorded (inside its ``with`` block), or ``None``."""
    return _runtime().tape


def struct_fields(value) -> dict[str, Any]:
    """``{name: value}`` of every field of the ``@wp.struct`` instance ``value``, in declaration order."""
    return {name: getattr(value, name) for name in value._cls.vars}


def struct_like(value):
    """A new, default-initialised instance of the struct of ``value``."""
    return value._cls()
