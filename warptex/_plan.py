"""A small call kept ready for the next call on the same objects: what a loop's call costs.

A loop that samples the same inputs again and again (an optimiser's step, a per-frame lookup)
paid for its checks, its argument structs and Warp's launch setup on every call: a 1,024-UV
:func:`~warptex.sample` spent ~90 us of Python around ~11 us of kernel.

A technique whose call qualifies (inputs that are objects or plain values, no recording
``wp.Tape``, see :func:`usable`) asks :func:`rerun` to run a plan kept under the call's key and its
objects, the very ones (compared by identity: the arrays' shapes and types, and a texture's
storage, cannot change): the same launch as before, on their current contents. Two arrays of a
call are its own rather than the objects': ``out=`` and a lookup's ``uv``. A plan serves any
array of the same layout (device, shape, strides, type; for ``uv``, ``requires_grad``) and points
the launch at it, so that a loop that makes them anew each call (a torch tensor's Warp view, an
output from ``wp.empty``) runs its plan too: the call's own path cost ~150 us of Python around a
1,024-UV lookup on the CPU, and a 1-UV call on an H200 took 153 us against 30 us into a kept
``out=`` while CUDA plans served only the very arrays they were made with. Without ``out=``
(``None``), the plan makes a new output as the call did (its shape, type and ``requires_grad``)
and points the launch at it: a new array costs ~6 us, where the call's own path cost ~50 us of
Python. A small new output (:data:`SPARE_BYTES` at most) is kept as a spare once returned, and a
later call on the same stream (on another CUDA stream, the earlier write could still be pending)
writes it again (and zeroes its gradient) once nothing else refers to it or its gradient: no one
can then read what it held, as with an array freed and allocated again, but the call costs no
Warp arrays (~13-20 us of Python each on the CPU, as much as the rest of a 1-pixel call; on an
H200 a new output took a 1-UV call from 30 to 72 us) nor their argument struct. A caller's view
of it, a NumPy or torch array of it, or a gradient tape's record all refer to it. A plan keeps :data:`SPARES` of them, so that ``y = sample(...)`` in a loop
finds the one before last free.
Otherwise the call runs as usual within :func:`recording`; its second call with the same objects
keeps the launch it made (``warptex._launch.launch`` reports it through :func:`launched`), so a
loop that passes new arrays every call never pays for plans it would not reuse. Only a call that
made exactly one launch, on one thread (a small call on the CPU: a large one is split over the
threads), is kept. Errors are unchanged: a plan is only made by a call that passed every check,
and a hit repeats that call's inputs (keys compare plain values of their exact types: a
``layer=True`` that a call refuses never matches a ``layer=1``).

A plan holds its objects weakly and goes when one of them does; it holds the packed argument
structs it names (``hold``) strongly, which hold a texture's arrays but not the texture, and its
spare outputs (at most ``SPARES * SPARE_BYTES``). At most :data:`MAX_PLANS` are kept per thread, the
oldest going first.
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import weakref

import warp as wp

from warptex._threads import never_split
from warptex._warp import active_tape, array_struct, cpu_capturing, kept_call
from warptex.kernels.family import one_pixel_active

#: Plans kept per thread.
MAX_PLANS = 32
#: New outputs a plan keeps to write again once the caller lets them go, and their largest size.
SPARES = 2
SPARE_BYTES = 64 << 10
#: The places of the per-sample struct and of the output in a launch's parameters,
#: ``kernel(args, pixels, first, out)`` (``warptex._launch.launch``).
PIXELS_PARAM, OUT_PARAM = 1, 3

_local = threading.local()


class _Plan:
    """A call's objects (weakly), what it holds, and its launch (``None`` once seen, not yet kept)."""

    __slots__ = ("refs", "hold", "cmd", "call", "zero", "like", "spares", "pointed")

    def holds(self, objects: tuple) -> bool:
        """Whether this plan's objects are these very ``objects`` (ids can be reused)."""
        return all(r() is o for r, o in zip(self.refs, objects))

    def run(self, lead: tuple, out: wp.array | None, uv: wp.array | None) -> wp.array | None:
        """Run the launch on ``uv`` (where given) into the caller's ``out``, or into a new output
        of shape ``(*lead, C)``; that output, or ``None`` (nothing run) where ``lead`` does not
        hold the launch's rows."""
        pointed = self.pointed  # the addresses the launch reads now: {"uv": ..., "out": ...} where addressed
        if "uv" in pointed and pointed["uv"] != (at := _address(uv)):
            field = self.call.field(PIXELS_PARAM, "uv")  # a ctypes array_t of the same layout as uv
            field.data, field.grad = pointed["uv"] = at
        if out is None:
            out = self._new_output(lead)
            if out is None:
                return None
        else:
            if "out" in pointed and pointed["out"] != (at := _address(out)):
                self.call.set(OUT_PARAM, array_struct(out, self.like[0]))  # (~5 us: only where it is another array)
                pointed["out"] = at
            if self.zero:  # a one-pixel kernel's output is zeroed first, as launch() zeroes it
                out.zero_()
            if out.grad is not None:  # and a new output's gradient
                out.grad.zero_()
        self.call()
        return out

    def _new_output(self, lead: tuple) -> wp.array | None:
        """A new output, as launch() was given one (its rows are the kernel's), the launch pointed
        at it: a spare that nothing else refers to, where there is one."""
        (rows, channels), dtype, grad = self.like
        if math.prod(lead) != rows:
            return None
        shape = (*lead, channels)
        device = self.cmd.device
        stream = device.stream.cuda_stream if device.is_cuda else None  # (the launch's: the device's current stream)
        for spare in self.spares:
            if _unheld(spare) and spare[0].shape == shape and spare[3] == stream:
                out, struct, gradient, _ = spare
                if self.zero:
                    out.zero_()
                if gradient is not None:
                    gradient.zero_()
                break
        else:
            out = (wp.zeros if self.zero else wp.empty)(shape, dtype=dtype, device=device, requires_grad=grad)
            struct = array_struct(out, (rows, channels))
            if out.capacity <= SPARE_BYTES:
                self.spares = (*self.spares, (out, struct, out.grad, stream))[-SPARES:]
        self.call.set(OUT_PARAM, struct)
        return out


