"""Splat-map terrain texturing: the kernels (options and layer reads: :mod:`.splat_layers`;
the blend: :mod:`.splat_blend`).

**Configurations** (:func:`splat_kernels`): a *capacity* of layers (8, 16, 32...: the layer count is
a run-time value, every per-layer loop is a loop, so a kernel's code does not grow with the layers),
and plain or ``stochastic`` sampling, each in a Warp module of its own (``warptex.splat8``,
``warptex.splat8.stochastic``), as for triplanar.

**Hand-written gradient.** Warp's generated adjoint replays each sampling function's forward pass
inside its reverse pass (about 5× the forward here). Where only texels, the transition and, with
plain sampling, the tiling need gradients (no sharpness, offsets or G-buffer gradients) and every
blend of taps is linear (no histogram), the texel-gradient kernel computes them directly: per pixel
it replays the forward once, takes the blend's derivatives by hand (``blend_backward``), and adds
each layer's colour gradient into the texels the layer read, each weight's into the splat-map
texels, and each layer's colour gradient times the sample's derivative along its tiling into the
tiling::

    colour = Σ w''_j c_j                          ∂/∂c_j = w''_j · g,   ∂/∂w''_j = g · c_j
    w''_j = v_j / max(Σ v, ε),  v_j = wh_j w'_j     (height blending, from h_j = height_j · w'_j)
    w'_j = w_j / max(Σ w, ε)                        (normalize),  w_j = max(splat_j, 0)

Where Warp's ``max`` has ties its adjoint takes the second operand; the hand-written one does the
same (the running height maximum credits the last layer at the maximum).

**Other gradients** (sharpness, offsets, the G-buffer, a stochastic method's tiling, a histogram)
take two steps (:class:`~.family.Staged`): every weighted layer's sample stored per pixel with
Warp's generated adjoint (a loop over layers that only writes, which that adjoint differentiates
exactly), then the blend of the stored samples, its gradient by hand as above.
"""

import functools

import warp as wp

from . import adjoint_module, inlined, specialised
from .native import use
from .family import Kernels, Staged, family, forward_kernel, lane_covered, lane_kernel, pixel_kernels
from .projection import SurfacePixels, surface_frame
from .splat_blend import blend_functions, capacity
from .lanes.splat import grad_lanes_take, lane_bodies, lane_saved, stochastic_grad_lanes_take, stochastic_lane_saved, stochastic_lanes_take
from .splat_layers import (
    HEIGHT_ARRAY,
    HEIGHT_CHANNEL,
    HEIGHT_NONE,
    PROJECT_TRIPLANAR,
    LayerPoint,
    SplatArgs,
    SplatParams,
    layer_textures,
    layer_weighted,
    pick,
    read_layer_outlined,
    read_layer_plain,
    read_layer_plain_once,
    read_layer_slope,
    read_layer_stochastic,
    scatter_layer_plain_once,
    scatter_layer_stochastic,
    surface_weights,
)
from .texels import SamplerArgs, TexelGrad, TextureView, read_channels, write_channels

@wp.struct
class SplatPixels:
    """The per-pixel G-buffer arrays a splat reads: UV0 and its derivatives, and the surface (world
    position, its derivatives, normal, coverage mask); and ``saved``, each pixel's layer colours
    (4 floats a layer), which the CPU's lane forward keeps for the texel-gradient lane to read
    instead of sampling the layers again (``Kernels.lane_saved``; empty: not kept)."""

    uv0: wp.array(dtype=wp.vec2)
    uv0_dx: wp.array(dtype=wp.vec2)
    uv0_dy: wp.array(dtype=wp.vec2)
    surface: SurfacePixels
    saved: wp.array2d(dtype=float)


@wp.func
def splat_covered(pixels: SplatPixels, base: wp.int32, count: wp.int32) -> bool:
    """Whether the G-buffer covers any of the lane's pixels (``covered`` of ``family.lane_kernel``)."""
    return lane_covered(pixels.surface.mask, base, count)


@wp.struct
class SplatGrads:
    """The hand-written gradient's targets (empty: not needed)."""

    layers: TexelGrad
    heights: TexelGrad
    maps: TexelGrad
    transition: wp.array(dtype=float)
    tiling: wp.array(dtype=float)


@wp.struct
class SplatSamples:
    """Per pixel, every weighted layer's sample (0 for the others) and, with separate heights, its height."""

    samples: wp.array2d(dtype=wp.vec4)
    height_samples: wp.array2d(dtype=float)


