"""Argument checks shared by the public API: every error names the function and the bad value."""

from __future__ import annotations

import enum
import math
import warnings
from typing import TypeVar

import numpy as np
import warp as wp

E = TypeVar("E", bound=enum.Enum)


def as_enum(func: str, name: str, value, kind: type[E]) -> E:
    """``value`` (an enum member or its string value) as a member of ``kind``."""
    if isinstance(value, kind):
        return value
    if isinstance(value, str):
        try:
            return kind(value.lower())
        except ValueError:
            pass
    choices = ", ".join(repr(m.value) for m in kind)
    raise ValueError(f"{func}(): {name} must be one of {choices}, got {value!r}")


def as_float(func: str, name: str, value, *, finite: bool = True) -> float:
    """``value`` as a Python float; NaN is always refused, infinities unless ``finite`` is False."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{func}(): {name} must be a number, got {type(value).__name__}")
    f = float(value)
    if math.isnan(f) or (finite and math.isinf(f)):
        raise ValueError(f"{func}(): {name} must be finite, got {f}")
    return f


def as_float_array(func: str, name: str, value) -> np.ndarray:
    """``value`` as a float32 NumPy array, refusing non-numeric data with a ``TypeError`` and
    ragged nested sequences with a ``ValueError``."""
    try:
        arr = np.asarray(value)
    except ValueError as err:
        raise ValueError(f"{func}(): {name} must be a rectangular array of numbers: {err}") from None
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{func}(): {name} must hold real numbers, got dtype {arr.dtype}")
    if arr.dtype == np.float32 or not np.issubdtype(arr.dtype, np.floating) or arr.dtype.itemsize < 4:
        return arr.astype(np.float32, copy=False)  # integers and halves fit float32's range
    with np.errstate(over="ignore"):  # a finite value past float32's range: said below, not as NumPy's warning
        cast = arr.astype(np.float32)
    infinite = np.isinf(cast)
    if infinite.any() and (beyond := infinite & np.isfinite(arr)).any():  # the second pass only where something overflowed
        where = tuple(int(i) for i in np.argwhere(beyond)[0])
        raise ValueError(f"{func}(): {name} holds {float(arr[where])!r} at {where}, beyond float32's range (about ±3.4e38), which the kernels compute in")
    return cast


def resolve_device(func: str, device, default) -> wp.context.Device:
    """The Warp device to launch on: ``device`` if given (it must match ``default``), else ``default``."""
    default = wp.get_device(default)
    if device is None:
        return default
    device = wp.get_device(device)
    if device != default:
        raise ValueError(f"{func}(): device {device} differs from the texture's device {default}")
    return device


def param_array(func, name, value, shapes, device, *, nonzero=False, nonnegative=False) -> wp.array:
    """A float32 parameter array of one of ``shapes``: the caller's ``wp.array`` (gradients flow
    into it) or an array of the numbers (shared by the calls that give the same numbers)."""
    if isinstance(value, wp.array):
        if value.dtype != wp.float32 or value.shape not in shapes:
            want = " or ".join(str(s) for s in shapes)
            raise ValueError(f"{func}(): {name} as a wp.array must be float32 with shape {want}, got {wp.types.type_repr(value.dtype)} {value.shape}")
        if value.device != device:
            raise ValueError(f"{func}(): {name} is on {value.device} but the G-buffer on {device}")
        if not value.is_contiguous:
            raise ValueError(f"{func}(): {name} must be contiguous")
        arr, values = value, value.numpy()
    else:
        if isinstance(value, bool):
            raise TypeError(f"{func}(): {name} must be numbers, got {value!r}")
        values = as_float_array(func, name, value)
        if values.ndim == 0:
            values = values.reshape(1)
        if values.shape not in shapes:
            want = " or ".join(str(s) for s in shapes)
            raise ValueError(f"{func}(): {name} must have shape {want}, got {values.shape}")
        arr = None
    if not np.isfinite(values).all():
        raise ValueError(f"{func}(): {name} must be finite, got {values.tolist()}")
    if nonzero and (values == 0).any():
        raise ValueError(f"{func}(): {name} must be non-zero, got {values.tolist()}")
    if nonnegative and (values < 0).any():
        raise ValueError(f"{func}(): {name} must be >= 0, got {values.tolist()}")
    if arr is None:
        arr = _constant(np.ascontiguousarray(values, np.float32), device)
    return arr


_constants: dict = {}
_MAX_CONSTANTS = 256


def _constant(values: np.ndarray, device) -> wp.array:
    """A float32 array of ``values`` on ``device``, one per distinct value and shared: kernels only
    read a parameter given as numbers, and making three new arrays cost a triplanar call ~50 us."""
    key = (values.shape, values.tobytes(), wp.get_device(device).alias)
    arr = _constants.get(key)
    if arr is None:
        if len(_constants) >= _MAX_CONSTANTS:  # a fit sweeping a parameter through many values
            _constants.clear()
        arr = _constants[key] = wp.array(values, dtype=float, device=device)
    return arr


#: How to install PyTorch, for the errors of what needs it: the package index has no warptex, so
#: not ``pip install 'warptex[torch]'``; and the CPU build, not the default CUDA one with its ~20
#: ``nvidia-*`` wheels, for a machine without a GPU.
TORCH_HINT = "pip install torch (without a GPU, the CPU build: pip install torch --index-url https://download.pytorch.org/whl/cpu)"


def check_layer_count(func: str, num_layers: int, maps) -> None:
    """Splat maps (a ``TextureArray``) of ``M`` maps of ``C`` channels hold weights for
    ``(M - 1)·C < L <= M·C`` layers."""
    m, c = maps.num_layers, maps.channels
    if not (m - 1) * c < num_layers <= m * c:
        need = -(-num_layers // c)
        raise ValueError(
            f"{func}(): {m} splat map(s) of {c} channel(s) hold weights for {(m - 1) * c + 1} to {m * c} layers, "
            f"but there are {num_layers} layers (use {need} map(s) of {c} channels)"
        )


def as_on_device(func: str, name: str, value, kind: type, what: str, device, *, beside: str = "the G-buffer"):
    """``value``, checked to be a ``kind`` (described as ``what``, e.g. "a TextureArray") on ``device``,
    where ``beside`` (what sets the device) is: a ``TypeError`` or ``ValueError`` naming ``func`` else."""
    if not isinstance(value, kind):
        raise TypeError(f"{func}(): {name} must be {what}, got {type(value).__name__}")
    if value.device != device:
        raise ValueError(f"{func}(): {name} is on {value.device} but {beside} on {device}")
    return value


def as_device_array(func: str, name: str, value: wp.array, device, *, beside: str) -> wp.array:
    """A ``wp.array`` input checked to be on ``device`` (where ``beside`` is) and contiguous."""
    if value.device != device:
        raise ValueError(f"{func}(): {name} is on {value.device} but {beside} on {device}")
    if not value.is_contiguous:
        raise ValueError(f"{func}(): {name} must be contiguous")
    return value


def checked_device(func: str, device):
    """``wp.get_device(device)``, or a ``ValueError`` that says which devices this machine has
    (Warp's own says only "Invalid device identifier"), starting ``"func(): "`` as every error of
    a function does, or ``"--device: "`` for a command-line option (a ``func`` starting ``-``)."""
    try:
        return wp.get_device(device)
    except (ValueError, RuntimeError):
        pass
    have = ", ".join(d.alias for d in wp.get_devices())
    cuda = "" if wp.get_cuda_device_count() else "no CUDA device is available here; "
    where = func if func.startswith("-") else f"{func}()"
    raise ValueError(f"{where}: device {device!r} does not exist: {cuda}the devices are {have}")


def warn_renamed(old: str, new: str, *, stacklevel: int = 3) -> None:
    """A ``DeprecationWarning`` that ``old`` (an argument, keyword or name) is now spelt ``new``;
    old spellings keep working for one release. ``stacklevel`` 3 points at the caller's caller."""
    warnings.warn(f"{old} is deprecated and goes in the next release: use {new}", DeprecationWarning, stacklevel=stacklevel)


def renamed_attribute(module: str, name: str, renamed: dict[str, str], scope: dict):
    """For a module's ``__getattr__``: the value of an old public name in ``renamed`` (``{old: new}``,
    ``new`` in ``scope``, the module's globals), with a warning naming the new one; an
    ``AttributeError`` for any other name."""
    if name not in renamed:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new = renamed[name]
    warn_renamed(f"{module}.{name}", f"{module}.{new}" + (", an internal helper" if new.startswith("_") else ""))
    return scope[new]
