"""One way to make kernel variants: kernel families, cached per configuration, and the pixel kernels.

A *kernel family* is what one technique launches (``sample``, ``triplanar``, ``splat``...), built
from one source for a *configuration*: keyword values that change what is compiled, such as
``stochastic=True`` or ``capacity=8``. :func:`family` turns a builder into a factory cached per
configuration (a Warp kernel must be built once: every build is a new kernel to compile) and
registers it with the configurations :func:`warptex.kernels.all_kernels` compiles ahead of time.
Those configurations are built when the family is defined (at import): Warp compiles a module with
the kernels it holds when first launched, and a kernel added to it later would change it and
compile it all again. Configurations built later (a splat of more layers) go into modules of their
own.
A factory returns :class:`Kernels`; ``warptex._op.run`` launches them and picks the backward pass.

**Pixel kernels.** Every per-pixel kernel has one of two signatures, made by :func:`pixel_kernels`
from ``@wp.func`` bodies, so that a technique writes what one pixel does and nothing else:

- ``forward(args, pixels, first, out)`` runs ``body(args, pixels, i, out)`` for pixel ``i = first +
  wp.tid()``: a launch computes the pixels from ``first`` on.
  ``args`` is a struct of what every pixel reads (textures, options); ``pixels`` a struct of
  per-pixel arrays (first axis: one entry per pixel); ``out`` the output, a per-pixel array or a
  struct of them. Compiled without Warp's generated adjoint, and once more with it (the
  ``adjoint`` kernel, in a generated-adjoint module, on the out-of-line blocks of ``adjoint_body``);
- ``texel_grad(args, pixels, first, grads, adj)`` runs ``scatter(args, pixels, i, grads, adj)``: the
  hand-written gradient, which adds the output gradients ``adj`` (typed as ``out``) into
  ``grads``, a struct of gradient targets: one field per input it differentiates, in the order of
  :attr:`Kernels.grads`, a :class:`~warptex.kernels.texels.TexelGrad` for a texture's texels or an
  array for anything else (empty: not needed, nothing is added).

``warptex._launch`` cuts a launch into chunks along the pixels: each chunk is a launch of the same
arguments over its pixels, from its ``first`` (a multiple of :data:`~.lanes.LANES`, so that a lane
kernel's lanes never straddle two chunks). The arguments are not sliced per chunk: the Python
that made sliced arrays and structs cost a bilinear lookup of the benchmark sphere 5% on 2 threads,
forward and forward+backward alike (interleaved runs).
"""


import contextlib
import dataclasses
import functools
import threading
from typing import Any, Callable, Iterable

import warp as wp

from . import adjoint_module
from .lanes import LANES
from .native import cpu_snippet, use

#: Gradient paths that name a per-pixel input start with this (see :attr:`Kernels.grads`).
PIXELS = "pixels."

#: The Warp modules of lane kernels are their technique's module's name with this suffix: the CPU
#: compiles them instead of the one-pixel kernels, CUDA never (:func:`cpu_only`).
LANES_SUFFIX = ".lanes"


@dataclasses.dataclass(frozen=True)
class Staged:
    """A two-step alternative to one of a technique's backward paths: ``first`` stores per-pixel
    intermediates, ``then`` makes the output from them.

    ``replaces`` is the path it stands in for, ``"texel_grad"`` or ``"adjoint"``; ``first`` has the
    backward ``replaces`` names, and ``then`` the other (or a hand-written one, where ``then`` has a
    ``texel_grad``: it serves the intermediates that carry gradients), so that the costly sampling
    is differentiated by hand and the cheap blend by Warp, or the other way round, or both by hand.
    ``first`` takes the technique's ``args`` and ``pixels``; ``intermediates(count, args)``
    gives its outputs as ``{field: (shape, dtype)}`` (the fields of ``first``'s ``out`` struct).
    ``then`` takes an ``args`` struct and a ``pixels`` struct whose fields are filled by name from the
    technique's ``args``, and from its ``pixels`` and the intermediates. ``then_only`` names the
    inputs (paths) only ``then`` differentiates: when they alone want gradients, the intermediates
    need none and ``first``'s backward is not recorded (where ``replaces`` is ``"texel_grad"``, they
    count as served by the hand-written pair: ``then``'s gradient must add into them). ``no_grad``
    names the intermediates no gradient flows back through (``first``'s backward does not read
    theirs): made without one.
    """

    replaces: str
    first: "Kernels"
    then: "Kernels"
    intermediates: Callable[[int, Any], dict]
    then_only: tuple = ()
    no_grad: tuple = ()


