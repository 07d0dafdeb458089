"""Triplanar and biplanar mapping, and triplanar normal mapping, per pixel over a G-buffer.

The projections, their weights and the mirror fix are the building blocks of
:mod:`warptex.kernels.projection`; the six face textures and the choice among them are in
:mod:`warptex.kernels.faces`. Biplanar mapping (Quilez) is triplanar with a weight function that is
exactly zero on the minor axis; the kernels skip zero-weight projections, so it reads at most two.

**Configurations** (:func:`triplanar_kernels`): colour or normal mapping; plain or ``stochastic``
sampling (a Warp module of its own: merely containing the stochastic code made plain sampling a
tenth slower, and compiling it costs several times more); one texture per axis or one per face
(``faces``, choosing by the normal's sign, again a module of its own). Colour has a hand-written
texel gradient; normal mapping, which is not linear in the texels, a two-step one (:class:`Staged`):
the projections' samples stored per pixel with a hand-written texel gradient, then the normal made
from them, with a hand-written gradient in the samples and the sharpness
(:mod:`warptex.kernels.normal_blend`). The kernels with Warp's
generated adjoint (for sharpness, offsets, G-buffer gradients, stochastic tiling or a histogram) are
one per output, the most general configuration's (stochastic, by face; the same results), built on
the out-of-line blocks of :mod:`warptex.kernels.projection`.
"""

import functools

import warp as wp

from . import adjoint_module, inlined, specialised
from .faces import COLOUR_GRADS, SAMPLE_GRADS, TEXEL_GRADS, FaceGrads, FaceTextures, on_axis_face, on_face
from .family import LANES_SUFFIX, Kernels, Staged, family, forward_kernel, lane_kernel, pixel_kernels
from .lanes.projection import surface_covered
from .lanes.triplanar import face_lane_bodies, lane_bodies, linear_blend_take, normal_lane_bodies, slopes_lanes_take, stochastic_lane_bodies
from .native import use
from .normal_blend import normal_from_samples_kernels, projected_normal, unit_base_normal, unit_normal, write_normal
from .normals import NormalMapArgs
from .projection import ProjectionArgs, SurfacePixels, projection_footprint, projection_sample, projection_tiling, projection_uv, projection_weights, surface, surface_frame
from .slopes import add_plane_slopes, projection_weights_slope
from .stochastic import StochasticArgs, sample_plain, sample_stochastic, scatter_plain, scatter_stochastic
from .texels import SamplerArgs, TexelGrad, TextureView, read_channels, write_channels

MODULE = use("warptex.triplanar")

# The stochastic kernels loop over the projections (and taps) rather than unroll them: unrolled, the
# colour and normal kernels held six copies of the stochastic sampling code, 38 s to compile for sm_90.
for _module in (f"{MODULE}.stochastic{faces}{grad}{lanes}" for faces in ("", ".faces") for grad in ("", ".grad") for lanes in ("", LANES_SUFFIX)):
    wp.set_module_options({"max_unroll": 1}, module=_module)


@wp.struct
class TriplanarArgs:
    """What every pixel of a triplanar launch reads: the face textures and the array layer read,
    the projections, the sampler, the stochastic options, and (normal mapping) the normal map's."""

    faces: FaceTextures
    layer: wp.int32
    proj: ProjectionArgs
    smp: SamplerArgs
    stoch: StochasticArgs
    normal_map: NormalMapArgs


@wp.struct
class ProjectionSamples:
    """Per pixel, what normal mapping reads from each projection (0 where its weight is 0 or the
    pixel is not covered), and the projections' weights."""

    samples: wp.array2d(dtype=wp.vec4)
    weights: wp.array(dtype=wp.vec3)


# -- reading one projection ----------------------------------------------------------------------------


def _projection_reads(sample, scatter, suffix: str):
    """``(read, add)``: projection ``axis`` of ``tex`` over the projection's own footprint, sampled
    with ``sample`` (plain or stochastic: every stochastic tap reads the unperturbed footprint's
    LOD), and the gradient of that read added into the texel gradient ``grad`` (nothing when it is
    empty: not needed; linear blends only)."""

    def read(tex: TextureView, layer: wp.int32, axis: wp.int32, args: TriplanarArgs, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3) -> wp.vec4:
        return sample(tex, layer, projection_uv(args.proj, axis, p, n), projection_footprint(tex, args.proj, axis, n, dpdx, dpdy, args.smp), args.smp, args.stoch)

    def add(tex: TextureView, grad: TexelGrad, layer: wp.int32, axis: wp.int32, args: TriplanarArgs, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, g: wp.vec4):
        if grad.texels.shape[0] > 0:
            scatter(tex, grad, layer, projection_uv(args.proj, axis, p, n), projection_footprint(tex, args.proj, axis, n, dpdx, dpdy, args.smp), args.smp, args.stoch, g)

    return inlined(specialised(read, "read_projection" + suffix)), inlined(specialised(add, "add_projection" + suffix))


