"""Triplanar and biplanar mapping, and triplanar normal mapping, per pixel over a G-buffer.

The projections, their weights and the mirror fix are the building blocks of
:mod:`warptex.kernels.projection`. Biplanar mapping (Quilez) is triplanar with a weight function
that is exactly zero on the minor axis; the kernels skip zero-weight projections, so it reads at
most two.

**Kernels.** Each kernel is built twice from one source (and each twice again, see below):
reading every projection with plain trilinear sampling (Warp module ``warptex.triplanar``), or
with the stochastic technique of its
``StochasticArgs`` (``warptex.triplanar.stochastic``); merely containing the stochastic code made
plain sampling a tenth slower, and compiling it costs several times more. Colour and normal mapping
come with hand-written texel gradients, in the ``.grad`` module beside each; the kernels with
Warp's generated adjoint (for sharpness, offsets, G-buffer gradients, stochastic tiling or a
histogram) are built on the out-of-line blocks of :mod:`warptex.kernels.projection`, in ``warptex.kernels.ADJOINT_MODULE``.

**Textures per face.** Every kernel takes six textures, one per face of the cube of directions:
``tex_x``/``tex_y``/``tex_z`` are read where the (projected-space) normal's component along the
projection's axis is ``>= 0``, ``tex_neg_x``/``tex_neg_y``/``tex_neg_z`` where it is negative
(:func:`face_texture`), so a ceiling can differ from the floor. The choice flips where
``n[axis] = 0``, where that projection's weight is 0 (for a sharpness > 0, triplanar and biplanar
alike), so the seam is as continuous as the blend. Only the kernels of the ``.faces`` modules make
that choice; the others read ``tex_x``/``tex_y``/``tex_z`` on both faces
(:func:`face_texture_per_axis`), as they did before faces existed, for one texture or one per axis.
The generated-adjoint kernels always choose by face (one kernel each; same results).
"""

import warp as wp

from . import ADJOINT_MODULE
from .normals import blend_projected, decode_normal, direction, to_world
from .projection import (
    ProjectionArgs,
    object_space,
    plane_coords,
    projection_footprint,
    projection_sample,
    projection_tiling,
    projection_uv,
    projection_weights,
    surface_frame,
    u_sign,
)
from .sampling import SamplerArgs, TexelGrad, TextureView, read_channels, sample_footprint, scatter_footprint, write_channels
from .stochastic import StochasticArgs, sample_stochastic, scatter_stochastic

MODULE = "warptex.triplanar"
STOCHASTIC_MODULE = "warptex.triplanar.stochastic"
GRAD_MODULE = MODULE + ".grad"
STOCHASTIC_GRAD_MODULE = STOCHASTIC_MODULE + ".grad"
# The same kernels with a texture per face (module docstring).
FACES_MODULE = MODULE + ".faces"
FACES_GRAD_MODULE = FACES_MODULE + ".grad"
STOCHASTIC_FACES_MODULE = STOCHASTIC_MODULE + ".faces"
STOCHASTIC_FACES_GRAD_MODULE = STOCHASTIC_FACES_MODULE + ".grad"
# The stochastic kernels loop over the projections (and taps) rather than unroll them: unrolled, the
# colour and normal kernels held six copies of the stochastic sampling code, 38 s to compile for sm_90.
for _module in (STOCHASTIC_MODULE, STOCHASTIC_GRAD_MODULE, STOCHASTIC_FACES_MODULE, STOCHASTIC_FACES_GRAD_MODULE):
    wp.set_module_options({"max_unroll": 1}, module=_module)


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
def axis_grad(grad_x: TexelGrad, grad_y: TexelGrad, grad_z: TexelGrad, axis: wp.int32):
    """The texel gradient of :func:`axis_texture`'s texture."""
    grad = grad_x
    if axis == 1:
        grad = grad_y
    elif axis == 2:
        grad = grad_z
    return grad


