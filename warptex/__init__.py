"""warptex: differentiable texture sampling as NVIDIA Warp kernels.

The public API: textures (:class:`Texture`, :class:`TextureArray`), :func:`sample` with its
:class:`Filter` and :class:`Address` modes, image I/O in :mod:`warptex.io`, cameras
(:func:`look_at`, :func:`orthographic`), G-buffers (:func:`rasterize`, :func:`save_gbuffer`,
:func:`load_gbuffer`), the procedural :func:`terrain`, the techniques (:func:`triplanar`,
:func:`biplanar`, :func:`triplanar_normal`, :func:`splat`, the atlas variant
:func:`splat_atlas`, and :func:`stochastic` anti-tiling sampling), the Lambert preview :func:`lambert`,
and :func:`set_num_threads` for the CPU threads a launch is split over. Fitting texturing to images:
:func:`fit_splat` over :class:`SplatParameters` (per-texel logits, log-tiling, softplus sharpness),
with :class:`FitView` targets and :class:`Stage` schedules; losses, blur and metrics in
:mod:`warptex.fit`.
"""

from warptex import io
from warptex._launch import get_num_threads, precompile, set_num_threads
from warptex.camera import Camera, look_at, orthographic
from warptex.gbuffer import GBuffer, load_mesh, rasterize
from warptex.gbuffer_io import load_gbuffer, save_gbuffer
from warptex.atlas import export_index_maps, pack_atlas, splat_atlas
from warptex.fit import SplatParameters, image_loss
from warptex.fit_loop import FitView, Stage, fit_splat
from warptex.layers import splat
from warptex.sampling import Address, Filter, sample
from warptex.terrain import terrain
from warptex.shade import lambert
from warptex.stochastic import Method, Stochastic, prepare_histogram, stochastic
from warptex.texture import Texture, TextureArray, mip_sizes
from warptex.triplanar import Blend, Space, biplanar, triplanar, triplanar_normal

__all__ = [
    "Address",
    "Blend",
    "Camera",
    "Filter",
    "FitView",
    "GBuffer",
    "Method",
    "Texture",
    "Space",
    "SplatParameters",
    "Stage",
    "TextureArray",
    "biplanar",
    "export_index_maps",
    "fit_splat",
    "get_num_threads",
    "image_loss",
    "io",
    "lambert",
    "load_gbuffer",
    "load_mesh",
    "look_at",
    "mip_sizes",
    "orthographic",
    "pack_atlas",
    "precompile",
    "prepare_histogram",
    "rasterize",
    "sample",
    "save_gbuffer",
    "set_num_threads",
    "splat",
    "splat_atlas",
    "Stochastic",
    "stochastic",
    "terrain",
    "triplanar",
    "triplanar_normal",
]
__version__ = "0.1.0"
