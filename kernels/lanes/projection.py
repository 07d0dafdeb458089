"""Plane projections for a lane of pixels on the CPU (:mod:`.lanes`): what each pixel of a triplanar
lane reads from each projection, its UV, LOD and weight, computed a lane at a time.

The scalar blocks of :mod:`.projection` and :mod:`.footprint` run one pixel at a time through Warp's
code, with a branch per projection and per test; in a triplanar lane on the benchmark's sphere they
took 59% of the time (timed with the TSC inside the kernel), the texture reads the rest.
``wt_triplanar_reads_lane`` restates them in C++, operation for operation (Warp's own ``wp::``
functions or their exact vector twins, no contraction), on clang vectors of a value per lane pixel
(the weights' exponent and the other launch-wide choices are tested once, outside them; loops over
lanes that the compiler was left to vectorise did not all vectorise), so the reads are the scalar
blocks' bits; the LODs' ``log2`` is :func:`~.footprint.lod_log2`'s, a lane at a time. It covers every
filter (the anisotropic footprint's branches as selects) and both weights on the vectors: biplanar's
branches, which pick each pixel's axes, as selects too (pixel by pixel in C++ they took half a
biplanar lane's reads; the rare pairs whose powers underflow still go pixel by pixel).
"""

import warp as wp

from ..faces import FaceGrads, FaceTextures
from ..family import lane_covered
from ..native import cpu_snippet
from ..normals import NormalMapArgs
from ..projection import ProjectionArgs, SurfacePixels
from ..texels import SamplerArgs
from . import lane_colours, lane_ints, lane_reads


@wp.func_native(cpu_snippet("return wt_triplanar_reads_lane(faces, proj, smp, pixels, base, count, unit_normals, side);\n", "return {};\n"))
def triplanar_reads_lane(faces: FaceTextures, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, unit_normals: wp.int32, side: wp.int32) -> lane_reads:
    """What the lane's pixels ``base .. base + count - 1`` read from each projection, with triplanar
    or biplanar weights (``proj.weights``): the UVs, footprints and weights of ``projection.projection_uv``,
    ``projection.projection_footprint`` and ``projection.projection_weights``, as
    :data:`~.lane_reads` (all 0 where a projection is not read: a zero weight, or an uncovered
    pixel). With ``unit_normals``, the UVs and footprints are those of the unit normal
    (``normal_blend.unit_base_normal``, as normal mapping reads them; the weights are the normal's as
    given either way): a normal's tiny component can round to zero as it is scaled, which turns its
    mirror-fix sign. ``side``: 0, each projection read on ``faces``' texture of its axis (``px``,
    ``py``, ``pz``); with a texture per face (``faces.on_face``), 1 or 2, each projection read on the
    face of that side (``+``: ``px``, ``py``, ``pz``; ``-``: ``nx``, ``ny``, ``nz``), its weight 0 where
    the normal looks at the other face."""
    ...


@wp.func_native(cpu_snippet("wt_triplanar_colour_lane(faces, proj, smp, pixels, base, count, layers, out);\n"))
def triplanar_colour_lane(faces: FaceTextures, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, layers: lane_ints,
                          out: wp.array2d(dtype=float)):  # fmt: skip
    """Row ``base + l`` of ``out``: lane pixel ``l``'s colour, its projections' samples (on ``faces``'
    texture of each axis, layer ``layers[l]``) over their footprints, blended by their weights in
    read order (``value += w · sample``), from the reads ``triplanar_reads_lane(faces, proj, smp,
    pixels, base, count, 0, 0)`` gives, in one call: the reads never become a :data:`~.lane_reads`
    matrix (one zeroed, returned and copied in per lane was 10% of a biplanar forward), and the
    colours are written as ``sample``'s are (Warp's element stores, a branch a channel, were 6%)."""
    ...


