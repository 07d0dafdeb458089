"""All of warptex's Warp code: ``@wp.func`` building blocks and ``@wp.kernel`` entry points.

This package sees only Warp and its own modules; the public API lives in ``warptex``. It is the
folder ``kernels/`` beside ``warptex/``: installed, ``pyproject.toml`` maps it to ``warptex.kernels``;
in a checkout, ``warptex/__init__.py`` grafts it there (``_find_kernels_of_a_checkout``).
``kernels/README.md`` maps the technique × {one pixel, lanes, gradient} grid onto the files.

**Kernel families.** Every technique's kernels come from one factory per technique, cached per
configuration, each per-pixel kernel made from ``@wp.func`` bodies by one shell (:mod:`.family`).

**Warp modules.** Warp compiles all the kernels of one module together, the first time one of them
is launched, and caches the result. warptex therefore names a Warp module for each group of kernels
(the ``MODULE`` constants of each file) so that a job compiles only what it runs: a technique's plain
kernels apart from its stochastic ones, forward and hand-written gradient kernels apart from the
kernels that carry Warp's generated adjoint (recorded only when an input other than the texels
needs gradients). ``benchmarks/bench_compile.py`` measures every module. Every module is named
through :func:`.native.use`, which gives its CPU build the native headers.
"""

import inspect

import warp as wp

from . import native

# The kernels with Warp's generated adjoint live in Warp modules of their own, compiled the first
# time such a gradient is recorded: ``warptex.adjoint`` for sample, stochastic and the atlas, and one
# module beside it for triplanar colour (``.triplanar``), for normal mapping (``.triplanar.normal``)
# and for splat (``.splat``). Kernels of one module share the out-of-line sampling blocks
# (``sample_lod_outlined``, ``sample_stochastic_outlined``...), which it compiles once; one module
# for all of them compiled for sm_90 in 27-32 s once the kernels took their arguments as structs
# (whose adjoints are code too), past the 30 s bar, and made a triplanar sharpness gradient wait
# for splat's adjoint. For CUDA they are compiled at -O2 instead of Warp's default -O3 (the CPU
# default is -O2 already): sm_90 in 13 s instead of 43 s.
ADJOINT_MODULE = "warptex.adjoint"


def adjoint_module(technique: str | None = None) -> str:
    """The Warp module of ``technique``'s generated-adjoint kernels (``None``: the shared one), at -O2."""
    name = ADJOINT_MODULE if technique is None else f"{ADJOINT_MODULE}.{technique}"
    wp.set_module_options({"optimization_level": 2}, module=name)
    return native.use(name)


# Warp 1.18 added the inline hint to @wp.func.
_HAS_INLINE_HINT = "inline" in inspect.signature(wp.func).parameters


def specialised(f, name: str):
    """``f``, a function made by a factory, renamed ``name`` before it becomes a ``@wp.func``: Warp
    names a function after its qualified name, which is the same for every function a factory makes."""
    f.__name__ = f.__qualname__ = name
    return f


def inlined(f, module=None):
    """``@wp.func`` forced inline into its callers (``@wp.func(inline=True)``): for the bodies of the
    pixel kernels (``family.pixel_kernels``), which take a launch's argument structs by value; left
    to the compiler, a body called once per pixel stayed a call that copied kilobytes of arguments
    per pixel (7% more instructions on a triplanar forward, 42% on its texel gradient). Warp
    releases before the inline hint get a plain ``@wp.func``."""
    options = {"module": module} if module is not None else {}
    return wp.func(f, inline=True, **options) if _HAS_INLINE_HINT else wp.func(f, **options)


def out_of_line(f):
    """``@wp.func`` kept out of line (``@wp.func(inline=False)``), adjoint included.

    For the building blocks that generated-adjoint kernels call from several places: the compiler
    then builds one copy of the function and of its adjoint instead of inlining both at every call,
    which made such a Warp module compile several times faster (CUDA and CPU alike). Warp releases
    before the inline hint get a plain ``@wp.func``: the same results, compiled more slowly.
    """
    return wp.func(inline=False)(f) if _HAS_INLINE_HINT else wp.func(f)


def all_kernels(layer_counts=(4,)) -> list:
    """Every kernel warptex has: each kernel family's (:mod:`.family`) in every configuration it
    lists (the splat kernels for each of ``layer_counts``), and the plain kernels of its modules."""
    import importlib
    import pkgutil

    from .family import registered_kernels

    kernels = []
    for info in pkgutil.iter_modules(__path__):  # every module: importing them registers their families
        module = importlib.import_module(f"{__name__}.{info.name}")
        kernels += [v for v in vars(module).values() if isinstance(v, wp.Kernel)]
    kernels += registered_kernels({"layer_counts": tuple(layer_counts)})
    return list({id(k): k for k in kernels}.values())


adjoint_module()
