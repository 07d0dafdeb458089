"""warptex: differentiable texture sampling as NVIDIA Warp kernels.

The library:

- textures: :class:`Texture`, :class:`TextureArray` (differentiable mip chains, :func:`mip_sizes`), stored
  in a :class:`Format` (float32, float16, 8-bit unorm or sRGB);
- options every technique takes: :class:`Sampler` (with :class:`Filter`, :class:`Address`) and
  :class:`Stochastic` (with :class:`Method`);
- the techniques: :func:`sample`, :func:`stochastic` (with :func:`prepare_histogram`,
  :class:`Histogram`), :func:`triplanar`, :func:`biplanar`, :func:`triplanar_normal`, :func:`biplanar_normal` (with
  :class:`Space`, :class:`Blend`), :func:`splat` (with :class:`LayerProjection`), and the atlas variant
  :func:`pack_atlas`, :func:`export_index_maps`, :func:`splat_atlas` (:class:`Atlas`);
- G-buffers: :func:`rasterize` of a mesh (:func:`load_mesh`) through a :class:`Camera`
  (:func:`look_at`, :func:`orthographic`) into a :class:`GBuffer`, :func:`save_gbuffer`,
  :func:`load_gbuffer`; image files in :mod:`warptex.io`;
- jobs larger than memory, in bands of rows: :func:`gbuffer_tiles` (:class:`Tile`),
  :func:`texture_gbuffer_tiles`, :func:`bake_gltf`;
- baking into a UV atlas and exporting glTF: :func:`bake` (:class:`Baked`), its texture-space
  G-buffer :func:`texture_gbuffer` over a :func:`unwrap` layout (:class:`UVLayout`),
  :func:`tangent_space` normal maps, :func:`export_gltf`;
- fitting to images: :mod:`warptex.fit` (:class:`~warptex.fit.SplatParameters`,
  :class:`~warptex.fit.FitView`, :func:`~warptex.fit.fit_splat`...);
- CPU threads and kernel compilation: :func:`set_num_threads`, :func:`get_num_threads`,
  :func:`precompile`.

The command line (``warptex render | demo | fit``) and its helpers (the procedural terrain,
previews, plots) are in :mod:`warptex.apps`, which the library never imports.
"""

import importlib as _importlib
import importlib.abc as _importlib_abc
import importlib.util as _importlib_util
import sys as _sys
import types as _types
from pathlib import Path as _Path


class _CheckoutKernels(_importlib_abc.MetaPathFinder):
    """Installed, the Warp code is the subpackage ``warptex.kernels``; in a source checkout it is the
    folder ``kernels/`` beside ``warptex/``. This finder gives that folder as ``warptex.kernels``
    when it is first imported, so that a checkout imports exactly as an install does (``python -m
    warptex``, ``python -m pytest``)."""

    def __init__(self, init: _Path):
        self.init = init

    def find_spec(self, name, path=None, target=None):
        if name != "warptex.kernels":
            return None
        return _importlib_util.spec_from_file_location(name, self.init, submodule_search_locations=[str(self.init.parent)])


def _find_kernels_of_a_checkout() -> None:
    package = _Path(__file__).resolve().parent
    checkout_kernels = package.parent / "kernels" / "__init__.py"
    if (package / "kernels").is_dir() or "warptex.kernels" in _sys.modules or not checkout_kernels.is_file():
        return
    if not any(isinstance(f, _CheckoutKernels) for f in _sys.meta_path):
        _sys.meta_path.insert(0, _CheckoutKernels(checkout_kernels))


_find_kernels_of_a_checkout()

# The public names and the modules they live in. They are imported when first used (PEP 562):
# ``import warptex`` costs no Warp, NumPy or trimesh import, so the command line starts, and
# answers Ctrl-C, before any of them loads.
_NAMES = {
    "fit": None, "io": None,
    "precompile": "_compile", "get_num_threads": "_threads", "set_num_threads": "_threads", "init_quietly": "_warp",
    "get_deterministic_gradients": "_accumulate", "set_deterministic_gradients": "_accumulate",
    "Atlas": "atlas", "export_index_maps": "atlas", "pack_atlas": "atlas", "splat_atlas": "atlas",
    "Baked": "bake", "bake": "bake", "tangent_space": "bake", "texture_gbuffer": "bake", "texture_gbuffer_tiles": "bake",
    "Camera": "camera", "look_at": "camera", "orthographic": "camera",
    "GBuffer": "gbuffer", "load_mesh": "mesh", "rasterize": "raster",
    "load_gbuffer": "gbuffer_io", "save_gbuffer": "gbuffer_io",
    "bake_gltf": "gltf", "export_gltf": "gltf",
    "Histogram": "histogram", "prepare_histogram": "histogram",
    "LayerProjection": "splat", "splat": "splat",
    "Address": "options", "Filter": "options", "Method": "options", "Sampler": "options", "Stochastic": "options",
    "resolve": "resolve", "sample": "sampling", "hex_taps": "stochastic", "stochastic": "stochastic",
    "Format": "formats", "Texture": "texture", "TextureArray": "texture", "mip_sizes": "texture",
    "Tile": "tiles", "gbuffer_tiles": "tiles",
    "Blend": "options", "Space": "options", "biplanar": "triplanar", "biplanar_normal": "triplanar", "triplanar": "triplanar", "triplanar_normal": "triplanar",
    "UVLayout": "unwrap", "unwrap": "unwrap",
}


def __getattr__(name: str):
    if name not in _NAMES:
        raise AttributeError(f"module 'warptex' has no attribute {name!r}")
    module = _NAMES[name]
    value = _importlib.import_module(f"warptex.{name}") if module is None else getattr(_importlib.import_module(f"warptex.{module}"), name)
    _Package.__setattr__(_sys.modules[__name__], name, value, force=True)
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(_types.ModuleType):
    """The ``warptex`` package: importing a submodule whose name is also a public function's
    (``warptex.bake``, ``.splat``, ``.triplanar``, ``.stochastic``, ``.resolve``, ``.unwrap``) does
    not replace the function with the module, as an eager ``from warptex.bake import bake`` after
    it never did; the modules stay in ``sys.modules``."""

    def __setattr__(self, name, value, force: bool = False):
        if not force and isinstance(value, _types.ModuleType) and _NAMES.get(name, "") is not None and name in _NAMES:
            return
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package

__all__ = [
    "Address",
    "Atlas",
    "Baked",
    "Blend",
    "Camera",
    "Filter",
    "Format",
    "GBuffer",
    "Histogram",
    "Method",
    "LayerProjection",
    "Sampler",
    "Space",
    "Stochastic",
    "Texture",
    "TextureArray",
    "Tile",
    "UVLayout",
    "bake",
    "bake_gltf",
    "biplanar",
    "biplanar_normal",
    "export_gltf",
    "export_index_maps",
    "fit",
    "gbuffer_tiles",
    "get_deterministic_gradients",
    "get_num_threads",
    "hex_taps",
    "init_quietly",
    "io",
    "load_gbuffer",
    "load_mesh",
    "look_at",
    "mip_sizes",
    "orthographic",
    "pack_atlas",
    "precompile",
    "prepare_histogram",
    "rasterize",
    "resolve",
    "sample",
    "save_gbuffer",
    "set_deterministic_gradients",
    "set_num_threads",
    "splat",
    "splat_atlas",
    "stochastic",
    "tangent_space",
    "texture_gbuffer",
    "texture_gbuffer_tiles",
    "triplanar",
    "triplanar_normal",
    "unwrap",
]
__version__ = "0.1.0"