@wp.struct
class BlendArgs:
    """What the blend of stored samples reads (filled by name from :class:`~.splat_layers.SplatArgs`)."""

    maps: TextureView
    params: SplatParams
    map_smp: SamplerArgs


@wp.struct
class BlendPixels:
    """The per-pixel inputs of the blend of stored samples."""

    uv0: wp.array(dtype=wp.vec2)
    mask: wp.array(dtype=float)
    samples: wp.array2d(dtype=wp.vec4)
    height_samples: wp.array2d(dtype=float)


@wp.struct
class BlendGrads:
    """The blend's hand-written gradient's targets: the splat maps' texels, the transition, UV0
    (through the maps' reads) and the stored samples (per pixel)."""

    maps: TexelGrad
    transition: wp.array(dtype=float)
    uv0: wp.array(dtype=wp.vec2)
    samples: wp.array2d(dtype=wp.vec4)
    height_samples: wp.array2d(dtype=float)


@inlined
def layer_point(args: SplatArgs, pixels: SplatPixels, i: wp.int32) -> LayerPoint:
    """Where pixel ``i`` reads its layers (world space: a splat projects no object space)."""
    pt = LayerPoint()
    pt.uv0 = pixels.uv0[i]
    pt.uv0_dx = pixels.uv0_dx[i]
    pt.uv0_dy = pixels.uv0_dy[i]
    pt.p = pixels.surface.position[i]
    pt.n = pixels.surface.normal[i]
    pt.dpdx = pixels.surface.position_dx[i]
    pt.dpdy = pixels.surface.position_dy[i]
    pt.tri_w = surface_weights(args.reads.params, args.reads.proj, pt.n)
    return pt


def _read_layers(cap: int, read_layer, plain: bool, name: str):
    """``read_layers(args, pt, w1)`` for ``cap`` layers, reading each with ``read_layer`` (``plain``:
    a call each for colour and height, faster; else one call for both, so that the read is compiled
    once)."""
    f = blend_functions(cap)
    weights_t, colours_t = f.weights_t, f.colours_t

    def read_layers_of(args: SplatArgs, pt: LayerPoint, w1: weights_t):
        """``(c, hv)``: every weighted layer's colour and raw height."""
        params = args.reads.params
        c = colours_t()
        hv = weights_t()
        for j in range(params.num_layers):
            if w1[j] > 0.0:
                if wp.static(plain):
                    value = read_layer(args.layers, j, args.reads, pt, args.stoch)
                    c[j] = value
                    if params.height_mode == HEIGHT_CHANNEL:
                        hv[j] = value[params.height_channel]
                    elif params.height_mode == HEIGHT_ARRAY:
                        hv[j] = read_layer(args.heights, j, args.reads, pt, args.height_stoch)[0]
                else:
                    for t in range(layer_textures(params)):
                        value = read_layer(pick(args.layers, args.heights, t), j, args.reads, pt, pick(args.stoch, args.height_stoch, t))
                        if t == 0:
                            c[j] = value
                            if params.height_mode == HEIGHT_CHANNEL:
                                hv[j] = value[params.height_channel]
                        else:
                            hv[j] = value[0]
        return c, hv

    return inlined(specialised(read_layers_of, name), module=f"warptex.splat{cap}")


