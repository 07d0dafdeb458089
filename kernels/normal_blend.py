"""Triplanar normal mapping's blend of projected normals: each projection's normal in world axes,
their weighted blend normalised, and the second step of the two-step gradient (``Staged`` in
:mod:`warptex.kernels.triplanar`): the normal made from the stored samples and weights, with a
hand-written gradient in the samples (Warp's generated adjoint of the same body cost four times its
forward pass) and in the sharpness, through the weights. The second step's kernels are a Warp module
of their own (they run only where gradients are recorded), and their CPU lanes another.
"""

import functools

import warp as wp

from . import inlined
from .family import Kernels, lane_kernel, pixel_kernels
from .lanes.triplanar import sharpness_lanes_take, stored_lane_bodies
from .native import use
from .normals import NormalMapArgs, blend_projected, blend_projected_grad, decode_normal, decode_normal_grad, direction, direction_grad, to_world
from .projection import ProjectionArgs, plane_coords, u_sign
from .slopes import projection_weights_slope

MODULE = use("warptex.triplanar.normal.blend")


@wp.struct
class NormalBlendArgs:
    """What the normal made from stored samples reads (filled by name from
    :class:`~.triplanar.TriplanarArgs`)."""

    proj: ProjectionArgs
    normal_map: NormalMapArgs


@wp.struct
class StoredSamples:
    """The per-pixel inputs of the normal made from stored samples: the G-buffer's normal and mask
    and the intermediates of :class:`~.triplanar.ProjectionSamples`."""

    normal: wp.array(dtype=wp.vec3)
    mask: wp.array(dtype=float)
    samples: wp.array2d(dtype=wp.vec4)
    weights: wp.array(dtype=wp.vec3)


@wp.struct
class StoredSampleGrads:
    """What the gradient of the normal made from stored samples adds into: the samples' gradient,
    and the sharpness' (through the weights, which carry no gradient of their own:
    :func:`~.triplanar._sample_shapes`); empty: not needed."""

    samples: wp.array2d(dtype=wp.vec4)
    sharpness: wp.array(dtype=float)


@wp.func
def projected_normal(texel: wp.vec4, axis: wp.int32, n: wp.vec3, proj: ProjectionArgs, nm: NormalMapArgs) -> wp.vec3:
    """Projection ``axis``' normal in world-aligned axes (unweighted): ``texel`` decoded, its ``x``
    mirror-fixed, blended with the unit surface normal ``n`` in the projection's frame, swizzled back."""
    t = decode_normal(texel, nm.channels, nm.strength, nm.flip_green)
    t = wp.vec3(t[0] * u_sign(n, axis, proj.mirror_fix), t[1], t[2])
    base = plane_coords(n, axis)
    return to_world(blend_projected(t, wp.vec3(base[0], base[1], n[axis]), nm.blend), axis)


@wp.func
def projected_normal_grad(texel: wp.vec4, axis: wp.int32, n: wp.vec3, proj: ProjectionArgs, nm: NormalMapArgs, g: wp.vec3) -> wp.vec4:
    """The gradient of :func:`projected_normal` in ``texel`` for the result's gradient ``g`` (the
    swizzle back to world axes is its own inverse, so it also takes ``g`` to the projection's frame)."""
    s = u_sign(n, axis, proj.mirror_fix)
    base = plane_coords(n, axis)
    gt = blend_projected_grad(wp.vec3(base[0], base[1], n[axis]), nm.blend, to_world(g, axis))
    return decode_normal_grad(texel, nm.channels, nm.strength, nm.flip_green, wp.vec3(gt[0] * s, gt[1], gt[2]))


@wp.func
def unit_normal(total: wp.vec3, n: wp.vec3, proj: ProjectionArgs) -> wp.vec3:
    """The blended normal ``total`` in world space, normalised; the surface normal ``n`` where the
    blend cancels out; ``(0, 0, 0)`` where both are zero or non-finite."""
    world = proj.normal_to_world * total
    surface_normal = proj.normal_to_world * n
    result = wp.vec3(0.0)
    if wp.length(world) > 1.0e-12 and wp.isfinite(world):
        result = direction(world)
    elif wp.length(surface_normal) > 0.0 and wp.isfinite(surface_normal):
        result = direction(surface_normal)
    return result


@wp.func
def unit_normal_grad(total: wp.vec3, proj: ProjectionArgs, g: wp.vec3) -> wp.vec3:
    """The gradient of :func:`unit_normal` in the blended normal ``total`` for the result's gradient
    ``g``: 0 where the blend cancels out (the surface normal does not depend on it)."""
    world = proj.normal_to_world * total
    result = wp.vec3(0.0)
    if wp.length(world) > 1.0e-12 and wp.isfinite(world):
        result = wp.transpose(proj.normal_to_world) * direction_grad(world, g)
    return result


