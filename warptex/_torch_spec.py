"""The PyTorch bridge's calls as its op carries them: argument roles, specs, output shapes.

The op (:mod:`warptex._torch_op`) takes a *spec*, a Python literal of the call's structure with every
tensor replaced by its index, and the list of tensors: what ``torch.library`` ops and
``torch.compile`` can carry. A tensor is handed to the native function by its argument's *role*,
from its name (one table, below): a texture (a texture array around the tensor, its mips built on
the tape), per-sample ``vec2`` UVs, float parameters, integer indices, or plain values passed on as
NumPy. The techniques the bridge runs are registered in :data:`TECHNIQUES` (``warptex.torch.bridge``).
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import functools
import math
from typing import Any, Callable

import numpy as np
import torch
import warp as wp

from warptex.gbuffer import FIELDS, GBuffer
from warptex.histogram import Histogram
from warptex.options import Sampler, Stochastic
from warptex.texture import TextureArray

# Argument roles: how a tensor argument of that name is handed to the native function.
TEXTURES = {"texture", "normal_map", "textures_per_axis", "textures_per_face", "layers", "heights", "splat_maps"}
VEC2 = {"uv", "uv_dx", "uv_dy"}
PARAMS = {"tiling", "sharpness", "offsets", "height_blend"}  # float32 parameter arrays, (1,) for a scalar
FLOATS = PARAMS | {"lod", "weights"}
INTS = {"layer", "indices"}
DIFFERENTIABLE = TEXTURES | VEC2 | FLOATS | {"histogram"}  # "histogram": its Gaussianised texture
HISTOGRAM = {"histogram.lut": wp.float32, "histogram.basis": wp.mat33, "histogram.centre": wp.vec3}


@dataclasses.dataclass(frozen=True)
class Technique:
    """A native technique as the bridge runs it: ``native`` with its ``positional`` arguments (by
    name, in order), an output per sample of ``uv`` (``rows="uv"``) or per G-buffer pixel
    (``"gbuffer"``), with ``channels`` channels or (``None``) those of its first texture."""

    native: Callable
    positional: tuple
    rows: str = "gbuffer"
    channels: int | None = None


#: The techniques, by the name the op carries (registered by :func:`warptex.torch.bridge`).
TECHNIQUES: dict[str, Technique] = {}


def op_arguments(name: str, args: dict[str, Any]) -> tuple[str, list[torch.Tensor]]:
    """``(spec, tensors)``: a call of technique ``name`` with ``args`` as the op takes it."""
    func = f"warptex.torch.{name}"
    tensors: list[torch.Tensor] = []
    key = None if torch.compiler.is_compiling() else _spec_key(name, args)
    head = _heads.get(key) if key is not None else None
    if head is None:
        head = _literal({"technique": name, "args": {k: _encode(func, k, v, tensors) for k, v in args.items()}})[:-1] + ", 'grad': "
        if key is not None and len(_heads) < MAX_HEADS:
            _heads[key] = head
    else:  # the same structure as an earlier call: its tensors, in the order _encode takes them
        tensors = [_role_tensor(func, k, v) for k, v in args.items() if isinstance(v, torch.Tensor)]
    devices = {t.device for t in tensors}
    if len(devices) > 1:
        raise ValueError(f"{func}(): every tensor must be on one device, got {sorted(str(d) for d in devices)}")
    if not tensors:
        raise ValueError(f"{func}(): needs tensor inputs (a texture tensor, a G-buffer)")
    grad = [i for i, t in enumerate(tensors) if t.requires_grad] if torch.is_grad_enabled() else []
    return head + _literal(grad) + "}", tensors


# A spec up to its "grad" list, by the call's structure (:func:`_spec_key`): a loop calls with the
# same structure again and again, and writing the spec was ~30 us of a 1,024-UV call's ~480.
_heads: dict[tuple, str] = {}
MAX_HEADS = 256


def _spec_key(name: str, args: dict) -> tuple | None:
    """What a spec's head is written from, where every argument is a top-level tensor (its role
    is its name), a plain value or a :class:`~warptex.Sampler`; ``None`` for other calls (a
    G-buffer, lists, stochastic options), which are written out each time."""
    parts: list = [name]
    for k, v in args.items():
        if isinstance(v, torch.Tensor):
            parts.append((k, torch.Tensor))
        elif v is None or isinstance(v, (bool, int, str, enum.Enum, Sampler)):
            parts.append((k, type(v), v))
        elif isinstance(v, float):
            parts.append((k, float, repr(v)))  # -0.0 is not 0.0 here, nor nan another nan
        else:
            return None
    return tuple(parts)


def _literal(value) -> str:
    """``value`` (dicts, lists, strings, numbers, ``None``) as a Python literal for
    ``ast.literal_eval``. Written out here because ``torch.compile`` traces this code, and it cannot
    trace ``json.dumps`` (a C encoder) or ``repr`` of containers."""
    if isinstance(value, _Written):
        return value
    if isinstance(value, dict):
        return "{" + ", ".join(_literal(k) + ": " + _literal(v) for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    if isinstance(value, float) and not math.isfinite(value):
        return "{'$float': " + repr(str(value)) + "}"
    if value is None or isinstance(value, (bool, int, float, str)):
        return repr(value)
    raise TypeError(f"warptex.torch: cannot pass {type(value).__name__} to the op")


class _Written(str):
    """A part of a spec already written as a literal (:func:`_sampler_literal`)."""


@functools.lru_cache(maxsize=64)
def _sampler_literal(sampler: Sampler) -> _Written:
    """A sampler's part of a spec, written once per distinct sampler: walking its fields was a
    fifth of a small bridge call's spec."""
    return _Written(_literal({"$sampler": {f.name: _encode("", "sampler", getattr(sampler, f.name), []) for f in dataclasses.fields(sampler)}}))


