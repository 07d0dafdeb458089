"""How a technique's kernels run, and which backward pass they record: one mechanism for all.

Every per-pixel technique has up to three kernels (:class:`Kernels`), built from one source:

- ``forward``: the outputs, compiled without Warp's generated adjoint;
- ``texel_grad``: its hand-written gradient. Sampling is linear in the texels, so the gradient of
  a linear blend of taps adds each tap's weight times the output gradient into the texels it read,
  at about the cost of one forward pass (Warp's generated adjoint, which replays every function's
  forward inside its reverse pass, cost five). Its arguments are the forward's inputs, then one
  gradient array per input it differentiates (:func:`run`'s ``by_hand``), then the outputs'
  gradients;
- ``adjoint``: the forward with Warp's generated adjoint, which differentiates everything else
  (UVs, sharpness, offsets, G-buffer arrays, a histogram blend). It lives in a Warp module of its
  own, compiled only the first time such a gradient is asked for.

:func:`run` picks one per launch: without a tape (or when no output needs a gradient) the forward
kernel alone; when every input that needs a gradient is one the texel-gradient kernel serves and
the blend is linear, the forward kernel with the texel-gradient kernel recorded as its backward;
otherwise the adjoint kernel. :func:`force_generated_adjoint` makes the last choice whenever a
backward pass is recorded, so tests compare the two on the same inputs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from typing import Any

import warp as wp

from warptex._launch import GENERATED, PerPixel, launch, per_pixel, scatter
from warptex._warp import active_tape

_forced = threading.local()


@contextlib.contextmanager
def force_generated_adjoint(enabled: bool = True):
    """Within this block (on this thread), every recorded backward pass is Warp's generated adjoint,
    never a hand-written gradient: for tests that compare the two."""
    previous = getattr(_forced, "value", False)
    _forced.value = enabled
    try:
        yield
    finally:
        _forced.value = previous


@dataclasses.dataclass(frozen=True)
class Kernels:
    """One technique's kernels (module docstring). ``texel_grad`` or ``adjoint`` may be ``None``
    where the technique has no such path."""

    forward: Any
    texel_grad: Any = None
    adjoint: Any = None


def needs_grad(*arrays) -> bool:
    """Whether any of ``arrays`` (``wp.array``, :func:`~warptex._launch.per_pixel` entries or ``None``) requires gradients."""
    return any(_array(a) is not None and _array(a).requires_grad for a in arrays)


def hand_written(others: list, linear: bool = True) -> bool:
    """Whether a hand-written gradient may be recorded: no array of ``others`` requires gradients,
    the blend is ``linear``, and :func:`force_generated_adjoint` is not in effect."""
    return linear and not needs_grad(*others) and not getattr(_forced, "value", False)


def run(kernels: Kernels, count: int, *, inputs: list, outputs: list, device, by_hand: list = (), others: list = (), linear: bool = True, covered: wp.array | None = None, touched: list | None = None) -> None:
    """Launch ``kernels`` over ``count`` pixels and record the backward pass a ``wp.Tape`` needs.

    Args:
        kernels: the technique's :class:`Kernels`.
        count: pixels (launch size).
        inputs: the kernels' inputs; per-pixel arrays wrapped with :func:`per_pixel`.
        outputs: the per-pixel outputs. An output that does not require gradients records nothing.
        device: the Warp device.
        by_hand: the arrays ``kernels.texel_grad`` adds gradients into, in its argument order
            (``None`` where absent; per-pixel ones wrapped with :func:`per_pixel`). Those that require
            gradients get them; the others are passed as empty arrays.
        others: every other differentiable array among the inputs: when one requires gradients,
            the generated adjoint runs.
        linear: whether the blend of taps is linear in the texels (``False``: a histogram blend,
            which only the generated adjoint differentiates).
        covered: the G-buffer's mask, for a launch over a G-buffer (see :func:`~warptex._launch.launch`).
        touched: per ``by_hand`` array, the ``(start, stop)`` entries the hand-written gradient can
            add into, where fewer than all (a constant-LOD lookup reads one or two mip levels): only
            those are summed from the per-thread copies (``None``: all).
    """
    tape = active_tape()
    if tape is None or not any(o.requires_grad for o in outputs):
        launch(kernels.forward, count, inputs=inputs, outputs=outputs, device=device, covered=covered)
        return
    if kernels.texel_grad is not None and hand_written(others, linear):
        backward = _texel_gradients(kernels.texel_grad, count, inputs, outputs, by_hand, device, covered, touched)
        launch(kernels.forward, count, inputs=inputs, outputs=outputs, device=device, backward=backward, covered=covered)
        return
    if kernels.adjoint is None:
        raise RuntimeError("warptex internal error: a gradient was asked for that this technique has no kernel for")
    launch(kernels.adjoint, count, inputs=inputs, outputs=outputs, device=device, backward=GENERATED, covered=covered)


def run_by_hand(kernels: Kernels, count: int, *, inputs: list, outputs: list, device, by_hand: list, covered: wp.array | None = None) -> None:
    """:func:`run` for a step whose hand-written gradient is always the one recorded, for a
    technique that composes it with a generated adjoint (e.g. a blend of stored samples)."""
    tape = active_tape()
    backward = _texel_gradients(kernels.texel_grad, count, inputs, outputs, by_hand, device, covered) if tape is not None else None
    launch(kernels.forward, count, inputs=inputs, outputs=outputs, device=device, backward=backward, covered=covered)


def _texel_gradients(kernel, count: int, inputs: list, outputs: list, by_hand: list, device, covered=None, touched=None):
    """``backward(tape)``: ``kernel`` adds the outputs' gradients, through the forward pass, into the
    gradients of the ``by_hand`` arrays that require them."""

    def backward(tape):
        grads, entries = [], {}
        for a, span in zip(by_hand, touched or [None] * len(by_hand)):
            array = _array(a)
            grad = tape.get_adjoint(array) if array is not None and array.requires_grad else None  # registered for tape.zero()
            grads.append(per_pixel(grad)[0] if isinstance(a, PerPixel) else grad)
            if grad is not None and span is not None:
                entries[id(grad)] = span
        adjoints = per_pixel(*[o.grad for o in outputs])
        targets = [g for g in grads if g is not None and not isinstance(g, PerPixel)]
        scatter(kernel, count, inputs=[*inputs, *grads, *adjoints], targets=targets, device=device, covered=covered, entries=entries)

    return backward


def _array(a) -> wp.array | None:
    return a.array if isinstance(a, PerPixel) else a