def _bodies(cap: int, read_layer, plain: bool, suffix: str, grad_reads) -> dict:
    """The forward and texel-gradient bodies for ``cap`` layers: the forward reads layers with
    ``read_layer`` (``plain``: plain sampling, split reads as in :func:`_read_layers`); the texel
    gradient with ``grad_reads``, a ``(read_layer, scatter_layer)`` of one call per read (with split
    reads beside their scatters, each inlined four times, ``warptex.splat8.grad`` took 26-38 s to
    compile for sm_90)."""
    f = blend_functions(cap)
    weights_t, colours_t = f.weights_t, f.colours_t
    read_layers = _read_layers(cap, read_layer, plain, f"splat{cap}_read_layers{suffix}")
    grad_read, grad_scatter = grad_reads
    grad_read_layers = read_layers if grad_read is read_layer else _read_layers(cap, grad_read, False, f"splat{cap}_read_layers{suffix}_once")

    def forward(args: SplatArgs, pixels: SplatPixels, i: wp.int32, out: wp.array2d(dtype=float)):
        """``out[i, c]``: the layers blended by the splat maps; 0 where the mask is 0."""
        colour = wp.vec4(0.0)
        if pixels.surface.mask[i] != 0.0:
            pt = layer_point(args, pixels, i)
            r, w0, total, w1 = f.splat_weights(args.maps, pt.uv0, args.map_smp, args.reads.params)
            c, hv = read_layers(args, pt, w1)
            colour = f.blend(w1, c, hv, args.reads.params)
        write_channels(out, i, colour)

    def scatter(args: SplatArgs, pixels: SplatPixels, i: wp.int32, grads: SplatGrads, adj: wp.array2d(dtype=float)):
        """Add the gradient ``adj[i]`` of :func:`forward` (linear blends of taps) into ``grads``:
        the forward replayed (with, for the tiling, the colours' and heights' slopes), then its blend
        reversed into the transition, the tiling (plain sampling only), the splat maps and the texels."""
        if pixels.surface.mask[i] != 0.0:
            params = args.reads.params
            pt = layer_point(args, pixels, i)
            r, w0, total, w1 = f.splat_weights(args.maps, pt.uv0, args.map_smp, params)
            c = colours_t()
            hv = weights_t()
            dc = colours_t()
            dhv = weights_t()
            tiling_grads = grads.tiling.shape[0] > 0
            if wp.static(plain):  # the stochastic kernels never take the tiling's gradient by hand (nor compile its reads)
                if tiling_grads:
                    for j in range(params.num_layers):
                        if w1[j] > 0.0:
                            value, slope = read_layer_slope(args.layers, j, args.reads, pt)
                            c[j] = value
                            dc[j] = slope
                            if params.height_mode == HEIGHT_ARRAY:
                                height, height_slope = read_layer_slope(args.heights, j, args.reads, pt)
                                hv[j] = height[0]
                                dhv[j] = height_slope[0]
                            elif params.height_mode == HEIGHT_CHANNEL:
                                hv[j] = c[j, params.height_channel]
                else:
                    c, hv = grad_read_layers(args, pt, w1)
            else:
                c, hv = grad_read_layers(args, pt, w1)
            gw1, gc, ghv, g_t = f.blend_backward(w1, c, hv, params, read_channels(adj, i))
            if grads.transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                wp.atomic_add(grads.transition, 0, g_t)
            if tiling_grads:
                for j in range(params.num_layers):
                    if w1[j] > 0.0:
                        wp.atomic_add(grads.tiling, wp.min(j, grads.tiling.shape[0] - 1), wp.dot(gc[j], dc[j]) + ghv[j] * dhv[j])
            gr = f.weights_backward(r, w0, total, gw1, params)
            f.scatter_maps(args.maps, grads.maps, pt.uv0, args.map_smp, gr, params)
            for j in range(params.num_layers):
                if w1[j] > 0.0:
                    for t in range(layer_textures(params)):
                        g = gc[j]
                        if t == 1:
                            g = wp.vec4(ghv[j], 0.0, 0.0, 0.0)
                        tex = pick(args.layers, args.heights, t)
                        grad_scatter(tex, pick(grads.layers, grads.heights, t), j, args.reads, pt, pick(args.stoch, args.height_stoch, t), g)

    return inlined(specialised(forward, f"splat{cap}_forward{suffix}"), module=f"warptex.splat{cap}"), inlined(specialised(scatter, f"splat{cap}_scatter{suffix}"), module=f"warptex.splat{cap}")


@inlined
def samples_outlined(args: SplatArgs, pixels: SplatPixels, i: wp.int32, out: SplatSamples):
    """``out.samples[i, j]``: layer ``j`` as the splat kernels read it, for every layer with a
    positive splat value (others stay 0); ``out.height_samples[i, j]``: its separate height. The first
    step of the two-step path, with Warp's generated adjoint on out-of-line blocks (module docstring)."""
    if pixels.surface.mask[i] != 0.0:
        reads, maps, map_smp = args.reads, args.maps, args.map_smp  # read once: each field read is adjoint code to compile
        params = reads.params
        pt = LayerPoint()
        pt.uv0 = pixels.uv0[i]
        pt.uv0_dx = pixels.uv0_dx[i]
        pt.uv0_dy = pixels.uv0_dy[i]
        p, n, dpdx, dpdy, tri_w = surface_frame(reads.proj, pixels.surface.position[i], pixels.surface.normal[i], pixels.surface.position_dx[i], pixels.surface.position_dy[i])
        pt.p = p
        pt.n = n
        pt.dpdx = dpdx
        pt.dpdy = dpdy
        pt.tri_w = wp.vec3(0.0)
        if params.projection == PROJECT_TRIPLANAR:
            pt.tri_w = tri_w
        for j in range(params.num_layers):
            if layer_weighted(maps, pt.uv0, map_smp, j, params.map_channels):
                out.samples[i, j] = read_layer_outlined(args.layers, j, reads, pt, args.stoch)
                if params.height_mode == HEIGHT_ARRAY:
                    height = read_layer_outlined(args.heights, j, reads, pt, args.height_stoch)
                    out.height_samples[i, j] = height[0]


