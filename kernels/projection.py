"""Plane projections: the building blocks of triplanar and biplanar mapping, shared by the
triplanar kernels and by splat layers mapped triplanar.

A surface point ``p`` with normal ``n`` is projected onto the three axis planes (``p.zy`` for the
X plane, ``p.xz`` for Y, ``p.xy`` for Z); each projection is sampled and the samples are blended
with weights that favour the plane the surface faces: ``w = |n|^k / Σ |n|^k`` (triplanar), or
Quilez' biplanar weights, exactly zero on the minor axis.

**Handedness of the mirror fix.** A plane projection seen from its back side reads mirrored, so the
``u`` axis of each plane is flipped by the sign of the normal. Golus ("Normal Mapping for a
Triplanar Shader", 2017) writes ``uvX.x *= sign(n.x)``, ``uvY.x *= sign(n.y)``,
``uvZ.x *= -sign(n.z)`` for Unity's left-handed world; in warptex's right-handed world those mirror
*every* face. warptex therefore uses their negation, ``-sign(n.x)``, ``-sign(n.y)``, ``+sign(n.z)``
(with ``sign(0) = +1``): seen from outside, every face then reads the right way round and
``(dp/du, dp/dv, n)`` is a right-handed frame, which is what tangent-space normal maps assume.
(The two conventions differ by one global mirror of ``u``.)

**Level of detail.** Each projection has its own footprint: its UV derivatives are the plane
components of the G-buffer's ``position_dx``/``position_dy`` times its tiling, so a wall and the
ground beside it pick their own mip levels (and, filtered anisotropically, their own axes).
"""

import warp as wp

from . import out_of_line
from .normals import FLOAT_MAX, sign_or_one, unsquared
from .filters import sample_footprint_derivatives
from .footprint import lod_scale_slope, texture_footprint
from .stochastic import StochasticArgs, sample_stochastic_outlined
from .texels import SamplerArgs, TextureView

# How the three projections are weighted.
WEIGHTS_TRIPLANAR = wp.constant(0)  # pow(|n|, sharpness), normalised
WEIGHTS_BIPLANAR = wp.constant(1)  # Quilez: major and median axes, remapped, normalised

# Quilez' biplanar remap: 1/sqrt(3), the smallest possible major component of a unit normal.
BIPLANAR_EDGE = wp.constant(0.5773)
# Weights are normalised by max(sum, WEIGHT_EPS); only a zero or non-finite normal gets near it.
WEIGHT_EPS = wp.constant(1.0e-20)


@wp.struct
class ProjectionArgs:
    """Where the three plane projections read, as kernels see it (packed by ``warptex._pack``).

    ``tiling`` holds 1 value (all planes) or 3 (X, Y, Z planes); ``offsets`` is ``(3, 2)``, a UV
    offset per plane; ``sharpness`` holds 1 value. They are arrays so that a ``wp.Tape`` can carry
    gradients into them. ``world_to_object`` / ``normal_to_object`` take the G-buffer's world-space
    position and normal into the space that is projected when ``object_space`` is set.
    """

    tiling: wp.array(dtype=float)
    offsets: wp.array2d(dtype=float)
    sharpness: wp.array(dtype=float)
    world_to_object: wp.mat44
    normal_to_object: wp.mat33
    normal_to_world: wp.mat33
    object_space: wp.int32  # 0: world space, the matrices are identities and are skipped
    mirror_fix: wp.int32
    weights: wp.int32
    origin: wp.vec3d  # the projected space's coordinates of the G-buffer's origin (its positions are relative to it)
    origin_mode: wp.int32  # ORIGIN_NONE, ORIGIN_FOLDED or ORIGIN_EXACT: how origin_uv adds it


# How plane UVs add the G-buffer's float64 origin (camera-relative positions, far from the world origin).
ORIGIN_NONE = wp.constant(0)  # the origin is the world origin: nothing to add
ORIGIN_FOLDED = wp.constant(1)  # origin × tiling less whole multiples of 2 (the period of wrap and mirror), in float64
ORIGIN_EXACT = wp.constant(2)  # origin × tiling, in float64, rounded to float32 (clamp, border: no period)


@wp.func
def origin_uv(proj: ProjectionArgs, axis: wp.int32, tiling: float) -> wp.vec2:
    """What the origin adds to projection ``axis``'s plane coordinates × ``tiling``, computed in
    float64 so that far from the world origin whole texture periods leave before float32 does
    (its derivative along the tiling is the origin's plane coordinates, as it should be)."""
    uv = wp.vec2(0.0)
    if proj.origin_mode != ORIGIN_NONE:
        a = proj.origin[0]
        b = proj.origin[1]
        if axis == 0:
            a = proj.origin[2]
        elif axis == 1:
            b = proj.origin[2]
        t = wp.float64(tiling)
        u = a * t
        v = b * t
        if proj.origin_mode == ORIGIN_FOLDED:
            u = u - wp.floor(u * wp.float64(0.5)) * wp.float64(2.0)
            v = v - wp.floor(v * wp.float64(0.5)) * wp.float64(2.0)
        uv = wp.vec2(wp.float32(u), wp.float32(v))
    return uv