@dataclasses.dataclass(frozen=True)
class Kernels:
    """One configuration of a kernel family (module docstring).

    Attributes:
        forward: ``forward(args, pixels, first, out)``, without Warp's generated adjoint.
        texel_grad: ``texel_grad(args, pixels, first, grads, adj)``, the hand-written gradient, or ``None``.
        adjoint: ``forward`` with Warp's generated adjoint, or ``None``.
        grads: for each field of ``texel_grad``'s ``grads`` struct, the input it differentiates: a
            dotted path into the kernel's arguments (``"args.layers"``: a ``TextureView``'s texels;
            ``"args.params.tiling"``, ``"pixels.samples"``: an array), or ``None`` where this
            configuration differentiates nothing there. Every other differentiable input is left to
            ``adjoint``.
        staged: a two-step alternative to a backward path, or ``None``.
        lanes: ``forward`` for CPU launches, a lane of pixels per launch index
            (:func:`lane_kernel`), or ``None``: the same bits, faster.
        texel_grad_lanes: ``texel_grad`` for CPU launches, likewise, or ``None``.
        lanes_take, grad_lanes_take: ``take(args) -> bool``, whether ``lanes`` (``texel_grad_lanes``)
            take a launch with the kernels' ``args`` struct (tested where the launch, or the backward
            pass, is recorded), or ``None``: always. The one-pixel kernel takes the rest.
        lane_saved: ``saved(args) -> int``, the floats per pixel that ``lanes`` keeps in
            ``pixels.saved`` for ``texel_grad_lanes`` to read instead of recomputing them; where it
            is set, ``texel_grad_lanes`` runs only after ``lanes`` ran the launch and kept them.
            ``None``: nothing is kept.
        kept_lanes: ``lanes`` for a forward that keeps what ``texel_grad_lanes`` reads, where
            keeping it needs code a forward alone does not (in the gradient's module, so that only
            jobs that take gradients compile it); ``None``: ``lanes`` keeps it.
        fills: ``forward`` (and ``adjoint``) write every entry of their outputs, as lanes do, so a
            launch need not zero them first (on CUDA, a memset launch per call); ``False``: a pixel
            may leave its entries as they were (a masked one, say), and they are zeroed first.
    """

    forward: Any
    texel_grad: Any = None
    adjoint: Any = None
    grads: tuple = ()
    staged: Staged | None = None
    lanes: Any = None
    texel_grad_lanes: Any = None
    lanes_take: Callable[[Any], bool] | None = None
    grad_lanes_take: Callable[[Any], bool] | None = None
    lane_saved: Callable[[Any], int] | None = None
    kept_lanes: Any = None
    fills: bool = False

    def launched(self, device, grad: bool = False):
        """The kernel a forward launch (``grad``: a hand-written gradient) runs on ``device``, as
        :func:`lanes_for` decides, for ``warptex.preload``."""
        return lanes_for(self, device, grad=grad) or (self.texel_grad if grad else self.forward)

    def all(self) -> list:
        """Every Warp kernel of this configuration, the staged steps' included."""
        kernels = [k for k in (self.forward, self.texel_grad, self.adjoint, self.lanes, self.texel_grad_lanes, self.kept_lanes) if k is not None]
        if self.staged is not None:
            kernels += self.staged.first.all() + self.staged.then.all()
        return kernels


_ONE_PIXEL = threading.local()


@contextlib.contextmanager
def thread_flag(flag: threading.local, enabled: bool):
    """``flag.value`` set to ``enabled`` within the block, on this thread."""
    previous = getattr(flag, "value", False)
    flag.value = enabled
    try:
        yield
    finally:
        flag.value = previous


def one_pixel_kernels(enabled: bool = True):
    """Within this block (on this thread), CPU launches run the one-pixel-per-index kernels, never
    their lane kernels: for tests and benchmarks that compare the two."""
    return thread_flag(_ONE_PIXEL, enabled)


def one_pixel_active() -> bool:
    """Whether this thread is within :func:`one_pixel_kernels`."""
    return getattr(_ONE_PIXEL, "value", False)


