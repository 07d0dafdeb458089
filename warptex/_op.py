"""How a technique's kernels run, and which backward pass they record: one decision, for every technique.

A technique hands :func:`run` its :class:`~warptex.kernels.family.Kernels`, its ``args`` and
``pixels`` structs and its output's shape; :func:`run` derives everything else from those inputs:

- **which arrays want gradients**: every float array among the inputs that requires them, struct
  fields included (a texture's texels, ``tiling``, a G-buffer array...). The output requires
  gradients exactly when one does, so a new differentiable input is never silently left out;
- **which backward pass is recorded**, once per launch: none without a tape (or when nothing wants
  a gradient); the hand-written texel gradient (``texel_grad``) when every array that wants one is
  among those it serves (``Kernels.grads``), the blend of taps is ``linear`` and
  :func:`force_generated_adjoint` is not in effect; else Warp's generated adjoint (``adjoint``).
  Sampling is linear in the texels, so the gradient of a linear blend of taps adds each tap's
  weight times the output gradient into the texels it read, at about the cost of one forward pass;
  Warp's generated adjoint, which replays every function's forward inside its reverse pass, cost
  five. Where a path is a :class:`~warptex.kernels.family.Staged` pair of steps, :func:`run`
  composes it: the first step's intermediates, then the second step with its own backward;
- **what the forward keeps for the backward**: where the CPU's lane kernels run both the launch and
  its hand-written backward, the values ``Kernels.lane_saved`` names, in an array the recorded pass
  holds (made by ``warptex._memory.empty``: a new 50 MB array cost ~25 ms of page faults here on
  its first writes, more than keeping the values saves).
"""

from __future__ import annotations

import threading

import warp as wp

from warptex._launch import GENERATED, Target, launch, output, scatter
from warptex._memory import empty
from warptex._pack import empty_array
from warptex._warp import active_tape, scalar_type, struct_array_values, struct_arrays, struct_fields, struct_like
from warptex.kernels.family import PIXELS, Kernels, Staged, lanes_for, one_pixel_kernels, thread_flag  # noqa: F401 (one_pixel_kernels: re-exported)
from warptex.kernels.texels import TextureView

_forced = threading.local()

# Scalar types of the arrays that can carry gradients.
_FLOATS = (wp.float16, wp.float32, wp.float64)


def force_generated_adjoint(enabled: bool = True):
    """Within this block (on this thread), every recorded backward pass is Warp's generated adjoint,
    never a hand-written gradient: for tests that compare the two."""
    return thread_flag(_forced, enabled)


def differentiable(value, path: str = ""):
    """``(path, array)`` of every float array in ``value`` (an array, a struct or a dict, walked as
    ``wp.Tape.get_adjoint`` walks it), e.g. ``("args.tex.texels", texels)``."""
    if wp.types.is_array(value):
        if scalar_type(value.dtype) in _FLOATS:
            yield path, value
    elif isinstance(value, dict):
        for name, field in value.items():
            yield from differentiable(field, f"{path}.{name}" if path else name)
    elif wp.types.is_struct(value):
        for dotted, array in struct_arrays(value, _FLOATS):
            yield (f"{path}.{dotted}" if path else dotted), array


def _requiring_grad(*values) -> list:
    """The float arrays in ``values`` (structs, read by one getter per struct type, or anything
    :func:`differentiable` walks) that require gradients, in :func:`differentiable`'s order."""
    found = []
    for value in values:
        arrays = struct_array_values(value, _FLOATS) if wp.types.is_struct(value) else [a for _, a in differentiable(value)]
        found += [a for a in arrays if a.requires_grad]
    return found


def resolve(inputs: dict, path: str) -> wp.array | None:
    """The array a gradient path names (``"args.layers"``: a ``TextureView``'s texels)."""
    value = inputs
    for name in path.split("."):
        value = value[name] if isinstance(value, dict) else getattr(value, name)
    if getattr(value, "_cls", None) is TextureView:  # a texture: its texels
        value = value.texels
    return value if wp.types.is_array(value) and value.shape[0] > 0 else None


