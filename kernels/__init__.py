"""All of warptex's Warp code: ``@wp.func`` building blocks and ``@wp.kernel`` entry points.

This package sees only Warp and its own modules; the public API lives in ``warptex``.

**Warp modules.** Warp compiles all the kernels of one module together, the first time one of them
is launched, and caches the result. warptex therefore names a Warp module for each kernel (the
``MODULE`` constants of each file) so that a job compiles only what it runs: a technique's plain
kernels apart from its stochastic ones, forward and hand-written gradient kernels apart from the
kernels that carry Warp's generated adjoint (recorded only when an input other than the texels
needs gradients). ``benchmarks/bench_compile.py`` measures every module.
"""

import inspect

import warp as wp

# Every kernel with Warp's generated adjoint that samples textures lives in this one Warp module,
# compiled the first time any of them runs: they share the out-of-line sampling blocks
# (``sample_lod_call``, ``sample_stochastic_call``...), which it then compiles once. For CUDA it is
# compiled at -O2 instead of Warp's default -O3 (the CPU default is -O2 already): sm_90 in 13 s
# instead of 43 s.
ADJOINT_MODULE = "warptex.adjoint"
wp.set_module_options({"optimization_level": 2}, module=ADJOINT_MODULE)

# Warp 1.18 added the inline hint to @wp.func.
_HAS_INLINE_HINT = "inline" in inspect.signature(wp.func).parameters


def specialised(f, name: str):
    """``f``, a function made by a factory, renamed ``name`` before it becomes a ``@wp.func``: Warp
    names a function after its qualified name, which is the same for every function a factory makes."""
    f.__name__ = f.__qualname__ = name
    return f


def out_of_line(f):
    """``@wp.func`` kept out of line (``@wp.func(inline=False)``), adjoint included.

    For the building blocks that generated-adjoint kernels call from several places: the compiler
    then builds one copy of the function and of its adjoint instead of inlining both at every call,
    which made such a Warp module compile several times faster (CUDA and CPU alike). Warp releases
    before the inline hint get a plain ``@wp.func``: the same results, compiled more slowly.
    """
    return wp.func(inline=False)(f) if _HAS_INLINE_HINT else wp.func(f)



def all_kernels(layer_counts=(4,)) -> list:
    """Every kernel warptex has, the splat kernels for each of ``layer_counts`` included."""
    import importlib

    kernels = []
    for name in ("sampling", "stochastic", "triplanar", "layers", "atlas", "raster", "resolve", "fit"):
        module = importlib.import_module(f"{__name__}.{name}")
        kernels += [v for v in vars(module).values() if isinstance(v, wp.Kernel)]
    layers = importlib.import_module(f"{__name__}.layers")
    for count in layer_counts:
        kernels += list(layers.splat_kernels(layers.capacity(count)).values())
    return kernels
