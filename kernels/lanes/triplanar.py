"""Triplanar and biplanar colour for a lane of pixels on the CPU (:mod:`.`), forward and texel
gradient, plain or stochastic, one texture per axis or per face; and triplanar normal mapping (its
forward, and both steps of its two-step gradient), plain or stochastic, one texture per axis or
per face.

What each pixel reads from each projection (its UV, footprint and weight, with triplanar or
biplanar weights) comes from :func:`~.projection.triplanar_reads_lane` for the whole lane, or
inside the one native call that also reads and writes (plain colour:
:func:`~.projection.triplanar_colour_lane`, and its texel-gradient adds,
:func:`~.projection.triplanar_scatter_lane`; plain normal mapping:
:func:`plain_normal_lane_bodies`); the other texel-gradient adds come from :mod:`.scatter`. All
take them in the order the scalar bodies do, so the outputs and the gradients are the scalar
kernels' bits. The anisotropic filter's footprints of several taps add pixel by pixel, read by
read, each read's taps in order, inside the native call (``wt_scatter_footprint_rows``), as the
scalar bodies add them.
"""

import functools

import warp as wp

from .. import inlined, specialised
from ..faces import FaceGrads, on_axis
from ..family import lane_covered
from ..projection import SurfacePixels
from ..texels import FILTER_ANISOTROPIC, pick3, read_channels
from . import LANES, lane_colours, lane_ints, lane_reads
from .normals import stored_normals_grad_lane, stored_normals_lane, surface_normals_lane
from .projection import triplanar_colour_lane, triplanar_normals_lane, triplanar_reads_lane, triplanar_samples_lane, triplanar_scatter_lane, triplanar_scatter_samples_lane
from .sample import accumulate_footprint_lane, write_lane
from .scatter import scatter_face_reads_lanes, scatter_projection_taps_lanes
from .stochastic import linear_blend, projection_taps_lane, scatter_stochastic_face_reads_lanes, scatter_stochastic_reads_lanes, stochastic_read_lane


def slopes_lanes_take(args) -> bool:
    """Whether the texel-gradient lanes of plain sampling with a texture per face (colour's, and
    normal mapping's stored samples') take a launch with ``args``: not where the tiling, offsets or
    sharpness need gradients, which their one-pixel kernel adds by hand (``slopes.add_plane_slopes``;
    with one texture per axis the lanes add them too: ``wt_add_plane_slopes``)."""
    return not (args.proj.tiling.requires_grad or args.proj.offsets.requires_grad or args.proj.sharpness.requires_grad)


def sharpness_lanes_take(args) -> bool:
    """Whether the gradient lanes of normal mapping's second step (the normal made from the stored
    samples, ``stored_lane_bodies``) take a launch with ``args``: not where the sharpness needs its
    gradient, which only the one-pixel kernel adds (``normal_blend.normal_from_samples_grad``)."""
    return not args.proj.sharpness.requires_grad


@functools.cache
def lane_bodies(args_t):
    """``(colour_lane, colour_grad_lane)``: the lane bodies of plain colour mapping and its texel
    gradient (one texture per axis), whose arguments are ``args_t``
    (:class:`~.triplanar.TriplanarArgs`)."""

    def colour_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        triplanar_colour_lane(args.faces, args.proj, args.smp, pixels, base, count, lane_ints(args.layer), out)  # the projections' samples, blended

    def colour_grad_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, grads: FaceGrads, adj: wp.array2d(dtype=float)):
        count = wp.min(adj.shape[0] - base, LANES)
        triplanar_scatter_lane(args.faces, grads, args.proj, args.smp, pixels, base, count, lane_ints(args.layer), adj)

    return inlined(specialised(colour_lane, "triplanar_colour_lane")), inlined(specialised(colour_grad_lane, "triplanar_colour_grad_lane"))