@wp.func
def slope_coords(proj: ProjectionArgs, p: wp.vec3, axis: wp.int32) -> wp.vec2:
    """The plane coordinates of the whole position (origin included): what a plane UV moves by per unit of tiling."""
    o = wp.vec3(wp.float32(proj.origin[0]), wp.float32(proj.origin[1]), wp.float32(proj.origin[2]))
    return plane_coords(p + o, axis)


@wp.struct
class SurfacePixels:
    """The per-pixel G-buffer arrays a planar projection reads: world position, its screen-space
    derivatives, normal, and the coverage mask (0: not shaded)."""

    position: wp.array(dtype=wp.vec3)
    position_dx: wp.array(dtype=wp.vec3)
    position_dy: wp.array(dtype=wp.vec3)
    normal: wp.array(dtype=wp.vec3)
    mask: wp.array(dtype=float)


@wp.func
def plane_coords(v: wp.vec3, axis: wp.int32) -> wp.vec2:
    """The plane components of ``v`` for projection ``axis``: ``v.zy``, ``v.xz`` or ``v.xy``."""
    c = wp.vec2(v[0], v[1])
    if axis == 0:
        c = wp.vec2(v[2], v[1])
    elif axis == 1:
        c = wp.vec2(v[0], v[2])
    return c


@wp.func
def u_sign(n: wp.vec3, axis: wp.int32, mirror_fix: wp.int32) -> float:
    """Direction of the plane's ``u`` along its first world axis: the (right-handed) mirror fix."""
    s = 1.0
    if mirror_fix != 0:
        if axis == 2:
            s = sign_or_one(n[2])
        else:
            s = -sign_or_one(n[axis])
    return s


@wp.func
def projection_tiling(proj: ProjectionArgs, axis: wp.int32) -> float:
    return proj.tiling[wp.min(axis, proj.tiling.shape[0] - 1)]


@wp.func
def plane_uv(proj: ProjectionArgs, axis: wp.int32, p: wp.vec3, n: wp.vec3, tiling: float) -> wp.vec2:
    """UV of projection ``axis`` at ``tiling``: plane coordinates × tiling, ``u`` mirror-fixed, plus the offset."""
    c = plane_coords(p, axis) * tiling + origin_uv(proj, axis, tiling)
    return wp.vec2(c[0] * u_sign(n, axis, proj.mirror_fix) + proj.offsets[axis, 0], c[1] + proj.offsets[axis, 1])


@wp.func
def plane_derivative(proj: ProjectionArgs, axis: wp.int32, n: wp.vec3, dp: wp.vec3, tiling: float) -> wp.vec2:
    """The UV derivative of projection ``axis`` at ``tiling`` along a position derivative ``dp``
    (the offset drops out; the mirror fix flips ``u``)."""
    c = plane_coords(dp, axis) * tiling
    return wp.vec2(c[0] * u_sign(n, axis, proj.mirror_fix), c[1])


@wp.func
def plane_footprint(tex: TextureView, proj: ProjectionArgs, axis: wp.int32, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, tiling: float, smp: SamplerArgs) -> wp.vec4:
    """The filter footprint (``warptex.kernels.sampling``) of projection ``axis`` at ``tiling``,
    from its own UV derivatives."""
    return texture_footprint(tex, plane_derivative(proj, axis, n, dpdx, tiling), plane_derivative(proj, axis, n, dpdy, tiling), smp)


@wp.func
def plane_sample_slope(tex: TextureView, layer: wp.int32, proj: ProjectionArgs, axis: wp.int32, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, tiling: float, smp: SamplerArgs):
    """``(value, d value / d tiling, d value / du, d value / dv)`` of plain sampling of projection
    ``axis`` at ``tiling``: the UV moves by the (mirror-fixed) plane coordinates, the LOD by
    ``1 / (tiling ln 2)`` and an anisotropic footprint's steps in proportion to ``tiling``. The UV
    slopes are also the slopes along the projection's offset (:func:`plane_uv` adds it as it is)."""
    value, d_u, d_v, d_lod, d_spread = sample_footprint_derivatives(tex, layer, plane_uv(proj, axis, p, n, tiling), plane_footprint(tex, proj, axis, n, dpdx, dpdy, tiling, smp), smp)
    c = slope_coords(proj, p, axis)
    lod_slope = lod_scale_slope(tex, plane_coords(dpdx, axis), plane_coords(dpdy, axis), tiling)
    return value, d_u * (c[0] * u_sign(n, axis, proj.mirror_fix)) + d_v * c[1] + d_lod * lod_slope + d_spread / tiling, d_u, d_v


