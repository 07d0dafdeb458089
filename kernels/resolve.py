"""Resolving a supersampled image: each ``s × s`` block of samples averaged into one pixel (a box
filter over the pixel), and the gradient of that average. Part of the rasteriser's Warp module:
what a supersampled G-buffer's renders need, compiled with it."""

import warp as wp

from .raster import MODULE


@wp.kernel(enable_backward=False, module=MODULE)
def resolve_kernel(image: wp.array3d(dtype=float), strata: wp.int32, out: wp.array3d(dtype=float)):
    """``out[i, j, c]``: the mean of ``image[i s + a, j s + b, c]`` over ``a, b < s``."""
    i, j, c = wp.tid()
    total = float(0.0)
    for a in range(strata):
        for b in range(strata):
            total = total + image[i * strata + a, j * strata + b, c]
    out[i, j, c] = total / float(strata * strata)


@wp.kernel(enable_backward=False, module=MODULE)
def resolve_adjoint_kernel(adj_out: wp.array3d(dtype=float), strata: wp.int32, adj_image: wp.array3d(dtype=float)):
    """The gradient of :func:`resolve_kernel`: each sample gets ``1 / s²`` of its pixel's."""
    i, j, c = wp.tid()
    adj_image[i, j, c] = adj_image[i, j, c] + adj_out[i // strata, j // strata, c] / float(strata * strata)
