"""Triplanar and biplanar mapping, and triplanar normal mapping, per pixel over a G-buffer.

A surface point ``p`` with normal ``n`` is textured by projecting it onto the three axis planes
(``p.zy`` for the X plane, ``p.xz`` for Y, ``p.xy`` for Z), sampling each projection, and blending
the samples with weights that favour the plane the surface faces. Biplanar mapping (Quilez) uses
only the major and median axes: it is triplanar with a weight function that is exactly zero on the
minor axis, and the kernels skip zero-weight taps, so it reads at most two projections.

**Handedness of the mirror fix.** A plane projection seen from its back side reads mirrored, so the
``u`` axis of each plane is flipped by the sign of the normal. Golus' signs (``uvX.x *= sign(n.x)``,
``uvY.x *= sign(n.y)``, ``uvZ.x *= -sign(n.z)``, DESIGN.md §3) are written for Unity's left-handed
world; in warptex's right-handed world they mirror *every* face. warptex therefore uses their
negation, ``-sign(n.x)``, ``-sign(n.y)``, ``+sign(n.z)`` (with ``sign(0) = +1``): seen from outside,
every face then reads the right way round and ``(dp/du, dp/dv, n)`` is a right-handed frame, which
is what tangent-space normal maps assume. (The two conventions differ by one global mirror of ``u``.)

**Level of detail.** Each projection has its own footprint: its UV derivatives are the plane
components of the G-buffer's ``position_dx``/``position_dy`` times its tiling, so a wall and the
ground beside it pick their own mip levels.
"""

import warp as wp

from .normals import blend_projected, decode_normal, sign_or_one, to_world
from .sampling import Sampler, TextureView, lod_from_derivatives, lod_scale_slope, read_channels, sample_lod, sample_lod_derivatives, splat_lod, write_channels
from .stochastic import StochasticParams, sample_stochastic, splat_stochastic

# How the three projections are weighted.
WEIGHTS_TRIPLANAR = wp.constant(0)  # pow(|n|, sharpness), normalised
WEIGHTS_BIPLANAR = wp.constant(1)  # Quilez: major and median axes, remapped, normalised

# Quilez' biplanar remap: 1/sqrt(3), the smallest possible major component of a unit normal.
BIPLANAR_EDGE = wp.constant(0.5773)
# Weights are normalised by max(sum, WEIGHT_EPS); only a zero or non-finite normal gets near it.
WEIGHT_EPS = wp.constant(1.0e-20)


