"""Triplanar and biplanar colour for a lane of pixels on the CPU (:mod:`.lanes`), forward and texel
gradient, one texture per axis, plain sampling.

Each pixel's surface, projection weights, UVs and footprints come from the scalar blocks; the lane's
texture reads from :func:`~.lanes.accumulate_footprint_lane` and its texel-gradient adds from
:func:`~.lane_scatter.scatter_lod_lanes`, both in the order the scalar bodies take them, so the
outputs and the gradients are the scalar kernels' bits. The gradient of the anisotropic filter,
whose footprints may take several taps, goes pixel by pixel through the scalar body.
"""

import functools

import warp as wp

from . import inlined, specialised
from .faces import FaceGrads, on_axis
from .lane_scatter import scatter_lod_lanes
from .lanes import LANES, accumulate_footprint_lane, lane_colours, lane_ints
from .projection import SurfacePixels, projection_footprint, projection_uv, projection_weights, surface
from .texels import FILTER_ANISOTROPIC, read_channels, write_channels

# Per projection (row) and lane pixel (column): what the pixel reads from the projection.
_lane_values = wp.types.matrix(shape=(3, LANES), dtype=float)


@functools.cache
def lane_bodies(colour, colour_grad, args_t):
    """``(colour_lane, colour_grad_lane)``: the lane bodies of the plain colour body ``colour`` and its
    texel gradient ``colour_grad`` (one texture per axis), whose arguments are ``args_t``
    (:class:`~.triplanar.TriplanarArgs`)."""

    def projection_reads(args: args_t, pixels: SurfacePixels, base: wp.int32, count: wp.int32):
        """``(u, v, lod, du, dv, taps, weight)``: what each lane pixel (column) reads from each
        projection (row), its UV and footprint (LOD, step, taps: footprint.py), and its weight (0:
        not read: a zero weight, or an uncovered pixel)."""
        faces = args.faces
        u = _lane_values()
        v = _lane_values()
        lod = _lane_values()
        du = _lane_values()
        dv = _lane_values()
        taps = _lane_values()
        weight = _lane_values()
        for l in range(count):
            i = base + l
            if pixels.mask[i] != 0.0:
                p, n, dpdx, dpdy = surface(args.proj, pixels, i)
                w = projection_weights(args.proj, n)
                for axis in range(3):
                    if w[axis] > 0.0:
                        uv = projection_uv(args.proj, axis, p, n)
                        fp = projection_footprint(on_axis(faces.px, faces.py, faces.pz, axis), args.proj, axis, n, dpdx, dpdy, args.smp)
                        u[axis, l] = uv[0]
                        v[axis, l] = uv[1]
                        lod[axis, l] = fp[0]
                        du[axis, l] = fp[1]
                        dv[axis, l] = fp[2]
                        taps[axis, l] = fp[3]
                        weight[axis, l] = w[axis]
        return u, v, lod, du, dv, taps, weight

    projection_reads = inlined(specialised(projection_reads, "triplanar_projection_reads"))

    def colour_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        faces = args.faces
        u, v, lod, du, dv, taps, weight = projection_reads(args, pixels, base, count)
        layers = lane_ints(args.layer)
        value = lane_colours()
        value = accumulate_footprint_lane(faces.px, args.smp, layers, u[0], v[0], lod[0], du[0], dv[0], taps[0], weight[0], 1, value)
        value = accumulate_footprint_lane(faces.py, args.smp, layers, u[1], v[1], lod[1], du[1], dv[1], taps[1], weight[1], 1, value)
        value = accumulate_footprint_lane(faces.pz, args.smp, layers, u[2], v[2], lod[2], du[2], dv[2], taps[2], weight[2], 1, value)
        for l in range(count):
            write_channels(out, base + l, value[l])

    def colour_grad_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, grads: FaceGrads, adj: wp.array2d(dtype=float)):
        count = wp.min(adj.shape[0] - base, LANES)
        if args.smp.filter == FILTER_ANISOTROPIC:
            for l in range(count):
                colour_grad(args, pixels, base + l, grads, adj)
        else:
            faces = args.faces
            u, v, lod, du, dv, taps, weight = projection_reads(args, pixels, base, count)
            g0 = lane_colours()  # each projection's share w · g of the pixel's output gradient (read where w > 0)
            g1 = lane_colours()
            g2 = lane_colours()
            for l in range(count):
                g = read_channels(adj, base + l)
                g0[l] = weight[0, l] * g
                g1[l] = weight[1, l] * g
                g2[l] = weight[2, l] * g
            scatter_lod_lanes(faces.px, faces.py, faces.pz, grads.px, grads.py, grads.pz, args.smp, 3, lane_ints(args.layer), u, v, lod, weight, g0, g1, g2)

    return inlined(specialised(colour_lane, "triplanar_colour_lane")), inlined(specialised(colour_grad_lane, "triplanar_colour_grad_lane"))