def run(kernels: Kernels, count: int, *, args, pixels, out: tuple, device, linear: bool = True, covered: wp.array | None = None, footprints: int = 1, touched: dict | None = None) -> wp.array:
    """Launch ``kernels`` over ``count`` pixels into a new output and record the backward pass a
    ``wp.Tape`` needs (module docstring).

    Args:
        kernels: the technique's :class:`~warptex.kernels.family.Kernels` for this configuration.
        count: pixels (launch size).
        args, pixels: the kernels' fixed and per-pixel argument structs.
        out: ``(shape, dtype)`` of a new output (first axis: ``count``), or the caller's array
            (``out=`` of a technique, checked by ``warptex._pack.out_array``), filled in place.
        device: the Warp device.
        linear: whether the blend of taps is linear in the texels (``False``: a histogram blend,
            which only the generated adjoint differentiates).
        covered: the G-buffer's mask, for a launch over a G-buffer (balances the threads' chunks).
        footprints: the bilinear footprints a pixel reads at most (``warptex._pack.footprints``):
            what its backward pass costs, which sizes the backward's chunks (``warptex._threads.grad_bounds``).
        touched: ``{path: (start, stop)}`` for hand-written gradient targets the kernel adds into
            only there (a constant-LOD lookup reads one or two mip levels): only those entries are
            summed from the per-thread copies.

    Returns:
        the output, requiring gradients when any differentiable input does.
    """
    inputs = {"args": args, "pixels": pixels}
    wanted = _requiring_grad(args, pixels)
    if isinstance(out, wp.array):
        result = out
        if wanted and not result.requires_grad and active_tape() is not None:
            raise ValueError("out= must be made with requires_grad=True: an input requires gradients, and the active wp.Tape records this call")
    else:
        result = output(*out, device=device, requires_grad=bool(wanted))
    cut = {"covered": covered, "footprints": footprints}  # how launches are cut into chunks
    if active_tape() is None or not wanted:
        launch(kernels.forward, count, args=args, pixels=pixels, out=result, device=device, lanes=lanes_for(kernels, device, args), fills=kernels.fills, **cut)
    else:
        path = _backward_path(kernels, inputs, wanted, linear)
        if path == "adjoint" and any(getattr(a, "warptex_carrier", False) for a in wanted):
            raise ValueError(
                "texel gradients of a texture stored in a compact format (float16, unorm8, srgb8) come from warptex's "
                "hand-written gradients, and this call needs Warp's generated one (a gradient of an input besides texels "
                "that the technique's own gradient does not serve: UV derivatives, G-buffer arrays, a stochastic lookup's "
                "tiling, UVs, sharpness or offsets, a splat's sharpness or offsets; or a histogram-preserving blend): "
                "sample a float32 copy of the texture, "
                "Texture(texture, format='float32'), or leave its requires_grad off"
            )
        _run_path(kernels, path, count, inputs, result, device, cut, touched)
    return result


def _backward_path(kernels: Kernels, inputs: dict, wanted: list, linear: bool) -> str:
    """``"texel_grad"`` when the hand-written gradient serves every array in ``wanted`` (a staged
    pair's: its first step's paths, and those only its second step differentiates), else ``"adjoint"``."""
    by_hand = kernels.texel_grad is not None or (kernels.staged is not None and kernels.staged.replaces == "texel_grad")
    if not by_hand or not linear or getattr(_forced, "value", False):
        return "adjoint"
    paths = kernels.grads if kernels.texel_grad is not None else kernels.staged.first.grads + kernels.staged.then_only
    served = {id(a) for a in (resolve(inputs, p) for p in paths if p is not None) if a is not None}
    return "texel_grad" if all(id(a) in served for a in wanted) else "adjoint"


