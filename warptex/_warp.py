"""The few things warptex needs from Warp that its public API does not offer, in one place.

Everything else warptex does with Warp goes through the public API (``wp.*``, ``wp.types``,
``wp.Tape``). These reach into Warp's internals, so they live here, each with the reason,
and ``tests/test_warp_adapter.py`` checks them against the installed Warp (CI runs it against the
oldest Warp release warptex supports as well):

- :func:`active_tape`: the ``wp.Tape`` being recorded. Warp records its own launches on it but does
  not say which it is; warptex records its threaded launches and hand-written gradients there too.
  :func:`paused_tape` stops recording for a block (a bake's argument check on an empty G-buffer).
- :func:`struct_fields` and :func:`struct_like`: the fields of a ``@wp.struct`` instance, and a new
  instance of the same struct. A threaded backward pass gives each worker copies of the kernel's
  struct arguments whose arrays accumulate their gradients privately. :func:`struct_arrays`: its
  arrays and their paths, nested structs' included (walked on every call, so the paths are cached
  per struct type);
  :func:`field_type`: a field's declared type.
- :func:`map_arrays`: a struct (or array) with its arrays replaced, built on the two above.
- :func:`scalar_type`: the scalar type of a vector or matrix dtype (which arrays can carry gradients).
- :func:`replay`: a launch through a kept ``wp.Launch`` (``record_cmd=True``), whose ``fwd_args``
  (what Warp keeps for CPU graph capture, an internal) it drops so that it holds no array.
  :func:`cpu_capturing`: whether a CPU graph capture records (Warp 1.19's APIC capture, an
  internal), where a launch must go through ``wp.launch`` to be recorded.
- :func:`kept_call`: a kept CPU ``wp.Launch`` called straight into its kernel's entry point
  (:class:`CpuLaunch`), as ``wp.Launch.launch`` does, less the ~6 us of Python it spends packing
  the arguments each time.

And :func:`init_quietly` (public as ``warptex.init_quietly``), for the command line and the
examples: Warp's native library prints a warning to the process's stderr on every start on a
machine without a CUDA driver, which a CPU user can do nothing about.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import operator
import os
import sys
import tempfile
import threading
from typing import Any

import warp as wp

#: What Warp's native library prints at start-up where there is no CUDA driver (a CPU machine).
NO_CUDA_DRIVER_WARNING = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver."


def _runtime():
    src = getattr(wp, "_src", None)  # Warp 1.10 moved its implementation into warp._src
    return (src.context if src is not None else wp.context).runtime


def array_struct(array: wp.array, shape: tuple) -> Any:
    """The ctypes struct a kernel's array parameter takes (Warp's ``array_t``) of contiguous
    ``array`` seen as ``shape`` (as many elements): a launch's parameter without making a view
    (``wp.Launch.set_param_at_index_from_ctype``)."""
    src = getattr(wp, "_src", None)
    struct = (src.types if src is not None else wp.types).array_t
    strides = [wp.types.type_size_in_bytes(array.dtype)]
    for n in reversed(shape[1:]):
        strides.insert(0, strides[0] * n)
    grad = 0 if array.grad is None else array.grad.ptr
    return struct(data=array.ptr, grad=grad, ndim=len(shape), shape=tuple(shape), strides=tuple(strides))


def active_tape() -> wp.Tape | None:
    """The ``wp.Tape`` being recorded (inside its ``with`` block), or ``None``."""
    return _runtime().tape


@contextlib.contextmanager
def paused_tape():
    """Launches inside this block are not recorded on the active ``wp.Tape`` (if any)."""
    runtime = _runtime()
    tape, runtime.tape = runtime.tape, None
    try:
        yield
    finally:
        runtime.tape = tape


def struct_fields(value) -> dict[str, Any]:
    """``{name: value}`` of every field of the ``@wp.struct`` instance ``value``, in declaration order."""
    return {name: getattr(value, name) for name in value._cls.vars}


def field_type(value, name: str):
    """The declared type of field ``name`` of the ``@wp.struct`` instance ``value``."""
    return value._cls.vars[name].type


def struct_arrays(value, scalars: tuple | None = None) -> list[tuple[str, Any]]:
    """``(dotted path, array)`` of every array field of the ``@wp.struct`` instance ``value``,
    those of its nested structs included, in declaration order; with ``scalars``, only the fields
    declared with one of those scalar types (e.g. the float arrays, which can carry gradients: Warp
    refuses an array of another dtype). Read by one ``operator.attrgetter`` made per struct type
    (a call of a technique walks its structs several times)."""
    paths, read = _reader(value._cls, scalars)
    return list(zip(paths, read(value))) if read is not None else []


def struct_array_values(value, scalars: tuple | None = None) -> tuple:
    """The arrays of :func:`struct_arrays`, without their paths."""
    read = _reader(value._cls, scalars)[1]
    return read(value) if read is not None else ()


@functools.lru_cache(maxsize=None)
def _reader(struct_t, scalars: tuple | None) -> tuple:
    paths = tuple(dotted for dotted, _ in _paths(struct_t, scalars))
    if not paths:
        return paths, None
    get = operator.attrgetter(*paths)
    return paths, (get if len(paths) > 1 else lambda value: (get(value),))


@functools.lru_cache(maxsize=None)
def _paths(struct_t, scalars: tuple | None) -> tuple:
    paths = []
    for name, var in struct_t.vars.items():
        if wp.types.is_array(var.type):
            if scalars is None or scalar_type(var.type.dtype) in scalars:
                paths.append((name, (name,)))
        elif isinstance(var.type, type(struct_t)):
            paths += [(f"{name}.{dotted}", (name, *names)) for dotted, names in _paths(var.type, scalars)]
    return tuple(paths)


def map_arrays(value, f):
    """``value`` with every array ``a`` in it replaced by ``f(a)``: an array, or a struct (nested
    ones included: a new instance, set field by field, so that it packs the new arrays)."""
    if wp.types.is_array(value):
        return f(value)
    if wp.types.is_struct(value):
        copy = struct_like(value)
        for name, field in struct_fields(value).items():
            setattr(copy, name, map_arrays(field, f))
        return copy
    return value


def scalar_type(dtype):
    """The scalar type of a Warp dtype: ``wp.float32`` for ``wp.vec2``, ``wp.mat33``, ``float``..."""
    return getattr(dtype, "_wp_scalar_type_", wp.float32 if dtype is float else dtype)


def struct_like(value):
    """A new, default-initialised instance of the struct of ``value``."""
    return value._cls()


def init_quietly() -> None:
    """``wp.init()``, leaving out of stderr the one line Warp's native library prints where there is
    no CUDA driver; anything else it prints goes through. The line is written by C code straight
    to file descriptor 2, so descriptor 2 is pointed at a temporary file while Warp starts. Also
    no start-up banner and no compile log (``log_level``, Warp 1.19; ``quiet`` before)."""
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True
    if _initialised():
        return
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        text = captured.read().decode("utf-8", "replace")
    kept = [line for line in text.splitlines(keepends=True) if not line.startswith(NO_CUDA_DRIVER_WARNING)]
    if kept:
        sys.stderr.write("".join(kept))
        sys.stderr.flush()


def _initialised() -> bool:
    src = getattr(wp, "_src", None)
    return (src.context if src is not None else wp.context).runtime is not None


_replays = threading.local()


def cpu_capturing() -> bool:
    """Whether a CPU graph capture (``wp.ScopedCapture`` on the CPU, Warp 1.19) is recording
    launches: a kept ``wp.Launch`` without its ``fwd_args`` cannot be recorded."""
    return getattr(_runtime(), "_apic_capture", None) is not None


class CpuLaunch:
    """A kept CPU ``wp.Launch`` (``record_cmd=True``, of a forward kernel, one thread per index)
    called straight into its kernel's entry point with one argument struct kept for it, as
    ``wp.Launch.launch`` calls it (Warp's ``invoke``: ``forward(&bounds, &args)``, the struct's
    fields the kernel's parameters, in order). ``wp.Launch.launch`` builds and fills that struct on
    every call, ~6 us of Python of a 1-pixel call's ~25. :meth:`set` changes one parameter, and
    :meth:`field` gives a struct parameter's field to change."""

    __slots__ = ("_forward", "_bounds", "_args", "_ref", "_names")

    def __init__(self, cmd: wp.Launch):
        names = [arg.label for arg in cmd.kernel.adj.args]
        values = cmd.params[1:]  # after the launch bounds
        self._args = type("ArgsStruct", (ctypes.Structure,), {"_fields_": [(n, type(v)) for n, v in zip(names, values)]})()
        for name, value in zip(names, values):
            setattr(self._args, name, value)
        self._forward, self._bounds, self._ref, self._names = cmd.hooks.forward, ctypes.byref(cmd.params[0]), ctypes.byref(self._args), names

    def set(self, index: int, value) -> None:
        """Parameter ``index`` (of the kernel's, from 0) to ``value``, a ctypes value of its type."""
        setattr(self._args, self._names[index], value)

    def field(self, index: int, name: str):
        """Field ``name`` of struct parameter ``index``: its ctypes value, in the kept struct (set
        its members to change the launch's)."""
        return getattr(getattr(self._args, self._names[index]), name)

    def __call__(self) -> None:
        self._forward(self._bounds, self._ref)


class _LaunchCall:
    """A kept ``wp.Launch`` with :class:`CpuLaunch`'s methods, through Warp's ``wp.Launch``."""

    __slots__ = ("_cmd", "_own")

    def __init__(self, cmd: wp.Launch):
        self._cmd, self._own = cmd, set()

    def set(self, index: int, value) -> None:
        self._cmd.set_param_at_index_from_ctype(index, value)

    def field(self, index: int, name: str):
        value = self._cmd.params[index + 1]  # the struct's own ctypes value, which wp.Launch reads at each launch
        if index not in self._own:  # a copy of its own, as CpuLaunch keeps, so that the struct is left as it was
            value = type(value).from_buffer_copy(value)
            self._cmd.set_param_at_index_from_ctype(index, value)
            self._own.add(index)
        return getattr(value, name)

    def __call__(self) -> None:
        self._cmd.launch()


def kept_call(cmd: wp.Launch) -> CpuLaunch | _LaunchCall:
    """A kept launch to set parameters of and run: called straight (:class:`CpuLaunch`) where
    ``wp.Launch.launch`` would do no more than that call, through ``wp.Launch`` otherwise (CUDA,
    a block of threads per index, an adjoint, parameters not as Warp 1.17-1.19 keep them)."""
    if cmd.device.is_cpu and getattr(cmd, "block_dim", 1) == 1 and not cmd.adjoint and len(cmd.params) == len(cmd.kernel.adj.args) + 1:
        return CpuLaunch(cmd)
    return _LaunchCall(cmd)


def replay(kernel, dim: int, params: tuple, device) -> None:
    """``wp.launch(kernel, dim, params)``, not recorded on a tape, through a ``wp.Launch`` kept per
    thread, kernel and device: its parameters are set and it runs. A small call's cost is mostly
    Python, and ``wp.launch`` resolves the module, hooks and argument types each time (a 1,024-UV
    lookup: ~9 us of its ~30 us). The kept launch holds no array (its parameters are their
    addresses only; ``fwd_args``, which Warp keeps for CPU graph capture, is dropped), so nothing
    is kept alive past the call."""
    if cpu_capturing():  # recorded with its arrays, as a plain launch is
        wp.launch(kernel, dim=dim, inputs=list(params), device=device)
        return
    launches = _replays.__dict__.setdefault("launches", {})
    key = (kernel, device.alias)
    cmd = launches.get(key)
    if cmd is None or cmd.kernel is not kernel:
        cmd = launches[key] = wp.launch(kernel, dim=dim, inputs=list(params), device=device, record_cmd=True)
    else:
        cmd.set_dim(dim)
        for index, value in enumerate(params):
            cmd.set_param_at_index(index, value)
    cmd.fwd_args = None
    cmd.launch()
