"""Normal mapping's arithmetic for a lane of pixels on the CPU (:mod:`.`, ``native/wt_normals.h``): each projection's
sample decoded, mirror-fixed, blended with the unit surface normal and swizzled back, the
projections blended by their weights and the blend normalised in world space, and the gradient of
all that in the samples, a lane wide in SIMD registers where Warp's scalar code took a pixel at
a time (it was most of normal mapping's time once the texture reads had lanes).

Every helper computes what the scalar blocks of :mod:`.normals` and :mod:`.triplanar` compute,
operation for operation and in the same order (Warp's ``wp::mul`` of a matrix and a vector column
by column; ``wp::length`` and ``wp::dot`` as Warp writes them; each branch computed in every lane
and chosen by selects; the rare blends past ~1.8e19 lane by lane with Warp's own functions), so the
lanes' normals and gradients are the one-pixel kernels' bits (``tests/test_lanes.py``,
``tests/test_normal_blend_gradient.py``).
"""

import warp as wp

from ..native import cpu_snippet
from ..normals import NormalMapArgs
from ..projection import ProjectionArgs, SurfacePixels
from . import lane_colours, lane_reads


@wp.func_native(cpu_snippet("return wt_surface_normals_lane(proj, nm, pixels, base, count, reads, sx, sy, sz);\n", "return {};\n"))
def surface_normals_lane(proj: ProjectionArgs, nm: NormalMapArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, reads: lane_reads, sx: lane_colours, sy: lane_colours, sz: lane_colours) -> lane_colours:  # fmt: skip
    """Row ``l``: lane pixel ``l``'s normal as normal mapping's pixel body makes it (``x, y, z, 0``),
    from its projections' weights (rows 9-11 of ``reads``) and samples ``sx``, ``sy``, ``sz``; 0
    where the pixel is not covered."""
    ...


@wp.func_native(cpu_snippet("return wt_stored_normals_lane(proj, nm, normal, mask, weights, samples, base, count);\n", "return {};\n"))
def stored_normals_lane(proj: ProjectionArgs, nm: NormalMapArgs, normal: wp.array(dtype=wp.vec3), mask: wp.array(dtype=float), weights: wp.array(dtype=wp.vec3),
                        samples: wp.array2d(dtype=wp.vec4), base: wp.int32, count: wp.int32) -> lane_colours:  # fmt: skip
    """Row ``l``: lane pixel ``l``'s normal made from its stored weights and samples
    (:func:`~.normal_blend.normal_from_samples`), ``(x, y, z, 0)``; 0 where it is not covered."""
    ...


@wp.func_native(cpu_snippet("wt_stored_normals_grad_lane(proj, nm, normal, mask, weights, samples, base, count, adj, grad);\n"))
def stored_normals_grad_lane(proj: ProjectionArgs, nm: NormalMapArgs, normal: wp.array(dtype=wp.vec3), mask: wp.array(dtype=float), weights: wp.array(dtype=wp.vec3),
                             samples: wp.array2d(dtype=wp.vec4), base: wp.int32, count: wp.int32, adj: wp.array2d(dtype=float), grad: wp.array2d(dtype=wp.vec4)):  # fmt: skip
    """:func:`~.normal_blend.normal_from_samples_grad` for the lane: the gradient ``adj[i]`` of lane pixel
    ``i``'s normal added into ``grad[i, axis]``, the gradient of its stored sample of each projection
    it reads (nothing where ``grad`` is empty)."""
    ...
