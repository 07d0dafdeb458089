"""Per-pixel kernel launches, split over CPU threads.

Every per-pixel kernel takes ``(args, pixels, first, out)`` or, for a hand-written gradient,
``(args, pixels, first, grads, adj)`` (``warptex.kernels.family``), and computes the pixels from
``first`` on. :func:`launch` cuts the pixels into contiguous chunks (``warptex._threads.Split``) and
launches them from the thread pool, each with the same arguments and its own ``first``. Every pixel
is computed by the same code from the same inputs, so the result is bit-identical to a single
launch.

Under a ``wp.Tape`` a launch is recorded as one backward step that runs the adjoint launches of
chunks fixed by the pixels and the gradients' sizes, never by the thread count
(``warptex._threads.grad_bounds``), on the threads too, adding into
shared gradients in chunk order through private copies (``warptex._accumulate``): the gradients are
the same bits at any thread count.

A launch's outputs are made with :func:`output` (allocated, not touched) and zeroed by
:func:`launch` chunk by chunk, on the thread that then fills the chunk: ``wp.zeros`` of a 12.6 MB
output and its gradient measured up to 8 ms on the calling thread where the memory came fresh from
the system (page faults), a third of a one-thread bilinear lookup of as many pixels. A lane kernel
writes every entry of its outputs, so only their gradients are zeroed: on the benchmark sphere,
a bilinear lookup is then memory-bound, and the zeroing was another pass over its 13 MB. So does
``sample``'s one-pixel kernel, CUDA's (``fills``): there a zeroing is a memset launch of its own.

CUDA launches are never split: one launch fills the device.
"""

from __future__ import annotations

import functools
import weakref
from typing import Iterator, NamedTuple

import warp as wp

from warptex import _plan
from warptex._compile import load_first
from warptex._accumulate import Copy, add_sums, exact_sums, exact_texel_grads, exact_views, private, run_ordered, set_exponents, slot_count, with_private_grads
from warptex._memory import empty
from warptex._pack import empty_array, packed
from warptex._threads import Split, cpu_count, grad_bounds, workers_for
from warptex._warp import active_tape, map_arrays, replay, struct_arrays, struct_like
from warptex.kernels.lanes import LANES
from warptex.kernels.texels import TexelGrad

GENERATED = "generated"
"""``backward=GENERATED``: record the kernel's generated adjoint (see :func:`launch`)."""


def output(shape, dtype, device, requires_grad: bool = False) -> wp.array:
    """A new per-pixel output for :func:`launch` (first axis: one row per pixel), and its gradient
    when ``requires_grad``: allocated (on the CPU from a kept block, ``warptex._memory``), not
    zeroed; :func:`launch` zeroes both, chunk by chunk on the threads that fill them (module
    docstring)."""
    out = empty(shape, dtype, device)
    if requires_grad:
        out.grad = empty(shape, dtype, device)
    return out


def arrays(value) -> Iterator[wp.array]:
    """The arrays of an argument: itself, or every array field of a struct (nested ones included)."""
    if wp.types.is_array(value):
        yield value
    elif wp.types.is_struct(value):
        for _, array in struct_arrays(value):
            yield array


def _zero_rows(out, lo: int, hi: int, filled: bool = False) -> None:
    """Zero rows ``lo .. hi`` of ``out`` (per-pixel outputs) and of their gradients; the outputs
    themselves only where the kernel does not write every entry (``filled``: a lane kernel, which
    does). Slices only what it zeroes (slicing costs Python time on the launching thread)."""
    for a in arrays(out):
        for b in ([] if filled else [a]) + ([a.grad] if a.grad is not None else []):
            (b if lo == 0 and hi == b.shape[0] else b[lo:hi]).zero_()


def _check_rows(count: int, *values) -> None:
    for a in (a for v in values for a in arrays(v)):
        if a.shape[0] not in (0, count):
            raise RuntimeError(f"warptex internal error: a per-pixel array has {a.shape[0]} rows for {count} pixels")