def _run_path(kernels: Kernels, path: str, count: int, inputs: dict, result, device, cut: dict, touched) -> None:
    """Launch ``kernels`` recording the backward ``path`` (or the staged pair that stands for it)."""
    if kernels.staged is not None and kernels.staged.replaces == path and (kernels.texel_grad if path == "texel_grad" else kernels.adjoint) is None:
        _run_staged(kernels.staged, count, inputs, result, device, cut)
    elif path == "texel_grad":
        lanes, grad_lanes = lanes_for(kernels, device, inputs["args"]), lanes_for(kernels, device, inputs["args"], grad=True)
        if kernels.lane_saved is not None and grad_lanes is not None:  # a gradient lane that reads what the forward lane keeps:
            # held by the recorded pass alone; once it is gone, a kept block for the next (warptex._memory)
            inputs["pixels"].saved = empty((count, kernels.lane_saved(inputs["args"])), float, device)
            lanes = kernels.kept_lanes or lanes
        launch(kernels.forward, count, args=inputs["args"], pixels=inputs["pixels"], out=result, device=device, lanes=lanes, fills=kernels.fills, **cut,
               backward=_texel_gradient(kernels, count, inputs, result, device, cut, touched, grad_lanes))  # fmt: skip
    elif kernels.adjoint is not None:
        launch(kernels.adjoint, count, args=inputs["args"], pixels=inputs["pixels"], out=result, device=device, fills=kernels.fills, **cut, backward=GENERATED)
    else:
        raise RuntimeError("warptex internal error: a gradient was asked for that this technique has no kernel for")


def _texel_gradient(kernels: Kernels, count: int, inputs: dict, result, device, cut: dict, touched, lanes):
    """``backward(tape)``: ``kernels.texel_grad`` adds the output's gradient, through the forward
    pass, into the gradients of the inputs ``kernels.grads`` names that require them (on the CPU by
    ``lanes``, its lane kernel, where not ``None``: decided where the pass is recorded)."""

    def backward(tape) -> None:
        targets, entries = [], {}
        for path in kernels.grads:
            array = resolve(inputs, path) if path is not None else None
            grad = tape.get_adjoint(array) if array is not None and array.requires_grad else None  # registered for tape.zero()
            targets.append(Target(grad, per_pixel=path is not None and path.startswith(PIXELS)))
            if grad is not None and touched and path in touched:
                entries[id(grad)] = touched[path]
        scatter(kernels.texel_grad, count, args=inputs["args"], pixels=inputs["pixels"], grads=targets, adj=_gradient_of(result), device=device, entries=entries, lanes=lanes, **cut)

    return backward


def _gradient_of(out):
    """The gradient arrays of an output: its ``.grad``, or a struct of its fields' ``.grad`` (an
    empty array for a field made without one: a staged step's ``no_grad`` intermediates)."""
    if wp.types.is_array(out):
        return out.grad
    grads = struct_like(out)
    for name, field in struct_fields(out).items():
        setattr(grads, name, field.grad if field.grad is not None else empty_array(field.dtype, field.ndim, field.device))
    return grads


def _run_staged(staged: Staged, count: int, inputs: dict, result, device, cut: dict) -> None:
    """The two steps of ``staged``: the intermediates (with the backward it replaces), then the
    output from them (with the other backward); the second step's arguments filled by name (nested
    structs' fields included)."""
    wanted = [a for p, a in differentiable(inputs) if a.requires_grad and not any(p == t or p.startswith(t + ".") for t in staged.then_only)]
    intermediates = _struct(next(a.type for a in staged.first.forward.adj.args if a.label == "out"), {})
    for name, (shape, dtype) in staged.intermediates(count, inputs["args"]).items():
        setattr(intermediates, name, output(shape, dtype, device, requires_grad=bool(wanted) and name not in staged.no_grad))
    second = "texel_grad" if staged.replaces == "adjoint" or staged.then.texel_grad is not None else "adjoint"
    _run_path(staged.first, staged.replaces, count, inputs, intermediates, device, cut, None)
    then_inputs = {
        "args": _struct(staged.then.forward.adj.args[0].type, _by_name(inputs["args"])),
        "pixels": _struct(staged.then.forward.adj.args[1].type, {**_by_name(inputs["pixels"]), **_by_name(intermediates)}),
    }
    _run_path(staged.then, second, count, then_inputs, result, device, cut, None)


def _by_name(value) -> dict:
    """A struct's fields by name, those of its nested structs included (a nested struct's own
    fields win over its name: ``pixels.surface.mask`` is found as ``mask``)."""
    fields = {}
    for name, field in struct_fields(value).items():
        fields[name] = field
        if wp.types.is_struct(field):
            fields.update(_by_name(field))
    return fields


def _struct(struct_t, fields: dict):
    """A ``struct_t`` whose fields are taken by name from ``fields``."""
    value = struct_t()
    for name in struct_t.vars:
        if name in fields:
            setattr(value, name, fields[name])
    return value