@wp.struct
class Projection:
    """Where the three plane projections read, shared by every triplanar kernel.

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
def projection_tiling(proj: Projection, axis: wp.int32) -> float:
    return proj.tiling[wp.min(axis, proj.tiling.shape[0] - 1)]


@wp.func
def plane_uv(proj: Projection, axis: wp.int32, p: wp.vec3, n: wp.vec3, tiling: float) -> wp.vec2:
    """UV of projection ``axis`` at ``tiling``: plane coordinates × tiling, ``u`` mirror-fixed, plus the offset."""
    c = plane_coords(p, axis) * tiling
    return wp.vec2(c[0] * u_sign(n, axis, proj.mirror_fix) + proj.offsets[axis, 0], c[1] + proj.offsets[axis, 1])


@wp.func
def plane_lod(tex: TextureView, axis: wp.int32, dpdx: wp.vec3, dpdy: wp.vec3, tiling: float) -> float:
    """Level of detail of projection ``axis`` at ``tiling``, from its own footprint (signs do not matter)."""
    return lod_from_derivatives(tex, plane_coords(dpdx, axis) * tiling, plane_coords(dpdy, axis) * tiling)


@wp.func
def plane_sample_slope(tex: TextureView, layer: wp.int32, proj: Projection, axis: wp.int32, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, tiling: float, smp: Sampler):
    """``(value, d value / d tiling)`` of plain sampling of projection ``axis`` at ``tiling``: the
    UV moves by the (mirror-fixed) plane coordinates, the LOD by ``1 / (tiling ln 2)``."""
    value, d_u, d_v, d_lod = sample_lod_derivatives(tex, layer, plane_uv(proj, axis, p, n, tiling), plane_lod(tex, axis, dpdx, dpdy, tiling), smp)
    c = plane_coords(p, axis)
    lod_slope = lod_scale_slope(tex, plane_coords(dpdx, axis), plane_coords(dpdy, axis), tiling)
    return value, d_u * (c[0] * u_sign(n, axis, proj.mirror_fix)) + d_v * c[1] + d_lod * lod_slope


@wp.func
def projection_uv(proj: Projection, axis: wp.int32, p: wp.vec3, n: wp.vec3) -> wp.vec2:
    return plane_uv(proj, axis, p, n, projection_tiling(proj, axis))


@wp.func
def projection_lod(tex: TextureView, proj: Projection, axis: wp.int32, dpdx: wp.vec3, dpdy: wp.vec3) -> float:
    return plane_lod(tex, axis, dpdx, dpdy, projection_tiling(proj, axis))


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
def biplanar_remap(a: float, exponent: float) -> float:
    return power_weight(wp.clamp((a - BIPLANAR_EDGE) / (1.0 - BIPLANAR_EDGE), 0.0, 1.0), exponent)


@wp.func
def biplanar_weights(n: wp.vec3, sharpness: float) -> wp.vec3:
    """Quilez' biplanar weights: major and median axes get ``clamp((|n| - 0.5773) / (1 - 0.5773), 0, 1)^(k/8)``,
    the minor axis 0, normalised to sum 1. Zero for a zero or non-finite normal.

    The normal is normalised first (the remap assumes unit length). The minor axis is the smallest
    component (the highest index among ties). Swapping tied major and median axes changes nothing;
    a median tied with the minor is at most 1/sqrt(3), where the remap is below 1.2e-4 (zero
    except near the exact diagonal), so the weights are continuous up to that.
    """
    w = wp.vec3(0.0)
    length = wp.length(n)
    if wp.isfinite(n) and length > 0.0:
        a = wp.vec3(wp.abs(n[0]), wp.abs(n[1]), wp.abs(n[2])) / length
        e = sharpness / 8.0
        if a[2] <= a[0] and a[2] <= a[1]:
            w = wp.vec3(biplanar_remap(a[0], e), biplanar_remap(a[1], e), 0.0)
        elif a[1] <= a[0]:
            w = wp.vec3(biplanar_remap(a[0], e), 0.0, biplanar_remap(a[2], e))
        else:
            w = wp.vec3(0.0, biplanar_remap(a[1], e), biplanar_remap(a[2], e))
        w = w / wp.max(w[0] + w[1] + w[2], WEIGHT_EPS)
    return w


@wp.func
def projection_weights(proj: Projection, n: wp.vec3) -> wp.vec3:
    w = wp.vec3(0.0)
    if proj.weights == WEIGHTS_BIPLANAR:
        w = biplanar_weights(n, proj.sharpness[0])
    else:
        w = triplanar_weights(n, proj.sharpness[0])
    return w


@wp.func
def object_space(proj: Projection, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3):
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
def triplanar_sample(
    tex: TextureView,
    layer: wp.int32,
    proj: Projection,
    w: wp.vec3,
    p: wp.vec3,
    n: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    tiling: float,
    smp: Sampler,
    stoch: StochasticParams,
) -> wp.vec4:
    """One texture layer read through all three projections at ``tiling``, blended by ``w``
    (zero-weight projections are not sampled; each is sampled as ``stoch`` says): the building
    block of triplanar splat layers."""
    value = wp.vec4(0.0)
    for axis in range(3):
        if w[axis] > 0.0:
            value += w[axis] * sample_stochastic(tex, layer, plane_uv(proj, axis, p, n, tiling), plane_lod(tex, axis, dpdx, dpdy, tiling), smp, stoch)
    return value


@wp.func
def axis_texture(tex_x: TextureView, tex_y: TextureView, tex_z: TextureView, axis: wp.int32) -> TextureView:
    """Projection ``axis``' texture: X ``tex_x``, Y ``tex_y``, Z ``tex_z`` (chosen, then sampled by
    one call: three inlined copies of the sampling code measured slower)."""
    tex = tex_x
    if axis == 1:
        tex = tex_y
    elif axis == 2:
        tex = tex_z
    return tex


@wp.func
def sample_one(
    tex: TextureView, layer: wp.int32, axis: wp.int32, proj: Projection, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: Sampler, stoch: StochasticParams
) -> wp.vec4:
    """Projection ``axis`` of ``tex`` at the projection's own LOD, sampled as ``stoch`` says
    (plain trilinear for ``METHOD_NONE``; the stochastic taps all use the unperturbed LOD)."""
    lod = projection_lod(tex, proj, axis, dpdx, dpdy)
    return sample_stochastic(tex, layer, projection_uv(proj, axis, p, n), lod, smp, stoch)


@wp.func
def sample_one_plain(
    tex: TextureView, layer: wp.int32, axis: wp.int32, proj: Projection, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: Sampler, stoch: StochasticParams
) -> wp.vec4:
    """:func:`sample_one` for ``stoch.method == METHOD_NONE``, without the stochastic code: a kernel
    that merely contains it (not called) measured a tenth slower on plain sampling."""
    return sample_lod(tex, layer, projection_uv(proj, axis, p, n), projection_lod(tex, proj, axis, dpdx, dpdy), smp)


# Kernels that sample the projections come in two variants from one source (``plain``): the general
# one (any ``stoch``; with the generated adjoint) and the plain-sampling one, forward only, which
# ``warptex.triplanar`` launches when ``stoch.method`` is ``METHOD_NONE`` and no generated adjoint is
# needed (no tape, or a tape on which only texels need gradients: those are written by hand).


def _colour_kernel(plain: bool):
    sample = sample_one_plain if plain else sample_one

    @wp.kernel(name="triplanar_plain_kernel" if plain else "triplanar_kernel", enable_backward=not plain)
    def triplanar_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: Projection,
        smp: Sampler,
        stoch: StochasticParams,
        out: wp.array2d(dtype=float),
    ):
        """``out[i, c]``: the triplanar (or biplanar) blend of the three (two) plane projections.

        Uncovered pixels (``mask == 0``) and zero or non-finite normals give 0. Zero-weight
        projections are not sampled.
        """
        i = wp.tid()
        colour = wp.vec4(0.0)
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            for axis in range(3):
                if w[axis] > 0.0:
                    colour += w[axis] * wp.static(sample)(axis_texture(tex_x, tex_y, tex_z, axis), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch)
        write_channels(out, i, colour)

    return triplanar_kernel


triplanar_kernel = _colour_kernel(plain=False)
triplanar_plain_kernel = _colour_kernel(plain=True)


@wp.func
def splat_one(
    tex: TextureView,
    grad: wp.array(dtype=wp.vec4),
    layer: wp.int32,
    axis: wp.int32,
    proj: Projection,
    p: wp.vec3,
    n: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    smp: Sampler,
    stoch: StochasticParams,
    g: wp.vec4,
):
    """Add the gradient ``g`` of projection ``axis`` (as :func:`sample_one` reads it; linear
    blends only) into ``grad``, the texels' gradient; nothing when ``grad`` is empty (not needed)."""
    if grad.shape[0] > 0:
        splat_stochastic(tex, grad, layer, projection_uv(proj, axis, p, n), projection_lod(tex, proj, axis, dpdx, dpdy), smp, stoch, g)