@wp.func
def unit_base_normal(n: wp.vec3) -> wp.vec3:
    """``n`` normalised when it has a length: the blends assume a unit base normal (object space may scale it)."""
    result = n
    if wp.length(n) > 0.0:
        result = direction(n)
    return result


@wp.func
def write_normal(out: wp.array2d(dtype=float), i: wp.int32, value: wp.vec3):
    out[i, 0] = value[0]
    out[i, 1] = value[1]
    out[i, 2] = value[2]


@wp.func
def stored_blend(args: NormalBlendArgs, pixels: StoredSamples, i: wp.int32):
    """``(w, n, total)``: covered pixel ``i``'s stored weights, unit surface normal and blend of its
    projections' normals (made from the stored samples), before the blend is normalised."""
    w = pixels.weights[i]
    n = unit_base_normal(args.proj.normal_to_object * pixels.normal[i])
    total = wp.vec3(0.0)
    for axis in range(3):
        if w[axis] > 0.0:
            total += w[axis] * projected_normal(pixels.samples[i, axis], axis, n, args.proj, args.normal_map)
    return w, n, total


@inlined
def normal_from_samples(args: NormalBlendArgs, pixels: StoredSamples, i: wp.int32, out: wp.array2d(dtype=float)):
    """The normal-mapping body with each projection's sample and weight read from the stored ones
    (the weights take no gradient of their own, the sharpness' reaches through them in
    :func:`normal_from_samples_grad`: this runs only where the G-buffer needs none)."""
    result = wp.vec3(0.0)
    if pixels.mask[i] != 0.0:
        w, n, total = stored_blend(args, pixels, i)
        result = unit_normal(total, n, args.proj)
    write_normal(out, i, result)


@inlined
def normal_from_samples_grad(args: NormalBlendArgs, pixels: StoredSamples, i: wp.int32, grads: StoredSampleGrads, adj: wp.array2d(dtype=float)):
    """The hand-written gradient of :func:`normal_from_samples` in the stored samples, added into
    ``grads.samples`` (Warp's generated adjoint of the same body cost four times its forward), and
    in the sharpness through each weight ``w_a`` of the blend ``total = Σ w_a · normal_a``:
    ``dot(g_total, normal_a) · d w_a / d sharpness`` (:func:`~.slopes.projection_weights_slope` of
    the normal the first step weighed), added into ``grads.sharpness`` projection by projection."""
    if pixels.mask[i] != 0.0 and (grads.samples.shape[0] > 0 or grads.sharpness.shape[0] > 0):
        w, n, total = stored_blend(args, pixels, i)
        g = unit_normal_grad(total, args.proj, wp.vec3(adj[i, 0], adj[i, 1], adj[i, 2]))
        dw = wp.vec3(0.0)
        if grads.sharpness.shape[0] > 0:
            weighed = pixels.normal[i]  # projection.object_space's normal, as the first step's weights read it
            if args.proj.object_space != 0:
                weighed = args.proj.normal_to_object * weighed
            dw = projection_weights_slope(args.proj, weighed)
        for axis in range(3):
            if w[axis] > 0.0:
                if grads.samples.shape[0] > 0:
                    grads.samples[i, axis] = grads.samples[i, axis] + projected_normal_grad(pixels.samples[i, axis], axis, n, args.proj, args.normal_map, w[axis] * g)
                if grads.sharpness.shape[0] > 0:
                    wp.atomic_add(grads.sharpness, 0, dw[axis] * wp.dot(g, projected_normal(pixels.samples[i, axis], axis, n, args.proj, args.normal_map)))


@functools.cache
def normal_from_samples_kernels() -> Kernels:
    """The second step of the two-step normal, one pair of kernels for every configuration, with its
    hand-written gradient in the stored samples, in a module of its own (it runs only where
    gradients are recorded), and their CPU lanes in another."""
    module = MODULE
    forward, texel_grad, _ = pixel_kernels("triplanar_normal_blend", module=module, grad_module=module, args=NormalBlendArgs, pixels=StoredSamples,
                                           out=wp.array2d(dtype=float), body=normal_from_samples, scatter=normal_from_samples_grad, grads=StoredSampleGrads)  # fmt: skip
    lane, grad_lane, covered = stored_lane_bodies(NormalBlendArgs, StoredSamples, StoredSampleGrads)
    lanes = lane_kernel(lane, NormalBlendArgs, StoredSamples, wp.array2d(dtype=float), module=module, name="triplanar_normal_blend_lanes", covered=covered)
    grad_lanes = lane_kernel(grad_lane, NormalBlendArgs, StoredSamples, wp.array2d(dtype=float), grads_t=StoredSampleGrads, module=module, name="triplanar_normal_blend_texel_grad_lanes", covered=covered)
    return Kernels(forward, texel_grad, grads=("pixels.samples", "args.proj.sharpness"), lanes=lanes, texel_grad_lanes=grad_lanes, grad_lanes_take=sharpness_lanes_take)