def _blend_bodies(cap: int):
    """The blend of stored samples for ``cap`` layers, and its hand-written gradient."""
    f = blend_functions(cap)
    weights_t, colours_t = f.weights_t, f.colours_t

    def stored_layers_of(pixels: BlendPixels, i: wp.int32, w1: weights_t, params: SplatParams):
        """``(c, hv)``: the colours and heights the first step stored."""
        c = colours_t()
        hv = weights_t()
        for j in range(params.num_layers):
            if w1[j] > 0.0:
                c[j] = pixels.samples[i, j]
                if params.height_mode == HEIGHT_CHANNEL:
                    hv[j] = c[j, params.height_channel]
                elif params.height_mode == HEIGHT_ARRAY:
                    hv[j] = pixels.height_samples[i, j]
        return c, hv

    stored_layers = wp.func(specialised(stored_layers_of, f"splat{cap}_stored_layers"), module=f"warptex.splat{cap}")

    def blend(args: BlendArgs, pixels: BlendPixels, i: wp.int32, out: wp.array2d(dtype=float)):
        """The forward body's blend, of the layers the first step stored."""
        colour = wp.vec4(0.0)
        if pixels.mask[i] != 0.0:
            r, w0, total, w1 = f.splat_weights(args.maps, pixels.uv0[i], args.map_smp, args.params)
            c, hv = stored_layers(pixels, i, w1, args.params)
            colour = f.blend(w1, c, hv, args.params)
        write_channels(out, i, colour)

    def blend_grad(args: BlendArgs, pixels: BlendPixels, i: wp.int32, grads: BlendGrads, adj: wp.array2d(dtype=float)):
        """The gradient of :func:`blend` into the splat-map texels, the transition, UV0 (through the
        maps' reads) and the stored samples (empty targets: not needed)."""
        if pixels.mask[i] != 0.0:
            params = args.params
            uv = pixels.uv0[i]
            r, w0, total, w1 = f.splat_weights(args.maps, uv, args.map_smp, params)
            c, hv = stored_layers(pixels, i, w1, params)
            gw1, gc, ghv, g_t = f.blend_backward(w1, c, hv, params, read_channels(adj, i))
            if grads.transition.shape[0] > 0 and params.height_mode != HEIGHT_NONE:
                wp.atomic_add(grads.transition, 0, g_t)
            gr = f.weights_backward(r, w0, total, gw1, params)
            f.scatter_maps(args.maps, grads.maps, uv, args.map_smp, gr, params)
            if grads.uv0.shape[0] > 0:
                grads.uv0[i] = grads.uv0[i] + f.maps_uv_gradient(args.maps, uv, args.map_smp, gr, params)
            for j in range(params.num_layers):
                if w1[j] > 0.0:
                    if grads.samples.shape[0] > 0:
                        grads.samples[i, j] = grads.samples[i, j] + gc[j]
                    if params.height_mode == HEIGHT_ARRAY and grads.height_samples.shape[0] > 0:
                        grads.height_samples[i, j] = grads.height_samples[i, j] + ghv[j]

    return inlined(specialised(blend, f"splat{cap}_blend"), module=f"warptex.splat{cap}"), inlined(specialised(blend_grad, f"splat{cap}_blend_grad"), module=f"warptex.splat{cap}")


def _sample_shapes(count: int, args) -> dict:
    layers = args.reads.params.num_layers
    separate = args.reads.params.height_mode == HEIGHT_ARRAY  # heights read separately: one per layer, else a placeholder column
    return {"samples": ((count, layers), wp.vec4), "height_samples": ((count, layers if separate else 1), float)}