# -- pixel bodies --------------------------------------------------------------------------------------


def _bodies(read, add, select, suffix: str, slopes: bool):
    """The bodies of one configuration: colour, its texel gradient, normal mapping, and the two-step
    normal's stored samples with their texel gradient. Uncovered pixels (``mask == 0``) and zero or
    non-finite normals give 0; zero-weight projections are not read. With ``slopes`` (plain
    sampling), colour's gradient also adds each projection read's share of the tiling's, offsets'
    and sharpness' gradients, in axis order, where they are needed (:func:`~.slopes.add_plane_slopes`
    with the read's gradient ``w g``), and so does the stored samples' gradient with each sample's
    own gradient ``g_axis`` (normal mapping's first step: the tiling and offsets, the read on the
    unit normal; the sharpness moves the weights, which the second step blends)."""

    def colour(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, out: wp.array2d(dtype=float)):
        value = wp.vec4(0.0)
        if pixels.mask[i] != 0.0:
            p, n, dpdx, dpdy = surface(args.proj, pixels, i)
            w = projection_weights(args.proj, n)
            for axis in range(3):
                if w[axis] > 0.0:
                    value += w[axis] * read(select(args.faces.px, args.faces.nx, args.faces.py, args.faces.ny, args.faces.pz, args.faces.nz, axis, n), args.layer, axis, args, p, n, dpdx, dpdy)
        write_channels(out, i, value)

    def colour_grad(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, grads: FaceGrads, adj: wp.array2d(dtype=float)):
        if pixels.mask[i] != 0.0:
            p, n, dpdx, dpdy = surface(args.proj, pixels, i)
            w = projection_weights(args.proj, n)
            g = read_channels(adj, i)
            dw = wp.vec3(0.0)
            if wp.static(slopes):
                if grads.sharpness.shape[0] > 0:
                    dw = projection_weights_slope(args.proj, n)
            for axis in range(3):
                if w[axis] > 0.0:
                    tex = select(args.faces.px, args.faces.nx, args.faces.py, args.faces.ny, args.faces.pz, args.faces.nz, axis, n)
                    add(tex, select(grads.px, grads.nx, grads.py, grads.ny, grads.pz, grads.nz, axis, n), args.layer, axis, args, p, n, dpdx, dpdy, w[axis] * g)
                    if wp.static(slopes):
                        add_plane_slopes(tex, args.layer, args.proj, args.smp, grads, axis, p, n, dpdx, dpdy, w[axis] * g, g, dw[axis])

    def normal(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, out: wp.array2d(dtype=float)):
        result = wp.vec3(0.0)
        if pixels.mask[i] != 0.0:
            p, n, dpdx, dpdy = surface(args.proj, pixels, i)
            w = projection_weights(args.proj, n)
            n = unit_base_normal(n)
            total = wp.vec3(0.0)
            for axis in range(3):
                if w[axis] > 0.0:
                    texel = read(select(args.faces.px, args.faces.nx, args.faces.py, args.faces.ny, args.faces.pz, args.faces.nz, axis, n), args.layer, axis, args, p, n, dpdx, dpdy)
                    total += w[axis] * projected_normal(texel, axis, n, args.proj, args.normal_map)
            result = unit_normal(total, n, args.proj)
        write_normal(out, i, result)

    def samples(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, out: ProjectionSamples):
        if pixels.mask[i] != 0.0:
            p, n, dpdx, dpdy = surface(args.proj, pixels, i)
            w = projection_weights(args.proj, n)
            out.weights[i] = w
            n = unit_base_normal(n)
            for axis in range(3):
                if w[axis] > 0.0:
                    out.samples[i, axis] = read(select(args.faces.px, args.faces.nx, args.faces.py, args.faces.ny, args.faces.pz, args.faces.nz, axis, n), args.layer, axis, args, p, n, dpdx, dpdy)

    def samples_grad(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, grads: FaceGrads, adj: ProjectionSamples):
        # adj.weights is not read: no gradient reaches the weights on this path.
        if pixels.mask[i] != 0.0:
            p, n, dpdx, dpdy = surface(args.proj, pixels, i)
            w = projection_weights(args.proj, n)
            n = unit_base_normal(n)
            for axis in range(3):
                if w[axis] > 0.0:
                    tex = select(args.faces.px, args.faces.nx, args.faces.py, args.faces.ny, args.faces.pz, args.faces.nz, axis, n)
                    add(tex, select(grads.px, grads.nx, grads.py, grads.ny, grads.pz, grads.nz, axis, n), args.layer, axis, args, p, n, dpdx, dpdy, adj.samples[i, axis])
                    if wp.static(slopes):
                        add_plane_slopes(tex, args.layer, args.proj, args.smp, grads, axis, p, n, dpdx, dpdy, adj.samples[i, axis], adj.samples[i, axis], 0.0)

    return {name: inlined(specialised(f, f"triplanar_{name}{suffix}")) for name, f in (("colour", colour), ("colour_grad", colour_grad), ("normal", normal), ("samples", samples), ("samples_grad", samples_grad))}


