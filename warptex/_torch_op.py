"""The PyTorch bridge's op (see :mod:`warptex.torch` for what it does and how to use it).

Each call is one ``torch.library`` custom op, ``warptex::technique``, taking a spec and its tensors
(:mod:`warptex._torch_spec`), where ``torch.compile`` traces it; in eager mode the same two passes
run as one ``torch.autograd.Function`` (:class:`_Eager`): an empty op's forward and backward took
0.4–0.5 ms here, an empty Function's 0.1. The forward runs the native function on zero-copy Warp
views of the tensors (on torch's current CUDA stream), under a ``wp.Tape`` when a gradient will be
needed; the tape is kept for the backward (``warptex::technique_backward``), which runs it once per
``backward()`` and returns the gradients as new tensors (a texture's own buffer where it can:
``warptex._torch_texture``, which also keeps the textures made around a tensor for its next calls).
The tape lives as long as the autograd graph that holds it (a token tensor saved in the graph; its
finaliser forgets the tape and gives the call's kept textures back).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import itertools
import threading
import weakref
from typing import Any

import numpy as np
import torch
import warp as wp

from warptex._pack import mip_levels, sampler_args
from warptex._torch_spec import DIFFERENTIABLE, HISTOGRAM, INTS, TECHNIQUES, TEXTURES, VEC2, op_arguments, out_shape, parse
from warptex._torch_texture import Handed, give_back, texture_around, view, zeros
from warptex.gbuffer import FIELDS, UV_FIELDS, GBuffer
from warptex.histogram import Histogram
from warptex.options import Sampler, Stochastic
from warptex.texture import Texture, TextureArray


def call(name: str, args: dict[str, Any]) -> torch.Tensor:
    """Run technique ``name`` on ``args`` through the op; the output is computed in float32 and
    returned in the floating dtype of the differentiable tensors among ``args`` (torch's promotion:
    float64 inputs give a float64 output; their gradients come back in their own dtypes)."""
    spec, tensors = op_arguments(name, args)
    if torch.compiler.is_compiling():  # what torch.compile sees: one opaque op, with its fake and autograd registrations
        out, _token = torch.ops.warptex.technique(spec, tensors)
    elif not parse(spec)["grad"]:  # eager, no gradient wanted: the forward alone, with no autograd node (~10 us)
        out = _forward(spec, tensors)[0]
    else:  # eager: the same passes without the custom op's dispatch, which cost a 1,024-UV call ~0.3 ms of ~2.5
        out = _Eager.apply(spec, *tensors)
    dtype = _result_dtype(args)
    return out if dtype == torch.float32 else out.to(dtype)


def _result_dtype(args: dict) -> torch.dtype:
    """The promoted floating dtype of the differentiable tensors among ``args`` (float32 without any)."""
    result = None
    for role, t in _tensors(args):
        if t.is_floating_point() and role in DIFFERENTIABLE:
            result = t.dtype if result is None else torch.promote_types(result, t.dtype)
    return torch.float32 if result is None else result


def _tensors(value, role: str | None = None):
    """``(role, tensor)`` of every tensor in an argument dict (or list) as ``call`` takes it."""
    if isinstance(value, torch.Tensor):
        yield role, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _tensors(v, k if role is None else role)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _tensors(v, role)


# The recorded tapes, by token, until the token tensor (saved in the autograd graph) dies.
_states: dict[int, "_State"] = {}
_tokens = itertools.count(1)
_states_lock = threading.RLock()  # re-entrant: a token's finaliser (_forget) can run in a collection under it


@dataclasses.dataclass
class _State:
    tape: wp.Tape
    out: torch.Tensor  # the output's buffer, which the tape's launches write (Warp's generated adjoints replay the forward)
    out_grad: torch.Tensor  # its gradient, where the tape's backward reads it
    grads: dict[int, Any]  # tensor index -> a function returning its gradient (a new tensor)
    leases: list  # the kept textures the recorded pass reads (warptex._torch_texture), given back with it
    passes: int = 0  # backward passes run so far


@dataclasses.dataclass
class _Decoding:
    """What :func:`_decode` reads and fills while it turns a spec into native arguments."""

    tensors: list[torch.Tensor]
    want: set  # the indices of the tensors that get gradients
    grads: dict[int, Any]  # filled: tensor index -> a function returning its gradient
    device: Any  # the Warp device
    mips: bool  # whether textures need their mips
    leases: list = dataclasses.field(default_factory=list)  # filled: the kept textures taken (warptex._torch_texture)


def _forward(spec: str, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    """The op's forward: ``[output, token]`` (the token names the kept tape; 0 without one)."""
    s = parse(spec)
    device = _warp_device(tensors[0].device)
    mips = _reads_mips(spec)
    decoding = _Decoding(tensors, set(s["grad"]), {}, device, mips)
    tape = wp.Tape() if decoding.want else None
    try:
        with _torch_stream(device), tape if tape is not None else contextlib.nullcontext():  # textures are built on the tape too: their mips' gradients reach level 0
            result, out_grad = _run(s, _decode(s["args"], decoding), tensors, device, gradient=tape is not None)
    except BaseException:
        give_back(decoding.leases)
        raise
    if tape is None:
        give_back(decoding.leases)
        return [result, torch.zeros(1, dtype=torch.int64)]
    with _states_lock:
        key = next(_tokens)
        _states[key] = _State(tape, result.detach(), out_grad, decoding.grads, decoding.leases)  # (an alias: the output itself would hold the graph)
    token = torch.tensor([key], dtype=torch.int64)
    weakref.finalize(token, _forget, key)
    return [result, token]