@functools.cache
def _samples() -> Kernels:
    """The first step of the two-step path, one kernel for every capacity (forward and generated adjoint)."""
    kernel = forward_kernel(samples_outlined, SplatArgs, SplatPixels, SplatSamples, module=adjoint_module("splat"), name="splat_samples_adjoint", enable_backward=True)
    return Kernels(kernel, None, kernel)


@functools.cache
def _staged(cap: int) -> Staged:
    """The two-step path of ``cap`` layers: the samples and their blend."""
    blend, blend_grad = _blend_bodies(cap)
    module = f"warptex.splat{cap}.blend"
    forward, texel_grad, _ = pixel_kernels(f"splat{cap}_blend", module=module, grad_module=module, args=BlendArgs, pixels=BlendPixels, out=wp.array2d(dtype=float),
                                           body=blend, scatter=blend_grad, grads=BlendGrads)  # fmt: skip
    then = Kernels(forward, texel_grad, grads=("args.maps", "args.params.transition", "pixels.uv0", "pixels.samples", "pixels.height_samples"))
    return Staged(replaces="adjoint", first=_samples(), then=then, intermediates=_sample_shapes, then_only=("args.maps", "args.reads.params.transition"))


def _configurations(options: dict) -> list:
    return [{"capacity": capacity(count), "stochastic": stochastic} for count in options.get("layer_counts", (4,)) for stochastic in (False, True)]


@family(configurations=_configurations)
def splat_kernels(*, capacity: int, stochastic: bool) -> Kernels:
    """The splat kernels for up to ``capacity`` layers (a :func:`~.splat_blend.capacity`), plain or
    ``stochastic`` (module docstring): the hand-written gradient reaches the layers', heights' and
    splat maps' texels, the transition and (plain sampling only) the tiling; anything else takes the
    two-step path."""
    module = f"warptex.splat{capacity}" + (".stochastic" if stochastic else "")
    if stochastic:  # loops rather than unrolled copies of the stochastic sampling code, as triplanar's: 37 s to compile for sm_90 unrolled
        for name in (module, module + ".grad"):
            wp.set_module_options({"max_unroll": 1}, module=use(name))
    read = read_layer_stochastic if stochastic else read_layer_plain
    grad_reads = (read_layer_stochastic, scatter_layer_stochastic) if stochastic else (read_layer_plain_once, scatter_layer_plain_once)
    body, scatter_body = _bodies(capacity, read, plain=not stochastic, suffix="_stochastic" if stochastic else "", grad_reads=grad_reads)
    forward, texel_grad, _ = pixel_kernels(f"splat{capacity}" + ("_stochastic" if stochastic else ""), module=module, args=SplatArgs, pixels=SplatPixels, out=wp.array2d(dtype=float),
                                           body=body, scatter=scatter_body, grads=SplatGrads)  # fmt: skip
    grads = ("args.layers", "args.heights", "args.maps", "args.reads.params.transition", None if stochastic else "args.reads.params.tiling")
    name = f"splat{capacity}" + ("_stochastic" if stochastic else "")
    lane, kept_lane, grad_lane = lane_bodies(capacity, SplatPixels, SplatGrads, stochastic)
    lanes = lane_kernel(lane, SplatArgs, SplatPixels, wp.array2d(dtype=float), module=module, name=f"{name}_lanes", covered=splat_covered)
    kept_lanes = None if kept_lane is None else lane_kernel(kept_lane, SplatArgs, SplatPixels, wp.array2d(dtype=float), module=module + ".grad", name=f"{name}_kept_lanes", covered=splat_covered)
    grad_lanes = lane_kernel(grad_lane, SplatArgs, SplatPixels, wp.array2d(dtype=float), grads_t=SplatGrads, module=module + ".grad", name=f"{name}_texel_grad_lanes", covered=splat_covered)
    if stochastic:
        return Kernels(forward, texel_grad, grads=grads, staged=_staged(capacity), lanes=lanes, texel_grad_lanes=grad_lanes, lanes_take=stochastic_lanes_take,
                       grad_lanes_take=stochastic_grad_lanes_take, lane_saved=stochastic_lane_saved)  # fmt: skip
    return Kernels(forward, texel_grad, grads=grads, staged=_staged(capacity), lanes=lanes, texel_grad_lanes=grad_lanes, grad_lanes_take=grad_lanes_take,
                   lane_saved=lane_saved, kept_lanes=kept_lanes)  # fmt: skip