@wp.func
def face_texture(
    tex_x: TextureView, tex_y: TextureView, tex_z: TextureView, tex_neg_x: TextureView, tex_neg_y: TextureView, tex_neg_z: TextureView, axis: wp.int32, n: wp.vec3
) -> TextureView:
    """Projection ``axis``' texture on the face the normal ``n`` looks at: the ``+axis`` face's
    (``tex_x``/``tex_y``/``tex_z``) where ``n[axis] >= 0`` (``sign(0) = +1``, as the mirror fix's
    :func:`~warptex.kernels.normals.sign_or_one`), else the ``-axis`` face's
    (``tex_neg_x``/``tex_neg_y``/``tex_neg_z``). Where the choice flips, ``n[axis] = 0``, the
    projection's weight is 0 (for a sharpness > 0), so the seam blends as the others do."""
    tex = axis_texture(tex_x, tex_y, tex_z, axis)
    if n[axis] < 0.0:
        tex = axis_texture(tex_neg_x, tex_neg_y, tex_neg_z, axis)
    return tex


@wp.func
def face_texture_per_axis(
    tex_x: TextureView, tex_y: TextureView, tex_z: TextureView, tex_neg_x: TextureView, tex_neg_y: TextureView, tex_neg_z: TextureView, axis: wp.int32, n: wp.vec3
) -> TextureView:
    """:func:`face_texture` where both faces of each axis have one texture, ``tex_x``/``tex_y``/``tex_z``
    (the ``tex_neg_*`` are not read): what the default kernels select, at the cost they always had."""
    return axis_texture(tex_x, tex_y, tex_z, axis)


@wp.func
def face_grad(
    grad_x: TexelGrad,
    grad_y: TexelGrad,
    grad_z: TexelGrad,
    grad_neg_x: TexelGrad,
    grad_neg_y: TexelGrad,
    grad_neg_z: TexelGrad,
    axis: wp.int32,
    n: wp.vec3,
):
    """The texel gradient of :func:`face_texture`'s texture."""
    grad = axis_grad(grad_x, grad_y, grad_z, axis)
    if n[axis] < 0.0:
        grad = axis_grad(grad_neg_x, grad_neg_y, grad_neg_z, axis)
    return grad


@wp.func
def face_grad_per_axis(
    grad_x: TexelGrad,
    grad_y: TexelGrad,
    grad_z: TexelGrad,
    grad_neg_x: TexelGrad,
    grad_neg_y: TexelGrad,
    grad_neg_z: TexelGrad,
    axis: wp.int32,
    n: wp.vec3,
):
    """The texel gradient of :func:`face_texture_per_axis`'s texture."""
    return axis_grad(grad_x, grad_y, grad_z, axis)


@wp.func
def sample_one(
    tex: TextureView, layer: wp.int32, axis: wp.int32, proj: ProjectionArgs, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs, stoch: StochasticArgs
) -> wp.vec4:
    """Projection ``axis`` of ``tex`` over the projection's own footprint, sampled as ``stoch`` says
    (the stochastic taps all use the unperturbed footprint's LOD)."""
    return sample_stochastic(tex, layer, projection_uv(proj, axis, p, n), projection_footprint(tex, proj, axis, n, dpdx, dpdy, smp), smp, stoch)


@wp.func
def sample_one_plain(
    tex: TextureView, layer: wp.int32, axis: wp.int32, proj: ProjectionArgs, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, smp: SamplerArgs, stoch: StochasticArgs
) -> wp.vec4:
    """:func:`sample_one` with plain sampling (``stoch`` is not read)."""
    return sample_footprint(tex, layer, projection_uv(proj, axis, p, n), projection_footprint(tex, proj, axis, n, dpdx, dpdy, smp), smp)


@wp.func
def scatter_one(
    tex: TextureView,
    grad: TexelGrad,
    layer: wp.int32,
    axis: wp.int32,
    proj: ProjectionArgs,
    p: wp.vec3,
    n: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    smp: SamplerArgs,
    stoch: StochasticArgs,
    g: wp.vec4,
):
    """Add the gradient ``g`` of projection ``axis`` (as :func:`sample_one` reads it; linear
    blends only) into ``grad``, the texels' gradient; nothing when ``grad`` is empty (not needed)."""
    if grad.texels.shape[0] > 0:
        scatter_stochastic(tex, grad, layer, projection_uv(proj, axis, p, n), projection_footprint(tex, proj, axis, n, dpdx, dpdy, smp), smp, stoch, g)


@wp.func
def scatter_one_plain(
    tex: TextureView,
    grad: TexelGrad,
    layer: wp.int32,
    axis: wp.int32,
    proj: ProjectionArgs,
    p: wp.vec3,
    n: wp.vec3,
    dpdx: wp.vec3,
    dpdy: wp.vec3,
    smp: SamplerArgs,
    stoch: StochasticArgs,
    g: wp.vec4,
):
    """:func:`scatter_one` for plain sampling (as :func:`sample_one_plain` reads it)."""
    if grad.texels.shape[0] > 0:
        scatter_footprint(tex, grad, layer, projection_uv(proj, axis, p, n), projection_footprint(tex, proj, axis, n, dpdx, dpdy, smp), smp, g)