def _forget(key: int) -> None:
    with _states_lock:
        state = _states.pop(key, None)
    if state is not None:
        give_back(state.leases)


@torch.library.custom_op("warptex::technique", mutates_args=())
def _technique(spec: str, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    return _forward(spec, tensors)


@_technique.register_fake
def _(spec, tensors):
    s = parse(spec)
    return [tensors[0].new_empty(out_shape(s, tensors), dtype=torch.float32), torch.empty(1, dtype=torch.int64)]


def _backward_pass(token: torch.Tensor, grad: torch.Tensor, spec: str, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    """The op's backward: the kept tape run with the output's gradient ``grad``; a gradient per
    tensor (an empty one where none is wanted)."""
    with _states_lock:
        state = _states.get(int(token[0]))
    if state is None:
        raise RuntimeError("warptex.torch: the recorded forward pass is gone (was backward() called after the graph was freed?)")
    device = _warp_device(grad.device)
    with _torch_stream(device):
        handed = [(r, r.buffer.clone()) for r in state.grads.values() if isinstance(r, Handed) and r.handed]  # torch holds them
        if state.passes:  # a second backward() (retain_graph=True) starts afresh; the first finds every gradient
            state.tape.zero()  # zeroed where the forward made or took it (a 256² texture's: ~50-100 us a memset)
        state.passes += 1
        if grad.device.type == "cpu":  # through NumPy (see warptex._torch_texture.texture_around); any strides
            np.copyto(state.out_grad.numpy(), grad.detach().numpy())
        else:
            state.out_grad.copy_(grad)
        state.tape.backward()
        result = [state.grads[i]() if i in state.grads else t.new_empty(0) for i, t in enumerate(tensors)]
        for reader, held in handed:  # the kernels add where the forward's launches point: these buffers, given back as torch had them
            reader.buffer.copy_(held)
        return result


@torch.library.custom_op("warptex::technique_backward", mutates_args=())
def _technique_backward(token: torch.Tensor, grad: torch.Tensor, spec: str, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    return _backward_pass(token, grad, spec, tensors)


@_technique_backward.register_fake
def _(token, grad, spec, tensors):
    want = set(parse(spec)["grad"])
    return [torch.empty_like(t) if i in want else t.new_empty(0) for i, t in enumerate(tensors)]


def _setup_context(ctx, inputs, output):
    spec, tensors = inputs
    ctx.spec = spec
    ctx.save_for_backward(output[1], *tensors)


def _input_grads(ctx, grad, backward) -> list:
    """The gradient of each input tensor of a call (``None`` where the spec wants none), from
    ``backward(token, grad, spec, tensors)`` (the op, or :func:`_backward_pass` itself)."""
    token, *tensors = ctx.saved_tensors
    want = set(parse(ctx.spec)["grad"])
    if grad is None or not want:
        return [None] * len(tensors)
    result = backward(token, grad, ctx.spec, tensors)
    return [r if i in want else None for i, r in enumerate(result)]


def _backward(ctx, grads):
    return None, _input_grads(ctx, grads[0], torch.ops.warptex.technique_backward)


_technique.register_autograd(_backward, setup_context=_setup_context)


class _Eager(torch.autograd.Function):
    """The op's forward and backward as one autograd node, for eager mode (:func:`call`)."""

    @staticmethod
    def forward(ctx, spec: str, *tensors: torch.Tensor) -> torch.Tensor:
        out, token = _forward(spec, list(tensors))
        ctx.spec = spec
        ctx.save_for_backward(token, *tensors)
        return out

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad):
        return (None, *_input_grads(ctx, grad, _backward_pass))


def _warp_device(device: torch.device):
    wp.init()  # the Warp device of a torch device needs Warp started (a no-op once it is)
    return wp.device_from_torch(device)


def _torch_stream(device):
    """Warp on torch's current stream of ``device`` (CUDA), so the op is ordered with torch's work
    (and after Warp's, except while torch captures a CUDA graph: a capture must not wait on work
    outside it, and CUDA invalidates one that does)."""
    if device.is_cuda:
        stream = torch.cuda.current_stream(device.ordinal)
        return wp.ScopedStream(wp.stream_from_torch(stream), sync_enter=not torch.cuda.is_current_stream_capturing())
    return wp.ScopedDevice(device)


def _run(spec: dict, args: dict, tensors: list[torch.Tensor], device, gradient: bool) -> tuple[torch.Tensor, torch.Tensor | None]:
    """``(output, its gradient buffer or None)``: the native call of the spec's technique (its
    positional arguments by name, the rest by keyword) into a new tensor, with a zeroed gradient
    buffer where ``gradient`` (torch's buffers: ``out=`` of the native call)."""
    technique = TECHNIQUES[spec["technique"]]
    shape = out_shape(spec, tensors)
    result = torch.empty(shape, dtype=torch.float32, device=tensors[0].device)
    out = view(result, device)
    out_grad = None
    if gradient:
        out_grad = zeros(shape, result.device)
        out.grad = view(out_grad, device)
    technique.native(*[args.pop(k) for k in technique.positional], **args, out=out)
    return result, out_grad


@functools.lru_cache(maxsize=256)
def _reads_mips(spec: str) -> bool:
    """Whether the call may read a texture's levels past 0, so that its textures need their mips
    (built in the op, with their backward: most of a small call's time). ``sample`` and
    ``stochastic`` without a LOD (no ``lod``, ``uv_dx`` or ``uv_dy``) read the level that their
    sampler's bias and clamps make of LOD 0 (``warptex._pack.mip_levels``): level 0 alone where
    that is 0, as with the default sampler. Decided once per spec."""
    s = parse(spec)
    args = s["args"]
    if s["technique"] not in ("sample", "stochastic") or any(args.get(k) is not None for k in ("lod", "uv_dx", "uv_dy")):
        return True
    sampler = args.get("sampler")
    if sampler is None:
        return False
    try:
        smp = sampler_args(s["technique"], _sampler(sampler["$sampler"]), has_lod=False)
    except (TypeError, ValueError, KeyError):  # the native call says what is wrong
        return True
    return mip_levels(0.0, smp, num_levels=1 << 16) != (0, 0.0)


def _decode(value, d: _Decoding):
    """The native arguments of a spec: tensors as Warp views (or textures built around them, with
    their mips where ``d.mips``), with gradient buffers where ``d.want`` asks, whose readers go into ``d.grads``."""
    if isinstance(value, list):
        return [_decode(v, d) for v in value]
    if not isinstance(value, dict):
        return value
    if "$t" in value:
        return _decode_tensor(value["role"], value["$t"], d)
    if "$gbuffer" in value:
        return _decode_gbuffer(value["$gbuffer"], d.tensors, d.device)
    if "$sampler" in value:
        return _sampler(value["$sampler"])
    if "$stochastic" in value:
        return Stochastic(**_decode(value["$stochastic"], d))
    if "$histogram" in value:
        return Histogram(**_decode(value["$histogram"], d))
    return {k: _decode(v, d) for k, v in value.items()}


@functools.lru_cache(maxsize=64)
def _sampler_from(fields: tuple) -> Sampler:
    return Sampler(**dict(fields))


def _sampler(fields: dict) -> Sampler:
    """The :class:`Sampler` a spec names (its fields are literals: numbers, strings, lists): made
    once per distinct one, as making one checks and packs it (a fifth of a small call's time)."""
    return _sampler_from(tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in fields.items()))


def _decode_tensor(role: str, i: int, d: _Decoding):
    # Every Warp view says requires_grad=False or names its gradient buffer: wp.from_torch would
    # otherwise give a tensor that requires gradients a .grad of its own (the user's, in eager mode).
    t, want, grads = d.tensors[i], d.want, d.grads
    if role in TEXTURES or role == "histogram":
        return texture_around(t, mipmaps=d.mips and role != "splat_maps", index=i if i in want else None, grads=grads, leases=d.leases)
    if role in HISTOGRAM:
        return wp.from_torch(t, dtype=HISTOGRAM[role], requires_grad=False)
    if role not in DIFFERENTIABLE and role not in INTS:
        return t.cpu().numpy()
    dtype = wp.vec2 if role in VEC2 else wp.int32 if role in INTS else wp.float32
    array = view(t, d.device, dtype)
    if i in want:
        g = torch.zeros_like(t)
        grads[i] = g.clone
        array.grad = view(g, d.device, dtype)
    return array


def _decode_gbuffer(fields: dict, tensors, device) -> GBuffer:
    arrays, sets, extra = {}, {}, {}
    for name, ref in fields.items():
        if not (isinstance(ref, dict) and "$t" in ref):
            raise TypeError(f"warptex.torch: G-buffer field {name!r} must be a tensor")
        t = tensors[ref["$t"]]
        if name == "origin":  # camera-relative positions: the float64 point they are relative to
            extra["origin"] = t.detach().cpu().double().numpy()
        elif name == "samples":
            extra["samples"] = int(t.reshape(-1)[0])
        elif "." in name:
            set_name, key = name.split(".", 1)
            if key not in UV_FIELDS:
                raise ValueError(f"warptex.torch: unknown G-buffer UV field {name!r} (UV fields: {', '.join(UV_FIELDS)})")
            sets.setdefault(set_name, {})[key] = _gbuffer_array(name, t, UV_FIELDS[key], device)
        elif name in FIELDS:
            arrays[name] = _gbuffer_array(name, t, FIELDS[name], device)
        else:
            raise ValueError(f"warptex.torch: unknown G-buffer field {name!r} (fields: {', '.join(FIELDS)}, origin, samples)")
    missing = [name for name in FIELDS if name not in arrays]
    if missing:
        raise ValueError(f"warptex.torch: the G-buffer dict lacks {', '.join(missing)}; make it with warptex.torch.gbuffer_tensors(gbuffer)")
    return GBuffer(**arrays, uv_sets=sets, **extra)


def _gbuffer_array(name: str, t: torch.Tensor, dtype, device) -> wp.array:
    length = getattr(dtype, "_length_", 1)  # vec3: 3; float32, int32: 1
    scalar = torch.int32 if dtype == wp.int32 else torch.float32
    if t.dtype != scalar or t.dim() - (length > 1) not in (2, 3) or (length > 1 and t.shape[-1] != length):
        want = "(H, W) or (V, H, W)" if length == 1 else f"(H, W, {length}) or (V, H, W, {length})"
        raise ValueError(f"warptex.torch: G-buffer field {name!r} must be a {scalar} tensor of shape {want}, got {t.dtype} {tuple(t.shape)}")
    return view(t, device, dtype)


def native_texture(values, dims: int) -> TextureArray:
    return Texture(values) if dims == 3 else TextureArray(values)