@functools.cache
def face_lane_bodies(args_t, stochastic: bool = False):
    """``(colour_lane, colour_grad_lane)``: the lane bodies of colour mapping with a texture per face
    (``faces.on_face``), plain or ``stochastic``: the lane's reads on the ``+`` faces and on the
    ``-`` faces (each pixel's weight on the side its normal looks at), read and added projection by
    projection, ``+`` then ``-`` (a pixel reads one of the two), in the order of the pixel bodies.
    Stochastic sampling (linear blends only: a histogram needs one texture for every projection,
    which is not this configuration) reads each projection over its footprint through its
    stochastic taps on both faces (:func:`~.stochastic.stochastic_read_lane`) and adds the one its
    pixel reads; the gradient goes back through the same taps
    (:func:`~.stochastic.scatter_stochastic_face_reads_lanes`)."""
    if stochastic:

        def face_colours(args: args_t, plus: lane_reads, minus: lane_reads, count: wp.int32) -> lane_colours:
            """The lane's colours: each projection's stochastic sample on the face its pixel reads,
            weighted."""
            f = args.faces
            layers = lane_ints(args.layer)
            value = lane_colours()
            for axis in range(3):
                sp = stochastic_read_lane(on_axis(f.px, f.py, f.pz, axis), args.smp, args.stoch, layers, plus, axis, count)
                sm = stochastic_read_lane(on_axis(f.nx, f.ny, f.nz, axis), args.smp, args.stoch, layers, minus, axis, count)
                for l in range(count):
                    w_plus = plus[9 + axis, l]
                    w_minus = minus[9 + axis, l]
                    if w_plus > 0.0:
                        value[l] = value[l] + w_plus * sp[l]
                    elif w_minus > 0.0:
                        value[l] = value[l] + w_minus * sm[l]
            return value

        def scatter_faces(args: args_t, plus: lane_reads, minus: lane_reads, grads: FaceGrads, g: lane_colours):
            f = args.faces
            scatter_stochastic_face_reads_lanes(f.px, f.nx, f.py, f.ny, f.pz, f.nz, grads.px, grads.nx, grads.py, grads.ny, grads.pz, grads.nz, args.smp, args.stoch, lane_ints(args.layer), plus, minus, 1, g, g, g)

    else:

        def face_colours(args: args_t, plus: lane_reads, minus: lane_reads, count: wp.int32) -> lane_colours:
            """The lane's colours: each projection's sample on the face its pixel reads, weighted."""
            f = args.faces
            layers = lane_ints(args.layer)
            value = lane_colours()
            for axis in range(3):
                value = accumulate_footprint_lane(on_axis(f.px, f.py, f.pz, axis), args.smp, layers, plus[axis], plus[3 + axis], plus[6 + axis], plus[12 + axis], plus[15 + axis], plus[18 + axis], plus[9 + axis], 1, value)
                value = accumulate_footprint_lane(on_axis(f.nx, f.ny, f.nz, axis), args.smp, layers, minus[axis], minus[3 + axis], minus[6 + axis], minus[12 + axis], minus[15 + axis], minus[18 + axis], minus[9 + axis], 1, value)
            return value

        def scatter_faces(args: args_t, plus: lane_reads, minus: lane_reads, grads: FaceGrads, g: lane_colours):
            f = args.faces
            scatter_face_reads_lanes(f.px, f.nx, f.py, f.ny, f.pz, f.nz, grads.px, grads.nx, grads.py, grads.ny, grads.pz, grads.nz, args.smp, lane_ints(args.layer), plus, minus, 1, g, g, g)

    kind = "_stochastic" if stochastic else ""
    face_colours = inlined(specialised(face_colours, f"triplanar{kind}_face_colours"))
    scatter_faces = inlined(specialised(scatter_faces, f"triplanar{kind}_scatter_faces"))

    def faces_colour_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        plus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 0, 1)
        minus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 0, 2)
        write_lane(out, base, count, face_colours(args, plus, minus, count))

    def faces_colour_grad_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, grads: FaceGrads, adj: wp.array2d(dtype=float)):
        count = wp.min(adj.shape[0] - base, LANES)
        plus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 0, 1)
        minus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 0, 2)
        g = lane_colours()
        for l in range(count):
            g[l] = read_channels(adj, base + l)
        scatter_faces(args, plus, minus, grads, g)

    return inlined(specialised(faces_colour_lane, f"triplanar{kind}_faces_colour_lane")), inlined(specialised(faces_colour_grad_lane, f"triplanar{kind}_faces_colour_grad_lane"))