@inlined
def colour_outlined(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, out: wp.array2d(dtype=float)):
    """The colour body (every configuration) on out-of-line blocks, for Warp's generated adjoint.
    The arguments' fields are read once, before the loop: every read of a struct field is one more
    adjoint accumulation to compile (read in the loop, they made the module compile twice as long)."""
    value = wp.vec4(0.0)
    if pixels.mask[i] != 0.0:
        faces, proj, smp, stoch = args.faces, args.proj, args.smp, args.stoch
        px, nx, py, ny, pz, nz = faces.px, faces.nx, faces.py, faces.ny, faces.pz, faces.nz
        p, n, dpdx, dpdy, w = surface_frame(proj, pixels.position[i], pixels.normal[i], pixels.position_dx[i], pixels.position_dy[i])
        for axis in range(3):
            if w[axis] > 0.0:
                tex = on_face(px, nx, py, ny, pz, nz, axis, n)
                value += w[axis] * projection_sample(tex, args.layer, proj, axis, p, n, dpdx, dpdy, projection_tiling(proj, axis), smp, stoch)
    write_channels(out, i, value)


@inlined
def normal_outlined(args: TriplanarArgs, pixels: SurfacePixels, i: wp.int32, out: wp.array2d(dtype=float)):
    """The normal-mapping body (every configuration) on out-of-line blocks, for Warp's generated
    adjoint (fields read once, as in :func:`colour_outlined`)."""
    result = wp.vec3(0.0)
    if pixels.mask[i] != 0.0:
        faces, proj, smp, stoch, nm = args.faces, args.proj, args.smp, args.stoch, args.normal_map
        px, nx, py, ny, pz, nz = faces.px, faces.nx, faces.py, faces.ny, faces.pz, faces.nz
        p, n, dpdx, dpdy, w = surface_frame(proj, pixels.position[i], pixels.normal[i], pixels.position_dx[i], pixels.position_dy[i])
        n = unit_base_normal(n)
        total = wp.vec3(0.0)
        for axis in range(3):
            if w[axis] > 0.0:
                tex = on_face(px, nx, py, ny, pz, nz, axis, n)
                texel = projection_sample(tex, args.layer, proj, axis, p, n, dpdx, dpdy, projection_tiling(proj, axis), smp, stoch)
                total += w[axis] * projected_normal(texel, axis, n, proj, nm)
        result = unit_normal(total, n, proj)
    write_normal(out, i, result)


_PLAIN = _projection_reads(sample_plain, scatter_plain, "_plain")
_STOCHASTIC = _projection_reads(sample_stochastic, scatter_stochastic, "_stochastic")
_BODIES = {
    (stochastic, faces): _bodies(*(_STOCHASTIC if stochastic else _PLAIN), on_face if faces else on_axis_face, ("_stochastic" if stochastic else "") + ("_faces" if faces else ""), not stochastic)
    for stochastic in (False, True)
    for faces in (False, True)
}
_CONFIGURATIONS = [{"normal": normal, "stochastic": stochastic, "faces": faces} for normal in (False, True) for stochastic in (False, True) for faces in (False, True)]


def _sample_shapes(count: int, args) -> dict:
    return {"samples": ((count, 3), wp.vec4), "weights": ((count,), wp.vec3)}