@wp.func
def splat_one_plain(
    tex: TextureView,
    grad: wp.array(dtype=wp.vec4),
    layer: wp.int32,
    axis: wp.int32,
    proj: Projection,
    p: wp.vec3,
    n: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    smp: Sampler,
    stoch: StochasticParams,
    g: wp.vec4,
):
    """:func:`splat_one` for plain sampling (as :func:`sample_one_plain` reads it)."""
    if grad.shape[0] > 0:
        splat_lod(tex, grad, layer, projection_uv(proj, axis, p, n), projection_lod(tex, proj, axis, dpdx, dpdy), smp, g)


@wp.func
def axis_grad(grad_x: wp.array(dtype=wp.vec4), grad_y: wp.array(dtype=wp.vec4), grad_z: wp.array(dtype=wp.vec4), axis: wp.int32):
    """The texel gradient of :func:`axis_texture`'s texture."""
    grad = grad_x
    if axis == 1:
        grad = grad_y
    elif axis == 2:
        grad = grad_z
    return grad


def _texel_grad_kernel(plain: bool):
    splat = splat_one_plain if plain else splat_one

    @wp.kernel(name="triplanar_texel_grad_plain_kernel" if plain else "triplanar_texel_grad_kernel", enable_backward=False)
    def triplanar_texel_grad_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        grad_x: wp.array(dtype=wp.vec4),
        grad_y: wp.array(dtype=wp.vec4),
        grad_z: wp.array(dtype=wp.vec4),
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: Projection,
        smp: Sampler,
        stoch: StochasticParams,
        adj_out: wp.array2d(dtype=float),
    ):
        """Add the gradient of :func:`triplanar_kernel` (linear blends: plain sampling, or
        stochastic without a histogram) with respect to the texels of ``tex_x``/``tex_y``/``tex_z``
        into ``grad_x``/``grad_y``/``grad_z`` (empty: not needed), given the output's gradient
        ``adj_out``: each projection's weight times ``adj_out[i]``, splatted into the texels it read."""
        i = wp.tid()
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            g = read_channels(adj_out, i)
            for axis in range(3):
                if w[axis] > 0.0:
                    tex = axis_texture(tex_x, tex_y, tex_z, axis)
                    wp.static(splat)(tex, axis_grad(grad_x, grad_y, grad_z, axis), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch, w[axis] * g)

    return triplanar_texel_grad_kernel


