"""warptex for PyTorch: every technique as a differentiable torch function.

::

    import torch
    import warptex.torch as wtt

    texture = torch.rand(256, 256, 3, requires_grad=True)   # [H, W, C], linear
    uv = torch.rand(4096, 2, requires_grad=True)
    colour = wtt.sample(texture, uv)                        # (4096, 3)
    colour.square().mean().backward()                       # texture.grad, uv.grad

The functions take the native functions' arguments (:func:`warptex.sample`, :func:`~warptex.stochastic`,
:func:`~warptex.triplanar`, :func:`~warptex.biplanar`, :func:`~warptex.triplanar_normal`,
:func:`~warptex.splat`, :func:`~warptex.splat_atlas`), with torch tensors where those take arrays:

- **textures** are float tensors, ``[H, W, C]`` for one texture or ``[L, H, W, C]`` for a texture
  array (``1 <= C <= 4``, linear). Their mip chain is built inside the op, on the tape, so the
  gradients of every level a sample reads reach the tensor with no extra step;
- **per-sample inputs** (``uv``, ``uv_dx``, ``uv_dy``: ``(..., 2)``; ``lod``: uv's sample shape;
  ``layer``: int, uv's sample shape) and **parameters** (``tiling``, ``sharpness``, ``offsets``,
  ``height_blend``, the atlas ``weights``) are tensors or plain numbers;
- the **G-buffer** is a :class:`~warptex.GBuffer` (e.g. :meth:`GBuffer.from_arrays
  <warptex.GBuffer.from_arrays>` of another renderer's tensors), or the dict of tensors that
  :func:`gbuffer_tensors` makes of one (the form to pass inside ``torch.compile``d code). Its
  arrays are read in place and receive no gradients;
- options (:class:`~warptex.Sampler`, :class:`~warptex.Stochastic`, enums, strings) as natively.

Gradients flow through torch autograd to every differentiable tensor: texels, ``uv``, ``lod``,
``uv_dx``/``uv_dy``, ``tiling``, ``sharpness``, ``offsets``, splat maps, ``heights``,
``height_blend``, atlas ``weights`` and layers, and a histogram's Gaussianised texture
(:func:`prepare_histogram`). Outputs are the native call's bit for bit, gradients the native backward
pass's (to float rounding; tests/test_torch.py).

How it runs. Each call is one ``torch.library`` custom op (``warptex::technique``), so autograd and
``torch.compile`` see a single opaque node. Its forward runs the native function on zero-copy Warp
views of the tensors (on torch's current CUDA stream), under a ``wp.Tape`` when a gradient will be
needed; the tape is kept for the backward op (``warptex::technique_backward``), which runs it once
per ``backward()`` and returns the gradients as new tensors. The tape lives as long as the autograd
graph that holds it. Inputs must not be modified in place between the forward and the backward
(torch's own rule for saved tensors; the Warp views read them in place). A second-order gradient
(a gradient of the gradient) is not supported.

Requires PyTorch (``pip install "warptex[torch]"``); the rest of warptex never imports it.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import itertools
import math
import threading
import weakref
from typing import Any

import numpy as np
import torch
import warp as wp

from warptex.atlas import pack_atlas, splat_atlas as _splat_atlas
from warptex.gbuffer import FIELDS, UV_FIELDS, GBuffer
from warptex.histogram import Histogram
from warptex.histogram import prepare_histogram as _prepare_histogram
from warptex.splat import splat as _splat
from warptex.options import Sampler, Stochastic
from warptex.sampling import sample as _sample
from warptex.stochastic import stochastic as _stochastic
from warptex.texture import Texture, TextureArray, mip_sizes
from warptex.triplanar import biplanar as _biplanar
from warptex.triplanar import triplanar as _triplanar
from warptex.triplanar import triplanar_normal as _triplanar_normal

__all__ = [
    "biplanar",
    "gbuffer_tensors",
    "prepare_histogram",
    "sample",
    "splat",
    "splat_atlas",
    "stochastic",
    "triplanar",
    "triplanar_normal",
]

# Argument roles: how a tensor argument of that name is handed to the native function.
_TEXTURES = {"texture", "textures_per_axis", "textures_per_face", "layers", "heights", "splat_maps"}
_VEC2 = {"uv", "uv_dx", "uv_dy"}
_PARAMS = {"tiling", "sharpness", "offsets", "height_blend"}  # float32 parameter arrays, (1,) for a scalar
_FLOATS = _PARAMS | {"lod", "weights"}
_INTS = {"layer", "indices"}
_DIFFERENTIABLE = _TEXTURES | _VEC2 | _FLOATS | {"histogram"}  # "histogram": its Gaussianised texture
_HISTOGRAM = {"histogram.lut": wp.float32, "histogram.basis": wp.mat33, "histogram.centre": wp.vec3}


# -- the public functions ---------------------------------------------------------------------------


def sample(texture, uv, *, layer=None, lod=None, uv_dx=None, uv_dy=None, sampler: Sampler | None = None) -> torch.Tensor:
    """:func:`warptex.sample` on tensors: ``texture`` ``[H, W, C]`` or ``[L, H, W, C]``, ``uv``
    ``(..., 2)``; returns ``(..., C)``. Gradients reach ``texture``, ``uv``, a per-sample ``lod``
    and ``uv_dx``/``uv_dy``. Bilinear ``sample`` with ``"clamp"`` addressing is
    ``torch.nn.functional.grid_sample(..., align_corners=False, padding_mode="border")`` at
    ``grid = (2u - 1, 1 - 2v)``."""
    return _call("sample", {"texture": texture, "uv": uv, "layer": layer, "lod": lod, "uv_dx": uv_dx, "uv_dy": uv_dy, "sampler": sampler})


def stochastic(texture, uv, method="hash4", *, layer=None, lod=None, uv_dx=None, uv_dy=None, sampler: Sampler | None = None) -> torch.Tensor:
    """:func:`warptex.stochastic` on tensors (see :func:`sample`). With a histogram
    (``Stochastic(method="hex", histogram=prepare_histogram(texture))``, this module's
    :func:`prepare_histogram`), the texels read are the histogram's Gaussianised texture, and the
    gradients go there: ``texture`` receives none."""
    return _call("stochastic", {"texture": texture, "uv": uv, "method": method, "layer": layer, "lod": lod, "uv_dx": uv_dx, "uv_dy": uv_dy, "sampler": sampler})


def triplanar(gbuffer, texture=None, **options) -> torch.Tensor:
    """:func:`warptex.triplanar` on tensors: ``texture`` (and ``textures_per_axis`` /
    ``textures_per_face`` entries) ``[H, W, C]`` or ``[L, H, W, C]``; ``tiling``, ``sharpness``,
    ``offsets`` numbers or tensors. Returns ``(H, W, C)``."""
    return _call("triplanar", {"gbuffer": gbuffer, "texture": texture, **options})


def biplanar(gbuffer, texture=None, **options) -> torch.Tensor:
    """:func:`warptex.biplanar` on tensors (see :func:`triplanar`). Returns ``(H, W, C)``."""
    return _call("biplanar", {"gbuffer": gbuffer, "texture": texture, **options})


def triplanar_normal(gbuffer, normal_map=None, **options) -> torch.Tensor:
    """:func:`warptex.triplanar_normal` on tensors (see :func:`triplanar`); ``normal_map`` as stored
    (``[0, 1]`` data). Returns unit world-space normals ``(H, W, 3)``."""
    return _call("triplanar_normal", {"gbuffer": gbuffer, "texture": normal_map, **options})


def splat(gbuffer, layers, splat_maps, **options) -> torch.Tensor:
    """:func:`warptex.splat` on tensors: ``layers`` ``[L, H, W, C]``, ``splat_maps`` ``[h, w, C]``
    or ``[M, h, w, C]`` (read on level 0, no mips), ``heights`` ``[L, h, w, 1]``. Returns
    ``(H, W, C)``; gradients reach the layers, the splat maps, ``heights``, ``tiling``,
    ``height_blend``, ``sharpness`` and ``offsets``."""
    return _call("splat", {"gbuffer": gbuffer, "layers": layers, "splat_maps": splat_maps, **options})


def splat_atlas(gbuffer, layers, indices, weights, *, gutter: int = 4, columns: int | None = None, **options) -> torch.Tensor:
    """:func:`warptex.splat_atlas` on tensors: ``layers`` ``[L, H, W, C]`` are packed into an atlas
    (:func:`warptex.pack_atlas` with ``gutter`` and ``columns``) inside the op, so their gradients
    come through the atlas; ``indices`` int ``[h, w, k]``, ``weights`` ``[h, w, k]``. Returns
    ``(H, W, C)``; gradients reach ``layers``, ``weights`` and ``tiling``."""
    return _call("splat_atlas", {"gbuffer": gbuffer, "layers": layers, "indices": indices, "weights": weights, "gutter": gutter, "columns": columns, **options})


def prepare_histogram(texture: torch.Tensor, *, lut_size: int = 4096, decorrelate: bool = False) -> Histogram:
    """:func:`warptex.prepare_histogram` of a texture tensor (``[H, W, C]`` or ``[L, H, W, C]``),
    for ``Stochastic(method="hex", histogram=...)`` in this module's functions.

    Returns a :class:`~warptex.Histogram` whose fields are tensors on ``texture``'s device:
    ``texture`` is the Gaussianised level 0 (shaped like the input; set ``requires_grad`` on it to
    fit it), ``lut``, ``basis`` and ``centre`` the transform. The transform is not differentiable.
    """
    func = "warptex.torch.prepare_histogram"
    t = _texture_tensor(func, "texture", texture)
    native = _prepare_histogram(_native_texture(t.detach().cpu().numpy(), t.dim()), lut_size=lut_size, decorrelate=decorrelate)

    def tensor(a):
        return None if a is None else torch.as_tensor(a.numpy()).to(t.device)

    level0 = native.texture.numpy(0)
    return Histogram(
        texture=torch.as_tensor(level0).to(t.device),
        lut=tensor(native.lut),
        lut_size=native.lut_size,
        levels=native.levels,
        basis=tensor(native.basis),
        centre=tensor(native.centre),
        decorrelate=native.decorrelate,
    )


def gbuffer_tensors(gbuffer: GBuffer) -> dict[str, torch.Tensor]:
    """A :class:`~warptex.GBuffer`'s arrays as zero-copy tensors, named as :meth:`GBuffer.numpy
    <warptex.GBuffer.numpy>` names them (``"position"``, ``"uv0.uv"``...): ``(H, W, 3)`` for
    ``vec3`` fields, ``(H, W)`` for scalars. Every function here takes this dict as its G-buffer,
    which keeps Warp out of ``torch.compile``d code."""
    if not isinstance(gbuffer, GBuffer):
        raise TypeError(f"warptex.torch.gbuffer_tensors(): gbuffer must be a GBuffer, got {type(gbuffer).__name__}")
    out = {name: wp.to_torch(getattr(gbuffer, name), requires_grad=False) for name in FIELDS}
    for set_name, arrays in gbuffer.uv_sets.items():
        out.update({f"{set_name}.{k}": wp.to_torch(v, requires_grad=False) for k, v in arrays.items()})
    return out


# -- packing arguments for the op -------------------------------------------------------------------
#
# The op takes a spec, a Python literal of the call's structure with every tensor replaced by its
# index, and the list of tensors: what torch.library ops and torch.compile can carry.


def _call(technique: str, args: dict[str, Any]) -> torch.Tensor:
    out, _token = torch.ops.warptex.technique(*_op_arguments(technique, args))
    return out


def _op_arguments(technique: str, args: dict[str, Any]) -> tuple[str, list[torch.Tensor]]:
    """``(spec, tensors)``: a call of ``technique`` with ``args`` as the op takes it."""
    func = f"warptex.torch.{technique}"
    tensors: list[torch.Tensor] = []
    spec = {"technique": technique, "args": {k: _encode(func, k, v, tensors) for k, v in args.items()}}
    devices = {t.device for t in tensors}
    if len(devices) > 1:
        raise ValueError(f"{func}(): every tensor must be on one device, got {sorted(str(d) for d in devices)}")
    if not tensors:
        raise ValueError(f"{func}(): needs tensor inputs (a texture tensor, a G-buffer)")
    spec["grad"] = [i for i, t in enumerate(tensors) if t.requires_grad] if torch.is_grad_enabled() else []
    return _literal(spec), tensors


def _literal(value) -> str:
    """``value`` (dicts, lists, strings, numbers, ``None``) as a Python literal for
    ``ast.literal_eval``. Written out here because ``torch.compile`` traces this code, and it cannot
    trace ``json.dumps`` (a C encoder) or ``repr`` of containers."""
    if isinstance(value, dict):
        return "{" + ", ".join(_literal(k) + ": " + _literal(v) for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    if isinstance(value, float) and not math.isfinite(value):
        return "{'$float': " + repr(str(value)) + "}"
    if value is None or isinstance(value, (bool, int, float, str)):
        return repr(value)
    raise TypeError(f"warptex.torch: cannot pass {type(value).__name__} to the op")


def _parse(spec: str):
    """The value :func:`_literal` wrote."""
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
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_encode(func, role, v, tensors) for v in value]
    if isinstance(value, GBuffer):
        return _encode(func, role, gbuffer_tensors(value), tensors)
    if isinstance(value, dict) and role == "gbuffer":
        return {"$gbuffer": {k: _encode(func, f"gbuffer.{k}", v, tensors) for k, v in value.items()}}
    if isinstance(value, Sampler):
        return {"$sampler": {f.name: _encode(func, role, getattr(value, f.name), tensors) for f in dataclasses.fields(value)}}
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
    if role in _INTS:
        if t.is_floating_point():
            raise TypeError(f"{func}(): {role} must be an integer tensor, got {t.dtype}")
        return t.to(torch.int32).contiguous()
    if role.startswith("gbuffer."):  # read in place, no gradient (its dtype is checked when decoded)
        return t.detach().contiguous()
    if role in _DIFFERENTIABLE:
        t = t.to(torch.float32).contiguous()
    elif role.startswith("histogram."):  # the transform's LUT, basis, centre: float32 data
        return t.detach().to(torch.float32).contiguous()
    else:  # e.g. object_to_world, face_layers: plain values, passed on as NumPy
        return t.detach().contiguous()
    if role in _VEC2 and (t.dim() < 2 or t.shape[-1] != 2):
        raise ValueError(f"{func}(): {role} must have shape (..., 2) with a sample axis (uv[None] for one UV), got {tuple(t.shape)}")
    if role in _PARAMS and t.dim() == 0:
        t = t.reshape(1)
    if role in _TEXTURES or role == "histogram":
        _texture_tensor(func, role, t)
    return t


def _texture_tensor(func: str, role: str, t) -> torch.Tensor:
    if not isinstance(t, torch.Tensor):
        raise TypeError(f"{func}(): {role} must be a torch tensor, got {type(t).__name__}")
    if t.dim() not in (3, 4) or not 1 <= t.shape[-1] <= 4 or 0 in t.shape:
        raise ValueError(f"{func}(): {role} must be a texture [H, W, C] or texture array [L, H, W, C] with 1 <= C <= 4, got shape {tuple(t.shape)}")
    return t


# -- the ops ----------------------------------------------------------------------------------------

_NATIVE = {
    "sample": _sample,
    "stochastic": _stochastic,
    "triplanar": _triplanar,
    "biplanar": _biplanar,
    "triplanar_normal": _triplanar_normal,
    "splat": _splat,
    "splat_atlas": _splat_atlas,
}

# The recorded tapes, by token, until the token tensor (saved in the autograd graph) dies.
_states: dict[int, "_State"] = {}
_tokens = itertools.count(1)
_states_lock = threading.Lock()


@dataclasses.dataclass
class _State:
    tape: wp.Tape
    out: wp.array
    grads: dict[int, Any]  # tensor index -> a function returning its gradient (a new tensor)


@torch.library.custom_op("warptex::technique", mutates_args=())
def _technique(spec: str, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    s = _parse(spec)
    device = _warp_device(tensors[0].device)
    with _torch_stream(device):
        grads: dict[int, Any] = {}
        want = set(s["grad"])
        tape = wp.Tape() if want else None
        if tape is not None:
            with tape:  # textures are built on the tape too: their mips' gradients reach level 0
                args = _decode(s["args"], tensors, want, grads, device)
                out = _run(s["technique"], args)
        else:
            args = _decode(s["args"], tensors, want, grads, device)
            out = _run(s["technique"], args)
        result = wp.to_torch(out, requires_grad=False)
    if tape is None:
        return [result, torch.zeros(1, dtype=torch.int64)]
    with _states_lock:
        key = next(_tokens)
        _states[key] = _State(tape, out, grads)
    token = torch.tensor([key], dtype=torch.int64)
    weakref.finalize(token, _forget, key)
    return [result, token]


def _forget(key: int) -> None:
    with _states_lock:
        _states.pop(key, None)


@_technique.register_fake
def _(spec, tensors):
    s = _parse(spec)
    return [tensors[0].new_empty(_out_shape(s, tensors), dtype=torch.float32), torch.empty(1, dtype=torch.int64)]


@torch.library.custom_op("warptex::technique_backward", mutates_args=())
def _technique_backward(token: torch.Tensor, grad: torch.Tensor, spec: str, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    with _states_lock:
        state = _states.get(int(token[0]))
    if state is None:
        raise RuntimeError("warptex.torch: the recorded forward pass is gone (was backward() called after the graph was freed?)")
    device = _warp_device(grad.device)
    with _torch_stream(device):
        state.tape.zero()  # a second backward() (retain_graph=True) starts afresh
        wp.copy(state.out.grad, _as_out(grad, state.out))
        state.tape.backward()
        return [state.grads[i]() if i in state.grads else t.new_empty(0) for i, t in enumerate(tensors)]


@_technique_backward.register_fake
def _(token, grad, spec, tensors):
    want = set(_parse(spec)["grad"])
    return [torch.empty_like(t) if i in want else t.new_empty(0) for i, t in enumerate(tensors)]


def _setup_context(ctx, inputs, output):
    spec, tensors = inputs
    ctx.spec = spec
    ctx.save_for_backward(output[1], *tensors)


def _backward(ctx, grads):
    token, *tensors = ctx.saved_tensors
    grad = grads[0]
    want = set(_parse(ctx.spec)["grad"])
    if grad is None or not want:
        return None, [None] * len(tensors)
    result = torch.ops.warptex.technique_backward(token, grad.contiguous(), ctx.spec, tensors)
    return None, [r if i in want else None for i, r in enumerate(result)]


_technique.register_autograd(_backward, setup_context=_setup_context)


def _as_out(grad: torch.Tensor, out: wp.array) -> wp.array:
    """The output gradient as a Warp array shaped like the op's output ``out``."""
    return wp.from_torch(grad.to(torch.float32).contiguous(), dtype=out.dtype, requires_grad=False).reshape(out.shape)


def _warp_device(device: torch.device):
    wp.init()  # the Warp device of a torch device needs Warp started (a no-op once it is)
    return wp.device_from_torch(device)


def _torch_stream(device):
    """Warp on torch's current stream of ``device`` (CUDA), so the op is ordered with torch's work."""
    if device.is_cuda:
        return wp.ScopedStream(wp.stream_from_torch(torch.cuda.current_stream(device.ordinal)))
    return wp.ScopedDevice(device)


def _run(technique: str, args: dict) -> wp.array:
    if technique == "splat_atlas":
        layers = args.pop("layers")
        atlas = pack_atlas(layers, gutter=args.pop("gutter"), columns=args.pop("columns"))
        return _splat_atlas(args.pop("gbuffer"), atlas, args.pop("indices"), args.pop("weights"), **args)
    native = _NATIVE[technique]
    if technique in ("sample", "stochastic"):
        return native(args.pop("texture"), args.pop("uv"), **args)
    if technique == "splat":
        return native(args.pop("gbuffer"), args.pop("layers"), args.pop("splat_maps"), **args)
    return native(args.pop("gbuffer"), args.pop("texture"), **args)


def _out_shape(spec: dict, tensors: list[torch.Tensor]) -> tuple[int, ...]:
    """The op's output shape, from the spec and the tensors' shapes (for torch.compile's tracing)."""
    args, technique = spec["args"], spec["technique"]

    def shape(ref):
        return tuple(tensors[ref["$t"]].shape)

    def first_texture(value):
        if isinstance(value, dict) and "$t" in value:
            return shape(value)
        if isinstance(value, list):
            return next((s for s in map(first_texture, value) if s is not None), None)
        return None

    if technique in ("sample", "stochastic"):
        return shape(args["uv"])[:-1] + (shape(args["texture"])[-1],)
    pixels = shape(args["gbuffer"]["$gbuffer"]["mask"])  # (H, W) or (V, H, W)
    if technique == "triplanar_normal":
        return (*pixels, 3)
    texture = next(s for s in (first_texture(args.get(k)) for k in ("layers", "texture", "textures_per_axis", "textures_per_face")) if s is not None)
    return (*pixels, texture[-1])


def _decode(value, tensors: list[torch.Tensor], want: set, grads: dict, device):
    """The native arguments of a spec: tensors as Warp views (or textures built around them), with
    gradient buffers where ``want`` asks, whose readers go into ``grads``."""
    if isinstance(value, list):
        return [_decode(v, tensors, want, grads, device) for v in value]
    if not isinstance(value, dict):
        return value
    if "$t" in value:
        return _decode_tensor(value["role"], value["$t"], tensors, want, grads, device)
    if "$gbuffer" in value:
        return _decode_gbuffer(value["$gbuffer"], tensors)
    if "$sampler" in value:
        return Sampler(**_decode(value["$sampler"], tensors, want, grads, device))
    if "$stochastic" in value:
        return Stochastic(**_decode(value["$stochastic"], tensors, want, grads, device))
    if "$histogram" in value:
        return Histogram(**_decode(value["$histogram"], tensors, want, grads, device))
    return {k: _decode(v, tensors, want, grads, device) for k, v in value.items()}


def _decode_tensor(role: str, i: int, tensors, want, grads, device):
    # Every Warp view says requires_grad=False or names its gradient buffer: wp.from_torch would
    # otherwise give a tensor that requires gradients a .grad of its own (the user's, in eager mode).
    t = tensors[i]
    if role in _TEXTURES or role == "histogram":
        return _texture_around(t, mipmaps=role != "splat_maps", index=i if i in want else None, grads=grads, device=device)
    if role in _HISTOGRAM:
        return wp.from_torch(t, dtype=_HISTOGRAM[role], requires_grad=False)
    if role not in _DIFFERENTIABLE and role not in _INTS:
        return t.cpu().numpy()
    dtype = wp.vec2 if role in _VEC2 else wp.int32 if role in _INTS else wp.float32
    if i not in want:
        return wp.from_torch(t, dtype=dtype, requires_grad=False)
    g = torch.zeros_like(t)
    grads[i] = g.clone
    return wp.from_torch(t, dtype=dtype, grad=g)


def _decode_gbuffer(fields: dict, tensors) -> GBuffer:
    arrays, sets = {}, {}
    for name, ref in fields.items():
        if not (isinstance(ref, dict) and "$t" in ref):
            raise TypeError(f"warptex.torch: G-buffer field {name!r} must be a tensor")
        t = tensors[ref["$t"]]
        if "." in name:
            set_name, key = name.split(".", 1)
            if key not in UV_FIELDS:
                raise ValueError(f"warptex.torch: unknown G-buffer UV field {name!r} (UV fields: {', '.join(UV_FIELDS)})")
            sets.setdefault(set_name, {})[key] = _gbuffer_array(name, t, UV_FIELDS[key])
        elif name in FIELDS:
            arrays[name] = _gbuffer_array(name, t, FIELDS[name])
        else:
            raise ValueError(f"warptex.torch: unknown G-buffer field {name!r} (fields: {', '.join(FIELDS)})")
    missing = [name for name in FIELDS if name not in arrays]
    if missing:
        raise ValueError(f"warptex.torch: the G-buffer dict lacks {', '.join(missing)}; make it with warptex.torch.gbuffer_tensors(gbuffer)")
    return GBuffer(**arrays, uv_sets=sets)


def _gbuffer_array(name: str, t: torch.Tensor, dtype) -> wp.array:
    length = getattr(dtype, "_length_", 1)  # vec3: 3; float32, int32: 1
    scalar = torch.int32 if dtype == wp.int32 else torch.float32
    if t.dtype != scalar or t.dim() - (length > 1) not in (2, 3) or (length > 1 and t.shape[-1] != length):
        want = "(H, W) or (V, H, W)" if length == 1 else f"(H, W, {length}) or (V, H, W, {length})"
        raise ValueError(f"warptex.torch: G-buffer field {name!r} must be a {scalar} tensor of shape {want}, got {t.dtype} {tuple(t.shape)}")
    return wp.from_torch(t, dtype=dtype, requires_grad=False)


def _zeros(shape: tuple, device: torch.device) -> torch.Tensor:
    """float32 zeros on ``device``; on the CPU from NumPy (see :func:`_texture_around`)."""
    if device.type == "cpu":
        return torch.from_numpy(np.zeros(shape, np.float32))
    return torch.zeros(shape, dtype=torch.float32, device=device)


def _native_texture(values, dims: int) -> TextureArray:
    return Texture(values) if dims == 3 else TextureArray(values)


def _texture_around(t: torch.Tensor, *, mipmaps: bool, index, grads: dict, device) -> TextureArray:
    """A :class:`Texture` (``t`` ``[H, W, C]``) or :class:`TextureArray` (``[L, H, W, C]``) whose
    chain is a torch buffer holding ``t`` at level 0, its mips built here (on the active tape);
    with ``index``, gradient buffers whose level 0 ``grads[index]`` returns shaped like ``t``.

    On the CPU the buffers are filled and read through NumPy, not torch: torch runs CPU tensor ops
    on its OpenMP threads, which keep spinning a while after each op, and the Warp launch that
    followed a torch copy of a 256² texture ran 20% slower on 2 cores (measured:
    ``benchmarks/bench_torch.py``)."""
    layers = t.unsqueeze(0) if t.dim() == 3 else t
    num_layers, height, width, channels = layers.shape
    sizes = mip_sizes(height, width, None if mipmaps else 1)
    texels = sum(num_layers * h * w for h, w in sizes)
    count = num_layers * height * width
    cpu = t.device.type == "cpu"
    chain = _zeros((texels, 4), t.device)
    if cpu:
        chain.numpy()[:count, :channels] = layers.detach().numpy().reshape(count, channels)
    else:
        chain[:count, :channels] = layers.detach().reshape(count, channels)
    grad = None
    if index is not None:
        grad = _zeros((texels, 4), t.device)
        if cpu:
            grads[index] = lambda: torch.from_numpy(grad.numpy()[:count, :channels].reshape(t.shape).copy())
        else:
            grads[index] = lambda: grad[:count, :channels].reshape(t.shape).clone()
    texture = (Texture if t.dim() == 3 else TextureArray).around(wp.from_torch(chain, dtype=wp.vec4, grad=grad), num_layers, sizes, channels)
    texture.update()
    return texture
