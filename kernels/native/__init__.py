"""The CPU's native code: C++ headers in this folder, one per concern, and the one loader that gives
them to Warp.

The CPU lanes (:mod:`warptex.kernels.lanes`) and the scalar ``log2`` of the LODs
(:func:`warptex.kernels.footprint.lod_log2`) are ``wp.func_native`` functions whose bodies are a
line or two: a call of a ``static inline`` function (a template over Warp's struct and array types)
of these headers. :func:`use` gives a Warp module the headers: this folder as an include directory,
and a preamble, inserted after Warp's own headers, of

1. the constants the C++ shares with Python (address and filter modes, LOD sources, lanes, hash
   streams, blend modes...), generated from the Python modules that define them
   (:func:`constants`), so that no value is written twice;
2. ``#include`` of the headers, between ``#pragma clang fp contract(off)`` and ``(on)``: the lanes
   compute the scalar ``@wp.func`` blocks' bits, operation for operation, and a fused
   multiply-add would round differently. A lane module gets every header; a one-pixel module only
   :data:`ONE_PIXEL_HEADERS` (``lod_log2``'s), which keeps the headers out of the compile of
   modules that never call them (all headers cost ``warptex.mips`` about 1.3 s of CPU compile).

The compiler reads the headers themselves, so an error names the header and its line. Warp hashes
their contents into the module's hash (``extra_build_dependencies``): editing one recompiles what
uses it. Each function names its scalar twin in a comment (``// twin: texels.reduce_coord``), which
``tests/test_native.py`` resolves; ``clang-format`` (``.clang-format`` at the repository root)
keeps them formatted. Only the CPU compiles them: a native function's CUDA body is its
``#else`` branch (:func:`cpu_snippet`), and the lane kernels never run on CUDA.
"""

from __future__ import annotations

import functools
from importlib import resources
from pathlib import Path

import warp as wp

#: The headers, in the order the preamble includes them (each includes what it needs as well).
HEADERS = (
    "wt_config.h",
    "wt_log2.h",
    "wt_core.h",
    "wt_footprint.h",
    "wt_sample.h",
    "wt_scatter.h",
    "wt_taps.h",
    "wt_normals.h",
    "wt_projection.h",
    "wt_splat_layers.h",
    "wt_splat_blend.h",
)


def folder() -> Path:
    """The folder of the headers (inside the installed package, or the checkout's ``kernels/native``)."""
    return Path(str(resources.files(__name__)))


def cpu_snippet(body: str, cuda: str = "") -> str:
    """A native function's snippet: ``body`` on the CPU (a call into the headers), ``cuda`` (never
    run: lane kernels are CPU-only) when NVRTC compiles it."""
    return "#if !defined(__CUDA_ARCH__)\n" + body + "#else\n" + cuda + "#endif\n"


def _define(name: str, value) -> str:
    if isinstance(value, float):
        return f"constexpr double {name} = {value!r};"
    return f"constexpr int {name} = {int(value)};"