def launch(kernel, count: int, *, args, pixels, out, device, threads: int | None = None, backward=None, covered: wp.array | None = None, footprints: int = 1, lanes=None, fills: bool = False) -> None:
    """Launch a per-pixel ``kernel(args, pixels, first, out)`` over ``count`` pixels, split over CPU threads.

    Args:
        kernel: a Warp kernel whose thread ``t`` reads and writes only entry ``i = first + t`` of the
            arrays of ``pixels`` and ``out`` (and reads anything else).
        count: pixels to launch.
        args, pixels: the kernel's fixed and per-pixel arguments (structs).
        out: the output, a per-pixel array or a struct of them, new from :func:`output`: it and its
            gradients are zeroed here, each chunk's rows before the kernel runs on them (only the
            gradients where ``lanes`` runs: a lane kernel writes every entry).
        device: the Warp device.
        threads: threads to use (default ``get_num_threads()``); CUDA always uses one launch.
        backward: what an active ``wp.Tape`` records for the backward pass (when an output requires
            gradients): ``None``, nothing; :data:`GENERATED`, the kernel's generated adjoint (the
            kernel must have one); or ``backward(tape)``, a hand-written gradient (see
            :func:`scatter`) that reads the outputs' ``.grad`` when the tape runs backwards.
        covered: the pixels' mask (``count`` entries, non-zero where a pixel is shaded), when the
            launch is over a G-buffer: chunks are then cut to equal estimated costs, so that the
            sky's cheap pixels do not unbalance the threads.
        footprints: the bilinear footprints a pixel reads at most: with the size of the gradients
            all pixels share, it sizes a backward pass's chunks (``warptex._threads.grad_bounds``).
        lanes: ``kernel``'s lane kernel (``warptex.kernels.family.lane_kernel``: the same outputs),
            to run instead, over a lane of pixels per launch index, where
            ``warptex.kernels.family.lanes_for`` decided the launch runs lanes; never with
            :data:`GENERATED` (Warp differentiates the one-pixel kernel).
        fills: ``kernel`` writes every entry of its outputs (``warptex.kernels.family.Kernels.fills``),
            as a lane kernel does: only their gradients are zeroed.
    """
    if count <= 0:
        return
    device = wp.get_device(device)
    _check_rows(count, pixels, out)
    if lanes is not None and backward is GENERATED:
        raise ValueError("a launch that records Warp's generated adjoint runs the one-pixel kernel, not lanes")
    tape = active_tape()
    recorded = [a for a in arrays(out) if a.requires_grad] if tape is not None and backward is not None else []
    if recorded and backward is not GENERATED:
        tape.record_func(_on(tape, backward), arrays=recorded)
    generated = bool(recorded) and backward is GENERATED
    exact = generated and bool(exact_texel_grads(args, device))  # CUDA: texel gradients summed in fixed point
    workers = workers_for(device, count, threads)
    if workers > 1:
        workers = min(workers, cpu_count())  # threads past the cores would only take turns
    chunks = grad_bounds(count, covered, _shared_bytes(args), footprints) if generated and device.is_cpu and not exact else [0, count]  # CUDA: one launch
    kernel, per_index = _with_lanes(kernel, lanes)
    fills = fills or per_index > 1  # a lane kernel writes every entry of its outputs (family.lane_kernel)
    if workers == 1:
        _zero_rows(out, 0, count, fills)
        if generated and len(chunks) == 2 and not exact:  # Warp records the launch's own adjoint on the tape
            wp.launch(kernel, dim=-(-count // per_index), inputs=[args, pixels, 0], outputs=[out], device=device, record_tape=True)
        else:
            dim, params = -(-count // per_index), (args, pixels, 0, out)
            replay(kernel, dim, params, device)
            if not recorded:  # a call kept for its next one on the same objects (warptex._plan)
                _plan.launched(kernel, dim, params, device, count=count, zeroes=not fills)
    else:
        load_first([kernel], device)  # not by each thread at its first launch (each would compile it)
        split = Split(count, workers, covered)

        def forward(worker: int, k: int) -> None:
            lo, hi = split.span(k)
            _zero_rows(out, lo, hi, fills)
            wp.launch(kernel, dim=-(-(hi - lo) // per_index), inputs=[args, pixels, lo], outputs=[out], device=device, record_tape=False)

        split.run(forward)
    if exact:
        backward = functools.partial(_backward_exact, kernel=kernel, count=count, args=args, pixels=pixels, out=out, device=device)
        tape.record_func(_on(tape, backward), arrays=recorded)
    elif generated and (workers > 1 or len(chunks) > 2):  # else Warp recorded the launch's own adjoint
        backward = functools.partial(_backward, kernel=kernel, bounds=chunks, workers=workers, args=args, pixels=pixels, out=out, device=device)
        tape.record_func(_on(tape, backward), arrays=recorded)


def _with_lanes(kernel, lanes) -> tuple:
    """``(kernel to launch, pixels per launch index)``: ``lanes`` and its lane width where the caller
    passed it (``warptex.kernels.family.lanes_for`` decided), else ``kernel`` and 1 (launched over
    ``ceil(pixels / width)`` indices)."""
    return (lanes, LANES) if lanes is not None else (kernel, 1)


def _nbytes(array: wp.array) -> int:
    return array.size * wp.types.type_size_in_bytes(array.dtype)


def _shared_bytes(args) -> int:
    """The bytes of the gradients of ``args``' arrays (those all pixels share), each counted once."""
    grads = {id(a.grad): a.grad for a in arrays(args) if a.grad is not None}
    return sum(_nbytes(g) for g in grads.values())


def _on(tape, backward):
    """``backward(tape)`` as the argument-less function ``wp.Tape.record_func`` records, holding the
    tape weakly: a tape that held itself through its own records would be freed only by Python's
    cycle collector, and until then keep its outputs and their gradients (tens of MB) alive, so the
    next pass allocated fresh memory and paid its page faults (a third more time for a bilinear
    forward and backward, measured)."""
    ref = weakref.ref(tape)
    return lambda: backward(ref())


def _backward(tape, *, kernel, bounds: list[int], workers: int, args, pixels, out, device) -> None:
    """The adjoints of a launch, chunk by chunk (``bounds``, see ``warptex._threads.grad_bounds``)
    on up to ``workers`` threads: chunk 0 accumulates into the real gradients, the others into
    private copies of the shared ones (``args``' arrays), added in chunk order (whole: Warp's
    generated adjoints do not mark tiles)."""
    tape.get_adjoint(args)  # registers the real gradients with the tape (for tape.zero()), as a recorded launch does
    tape.get_adjoint(pixels)
    chunks = len(bounds) - 1
    workers = min(workers, chunks, cpu_count())  # fixed chunks: threads past the cores only take turns
    slots = [[] for _ in range(slot_count(chunks, workers))]  # each slot's (real gradient, private copy) pairs
    slot_args = [with_private_grads(args, copies, slot) for slot, copies in enumerate(slots)]
    if workers > 1:
        load_first([kernel], device)

    def backward(k: int, slot: int | None) -> None:
        lo, hi = bounds[k], bounds[k + 1]
        a = args if slot is None else slot_args[slot]
        wp.launch(kernel, dim=hi - lo, inputs=[a, pixels, lo], outputs=[out], adj_inputs=[tape.get_adjoint(a), tape.get_adjoint(pixels), 0], adj_outputs=[tape.get_adjoint(out)], device=device, adjoint=True)

    run_ordered(chunks, workers, backward, slots.__getitem__)


def _backward_exact(tape, *, kernel, count: int, args, pixels, out, device) -> None:
    """The generated adjoint of a launch, its texel gradients summed in fixed point
    (``warptex._accumulate.exact_views``, new sums each backward pass): two launches over every
    pixel, then the sums added into the texel gradients (one launch with float atomics where the
    sums were turned off since the forward pass). The second adds everything, as Warp's own adjoint would. The first only
    bounds each texel's contributions, so nothing else may change: Warp's adjoint adds a struct's
    array reads into the array's own ``.grad`` and reads (then zeroes) the gradient of a struct's
    output array there too, whatever adjoint structs the launch is given. So the first pass reads
    views of the inputs without gradients, and views of the outputs whose gradients are copies."""
    tape.get_adjoint(args)  # registers the real gradients with the tape (for tape.zero()), as a recorded launch does
    exact = exact_views(args, device)
    if exact is None:
        wp.launch(kernel, dim=count, inputs=[args, pixels, 0], outputs=[out], adj_inputs=[tape.get_adjoint(args), tape.get_adjoint(pixels), 0], adj_outputs=[tape.get_adjoint(out)], device=device, adjoint=True)
        return
    inputs = [map_arrays(exact.first, _bare), map_arrays(pixels, _bare)]
    outputs = map_arrays(out, _with_gradient_copy)
    wp.launch(kernel, dim=count, inputs=[*inputs, 0], outputs=[outputs], adj_inputs=[*map(struct_like, inputs), 0], adj_outputs=[map_arrays(outputs, _gradient)], device=device, adjoint=True)
    set_exponents(exact.sums)
    wp.launch(kernel, dim=count, inputs=[exact.second, pixels, 0], outputs=[out], adj_inputs=[tape.get_adjoint(exact.second), tape.get_adjoint(pixels), 0], adj_outputs=[tape.get_adjoint(out)], device=device, adjoint=True)
    add_sums(exact.sums)


def _bare(array: wp.array) -> wp.array:
    """``array``, or a view of it without its gradient where it has one."""
    if array.grad is None or not array.ptr:
        return array
    return wp.array(ptr=array.ptr, shape=array.shape, strides=array.strides, dtype=array.dtype, device=array.device)


def _with_gradient_copy(array: wp.array) -> wp.array:
    """A view of ``array`` whose gradient is a copy of ``array``'s (none where it has none)."""
    view = _bare(array)
    if view is not array:
        view.grad = wp.clone(array.grad)
    return view


def _gradient(array: wp.array):
    return array.grad


class Target(NamedTuple):
    """A field of a hand-written gradient's ``grads`` struct: the gradient array it adds into
    (``None``: not needed, passed empty), and whether it is per-pixel (each chunk adds into its own
    rows) rather than shared by every pixel (added into through per-worker private copies)."""

    grad: wp.array | None
    per_pixel: bool = False


def scatter(kernel, count: int, *, args, pixels, grads: list[Target], adj, device, threads: int | None = None, covered: wp.array | None = None, footprints: int = 1, entries: dict | None = None, lanes=None) -> None:
    """Launch a hand-written gradient ``kernel(args, pixels, first, grads, adj)``, which *adds* into the
    arrays of ``grads``, over ``count`` pixels, split over CPU threads as :func:`launch` splits a launch.

    Warp's CPU atomics are plain read-modify-writes, so the pixels are cut into chunks fixed by
    their count, cost and shared gradients' size (``warptex._threads.grad_bounds``): the first adds
    into the shared targets, the others into private zeroed copies, added in chunk order (``warptex._accumulate``), the same
    bits at any thread count. A ``TexelGrad`` field's private copy marks the tiles it adds into,
    and only those are added (a chunk's pixels often read a part of a texture only). Not recorded
    on a tape: this is what a backward step runs.

    Args:
        kernel: the Warp kernel; its ``grads`` argument is a struct with one field per ``grads`` entry.
        count, args, pixels, device, threads, covered, footprints: as for :func:`launch`.
        grads: the targets, in the order of the struct's fields.
        adj: the outputs' gradients, shaped as ``out`` (an array or a struct of them).
        entries: ``{id(target): (start, stop)}`` for shared targets the kernel adds into only there
            (the mip levels a constant-LOD lookup reads): only the tiles of those entries are summed
            from the private copies, tracked or not (the rest stays zero).
        lanes: ``kernel``'s lane kernel (the same sums in the same order), to run instead, a lane
            of pixels per launch index, where ``warptex.kernels.family.lanes_for`` decided so.
    """
    if count <= 0:
        return
    device = wp.get_device(device)
    _check_rows(count, pixels, adj, *[t.grad for t in grads if t.per_pixel and t.grad is not None])
    grads_t = next(a.type for a in kernel.adj.args if a.label == "grads")
    texel = [t.grad for (name, ftype), t in zip(grads_t.vars.items(), grads) if t.grad is not None and not t.per_pixel and ftype.type is TexelGrad]
    plain = [t.grad for (name, ftype), t in zip(grads_t.vars.items(), grads) if t.grad is not None and not t.per_pixel and ftype.type is not TexelGrad]
    shared = list({id(g): g for g in texel + plain}.values())  # one texture may feed several fields
    sums = exact_sums(device, list({id(g): g for g in texel}.values()))
    if sums is not None:  # CUDA: texels summed in fixed point, by the scalar kernel (warptex._accumulate)
        _scatter_exact(kernel, count, args=args, pixels=pixels, grads_t=grads_t, grads=grads, adj=adj, sums=sums, device=device)
        return
    kernel, per_index = _with_lanes(kernel, lanes)
    bounds = grad_bounds(count, covered, sum(_nbytes(g) for g in shared), footprints) if device.is_cpu else [0, count]  # CUDA: one launch, atomics
    chunks = len(bounds) - 1
    if chunks == 1:  # the targets' struct made once while they live (a loop's texture gradient is the same array every call)
        real = packed(grads_t, ("grads", device.alias, *(t.per_pixel for t in grads)), lambda: _grads_struct(grads_t, grads, {}, device), weakly=[t.grad for t in grads])
        replay(kernel, -(-count // per_index), (args, pixels, 0, real, adj), device)
        return
    workers = min(workers_for(device, count, threads), chunks, cpu_count())  # fixed chunks: threads past the cores only take turns
    tracked = {id(g) for g in texel} - {id(g) for g in plain}
    slots: list[list[tuple[wp.array, Copy]]] = []
    structs = []
    for slot in range(slot_count(chunks, workers)):
        mine = {id(g): private(g, slot, tracked=id(g) in tracked) for g in shared}
        slots.append([(g, mine[id(g)]) for g in shared])
        structs.append(_grads_struct(grads_t, grads, mine, device))
    real = _grads_struct(grads_t, grads, {}, device)
    if workers > 1:
        load_first([kernel], device)

    def run(k: int, slot: int | None) -> None:
        lo, hi = bounds[k], bounds[k + 1]
        wp.launch(kernel, dim=-(-(hi - lo) // per_index), inputs=[args, pixels, lo, real if slot is None else structs[slot], adj], device=device, record_tape=False)

    run_ordered(chunks, workers, run, slots.__getitem__, entries)


def _scatter_exact(kernel, count: int, *, args, pixels, grads_t, grads: list[Target], adj, sums: dict, device) -> None:
    """:func:`scatter`'s deterministic CUDA backward: two launches of ``kernel`` over every pixel,
    the first bounding each texel's contributions (texel targets only: nothing else is added
    into), the second adding them in fixed point, then the sums added into the texel gradients.
    Each launch is a kept one (``replay``): ``wp.launch`` resolves the module and the arguments'
    types anew each time, which a small call on a GPU pays on every launch."""
    bound = _grads_struct(grads_t, [t if t.grad is not None and id(t.grad) in sums else Target(None) for t in grads], {}, device, sums, first_pass=True)
    replay(kernel, count, (args, pixels, 0, bound, adj), device)
    set_exponents(sums)
    replay(kernel, count, (args, pixels, 0, _grads_struct(grads_t, grads, {}, device, sums), adj), device)
    add_sums(sums)


def _grads_struct(grads_t, grads: list[Target], copies: dict, device, sums: dict | None = None, first_pass: bool = False):
    """A ``grads_t`` struct of ``grads``: each shared target replaced by its copy in ``copies`` (by
    id) where it has one; ``TexelGrad`` fields with the copy's tiles (the real gradient untracked)
    or, where ``sums`` has one for the gradient, its fixed-point sum (``first_pass``: without the
    int64 sums, as the bounding pass takes it); empty arrays where a target is not needed.
    Per-pixel targets are whole: a chunk's pixels add into their own rows only."""
    value = grads_t()
    for (name, field), target in zip(grads_t.vars.items(), grads):
        ftype = field.type
        if ftype is TexelGrad:
            g = TexelGrad()
            copy = copies.get(id(target.grad)) if target.grad is not None else None
            exact = sums.get(id(target.grad)) if sums and target.grad is not None else None
            g.texels = copy.array if copy is not None else target.grad if target.grad is not None else empty_array(wp.vec4, 1, device)
            g.tiles = copy.tiles if copy is not None and copy.tiles is not None else empty_array(wp.int32, 1, device)
            if exact is not None:  # else left unset: empty (each field set costs a small call ~1 us)
                g.exponents = exact.exponents
                g.fixed = exact.fixed if not first_pass else empty_array(wp.int64, 1, device)
            setattr(value, name, g)
        else:
            copy = copies.get(id(target.grad)) if target.grad is not None else None
            setattr(value, name, copy.array if copy is not None else target.grad if target.grad is not None else empty_array(ftype.dtype, ftype.ndim, device))
    return value