@functools.cache
def stochastic_lane_bodies(args_t):
    """``(colour_lane, colour_grad_lane)``: the lane bodies of stochastic colour mapping (one texture
    per axis) and its texel gradient: the lane's reads, then per projection
    ``stochastic.sample_stochastic`` over each pixel's footprint (:func:`~.stochastic.stochastic_read_lane`: each footprint tap's stochastic taps worked out
    natively and read tap by tap; NaN where the UV or LOD is not finite), added with the
    projection's weight, in the order of the pixel body; the gradient adds each tap's share of the
    projection's share (``.scatter.scatter_projection_taps_lanes``; with the anisotropic filter,
    every footprint tap's taps in order: :func:`~.stochastic.scatter_stochastic_reads_lanes`). A
    histogram's blend is not theirs (:func:`linear_blend_take`)."""

    def stochastic_colour_grad_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, grads: FaceGrads, adj: wp.array2d(dtype=float)):
        count = wp.min(adj.shape[0] - base, LANES)
        if args.smp.filter == FILTER_ANISOTROPIC:
            faces = args.faces
            reads = triplanar_reads_lane(faces, args.proj, args.smp, pixels, base, count, 0, 0)
            gs = lane_colours()
            for l in range(count):
                gs[l] = read_channels(adj, base + l)
            scatter_stochastic_reads_lanes(faces.px, faces.py, faces.pz, grads.px, grads.py, grads.pz, args.smp, args.stoch, lane_ints(args.layer), reads, 1, gs, gs, gs)
        else:
            faces = args.faces
            reads = triplanar_reads_lane(faces, args.proj, args.smp, pixels, base, count, 0, 0)
            gx = lane_colours()
            gy = lane_colours()
            gz = lane_colours()
            for l in range(count):
                g = read_channels(adj, base + l)
                gx[l] = reads[9, l] * g  # each projection's share, w · g, as the pixel body adds it
                gy[l] = reads[10, l] * g
                gz[l] = reads[11, l] * g
            tx = projection_taps_lane(args.stoch, reads, 0, count)
            ty = projection_taps_lane(args.stoch, reads, 1, count)
            tz = projection_taps_lane(args.stoch, reads, 2, count)
            scatter_projection_taps_lanes(faces.px, faces.py, faces.pz, grads.px, grads.py, grads.pz, args.smp, lane_ints(args.layer), tx, ty, tz, gx, gy, gz)

    def stochastic_colour_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        faces = args.faces
        reads = triplanar_reads_lane(faces, args.proj, args.smp, pixels, base, count, 0, 0)
        layers = lane_ints(args.layer)
        value = lane_colours()
        for axis in range(3):
            sampled = stochastic_read_lane(on_axis(faces.px, faces.py, faces.pz, axis), args.smp, args.stoch, layers, reads, axis, count)
            for l in range(count):
                w = reads[9 + axis, l]
                if w > 0.0:
                    value[l] = value[l] + w * sampled[l]
        write_lane(out, base, count, value)

    return inlined(specialised(stochastic_colour_lane, "triplanar_stochastic_colour_lane")), inlined(specialised(stochastic_colour_grad_lane, "triplanar_stochastic_colour_grad_lane"))