triplanar_texel_grad_kernel = _texel_grad_kernel(plain=False)
triplanar_texel_grad_plain_kernel = _texel_grad_kernel(plain=True)


@wp.func
def projected_normal(texel: wp.vec4, axis: wp.int32, n: wp.vec3, proj: Projection, channels: wp.int32, strength: float, flip_green: wp.int32, blend: wp.int32) -> wp.vec3:
    """Projection ``axis``' normal in world-aligned axes (unweighted): ``texel`` decoded, its ``x``
    mirror-fixed, blended with the unit surface normal ``n`` in the projection's frame, swizzled back."""
    t = decode_normal(texel, channels, strength, flip_green)
    t = wp.vec3(t[0] * u_sign(n, axis, proj.mirror_fix), t[1], t[2])
    base = plane_coords(n, axis)
    return to_world(blend_projected(t, wp.vec3(base[0], base[1], n[axis]), blend), axis)


@wp.func
def unit_normal(total: wp.vec3, n: wp.vec3, proj: Projection) -> wp.vec3:
    """The blended normal ``total`` in world space, normalised; the surface normal ``n`` where the
    blend cancels out; ``(0, 0, 0)`` where both are zero or non-finite."""
    world = proj.normal_to_world * total
    surface = proj.normal_to_world * n
    result = wp.vec3(0.0)
    if wp.length(world) > 1.0e-12 and wp.isfinite(world):
        result = wp.normalize(world)
    elif wp.length(surface) > 0.0 and wp.isfinite(surface):
        result = wp.normalize(surface)
    return result


@wp.func
def unit_base_normal(n: wp.vec3) -> wp.vec3:
    """``n`` normalised when it has a length: the blends assume a unit base normal (object space may scale it)."""
    result = n
    if wp.length(n) > 0.0:
        result = wp.normalize(n)
    return result


def _normal_kernel(plain: bool):
    sample = sample_one_plain if plain else sample_one

    @wp.kernel(name="triplanar_normal_plain_kernel" if plain else "triplanar_normal_kernel", enable_backward=not plain)
    def triplanar_normal_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: Projection,
        smp: Sampler,
        stoch: StochasticParams,
        channels: wp.int32,
        strength: float,
        flip_green: wp.int32,
        blend: wp.int32,
        out: wp.array2d(dtype=float),
    ):
        """``out[i, :]``: the unit world-space normal after triplanar normal mapping.

        Each projection's tangent-space normal is decoded, turned into the projection's
        world-aligned frame (its ``x`` follows the mirror-fixed ``u``), blended with the surface
        normal there (whiteout, UDN or RNM), swizzled back to world axes, and the weighted sum is
        normalised. Uncovered pixels, zero or non-finite normals give ``(0, 0, 0)``; if the blend
        cancels out, the surface normal is returned.
        """
        i = wp.tid()
        result = wp.vec3(0.0)
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            n = unit_base_normal(n)
            total = wp.vec3(0.0)
            for axis in range(3):
                if w[axis] > 0.0:
                    texel = wp.static(sample)(axis_texture(tex_x, tex_y, tex_z, axis), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch)
                    total += w[axis] * projected_normal(texel, axis, n, proj, channels, strength, flip_green, blend)
            result = unit_normal(total, n, proj)
        for c in range(3):
            out[i, c] = result[c]

    return triplanar_normal_kernel