@functools.cache
def _adjoint(normal: bool):
    """The generated-adjoint kernel of colour (or ``normal``) mapping, one for every configuration:
    the most general one's (stochastic, by face), on the out-of-line blocks. Each in a module of its
    own (``warptex.adjoint.triplanar``, ``.triplanar.normal``): a job differentiates one or the
    other, and the two in one module took 23-28 s to compile for sm_90, near the 30 s bar."""
    body = normal_outlined if normal else colour_outlined
    module = adjoint_module("triplanar.normal" if normal else "triplanar")
    return forward_kernel(body, TriplanarArgs, SurfacePixels, wp.array2d(dtype=float), module=module, name="triplanar" + ("_normal" if normal else "") + "_adjoint", enable_backward=True)


@family(configurations=_CONFIGURATIONS)
def triplanar_kernels(*, normal: bool, stochastic: bool, faces: bool) -> Kernels:
    """The kernels of colour (or ``normal``) mapping, plain or ``stochastic``, one texture per axis
    or per face (``faces``): module docstring."""
    module = MODULE + (".stochastic" if stochastic else "") + (".faces" if faces else "")
    grad_module = module + ".grad"
    bodies = _BODIES[stochastic, faces]
    name = "triplanar" + ("_stochastic" if stochastic else "") + ("_faces" if faces else "")
    take = linear_blend_take if stochastic else None  # a histogram's blend runs the one-pixel kernels
    grad_take = take if stochastic else slopes_lanes_take if faces else None
    if not normal:
        forward, texel_grad, _ = pixel_kernels(name, module=module, args=TriplanarArgs, pixels=SurfacePixels, out=wp.array2d(dtype=float), body=bodies["colour"],
                                               scatter=bodies["colour_grad"], grads=FaceGrads)  # fmt: skip
        if stochastic and not faces:
            colour_lane, colour_grad_lane = stochastic_lane_bodies(TriplanarArgs)
        elif faces:
            colour_lane, colour_grad_lane = face_lane_bodies(TriplanarArgs, stochastic)
        else:
            colour_lane, colour_grad_lane = lane_bodies(TriplanarArgs)
        lanes = lane_kernel(colour_lane, TriplanarArgs, SurfacePixels, wp.array2d(dtype=float), module=module, name=name + "_lanes", covered=surface_covered)
        grad_lanes = lane_kernel(colour_grad_lane, TriplanarArgs, SurfacePixels, wp.array2d(dtype=float), grads_t=FaceGrads, module=grad_module, name=name + "_texel_grad_lanes", covered=surface_covered)
        return Kernels(forward, texel_grad, _adjoint(False), grads=TEXEL_GRADS if stochastic else COLOUR_GRADS, lanes=lanes, texel_grad_lanes=grad_lanes, lanes_take=take, grad_lanes_take=grad_take)
    forward, _, _ = pixel_kernels(name + "_normal", module=module, args=TriplanarArgs, pixels=SurfacePixels, out=wp.array2d(dtype=float), body=bodies["normal"])
    # normal mapping's lanes, in modules of their own (colour-only jobs do not compile them)
    normal_lane, samples_lane, samples_grad_lane = normal_lane_bodies(TriplanarArgs, ProjectionSamples, stochastic, faces)
    lanes = lane_kernel(normal_lane, TriplanarArgs, SurfacePixels, wp.array2d(dtype=float), module=module + ".normal", name=name + "_normal_lanes", covered=surface_covered)
    first_lanes = {"lanes": lane_kernel(samples_lane, TriplanarArgs, SurfacePixels, ProjectionSamples, module=module + ".normal.grad", name=name + "_samples_lanes"),
                   "texel_grad_lanes": lane_kernel(samples_grad_lane, TriplanarArgs, SurfacePixels, ProjectionSamples, grads_t=FaceGrads, module=module + ".normal.grad", name=name + "_samples_texel_grad_lanes"),
                   "lanes_take": take, "grad_lanes_take": grad_take}  # fmt: skip
    first = pixel_kernels(name + "_samples", module=grad_module, grad_module=grad_module, args=TriplanarArgs, pixels=SurfacePixels, out=ProjectionSamples,
                          body=bodies["samples"], scatter=bodies["samples_grad"], grads=FaceGrads)  # fmt: skip
    staged = Staged(replaces="texel_grad", first=Kernels(*first, grads=TEXEL_GRADS if stochastic else SAMPLE_GRADS, **first_lanes), then=normal_from_samples_kernels(), intermediates=_sample_shapes,
                    then_only=("args.proj.sharpness",), no_grad=("weights",))  # fmt: skip
    return Kernels(forward, None, _adjoint(True), staged=staged, lanes=lanes, lanes_take=take)