def lanes_for(kernels: Kernels, device, args=None, grad: bool = False):
    """The one place that decides whether a launch runs lanes: ``kernels``' lane kernel (of the
    hand-written gradient with ``grad``) where the launch on ``device`` runs it, else ``None`` (the
    one-pixel kernel runs). Lanes run on the CPU only, where the configuration has them, where they
    take a launch with the kernels' ``args`` struct (``None``: any launch, as for compiling ahead),
    and not within :func:`one_pixel_kernels`. A gradient lane that reads what the forward lane keeps
    (``Kernels.lane_saved``) runs only where the forward lane does."""
    if getattr(_ONE_PIXEL, "value", False) or not wp.get_device(device).is_cpu:
        return None
    if grad and kernels.lane_saved is not None and lanes_for(kernels, device, args) is None:
        return None
    lanes, take = (kernels.texel_grad_lanes, kernels.grad_lanes_take) if grad else (kernels.lanes, kernels.lanes_take)
    if lanes is None or (args is not None and take is not None and not take(args)):
        return None
    return lanes


# Every family's cached factory, with the configurations all_kernels() compiles.
_FAMILIES: list[tuple[Callable, Callable[[dict], Iterable[dict]]]] = []


def family(configurations: Callable[[dict], Iterable[dict]] | Iterable[dict] = ({},)):
    """Decorator: ``build(**configuration) -> Kernels`` as a factory cached per configuration,
    registered for :func:`warptex.kernels.all_kernels`.

    Args:
        configurations: the configurations to compile ahead of time (``warptex.precompile``): a
            sequence of keyword dicts, or a function of ``all_kernels``' options (e.g.
            ``layer_counts``) returning one.
    """

    def register(build: Callable[..., Kernels]) -> Callable[..., Kernels]:
        cached = functools.cache(build)
        listed = configurations if callable(configurations) else (lambda options, fixed=tuple(configurations): fixed)
        _FAMILIES.append((cached, listed))
        for configuration in listed({}):  # built now: a Warp module holds every kernel it ever will
            cached(**configuration)
        return cached

    return register


def registered_kernels(options: dict) -> list:
    """Every kernel of every registered family, in each of its configurations for ``options``."""
    kernels = []
    for factory, configurations in _FAMILIES:
        for configuration in configurations(options):
            kernels += factory(**configuration).all()
    return kernels


def pixel_kernels(name: str, *, module: str, args, pixels, out, body, scatter=None, grads=None, adjoint_body=None, grad_module: str | None = None, adjoint_of: str | None = None):
    """``(forward, texel_grad, adjoint)``: the pixel kernels of one configuration (module docstring).

    Args:
        name: the kernels' name stem, unique among the kernels of their Warp modules.
        module: the Warp module of ``forward``; ``texel_grad`` goes into ``grad_module`` (default
            ``module + ".grad"``: a job that needs no gradient does not compile it), ``adjoint``
            into ``kernels.adjoint_module(adjoint_of)``.
        args, pixels, out: the struct types of the fixed and the per-pixel arguments, and the
            output's type (an array type or a struct of per-pixel arrays).
        body: ``@wp.func body(args, pixels, i, out)``, what pixel ``i`` computes.
        scatter: ``@wp.func scatter(args, pixels, i, grads, adj)``, its hand-written gradient, with
            ``grads`` (the struct type of its targets); ``None``: no texel-gradient kernel.
        adjoint_body: the ``body`` to compile with Warp's generated adjoint (on out-of-line blocks,
            which such a module then compiles once with their adjoints); ``None``: no adjoint kernel.
        adjoint_of: the technique whose generated-adjoint module ``adjoint`` goes into (``None``:
            the shared one).
    """
    forward = forward_kernel(body, args, pixels, out, module=module, name=f"{name}_forward", enable_backward=False)
    texel_grad = None if scatter is None else _texel_grad(scatter, args, pixels, grads, out, module=grad_module or module + ".grad", name=f"{name}_texel_grad")
    adjoint = None if adjoint_body is None else forward_kernel(adjoint_body, args, pixels, out, module=adjoint_module(adjoint_of), name=f"{name}_adjoint", enable_backward=True)
    return forward, texel_grad, adjoint


def forward_kernel(body, args_t, pixels_t, out_t, *, module: str, name: str, enable_backward: bool):
    """The ``forward(args, pixels, first, out)`` kernel of ``body`` alone (see :func:`pixel_kernels`)."""

    @wp.kernel(enable_backward=enable_backward, module=use(module), name=name)
    def forward(args: args_t, pixels: pixels_t, first: wp.int32, out: out_t):
        body(args, pixels, first + wp.tid(), out)

    return forward