@functools.cache
def plain_normal_lane_bodies(args_t, samples_t):
    """:func:`normal_lane_bodies` of plain sampling with a texture per axis: each body one native
    call, which reads the projections on the unit normal and their samples and makes the normals
    (:func:`~.projection.triplanar_normals_lane`), stores the samples and weights
    (:func:`~.projection.triplanar_samples_lane`) or adds the samples' gradients into their texels
    (:func:`~.projection.triplanar_scatter_samples_lane`). Through Warp, the reads were a zeroed
    :data:`~.lane_reads` matrix returned and then copied into each native call that took them, with
    each projection's samples (10% of a normal-mapping forward and backward in ``perf``)."""

    def normal_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        write_lane(out, base, count, triplanar_normals_lane(args.faces, args.proj, args.normal_map, args.smp, pixels, base, count, lane_ints(args.layer)))

    def samples_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: samples_t):
        count = wp.min(out.weights.shape[0] - base, LANES)
        triplanar_samples_lane(args.faces, args.proj, args.smp, pixels, base, count, lane_ints(args.layer), out.samples, out.weights)

    def samples_grad_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, grads: FaceGrads, adj: samples_t):
        count = wp.min(adj.samples.shape[0] - base, LANES)
        triplanar_scatter_samples_lane(args.faces, grads, args.proj, args.smp, pixels, base, count, lane_ints(args.layer), adj.samples)

    return (
        inlined(specialised(normal_lane, "triplanar_normal_lane")),
        inlined(specialised(samples_lane, "triplanar_samples_lane")),
        inlined(specialised(samples_grad_lane, "triplanar_samples_grad_lane")),
    )