@wp.func_native(cpu_snippet("wt_triplanar_scatter_lane(faces, grads, proj, smp, pixels, base, count, layers, adj);\n"))
def triplanar_scatter_lane(faces: FaceTextures, grads: FaceGrads, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, layers: lane_ints,
                           adj: wp.array2d(dtype=float)):  # fmt: skip
    """The texel gradients of plain colour's reads for the lane's pixels ``base .. base + count - 1``:
    each projection's share ``w · adj[base + l]`` of a pixel's output gradient, into the gradient of
    its axis's texture (``grads.px``, ``py``, ``pz``; layer ``layers[l]``), pixel by pixel and read by
    read as the scalar kernels add them, from the reads ``triplanar_reads_lane(faces, proj, smp,
    pixels, base, count, 0, 0)`` gives, in one call (the reads as a zeroed :data:`~.lane_reads`,
    returned, then copied into the scatter, were 11% of a biplanar forward and backward). Where
    ``grads.tiling``, ``grads.offsets`` or ``grads.sharpness`` is not empty, each read's share of
    their gradients (``slopes.add_plane_slopes``), pixel by pixel and projection by projection."""
    ...


@wp.func_native(cpu_snippet("return wt_triplanar_normals_lane(faces, proj, nm, smp, pixels, base, count, layers);\n", "return {};\n"))
def triplanar_normals_lane(faces: FaceTextures, proj: ProjectionArgs, nm: NormalMapArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, layers: lane_ints) -> lane_colours:  # fmt: skip
    """Row ``l``: lane pixel ``l``'s normal as normal mapping's pixel body makes it (``x, y, z, 0``; 0
    where it is not covered), from its reads on the unit normal (``triplanar_reads_lane(faces,
    proj, smp, pixels, base, count, 1, 0)``'s), each projection's sample on ``faces``' texture of
    its axis (layer ``layers[l]``, read in place: ``wt_read_lane``) and ``surface_normals_lane``'s
    arithmetic, in one call."""
    ...


@wp.func_native(cpu_snippet("wt_triplanar_samples_lane(faces, proj, smp, pixels, base, count, layers, samples, weights);\n"))
def triplanar_samples_lane(faces: FaceTextures, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32, layers: lane_ints,
                           samples: wp.array2d(dtype=wp.vec4), weights: wp.array(dtype=wp.vec3)):  # fmt: skip
    """What normal mapping's first step stores for the lane's pixels ``i = base .. base + count - 1``
    (:class:`~warptex.kernels.triplanar.ProjectionSamples`), from the reads and samples
    :func:`triplanar_normals_lane` makes: ``weights[i]``, the projections' weights (0 where the
    pixel is not covered), and ``samples[i, axis]``, each projection's sample (0 where its weight
    is 0)."""
    ...


@wp.func_native(cpu_snippet("wt_triplanar_scatter_samples_lane(faces, grads, proj, smp, pixels, base, count, layers, adj);\n"))
def triplanar_scatter_samples_lane(faces: FaceTextures, grads: FaceGrads, proj: ProjectionArgs, smp: SamplerArgs, pixels: SurfacePixels, base: wp.int32, count: wp.int32,
                                   layers: lane_ints, adj: wp.array2d(dtype=wp.vec4)):  # fmt: skip
    """The gradients ``adj[i, axis]`` of the samples :func:`triplanar_samples_lane` stored for the
    lane's pixels ``i = base .. base + count - 1``, each added (not weighted) into the texels of its
    projection's read on the unit normal (``grads.px``, ``py``, ``pz``; layer ``layers[l]``),
    pixel by pixel and read by read as the scalar kernels add them, and where ``grads.tiling`` or
    ``grads.offsets`` is not empty, into them (``slopes.add_plane_slopes``)."""
    ...


@wp.func
def surface_covered(pixels: SurfacePixels, base: wp.int32, count: wp.int32) -> bool:
    """Whether the G-buffer covers any of the lane's pixels (``covered`` of ``family.lane_kernel``)."""
    return lane_covered(pixels.mask, base, count)
