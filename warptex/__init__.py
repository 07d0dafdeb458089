"""warptex: differentiable texture sampling as NVIDIA Warp kernels.

The library:

- textures: :class:`Texture`, :class:`TextureArray` (differentiable mip chains, :func:`mip_sizes`);
- options every technique takes: :class:`Sampler` (with :class:`Filter`, :class:`Address`) and
  :class:`Stochastic` (with :class:`Method`);
- the techniques: :func:`sample`, :func:`stochastic` (with :func:`prepare_histogram`,
  :class:`Histogram`), :func:`triplanar`, :func:`biplanar`, :func:`triplanar_normal` (with
  :class:`Space`, :class:`Blend`), :func:`splat` (with :class:`LayerProjection`), and the atlas variant
  :func:`pack_atlas`, :func:`export_index_maps`, :func:`splat_atlas` (:class:`Atlas`);
- G-buffers: :func:`rasterize` of a mesh (:func:`load_mesh`) through a :class:`Camera`
  (:func:`look_at`, :func:`orthographic`) into a :class:`GBuffer`, :func:`save_gbuffer`,
  :func:`load_gbuffer`; image files in :mod:`warptex.io`;
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

import importlib.util as _importlib_util
import sys as _sys
from pathlib import Path as _Path


def _import_kernels_of_a_checkout() -> None:
    """Installed, the Warp code is the subpackage ``warptex.kernels``; in a source checkout it is the
    folder ``kernels/`` beside ``warptex/``. Register that folder as ``warptex.kernels`` so that a
    checkout imports exactly as an install does (``python -m warptex``, ``python -m pytest``)."""
    package = _Path(__file__).resolve().parent
    checkout_kernels = package.parent / "kernels" / "__init__.py"
    if (package / "kernels").is_dir() or "warptex.kernels" in _sys.modules or not checkout_kernels.is_file():
        return
    spec = _importlib_util.spec_from_file_location("warptex.kernels", checkout_kernels, submodule_search_locations=[str(checkout_kernels.parent)])
    module = _importlib_util.module_from_spec(spec)
    _sys.modules["warptex.kernels"] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del _sys.modules["warptex.kernels"]
        raise


_import_kernels_of_a_checkout()

from warptex import fit, io
from warptex._compile import precompile
from warptex._threads import get_num_threads, set_num_threads
from warptex._warp import init_quietly
from warptex.atlas import Atlas, export_index_maps, pack_atlas, splat_atlas
from warptex.bake import Baked, bake, tangent_space, texture_gbuffer
from warptex.camera import Camera, look_at, orthographic
from warptex.gbuffer import GBuffer, load_mesh, rasterize
from warptex.gbuffer_io import load_gbuffer, save_gbuffer
from warptex.gltf import export_gltf
from warptex.histogram import Histogram, prepare_histogram
from warptex.splat import LayerProjection, splat
from warptex.options import Address, Filter, Method, Sampler, Stochastic
from warptex.resolve import resolve
from warptex.sampling import sample
from warptex.stochastic import hex_taps, stochastic
from warptex.texture import Texture, TextureArray, mip_sizes
from warptex.triplanar import Blend, Space, biplanar, triplanar, triplanar_normal
from warptex.unwrap import UVLayout, unwrap

__all__ = [
    "Address",
    "Atlas",
    "Baked",
    "Blend",
    "Camera",
    "Filter",
    "GBuffer",
    "Histogram",
    "Method",
    "LayerProjection",
    "Sampler",
    "Space",
    "Stochastic",
    "Texture",
    "TextureArray",
    "UVLayout",
    "bake",
    "biplanar",
    "export_gltf",
    "export_index_maps",
    "fit",
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
    "set_num_threads",
    "splat",
    "splat_atlas",
    "stochastic",
    "tangent_space",
    "texture_gbuffer",
    "triplanar",
    "triplanar_normal",
    "unwrap",
]
__version__ = "0.1.0"
