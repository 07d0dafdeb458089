"""warptex: differentiable texture sampling as NVIDIA Warp kernels.

The public API: textures (:class:`Texture`, :class:`TextureArray`), :func:`sample` with its
:class:`Filter` and :class:`Address` modes, and image I/O in :mod:`warptex.io`.
"""

from warptex import io
from warptex.sampling import Address, Filter, sample
from warptex.texture import Texture, TextureArray, mip_sizes

__all__ = ["Address", "Filter", "Texture", "TextureArray", "io", "mip_sizes", "sample"]
__version__ = "0.1.0"