def _layout(array: wp.array | None, grad: bool):
    """What a plan's key holds of a call's own array, whose address the plan points its launch at:
    its layout, what the call checked of it (its device too: a CUDA launch must not read a host
    address), and with ``grad`` (an input's) its ``requires_grad`` (a new output requires
    gradients where an input does)."""
    if array is None:
        return None
    return (array.device.alias, array.shape, array.strides, array.dtype, grad and array.requires_grad)


def _address(array: wp.array) -> tuple:
    """Where an array parameter points: its data and its gradient's (``array_t``'s ``data``, ``grad``)."""
    grad = array.grad
    return array.ptr, 0 if grad is None else grad.ptr


def _full(key: tuple, objects: tuple, out, uv) -> tuple:
    """The plan's full key of a call: its key, the layouts of its own arrays, and the identities of
    its objects."""
    return (key, _layout(out, False), _layout(uv, True), *map(id, objects))


def _references(spare: tuple, item: int) -> int:
    """References to one item of a spare (a tuple that only its plan holds)."""
    return sys.getrefcount(spare[item])


#: :func:`_references` of an object only its tuple refers to (measured: it depends on the
#: interpreter).
_UNHELD = _references((object(),), 0)


def _unheld(spare: tuple) -> bool:
    """Whether nothing but its plan refers to a spare ``(output, struct, gradient, stream)``: not to
    the output, nor to its gradient (``None`` where it has none), which the output still has."""
    if _references(spare, 0) != _UNHELD or spare[0].grad is not spare[2]:
        return False
    return spare[2] is None or _references(spare, 2) == _UNHELD + 1  # (+ the output's own)


def usable() -> bool:
    """Whether plans may be recalled and kept on this thread now: not while a ``wp.Tape`` records
    (a recorded call keeps its own structs for its backward pass) or a CPU graph capture does (a
    plan's launch holds no arrays to record), nor within ``one_pixel_kernels`` (a plan runs the
    kernel it was made with)."""
    return active_tape() is None and not one_pixel_active() and not cpu_capturing()


def recall(key: tuple, objects: tuple, *, out: wp.array | None = None, uv: wp.array | None = None) -> _Plan | None:
    """The plan kept for ``key`` (a hashable tuple of the call's plain values) on these very
    ``objects`` and the call's own ``out`` and ``uv`` (module docstring), or ``None``."""
    plans = getattr(_local, "plans", None)
    if not plans:
        return None
    plan = plans.get(_full(key, objects, out, uv))
    if plan is None or plan.cmd is None or not plan.holds(objects):
        return None
    return plan