@functools.cache
def normal_lane_bodies(args_t, samples_t, stochastic: bool = False, faces: bool = False):
    """``(normal_lane, samples_lane, samples_grad_lane)``: the lane bodies of normal mapping, one
    texture per axis or per face (``faces``), and of the first step of its two-step gradient, which
    stores each projection's sample and the weights (``samples_t``:
    :class:`~.triplanar.ProjectionSamples`) and adds their texel gradients. Each reads the
    projections on the unit normal, as the bodies do (``triplanar_reads_lane``'s ``unit_normals``;
    with a texture per face, the face the unit normal looks at); the forward makes the normals
    from them natively (:func:`~.normals.surface_normals_lane`). Plain sampling, or a
    ``stochastic`` method: each projection's sample read over its footprint as stochastic colour
    reads it (:func:`~.stochastic.stochastic_read_lane`), its gradient added back through the same
    taps (``.scatter.scatter_projection_taps_lanes``; with the anisotropic filter,
    :func:`~.stochastic.scatter_stochastic_reads_lanes`; per face,
    :func:`~.stochastic.scatter_stochastic_face_reads_lanes`); a histogram's blend is not theirs
    (:func:`linear_blend_take`). Plain sampling with a texture per axis:
    :func:`plain_normal_lane_bodies`."""
    if not stochastic and not faces:
        return plain_normal_lane_bodies(args_t, samples_t)
    if faces:

        def face_samples(args: args_t, plus: lane_reads, minus: lane_reads, axis: wp.int32, count: wp.int32) -> lane_colours:
            """Row ``l``: lane pixel ``l``'s unweighted sample of projection ``axis`` on the face it
            reads (``plus``, ``minus``: the reads of the two sides), where its weight is positive."""
            f = args.faces
            layers = lane_ints(args.layer)
            value = lane_colours()
            if wp.static(stochastic):
                sp = stochastic_read_lane(on_axis(f.px, f.py, f.pz, axis), args.smp, args.stoch, layers, plus, axis, count)
                sm = stochastic_read_lane(on_axis(f.nx, f.ny, f.nz, axis), args.smp, args.stoch, layers, minus, axis, count)
                for l in range(count):
                    if plus[9 + axis, l] > 0.0:
                        value[l] = sp[l]
                    elif minus[9 + axis, l] > 0.0:
                        value[l] = sm[l]
            else:  # put in place (not added): the + face's sample, then the - face's where the pixel reads that one
                value = accumulate_footprint_lane(on_axis(f.px, f.py, f.pz, axis), args.smp, layers, plus[axis], plus[3 + axis], plus[6 + axis], plus[12 + axis], plus[15 + axis], plus[18 + axis], plus[9 + axis], 0, value)
                value = accumulate_footprint_lane(on_axis(f.nx, f.ny, f.nz, axis), args.smp, layers, minus[axis], minus[3 + axis], minus[6 + axis], minus[12 + axis], minus[15 + axis], minus[18 + axis], minus[9 + axis], 0, value)
            return value

        face_samples = inlined(specialised(face_samples, f"triplanar{'_stochastic' if stochastic else ''}_normal_face_samples"))

        def unit_normal_samples(args: args_t, pixels: SurfacePixels, base: wp.int32, count: wp.int32):
            """``(reads, sx, sy, sz)``: the lane's reads on the unit normal (each projection's weight
            whichever face it reads) and each projection's samples."""
            plus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 1, 1)
            minus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 1, 2)
            sx = face_samples(args, plus, minus, 0, count)
            sy = face_samples(args, plus, minus, 1, count)
            sz = face_samples(args, plus, minus, 2, count)
            reads = lane_reads()
            for axis in range(3):  # a pixel reads one face of each projection: the other's weight is 0
                for l in range(LANES):
                    reads[9 + axis, l] = plus[9 + axis, l] + minus[9 + axis, l]
            return reads, sx, sy, sz

        def scatter_samples(args: args_t, pixels: SurfacePixels, base: wp.int32, count: wp.int32, grads: FaceGrads, gx: lane_colours, gy: lane_colours, gz: lane_colours):
            """Each projection's own gradient (unweighted) added into the face it read."""
            plus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 1, 1)
            minus = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 1, 2)
            f = args.faces
            if wp.static(stochastic):
                scatter_stochastic_face_reads_lanes(f.px, f.nx, f.py, f.ny, f.pz, f.nz, grads.px, grads.nx, grads.py, grads.ny, grads.pz, grads.nz, args.smp, args.stoch, lane_ints(args.layer), plus, minus, 0, gx, gy, gz)
            else:
                scatter_face_reads_lanes(f.px, f.nx, f.py, f.ny, f.pz, f.nz, grads.px, grads.nx, grads.py, grads.ny, grads.pz, grads.nz, args.smp, lane_ints(args.layer), plus, minus, 0, gx, gy, gz)

    else:  # stochastic (plain sampling: plain_normal_lane_bodies)

        def unit_normal_samples(args: args_t, pixels: SurfacePixels, base: wp.int32, count: wp.int32):
            """``(reads, sx, sy, sz)``: the lane's reads on the unit normal and each projection's samples."""
            reads = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 1, 0)
            layers = lane_ints(args.layer)
            sx = stochastic_read_lane(args.faces.px, args.smp, args.stoch, layers, reads, 0, count)
            sy = stochastic_read_lane(args.faces.py, args.smp, args.stoch, layers, reads, 1, count)
            sz = stochastic_read_lane(args.faces.pz, args.smp, args.stoch, layers, reads, 2, count)
            return reads, sx, sy, sz

        def scatter_samples(args: args_t, pixels: SurfacePixels, base: wp.int32, count: wp.int32, grads: FaceGrads, gx: lane_colours, gy: lane_colours, gz: lane_colours):
            """Each projection's own gradient (unweighted) added back through its stochastic taps."""
            reads = triplanar_reads_lane(args.faces, args.proj, args.smp, pixels, base, count, 1, 0)
            faces = args.faces
            layers = lane_ints(args.layer)
            if args.smp.filter == FILTER_ANISOTROPIC:
                scatter_stochastic_reads_lanes(faces.px, faces.py, faces.pz, grads.px, grads.py, grads.pz, args.smp, args.stoch, layers, reads, 0, gx, gy, gz)
            else:
                tx = projection_taps_lane(args.stoch, reads, 0, count)
                ty = projection_taps_lane(args.stoch, reads, 1, count)
                tz = projection_taps_lane(args.stoch, reads, 2, count)
                scatter_projection_taps_lanes(faces.px, faces.py, faces.pz, grads.px, grads.py, grads.pz, args.smp, layers, tx, ty, tz, gx, gy, gz)

    kind = ("_stochastic" if stochastic else "") + ("_faces" if faces else "")
    unit_normal_samples = inlined(specialised(unit_normal_samples, f"triplanar{kind}_unit_normal_samples"))
    scatter_samples = inlined(specialised(scatter_samples, f"triplanar{kind}_scatter_samples"))

    def normal_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        reads, sx, sy, sz = unit_normal_samples(args, pixels, base, count)
        write_lane(out, base, count, surface_normals_lane(args.proj, args.normal_map, pixels, base, count, reads, sx, sy, sz))

    def samples_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, out: samples_t):
        count = wp.min(out.weights.shape[0] - base, LANES)
        reads, sx, sy, sz = unit_normal_samples(args, pixels, base, count)
        for l in range(count):
            i = base + l
            out.weights[i] = wp.vec3(reads[9, l], reads[10, l], reads[11, l])  # 0 where not covered, as the body leaves it
            for axis in range(3):
                value = wp.vec4(0.0)
                if reads[9 + axis, l] > 0.0:
                    value = pick3(sx[l], sy[l], sz[l], axis)
                out.samples[i, axis] = value

    def samples_grad_lane(args: args_t, pixels: SurfacePixels, base: wp.int32, grads: FaceGrads, adj: samples_t):
        count = wp.min(adj.samples.shape[0] - base, LANES)
        gx = lane_colours()
        gy = lane_colours()
        gz = lane_colours()
        for l in range(count):
            gx[l] = adj.samples[base + l, 0]
            gy[l] = adj.samples[base + l, 1]
            gz[l] = adj.samples[base + l, 2]
        scatter_samples(args, pixels, base, count, grads, gx, gy, gz)

    return (
        inlined(specialised(normal_lane, f"triplanar{kind}_normal_lane")),
        inlined(specialised(samples_lane, f"triplanar{kind}_samples_lane")),
        inlined(specialised(samples_grad_lane, f"triplanar{kind}_samples_grad_lane")),
    )