@functools.cache
def constants() -> str:
    """The constants the headers share with Python, as C++ (``constexpr`` values named ``WT_*``),
    read from the modules that define them."""
    from .. import hashing, hexgrid, normals, projection, splat_layers, stochastic, texels
    from ..lanes import LANES

    values = {
        "WT_WRAP": texels.ADDRESS_WRAP, "WT_CLAMP": texels.ADDRESS_CLAMP, "WT_MIRROR": texels.ADDRESS_MIRROR, "WT_BORDER": texels.ADDRESS_BORDER,
        "WT_NEAREST": texels.FILTER_NEAREST, "WT_BILINEAR": texels.FILTER_BILINEAR, "WT_TRILINEAR": texels.FILTER_TRILINEAR, "WT_ANISOTROPIC": texels.FILTER_ANISOTROPIC,
        "WT_LOD_CONSTANT": texels.LOD_CONSTANT, "WT_LOD_PER_SAMPLE": texels.LOD_PER_SAMPLE, "WT_LOD_DERIVATIVES": texels.LOD_DERIVATIVES,
        "WT_TILE_SHIFT": texels.TILE_SHIFT,
        "WT_FLOAT32": texels.FORMAT_FLOAT32, "WT_FLOAT16": texels.FORMAT_FLOAT16, "WT_8BIT": texels.FORMAT_8BIT, "WT_UNORM8": texels.FORMAT_UNORM8,
        "WT_WEIGHTS_BIPLANAR": projection.WEIGHTS_BIPLANAR, "WT_MAX_INT_EXPONENT": projection.MAX_INT_EXPONENT,
        "WT_BIPLANAR_EDGE": float(projection.BIPLANAR_EDGE), "WT_WEIGHT_EPS": float(projection.WEIGHT_EPS), "WT_ORIGIN_FOLDED": projection.ORIGIN_FOLDED,
        "WT_BLEND_UDN": normals.BLEND_UDN, "WT_BLEND_RNM": normals.BLEND_RNM,
        "WT_HASH4": stochastic.METHOD_HASH4, "WT_CHEAP2": stochastic.METHOD_CHEAP2,
        "WT_STREAM_CELL": hashing.STREAM_HASH4_CELL, "WT_STREAM_OFFSET": hashing.STREAM_CHEAP2_OFFSET,
        "WT_STREAM_NOISE": hashing.STREAM_CHEAP2_NOISE, "WT_STREAM_HEX": hashing.STREAM_HEX_VERTEX,
        "WT_HEX_SCALE": float(hexgrid.HEX_SCALE), "WT_INV_SQRT3": float(hexgrid.INV_SQRT3), "WT_HALF_SQRT3": float(hexgrid.HALF_SQRT3), "WT_PI": float(hexgrid.PI),
        "WT_PROJECT_UV": splat_layers.PROJECT_UV, "WT_PROJECT_WORLD_XZ": splat_layers.PROJECT_WORLD_XZ, "WT_PROJECT_TRIPLANAR": splat_layers.PROJECT_TRIPLANAR,
        "WT_HEIGHT_NONE": splat_layers.HEIGHT_NONE, "WT_HEIGHT_CHANNEL": splat_layers.HEIGHT_CHANNEL, "WT_HEIGHT_ARRAY": splat_layers.HEIGHT_ARRAY,
        "WT_SPLAT_EPS": float(splat_layers.SPLAT_EPS),
    }
    # the lane width as a macro: the headers pick their transposes with #if
    lines = [f"#define WT_L {LANES}"] + [_define(name, value) for name, value in values.items()]
    return "// Generated by warptex.kernels.native from the Python constants: the C++ names them WT_*.\n#define WT_CONSTANTS\n" + "\n".join(lines) + "\n"


def preamble(headers=HEADERS) -> str:
    """The CPU preamble of a Warp module that uses the headers: the constants, then ``headers``,
    without contraction."""
    includes = "".join(f'#include "{name}"\n' for name in headers)
    return constants() + "#pragma clang fp contract(off)\n" + includes + "#pragma clang fp contract(on)\n"


#: What a module of one-pixel kernels needs: ``footprint.lod_log2``'s ``wt_log2``.
ONE_PIXEL_HEADERS = ("wt_config.h", "wt_log2.h")


@functools.cache
def build_options(headers=HEADERS) -> wp.ModuleBuildOptions:
    """The build options that give a Warp module ``headers`` (module docstring)."""
    here = folder()
    return wp.ModuleBuildOptions(
        extra_cpu_include_dirs=[str(here)],
        extra_cpu_preamble=preamble(headers),
        extra_build_dependencies=[str(here / name) for name in headers],
    )


_used: dict[str, bool] = {}  # module -> lanes


def use(module: str, *, lanes: bool = False) -> str:
    """Give Warp module ``module`` the headers (once), before its kernels compile; returns its name.
    ``lanes``: a module of lane kernels (every header), else of one-pixel kernels
    (:data:`ONE_PIXEL_HEADERS`).

    Every Warp module whose kernels call a function with native CPU code needs it, a module of
    one's own included: ``@wp.kernel(module=native.use("my.module"))`` for one that calls
    ``footprint.lod_log2`` (under every sampler), ``lanes=True`` for one that calls a lane
    function; without, the CPU build fails on an undeclared ``wt_...`` identifier."""
    if module not in _used:
        wp.set_module_options({"extra_build_options": build_options(HEADERS if lanes else ONE_PIXEL_HEADERS)}, module=module)
        _used[module] = lanes
    elif _used[module] != lanes:
        raise ValueError(f"warptex internal error: Warp module {module!r} named both for lanes and for one-pixel kernels")
    return module