@wp.func
def projection_uv(proj: ProjectionArgs, axis: wp.int32, p: wp.vec3, n: wp.vec3) -> wp.vec2:
    return plane_uv(proj, axis, p, n, projection_tiling(proj, axis))


@wp.func
def projection_footprint(tex: TextureView, proj: ProjectionArgs, axis: wp.int32, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs) -> wp.vec4:
    return plane_footprint(tex, proj, axis, n, dpdx, dpdy, projection_tiling(proj, axis), smp)


# Integer exponents below this are raised by multiplication (power_weight).
MAX_INT_EXPONENT = wp.constant(32)


@wp.func
def power_weight(r: float, exponent: float) -> float:
    """``r^exponent`` for ``r`` in ``[0, 1]``, with ``0^0 = 1`` and no ``log 0`` in the gradient.

    Integer exponents from 1 to 31 (the usual sharpness values) are raised by multiplying ``r``'s
    squares, which is at least as accurate as ``exp(exponent · log r)`` and made the triplanar
    forward 5% faster; others take ``exp`` and ``log``. The gradient
    (:func:`adj_power_weight`) is the same on both paths.
    """
    w = 0.0
    if exponent == 0.0:
        w = 1.0
    elif r > 0.0:
        k = int(exponent)
        if float(k) == exponent and k > 0 and k < MAX_INT_EXPONENT:
            r2 = r * r
            r4 = r2 * r2
            r8 = r4 * r4
            w = wp.where((k & 1) != 0, r, 1.0) * wp.where((k & 2) != 0, r2, 1.0) * wp.where((k & 4) != 0, r4, 1.0)
            w = w * wp.where((k & 8) != 0, r8, 1.0) * wp.where((k & 16) != 0, r8 * r8, 1.0)
        else:
            w = wp.exp(exponent * wp.log(r))
    return w


@wp.func_grad(power_weight)
def adj_power_weight(r: float, exponent: float, adj_w: float):
    """``d r^e / d r = e r^e / r`` and ``d r^e / d e = r^e ln r`` for ``r > 0`` (the exponent's
    slope at ``e = 0`` included, so a sharpness fitted from 0 can move); nothing at ``r = 0``."""
    if r > 0.0:
        w = power_weight(r, exponent)
        wp.adjoint[r] += adj_w * exponent * w / r
        wp.adjoint[exponent] += adj_w * w * wp.log(r)


@wp.func
def triplanar_weights(n: wp.vec3, sharpness: float) -> wp.vec3:
    """``pow(|n|, sharpness)`` normalised to sum 1; zero for a zero or non-finite normal.

    ``|n|`` is first divided by its largest component, which leaves the normalised weights
    unchanged but keeps ``pow`` from underflowing at high sharpness.
    """
    a = wp.vec3(wp.abs(n[0]), wp.abs(n[1]), wp.abs(n[2]))
    m = wp.max(a)
    w = wp.vec3(0.0)
    if wp.isfinite(n) and m > 0.0:
        w = wp.vec3(power_weight(a[0] / m, sharpness), power_weight(a[1] / m, sharpness), power_weight(a[2] / m, sharpness))
        w = w / wp.max(w[0] + w[1] + w[2], WEIGHT_EPS)
    return w


@wp.func
def biplanar_pair(major: float, median: float, exponent: float) -> wp.vec2:
    """The unnormalised biplanar weights of the major and median axes (their ``|n|`` components):
    ``clamp((a - 0.5773) / (1 - 0.5773), 0, 1)^exponent``. Where both powers underflow (high
    sharpness) each base is first divided by the larger, which leaves the normalised weights as
    they are; where both bases are 0 (a normal on the diagonal) the weights are equal, their limit."""
    b0 = wp.clamp((major - BIPLANAR_EDGE) / (1.0 - BIPLANAR_EDGE), 0.0, 1.0)
    b1 = wp.clamp((median - BIPLANAR_EDGE) / (1.0 - BIPLANAR_EDGE), 0.0, 1.0)
    w = wp.vec2(power_weight(b0, exponent), power_weight(b1, exponent))
    if w[0] + w[1] < WEIGHT_EPS:
        m = wp.max(b0, b1)
        if m > 0.0:
            w = wp.vec2(power_weight(b0 / m, exponent), power_weight(b1 / m, exponent))
        else:
            w = wp.vec2(1.0, 1.0)
    return w