triplanar_normal_kernel = _normal_kernel(plain=False)
triplanar_normal_plain_kernel = _normal_kernel(plain=True)


# -- triplanar normal mapping under a tape, texels only needing gradients ---------------------------
#
# Normal mapping is not linear in the texels (decode, blend, normalise), so its gradient is taken in
# two steps: the projections' samples are stored per pixel (projection_samples_kernel), the normal
# is computed from them by a kernel whose generated adjoint is cheap (no sampling in it), and the
# samples' gradient is added into the texels they read by hand (projection_texel_grad_kernel).


def _projection_samples_kernel(plain: bool):
    sample = sample_one_plain if plain else sample_one

    @wp.kernel(name="projection_samples_plain_kernel" if plain else "projection_samples_kernel", enable_backward=False)
    def projection_samples_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: Projection,
        smp: Sampler,
        stoch: StochasticParams,
        samples: wp.array2d(dtype=wp.vec4),
        weights: wp.array(dtype=wp.vec3),
    ):
        """``samples[i, axis]``: what :func:`triplanar_normal_kernel` reads from projection ``axis``
        (0 where its weight is 0 or the pixel is not covered); ``weights[i]``: the projections' weights."""
        i = wp.tid()
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            weights[i] = w
            n = unit_base_normal(n)
            for axis in range(3):
                if w[axis] > 0.0:
                    samples[i, axis] = wp.static(sample)(axis_texture(tex_x, tex_y, tex_z, axis), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch)

    return projection_samples_kernel


projection_samples_kernel = _projection_samples_kernel(plain=False)
projection_samples_plain_kernel = _projection_samples_kernel(plain=True)


@wp.kernel
def triplanar_normal_from_samples_kernel(
    samples: wp.array2d(dtype=wp.vec4),
    weights: wp.array(dtype=wp.vec3),
    normal: wp.array(dtype=wp.vec3),
    mask: wp.array(dtype=float),
    proj: Projection,
    channels: wp.int32,
    strength: float,
    flip_green: wp.int32,
    blend: wp.int32,
    out: wp.array2d(dtype=float),
):
    """:func:`triplanar_normal_kernel` with each projection's sample and weight read from
    ``samples`` and ``weights`` (no gradient reaches the weights: this runs only where the
    sharpness and the G-buffer need none)."""
    i = wp.tid()
    result = wp.vec3(0.0)
    if mask[i] != 0.0:
        w = weights[i]
        n = unit_base_normal(proj.normal_to_object * normal[i])
        total = wp.vec3(0.0)
        for axis in range(3):
            if w[axis] > 0.0:
                total += w[axis] * projected_normal(samples[i, axis], axis, n, proj, channels, strength, flip_green, blend)
        result = unit_normal(total, n, proj)
    for c in range(3):
        out[i, c] = result[c]


def _projection_texel_grad_kernel(plain: bool):
    splat = splat_one_plain if plain else splat_one

    @wp.kernel(name="projection_texel_grad_plain_kernel" if plain else "projection_texel_grad_kernel", enable_backward=False)
    def projection_texel_grad_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        grad_x: wp.array(dtype=wp.vec4),
        grad_y: wp.array(dtype=wp.vec4),
        grad_z: wp.array(dtype=wp.vec4),
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: Projection,
        smp: Sampler,
        stoch: StochasticParams,
        adj_samples: wp.array2d(dtype=wp.vec4),
    ):
        """Add the gradient ``adj_samples`` of :func:`projection_samples_kernel`'s samples (linear
        blends of taps) into the texels they read, as :func:`triplanar_texel_grad_kernel` does."""
        i = wp.tid()
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            n = unit_base_normal(n)
            for axis in range(3):
                if w[axis] > 0.0:
                    tex = axis_texture(tex_x, tex_y, tex_z, axis)
                    wp.static(splat)(tex, axis_grad(grad_x, grad_y, grad_z, axis), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch, adj_samples[i, axis])

    return projection_texel_grad_kernel


projection_texel_grad_kernel = _projection_texel_grad_kernel(plain=False)
projection_texel_grad_plain_kernel = _projection_texel_grad_kernel(plain=True)