@functools.lru_cache(maxsize=256)
def parse(spec: str):
    """The value :func:`_literal` wrote; shared between the calls of one spec (a loop calls with
    the same spec again and again, and parsing it was ~40 us of each forward and backward), so
    never changed by its readers."""
    return _unfloat(ast.literal_eval(spec))


def _unfloat(value):
    if isinstance(value, dict):
        return float(value["$float"]) if set(value) == {"$float"} else {k: _unfloat(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_unfloat(v) for v in value]
    return value


def _encode(func: str, role: str, value, tensors: list):
    """``value`` for the spec, its tensors appended to ``tensors`` (converted to what the role takes)."""
    if isinstance(value, torch.Tensor):
        tensors.append(_role_tensor(func, role, value))
        return {"$t": len(tensors) - 1, "role": role}
    if isinstance(value, enum.Enum):
        return value.value
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (np.integer, np.floating, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        if role in TEXTURES or role in VEC2:
            raise TypeError(f"{func}(): {role} must be a torch tensor, got a NumPy array; torch.from_numpy() makes one")
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_encode(func, role, v, tensors) for v in value]
    if isinstance(value, GBuffer):
        return _encode(func, role, gbuffer_tensors(value), tensors)
    if isinstance(value, dict) and role == "gbuffer":
        return {"$gbuffer": {k: _encode(func, f"gbuffer.{k}", v, tensors) for k, v in value.items()}}
    if isinstance(value, Sampler):  # (torch.compile traces the function itself: it warns at a cache)
        return (_sampler_literal.__wrapped__ if torch.compiler.is_compiling() else _sampler_literal)(value)
    if isinstance(value, Stochastic):
        return {"$stochastic": {f.name: _encode(func, f.name, getattr(value, f.name), tensors) for f in dataclasses.fields(value)}}
    if isinstance(value, Histogram):
        if not isinstance(value.texture, torch.Tensor):
            raise TypeError(f"{func}(): a histogram here comes from warptex.torch.prepare_histogram() (tensors), not warptex.prepare_histogram()")
        fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
        return {"$histogram": {k: _encode(func, "histogram" if k == "texture" else f"histogram.{k}", v, tensors) for k, v in fields.items()}}
    if isinstance(value, (TextureArray, wp.array)):
        raise TypeError(f"{func}(): {role} must be a torch tensor (this is the torch bridge), got a {type(value).__name__}; the native warptex.{func.rsplit('.', 1)[1]}() takes those")
    raise TypeError(f"{func}(): unsupported value for {role}: {type(value).__name__}")


def _role_tensor(func: str, role: str, t: torch.Tensor) -> torch.Tensor:
    """``t`` as the op takes it for ``role``: float32 or int32, contiguous, parameters 1-D (torch
    ops, so that autograd carries gradients through the conversion)."""
    if t.is_complex():
        raise TypeError(f"{func}(): {role} must be real, got {t.dtype}")
    if role in INTS:
        if t.is_floating_point():
            raise TypeError(f"{func}(): {role} must be an integer tensor, got {t.dtype}")
        return t.to(torch.int32).contiguous()
    if role.startswith("gbuffer."):  # read in place, no gradient (its dtype is checked when decoded)
        return t.detach().contiguous()
    if (role in TEXTURES or role == "histogram") and not t.is_floating_point():
        t = _unorm(func, role, t)
    if role in DIFFERENTIABLE:
        t = t.to(torch.float32).contiguous()
    elif role.startswith("histogram."):  # the transform's LUT, basis, centre: float32 data
        return t.detach().to(torch.float32).contiguous()
    else:  # e.g. object_to_world, layers_per_face: plain values, passed on as NumPy
        return t.detach().contiguous()
    if role in VEC2 and (t.dim() < 2 or t.shape[-1] != 2):
        raise ValueError(f"{func}(): {role} must have shape (..., 2) with a sample axis (uv[None] for one UV), got {tuple(t.shape)}")
    if role in PARAMS and t.dim() == 0:
        t = t.reshape(1)
    if role in TEXTURES or role == "histogram":
        texture_tensor(func, role, t)
    return t


# What integer texture tensors are divided by (torch.uint16 is new in PyTorch 2.3).
_UNORM_SCALES = {torch.uint8: 255.0, **({torch.uint16: 65535.0} if hasattr(torch, "uint16") else {})}


def _unorm(func: str, role: str, t: torch.Tensor) -> torch.Tensor:
    """An integer texture tensor as the native textures read integer arrays
    (:func:`warptex.texture_input.texel_values`): uint8 / uint16 divided by 255 / 65535 (in float64,
    then rounded, as NumPy does there), other integer dtypes refused."""
    scale = _UNORM_SCALES.get(t.dtype)
    if scale is None:
        raise TypeError(f"{func}(): {role} has integer dtype {t.dtype}; pass floats (linear, usually in [0, 1]), or uint8 / uint16, which are divided by 255 / 65535")
    return (t.to(torch.float64) / scale).to(torch.float32)


def texture_tensor(func: str, role: str, t) -> torch.Tensor:
    if not isinstance(t, torch.Tensor):
        raise TypeError(f"{func}(): {role} must be a torch tensor, got {type(t).__name__}")
    if t.dim() not in (3, 4) or not 1 <= t.shape[-1] <= 4 or 0 in t.shape:
        raise ValueError(f"{func}(): {role} must be a texture [H, W, C] or texture array [L, H, W, C] with 1 <= C <= 4, got shape {tuple(t.shape)}")
    return t


def out_shape(spec: dict, tensors: list[torch.Tensor]) -> tuple[int, ...]:
    """The op's output shape, from the spec and the tensors' shapes (for torch.compile's tracing)."""
    args, technique = spec["args"], TECHNIQUES[spec["technique"]]

    def shape(ref):
        return tuple(tensors[ref["$t"]].shape)

    def first_texture(value):
        if isinstance(value, dict) and "$t" in value:
            return shape(value)
        if isinstance(value, list):
            return next((s for s in map(first_texture, value) if s is not None), None)
        return None

    if technique.rows == "uv":
        rows = shape(args["uv"])[:-1]
    else:
        rows = shape(args["gbuffer"]["$gbuffer"]["mask"])  # (H, W) or (V, H, W)
    channels = technique.channels
    if channels is None:
        channels = next(s for s in (first_texture(args.get(k)) for k in technique.positional + ("textures_per_axis", "textures_per_face")) if s is not None)[-1]
    return (*rows, channels)


def gbuffer_tensors(gbuffer: GBuffer) -> dict[str, torch.Tensor]:
    """A :class:`~warptex.GBuffer`'s arrays as zero-copy tensors, named as :meth:`GBuffer.numpy
    <warptex.GBuffer.numpy>` names them (``"position"``, ``"uv0.uv"``...): ``(H, W, 3)`` for
    ``vec3`` fields, ``(H, W)`` for scalars; and, where they are not the defaults, ``"origin"``
    (float64 ``(3,)``, the world point the positions are relative to) and ``"samples"`` (int64
    ``(1,)``, samples per image pixel), so that a camera-relative or supersampled G-buffer keeps what
    it is. Every function here takes this dict as its G-buffer, which keeps Warp out of code that
    ``torch.compile`` compiles."""
    if not isinstance(gbuffer, GBuffer):
        raise TypeError(f"warptex.torch.gbuffer_tensors(): gbuffer must be a GBuffer, got {type(gbuffer).__name__}")
    out = {name: wp.to_torch(getattr(gbuffer, name), requires_grad=False) for name in FIELDS}
    for set_name, arrays in gbuffer.uv_sets.items():
        out.update({f"{set_name}.{k}": wp.to_torch(v, requires_grad=False) for k, v in arrays.items()})
    device = out["mask"].device
    if np.any(gbuffer.origin != 0.0):
        out["origin"] = torch.tensor(gbuffer.origin, dtype=torch.float64, device=device)
    if gbuffer.samples != 1:
        out["samples"] = torch.tensor([gbuffer.samples], dtype=torch.int64, device=device)
    return out