@wp.func
def projected_normal(texel: wp.vec4, axis: wp.int32, n: wp.vec3, proj: ProjectionArgs, channels: wp.int32, strength: float, flip_green: wp.int32, blend: wp.int32) -> wp.vec3:
    """Projection ``axis``' normal in world-aligned axes (unweighted): ``texel`` decoded, its ``x``
    mirror-fixed, blended with the unit surface normal ``n`` in the projection's frame, swizzled back."""
    t = decode_normal(texel, channels, strength, flip_green)
    t = wp.vec3(t[0] * u_sign(n, axis, proj.mirror_fix), t[1], t[2])
    base = plane_coords(n, axis)
    return to_world(blend_projected(t, wp.vec3(base[0], base[1], n[axis]), blend), axis)


@wp.func
def unit_normal(total: wp.vec3, n: wp.vec3, proj: ProjectionArgs) -> wp.vec3:
    """The blended normal ``total`` in world space, normalised; the surface normal ``n`` where the
    blend cancels out; ``(0, 0, 0)`` where both are zero or non-finite."""
    world = proj.normal_to_world * total
    surface = proj.normal_to_world * n
    result = wp.vec3(0.0)
    if wp.length(world) > 1.0e-12 and wp.isfinite(world):
        result = direction(world)
    elif wp.length(surface) > 0.0 and wp.isfinite(surface):
        result = direction(surface)
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


# -- colour ---------------------------------------------------------------------------------------------


def _colour_kernel(module: str, sample, select):
    @wp.kernel(enable_backward=False, module=module)
    def triplanar_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        tex_neg_x: TextureView,
        tex_neg_y: TextureView,
        tex_neg_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: ProjectionArgs,
        smp: SamplerArgs,
        stoch: StochasticArgs,
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
                    colour += w[axis] * sample(select(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch)
        write_channels(out, i, colour)

    return triplanar_kernel


def _colour_texel_grad_kernel(module: str, scatter, select, select_grad):
    @wp.kernel(enable_backward=False, module=module)
    def triplanar_texel_grad_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        tex_neg_x: TextureView,
        tex_neg_y: TextureView,
        tex_neg_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: ProjectionArgs,
        smp: SamplerArgs,
        stoch: StochasticArgs,
        grad_x: TexelGrad,
        grad_y: TexelGrad,
        grad_z: TexelGrad,
        grad_neg_x: TexelGrad,
        grad_neg_y: TexelGrad,
        grad_neg_z: TexelGrad,
        adj_out: wp.array2d(dtype=float),
    ):
        """Add the gradient of :func:`triplanar_kernel` (same inputs; linear blends: plain sampling,
        or stochastic without a histogram) with respect to the texels of the six face textures
        ``tex_x``... ``tex_neg_z`` into ``grad_x``... ``grad_neg_z`` (empty: not needed; a texture
        passed for several faces gets one gradient array for all of them), given the output's gradient
        ``adj_out``: each projection's weight times ``adj_out[i]``, added into the texels it read."""
        i = wp.tid()
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            g = read_channels(adj_out, i)
            for axis in range(3):
                if w[axis] > 0.0:
                    tex = select(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n)
                    scatter(tex, select_grad(grad_x, grad_y, grad_z, grad_neg_x, grad_neg_y, grad_neg_z, axis, n), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch, w[axis] * g)

    return triplanar_texel_grad_kernel


