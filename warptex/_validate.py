"""Argument checks shared by the public API: every error names the function and the bad value."""

from __future__ import annotations

import enum
import math
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
    """``value`` as a float32 NumPy array, refusing non-numeric data with a ``TypeError``."""
    arr = np.asarray(value)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{func}(): {name} must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float32, copy=False)


def resolve_device(func: str, device, default) -> wp.context.Device:
    """The Warp device to launch on: ``device`` if given (it must match ``default``), else ``default``."""
    default = wp.get_device(default)
    if device is None:
        return default
    device = wp.get_device(device)
    if device != default:
        raise ValueError(f"{func}(): device {device} differs from the texture's device {default}")
    return device