@wp.func
def biplanar_axes(n: wp.vec3):
    """``(major, median, minor)`` of :func:`biplanar_weights`: the major and median components of
    the unit normal's ``|n|``, and the minor axis' index (the smallest component, the highest index
    among ties); ``minor = -1`` for a zero or non-finite normal, which has no weights."""
    u = n
    length = wp.length(n)
    if length > FLOAT_MAX:  # |n|² overflowed
        u = unsquared(n)
        length = wp.length(u)
    major = float(0.0)
    median = float(0.0)
    minor = int(-1)
    if wp.isfinite(n) and length > 0.0:
        a = wp.vec3(wp.abs(u[0]), wp.abs(u[1]), wp.abs(u[2])) / length
        if a[2] <= a[0] and a[2] <= a[1]:
            major = a[0]
            median = a[1]
            minor = 2
        elif a[1] <= a[0]:
            major = a[0]
            median = a[2]
            minor = 1
        else:
            major = a[1]
            median = a[2]
            minor = 0
    return major, median, minor


@wp.func
def biplanar_spread(pair: wp.vec2, minor: wp.int32) -> wp.vec3:
    """The major and median axes' values ``pair`` in their places, 0 on the ``minor`` axis."""
    v = wp.vec3(0.0, pair[0], pair[1])
    if minor == 2:
        v = wp.vec3(pair[0], pair[1], 0.0)
    elif minor == 1:
        v = wp.vec3(pair[0], 0.0, pair[1])
    return v


@wp.func
def biplanar_weights(n: wp.vec3, sharpness: float) -> wp.vec3:
    """Quilez' biplanar weights: major and median axes get ``clamp((|n| - 0.5773) / (1 - 0.5773), 0, 1)^(k/8)``
    (:func:`biplanar_pair`), the minor axis 0, normalised to sum 1. Zero for a zero or non-finite
    normal.

    The normal is normalised first (the remap assumes unit length). The minor axis is the smallest
    component (the highest index among ties). Swapping tied major and median axes changes nothing;
    a median tied with the minor is at most 1/sqrt(3), where the remap is below 1.2e-4 (zero
    except near the exact diagonal), so the weights are continuous up to that.
    """
    w = wp.vec3(0.0)
    major, median, minor = biplanar_axes(n)
    if minor >= 0:
        w = biplanar_spread(biplanar_pair(major, median, sharpness / 8.0), minor)
        w = w / wp.max(w[0] + w[1] + w[2], WEIGHT_EPS)
    return w


@wp.func
def projection_weights(proj: ProjectionArgs, n: wp.vec3) -> wp.vec3:
    w = wp.vec3(0.0)
    if proj.weights == WEIGHTS_BIPLANAR:
        w = biplanar_weights(n, proj.sharpness[0])
    else:
        w = triplanar_weights(n, proj.sharpness[0])
    return w


@wp.func
def object_space(proj: ProjectionArgs, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3):
    """Position, normal and position derivatives in the projected space (skipping the identity
    transforms of world space measured 4% of a triplanar sample's time)."""
    if proj.object_space == 0:
        return p, n, dpdx, dpdy
    m = proj.world_to_object
    return (
        wp.transform_point(m, p),
        proj.normal_to_object * n,
        wp.transform_vector(m, dpdx),
        wp.transform_vector(m, dpdy),
    )


@wp.func
def surface(proj: ProjectionArgs, pixels: SurfacePixels, i: wp.int32):
    """Pixel ``i``'s ``(p, n, dpdx, dpdy)`` in the projected space (:func:`object_space`)."""
    return object_space(proj, pixels.position[i], pixels.normal[i], pixels.position_dx[i], pixels.position_dy[i])


# -- out of line, for the generated-adjoint kernels ---------------------------------------------------


@out_of_line
def surface_frame(proj: ProjectionArgs, position: wp.vec3, normal: wp.vec3, position_dx: wp.vec3, position_dy: wp.vec3):
    """``(p, n, dpdx, dpdy, w)``: :func:`object_space` and the projections' weights, out of line."""
    p, n, dpdx, dpdy = object_space(proj, position, normal, position_dx, position_dy)
    return p, n, dpdx, dpdy, projection_weights(proj, n)


@out_of_line
def projection_sample(
    tex: TextureView,
    layer: wp.int32,
    proj: ProjectionArgs,
    axis: wp.int32,
    p: wp.vec3,
    n: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    tiling: float,
    smp: SamplerArgs,
    stoch: StochasticArgs,
) -> wp.vec4:
    """Projection ``axis`` of ``tex`` at ``tiling``, over its own footprint, sampled as ``stoch`` says, out of line."""
    return sample_stochastic_outlined(tex, layer, plane_uv(proj, axis, p, n, tiling), plane_footprint(tex, proj, axis, n, dpdx, dpdy, tiling, smp), smp, stoch)