def rerun(key: tuple | None, objects: tuple, lead: tuple = (), *, out: wp.array | None = None, uv: wp.array | None = None) -> wp.array | None:
    """Run the plan kept for ``key`` on ``objects``, ``out`` and ``uv`` (:func:`recall`) where
    there is one: the output it wrote (the caller's ``out=``, or a new ``(*lead, C)`` array where
    ``out`` is ``None``: ``lead`` is the result's shape less its channels), else ``None``.
    ``key=None``: the call does not qualify."""
    plan = recall(key, objects, out=out, uv=uv) if key is not None else None
    return plan.run(lead, out, uv) if plan is not None else None


@contextlib.contextmanager
def recording(key: tuple | None, objects: tuple, *, out: wp.array | None = None, uv: wp.array | None = None, hold=()):
    """Run the block (a call's usual path) and, where this is the second call on ``key``,
    ``objects`` and arrays of the same layouts as ``out`` and ``uv`` (:func:`recall`), and the
    block made one launch (:func:`launched`), keep that launch for :func:`recall`. ``key=None``:
    the call does not qualify; nothing is kept. ``out``: the caller's output array (``None``: the
    call makes a new one); ``uv``: the UVs that the launch reads as its per-sample struct's
    ``uv`` (a lookup's); ``hold``: what the plan keeps alive (the packed structs)."""
    if key is None or not usable() or getattr(_local, "capture", None) is not None:  # (a call within a recorded one: not kept)
        yield
        return
    plans = _local.__dict__.setdefault("plans", {})
    full = _full(key, objects, out, uv)
    seen = plans.get(full)
    if seen is None or not seen.holds(objects):
        _remember(plans, full, objects, hold)  # first sighting: nothing recorded
        yield
        return
    _local.capture = capture = []
    try:
        yield
    finally:
        _local.capture = None
    if len(capture) != 1 or capture[0] is None or seen.cmd is not None:
        return
    cmd, zero, like = capture[0]
    call = kept_call(cmd)
    if like is None or (uv is not None and call.field(PIXELS_PARAM, "uv").data != uv.ptr):
        return  # an output the plan cannot point at (not one array of rows), or UVs the launch does not read in place
    seen.cmd, seen.zero, seen.like, seen.call = cmd, zero, like, call
    seen.pointed = {name: None for name, a in (("out", out), ("uv", uv)) if a is not None}  # (pointed by the first run)


def _remember(plans: dict, full: tuple, objects: tuple, hold) -> None:
    plan = _Plan()
    drop = lambda _ref, plans=plans, full=full: plans.pop(full, None)  # noqa: E731 (an object went: so does its plan)
    refs = tuple(_no_object if o is None else weakref.ref(o, drop) for o in objects)
    plan.refs, plan.hold, plan.cmd, plan.call, plan.zero, plan.like, plan.spares, plan.pointed = refs, tuple(hold), None, None, False, None, (), {}
    plans.pop(full, None)
    while len(plans) >= MAX_PLANS:
        plans.pop(next(iter(plans)), None)
    plans[full] = plan


def _no_object():  # the "reference" of an object that is None
    return None


def launched(kernel, dim: int, params: tuple, device, *, count: int, zeroes: bool) -> None:
    """``warptex._launch.launch`` made an unsplit, unrecorded launch of ``count`` pixels (after
    zeroing its output where ``zeroes``, and its output's gradient where it has one) with
    ``params`` ``(args, pixels, first, out)``: within :func:`recording`'s second call, its own
    kept copy (a ``wp.Launch`` holding addresses only), and the shape, type and ``requires_grad``
    of its output where that is one array of rows. Not kept: a CPU launch large enough to be
    split over threads (a plan runs on one), or more than one launch."""
    capture = getattr(_local, "capture", None)
    if capture is None:
        return
    if not never_split(device, count):
        capture.append(None)
        return
    cmd = wp.launch(kernel, dim=dim, inputs=list(params), device=device, record_cmd=True)
    cmd.fwd_args = None  # addresses only: the plan keeps no array alive
    out = params[OUT_PARAM]
    like = (tuple(out.shape), out.dtype, out.requires_grad) if wp.types.is_array(out) and out.ndim == 2 and out.is_contiguous else None
    capture.append((cmd, zeroes, like))