@wp.kernel(module=ADJOINT_MODULE)
def triplanar_adjoint_kernel(
    tex_x: TextureView,
    tex_y: TextureView,
    tex_z: TextureView,
    tex_neg_x: TextureView,
    tex_neg_y: TextureView,
    tex_neg_z: TextureView,
    layer: wp.int32,
    position: wp.array(dtype=wp.vec3),
    position_dx: wp.array(dtype=wp.vec3),
    position_dy: wp.array(dtype=wp.vec3),
    normal: wp.array(dtype=wp.vec3),
    mask: wp.array(dtype=float),
    proj: ProjectionArgs,
    smp: SamplerArgs,
    stoch: StochasticArgs,
    out: wp.array2d(dtype=float),
):
    """:func:`triplanar_kernel` (either variant) with Warp's generated adjoint, on out-of-line blocks."""
    i = wp.tid()
    colour = wp.vec4(0.0)
    if mask[i] != 0.0:
        p, n, dpdx, dpdy, w = surface_frame(proj, position[i], normal[i], position_dx[i], position_dy[i])
        for axis in range(3):
            if w[axis] > 0.0:
                tex = face_texture(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n)
                colour += w[axis] * projection_sample(tex, layer, proj, axis, p, n, dpdx, dpdy, projection_tiling(proj, axis), smp, stoch)
    write_channels(out, i, colour)


# -- normal mapping -------------------------------------------------------------------------------------