def linear_blend_take(args) -> bool:
    """Whether stochastic colour and normal mapping's lanes take a launch with ``args``
    (:class:`~.triplanar.TriplanarArgs`; ``Kernels.lanes_take``): a linear blend
    (:func:`~.stochastic.linear_blend`); a histogram's runs the one-pixel kernels, whose pixel
    bodies the lane modules then need not compile."""
    return linear_blend(args.stoch)


@functools.cache
def stored_lane_bodies(args_t, pixels_t, grads_t):
    """``(stored_lane, stored_grad_lane, covered)``: the lane bodies of the second step of normal
    mapping's two-step gradient (the normal made from the stored samples, and its gradient in them,
    natively: :mod:`.normals`), whose arguments are ``args_t``, ``pixels_t`` and ``grads_t``
    (:class:`~.normal_blend.NormalBlendArgs`, ``StoredSamples``, ``StoredSampleGrads``), and their
    lanes' ``covered`` (``family.lane_kernel``)."""

    def stored_lane(args: args_t, pixels: pixels_t, base: wp.int32, out: wp.array2d(dtype=float)):
        count = wp.min(out.shape[0] - base, LANES)
        write_lane(out, base, count, stored_normals_lane(args.proj, args.normal_map, pixels.normal, pixels.mask, pixels.weights, pixels.samples, base, count))

    def stored_grad_lane(args: args_t, pixels: pixels_t, base: wp.int32, grads: grads_t, adj: wp.array2d(dtype=float)):
        count = wp.min(adj.shape[0] - base, LANES)
        stored_normals_grad_lane(args.proj, args.normal_map, pixels.normal, pixels.mask, pixels.weights, pixels.samples, base, count, adj, grads.samples)

    def covered(pixels: pixels_t, base: wp.int32, count: wp.int32) -> bool:
        return lane_covered(pixels.mask, base, count)

    return (
        inlined(specialised(stored_lane, "triplanar_stored_lane")),
        inlined(specialised(stored_grad_lane, "triplanar_stored_grad_lane")),
        inlined(specialised(covered, "triplanar_stored_covered")),
    )