def lane_kernel(lane_body, args_t, pixels_t, out_t, *, module: str, name: str, grads_t=None, covered=None):
    """A CPU pixel kernel of ``lane_body``, which computes what a pixel body computes for pixels
    ``base .. base + LANES - 1`` (:mod:`.lanes`; fewer in the last lane: the pixel count is the first
    axis of the per-pixel arrays): ``forward(args, pixels, first, out)`` running ``lane_body(args,
    pixels, base, out)`` for ``base = first + LANES · wp.tid()``, or, with ``grads_t``,
    ``texel_grad(args, pixels, first, grads, adj)`` running ``lane_body(args, pixels, base, grads,
    adj)``. Launched over ``ceil(pixels / LANES)`` indices from a ``first`` that is a multiple of
    ``LANES`` (``warptex._launch``); never on CUDA, which runs the one-pixel kernels. A forward lane body
    writes every entry of ``out`` (every channel of each of its rows, uncovered pixels included):
    ``warptex._launch`` does not zero a lane kernel's output first. It goes into the CPU-only
    Warp module ``module + LANES_SUFFIX``, so that a CPU job compiles no one-pixel kernel it does not
    run, nor a GPU job a lane kernel.

    ``covered``: for a G-buffer technique, ``@wp.func covered(pixels, base, count) -> bool``, whether
    any of the lane's ``count`` pixels is shaded (:func:`lane_covered` of its mask). A lane with none
    runs no body: the forward writes its rows 0 (``out`` is a 2-D float array), as the one-pixel
    kernels leave an uncovered pixel, and the gradient adds nothing, as they add nothing for one.
    The sky's lanes otherwise cost nearly half as much as the shaded ones (they read the G-buffer
    and work out footprints for no read): a triplanar lookup of an all-sky view took 15.5 ns a
    pixel against 36 for a shaded one; skipped, 2.4 (1 thread). Without ``covered`` (no G-buffer)
    the kernels test nothing: a test that always passed (``return True``) made the ``sample``
    gradient lane 30% slower on random UVs, with the same native code inlined either way."""
    module = use(module + LANES_SUFFIX, lanes=True)
    if covered is None:
        if grads_t is None:

            @wp.kernel(enable_backward=False, module=module, name=name)
            def lanes(args: args_t, pixels: pixels_t, first: wp.int32, out: out_t):
                lane_body(args, pixels, first + wp.tid() * LANES, out)

            return lanes

        @wp.kernel(enable_backward=False, module=module, name=name)
        def grad_lanes(args: args_t, pixels: pixels_t, first: wp.int32, grads: grads_t, adj: out_t):
            lane_body(args, pixels, first + wp.tid() * LANES, grads, adj)

        return grad_lanes
    if grads_t is None:

        @wp.kernel(enable_backward=False, module=module, name=name)
        def covered_lanes(args: args_t, pixels: pixels_t, first: wp.int32, out: out_t):
            base = first + wp.tid() * LANES
            count = wp.min(out.shape[0] - base, LANES)
            if covered(pixels, base, count):
                lane_body(args, pixels, base, out)
            else:
                zero_rows(out, base, count)

        return covered_lanes

    @wp.kernel(enable_backward=False, module=module, name=name)
    def covered_grad_lanes(args: args_t, pixels: pixels_t, first: wp.int32, grads: grads_t, adj: out_t):
        base = first + wp.tid() * LANES
        if covered(pixels, base, wp.min(adj.shape[0] - base, LANES)):
            lane_body(args, pixels, base, grads, adj)

    return covered_grad_lanes


@wp.func_native(cpu_snippet("wt_zero_rows(out, base, count);\n"))
def zero_rows(out: wp.array2d(dtype=float), base: wp.int32, count: wp.int32):
    """Rows ``base .. base + count - 1`` of ``out`` set to 0, on the CPU (one ``memset`` where the
    rows are packed: Warp's element stores took 77 ns a lane of 16 RGBA rows)."""
    ...


@wp.func
def lane_covered(mask: wp.array(dtype=float), base: wp.int32, count: wp.int32) -> bool:
    """Whether any of pixels ``base .. base + count - 1`` is covered (``mask != 0``): a G-buffer
    technique's ``covered`` for :func:`lane_kernel`."""
    for l in range(count):
        if mask[base + l] != 0.0:
            return True
    return False


def cpu_only(kernel) -> bool:
    """Whether ``kernel`` runs on the CPU only (a lane kernel)."""
    return kernel.module.name.endswith(LANES_SUFFIX)


def _texel_grad(scatter, args_t, pixels_t, grads_t, adj_t, *, module: str, name: str):
    @wp.kernel(enable_backward=False, module=use(module), name=name)
    def texel_grad(args: args_t, pixels: pixels_t, first: wp.int32, grads: grads_t, adj: adj_t):
        scatter(args, pixels, first + wp.tid(), grads, adj)

    return texel_grad