def _normal_kernel(module: str, sample, select):
    @wp.kernel(enable_backward=False, module=module)
    def triplanar_normal_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        tex_neg_x: TextureView,
        tex_neg_y: TextureView,
        tex_neg_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: ProjectionArgs,
        smp: SamplerArgs,
        stoch: StochasticArgs,
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
                    texel = sample(select(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch)
                    total += w[axis] * projected_normal(texel, axis, n, proj, channels, strength, flip_green, blend)
            result = unit_normal(total, n, proj)
        write_normal(out, i, result)

    return triplanar_normal_kernel


@wp.kernel(module=ADJOINT_MODULE)
def triplanar_normal_adjoint_kernel(
    tex_x: TextureView,
    tex_y: TextureView,
    tex_z: TextureView,
    tex_neg_x: TextureView,
    tex_neg_y: TextureView,
    tex_neg_z: TextureView,
    layer: wp.int32,
    position: wp.array(dtype=wp.vec3),
    position_dx: wp.array(dtype=wp.vec3),
    position_dy: wp.array(dtype=wp.vec3),
    normal: wp.array(dtype=wp.vec3),
    mask: wp.array(dtype=float),
    proj: ProjectionArgs,
    smp: SamplerArgs,
    stoch: StochasticArgs,
    channels: wp.int32,
    strength: float,
    flip_green: wp.int32,
    blend: wp.int32,
    out: wp.array2d(dtype=float),
):
    """:func:`triplanar_normal_kernel` (either variant) with Warp's generated adjoint, on out-of-line blocks."""
    i = wp.tid()
    result = wp.vec3(0.0)
    if mask[i] != 0.0:
        p, n, dpdx, dpdy, w = surface_frame(proj, position[i], normal[i], position_dx[i], position_dy[i])
        n = unit_base_normal(n)
        total = wp.vec3(0.0)
        for axis in range(3):
            if w[axis] > 0.0:
                tex = face_texture(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n)
                texel = projection_sample(tex, layer, proj, axis, p, n, dpdx, dpdy, projection_tiling(proj, axis), smp, stoch)
                total += w[axis] * projected_normal(texel, axis, n, proj, channels, strength, flip_green, blend)
        result = unit_normal(total, n, proj)
    write_normal(out, i, result)


# Normal mapping is not linear in the texels (decode, blend, normalise), so where only texels need
# gradients it runs in two steps: the projections' samples are stored per pixel with a hand-written
# texel gradient (projection_samples_kernel, projection_texel_grad_kernel), and the normal is
# computed from them by a kernel whose generated adjoint is cheap: it samples nothing.


def _projection_samples_kernel(module: str, sample, select):
    @wp.kernel(enable_backward=False, module=module)
    def projection_samples_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        tex_neg_x: TextureView,
        tex_neg_y: TextureView,
        tex_neg_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: ProjectionArgs,
        smp: SamplerArgs,
        stoch: StochasticArgs,
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
                    samples[i, axis] = sample(select(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch)

    return projection_samples_kernel


def _projection_texel_grad_kernel(module: str, scatter, select, select_grad):
    @wp.kernel(enable_backward=False, module=module)
    def projection_texel_grad_kernel(
        tex_x: TextureView,
        tex_y: TextureView,
        tex_z: TextureView,
        tex_neg_x: TextureView,
        tex_neg_y: TextureView,
        tex_neg_z: TextureView,
        layer: wp.int32,
        position: wp.array(dtype=wp.vec3),
        position_dx: wp.array(dtype=wp.vec3),
        position_dy: wp.array(dtype=wp.vec3),
        normal: wp.array(dtype=wp.vec3),
        mask: wp.array(dtype=float),
        proj: ProjectionArgs,
        smp: SamplerArgs,
        stoch: StochasticArgs,
        grad_x: TexelGrad,
        grad_y: TexelGrad,
        grad_z: TexelGrad,
        grad_neg_x: TexelGrad,
        grad_neg_y: TexelGrad,
        grad_neg_z: TexelGrad,
        adj_samples: wp.array2d(dtype=wp.vec4),
        adj_weights: wp.array(dtype=wp.vec3),
    ):
        """Add the gradient ``adj_samples`` of :func:`projection_samples_kernel`'s samples (linear
        blends of taps) into the texels they read, as :func:`triplanar_texel_grad_kernel` does
        (``adj_weights`` is not read: no gradient reaches the weights on this path)."""
        i = wp.tid()
        if mask[i] != 0.0:
            p, n, dpdx, dpdy = object_space(proj, position[i], normal[i], position_dx[i], position_dy[i])
            w = projection_weights(proj, n)
            n = unit_base_normal(n)
            for axis in range(3):
                if w[axis] > 0.0:
                    tex = select(tex_x, tex_y, tex_z, tex_neg_x, tex_neg_y, tex_neg_z, axis, n)
                    scatter(tex, select_grad(grad_x, grad_y, grad_z, grad_neg_x, grad_neg_y, grad_neg_z, axis, n), layer, axis, proj, p, n, dpdx, dpdy, smp, stoch, adj_samples[i, axis])

    return projection_texel_grad_kernel


@wp.kernel(module=GRAD_MODULE)
def triplanar_normal_from_samples_kernel(
    samples: wp.array2d(dtype=wp.vec4),
    weights: wp.array(dtype=wp.vec3),
    normal: wp.array(dtype=wp.vec3),
    mask: wp.array(dtype=float),
    proj: ProjectionArgs,
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
    write_normal(out, i, result)


def _variants(module: str, grad_module: str, sample, scatter, select, select_grad) -> tuple:
    """The kernels of one module pair: colour, normal, texel gradient, projection samples and their
    texel gradient, sampling with ``sample``/``scatter`` and choosing textures with ``select``."""
    return (
        _colour_kernel(module, sample, select),
        _normal_kernel(module, sample, select),
        _colour_texel_grad_kernel(grad_module, scatter, select, select_grad),
        _projection_samples_kernel(grad_module, sample, select),
        _projection_texel_grad_kernel(grad_module, scatter, select, select_grad),
    )


# One texture per axis (textures_per_face not given, or the same as textures_per_axis).
(
    triplanar_kernel,
    triplanar_normal_kernel,
    triplanar_texel_grad_kernel,
    projection_samples_kernel,
    projection_texel_grad_kernel,
) = _variants(MODULE, GRAD_MODULE, sample_one_plain, scatter_one_plain, face_texture_per_axis, face_grad_per_axis)
(
    triplanar_stochastic_kernel,
    triplanar_normal_stochastic_kernel,
    triplanar_stochastic_texel_grad_kernel,
    projection_samples_stochastic_kernel,
    projection_stochastic_texel_grad_kernel,
) = _variants(STOCHASTIC_MODULE, STOCHASTIC_GRAD_MODULE, sample_one, scatter_one, face_texture_per_axis, face_grad_per_axis)

# A texture per face: the same kernels choosing by the normal's sign, in modules of their own. In the
# default kernels that choice cost 7% of a plain triplanar sample (selecting a TextureView copies it);
# here it is paid, and compiled, only where the faces of an axis differ.
(
    triplanar_faces_kernel,
    triplanar_normal_faces_kernel,
    triplanar_faces_texel_grad_kernel,
    projection_samples_faces_kernel,
    projection_faces_texel_grad_kernel,
) = _variants(FACES_MODULE, FACES_GRAD_MODULE, sample_one_plain, scatter_one_plain, face_texture, face_grad)
(
    triplanar_stochastic_faces_kernel,
    triplanar_normal_stochastic_faces_kernel,
    triplanar_stochastic_faces_texel_grad_kernel,
    projection_samples_stochastic_faces_kernel,
    projection_stochastic_faces_texel_grad_kernel,
) = _variants(STOCHASTIC_FACES_MODULE, STOCHASTIC_FACES_GRAD_MODULE, sample_one, scatter_one, face_texture, face_grad)
