"""warptex: differentiable texture sampling as NVIDIA Warp kernels.

The public API: textures (:class:`Texture`, :class:`TextureArray`), :func:`sample` with its
:class:`Filter` and :class:`Address` modes, image I/O in :mod:`warptex.io`, cameras
(:func:`look_at`, :func:`orthographic`), G-buffers (:func:`rasterize`, :func:`save_gbuffer`,
:func:`load_gbuffer`) and the procedural :func:`terrain`.
"""

from warptex import io
from warptex.camera import Camera, look_at, orthographic
from warptex.gbuffer import GBuffer, load_mesh, rasterize
from warptex.gbuffer_io import load_gbuffer, save_gbuffer
from warptex.sampling import Address, Filter, sample
from warptex.terrain import terrain
from warptex.texture import Texture, TextureArray, mip_sizes

__all__ = [
    "Address",
    "Camera",
    "Filter",
    "GBuffer",
    "Texture",
    "TextureArray",
    "io",
    "load_gbuffer",
    "load_mesh",
    "look_at",
    "mip_sizes",
    "orthographic",
    "rasterize",
    "sample",
    "save_gbuffer",
    "terrain",
]
__version__ = "0.1.0"
