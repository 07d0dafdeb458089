"""The ``stochastic`` technique's kernels: stochastic sampling at given UVs (``warptex.stochastic``),
one pixel per launch index and, on the CPU, a lane of pixels per index, forward and texel gradient;
and the hex technique's taps for inspection. The sampling blocks they are built from are in
:mod:`.stochastic`.
"""

import warp as wp

from . import inlined, specialised
from .family import Kernels, family, lane_kernel, pixel_kernels
from .hexgrid import hex_grid, hex_steps, hex_tap, hex_weights
from .lanes.stochastic import lane_bodies, linear_blend_take
from .native import use
from .sampling import SampleArgs, SampleGrads, SamplePixels, sample_footprint_of, sample_layer
from .stochastic import StochasticArgs, periodic_base, sample_stochastic, sample_stochastic_outlined, scatter_stochastic
from .texels import read_channels, write_channels

MODULE = use("warptex.stochastic")


@wp.struct
class StochasticSampleArgs:
    """What every sample of a ``stochastic`` launch reads: ``sample`` as for ``sample`` (the
    per-sample LOD variants), and the technique's options."""

    sample: SampleArgs
    params: StochasticArgs


def _stochastic_body(sample, name: str):
    def body(args: StochasticSampleArgs, pixels: SamplePixels, i: wp.int32, out: wp.array2d(dtype=float)):
        """``out[i, c]`` = channel ``c`` of :func:`sample_stochastic` at ``pixels.uv[i]``."""
        a = args.sample
        write_channels(out, i, sample(a.tex, sample_layer(a, pixels, i), pixels.uv[i], sample_footprint_of(a, pixels, i), a.smp, args.params))

    return inlined(specialised(body, name))


@inlined
def scatter_stochastic_pixel(args: StochasticSampleArgs, pixels: SamplePixels, i: wp.int32, grads: SampleGrads, adj: wp.array2d(dtype=float)):
    """Add the gradient ``adj[i]`` of the stochastic body (linear blends only) into the texels it read."""
    a = args.sample
    scatter_stochastic(a.tex, grads.tex, sample_layer(a, pixels, i), pixels.uv[i], sample_footprint_of(a, pixels, i), a.smp, args.params, read_channels(adj, i))


stochastic_pixel = _stochastic_body(sample_stochastic, "stochastic_pixel")
stochastic_pixel_outlined = _stochastic_body(sample_stochastic_outlined, "stochastic_pixel_outlined")


@family()
def stochastic_kernels() -> Kernels:
    """The ``stochastic`` kernels (per-sample LODs, as ``sample_kernels(level=False)``): the
    hand-written gradient reaches the texels (linear blends: no histogram)."""
    kernels = pixel_kernels("stochastic", module=MODULE, args=StochasticSampleArgs, pixels=SamplePixels, out=wp.array2d(dtype=float),
                            body=stochastic_pixel, scatter=scatter_stochastic_pixel, grads=SampleGrads, adjoint_body=stochastic_pixel_outlined)  # fmt: skip
    stochastic_lane, scatter_stochastic_lane = lane_bodies(StochasticSampleArgs)
    lanes = lane_kernel(stochastic_lane, StochasticSampleArgs, SamplePixels, wp.array2d(dtype=float), module=MODULE, name="stochastic_lanes")
    grad_lanes = lane_kernel(scatter_stochastic_lane, StochasticSampleArgs, SamplePixels, wp.array2d(dtype=float), grads_t=SampleGrads, module=MODULE + ".grad", name="stochastic_texel_grad_lanes")
    return Kernels(*kernels, grads=("args.sample.tex",), lanes=lanes, texel_grad_lanes=grad_lanes, lanes_take=linear_blend_take, grad_lanes_take=linear_blend_take)


@wp.kernel(enable_backward=False, module=MODULE)
def hex_taps_kernel(
    uv: wp.array(dtype=wp.vec2),
    params: StochasticArgs,
    weights: wp.array(dtype=wp.vec3),
    vertices: wp.array2d(dtype=wp.vec2i),
    taps: wp.array2d(dtype=wp.vec2),
):
    """The hex technique's taps at ``uv[i]``: normalised weights, vertex ids and tap UVs (3 each)."""
    i = wp.tid()
    bary, f, v0, v1, v2 = hex_grid(uv[i])
    weights[i] = hex_weights(bary, params.contrast)
    base = periodic_base(uv[i])
    s0, s1, s2 = hex_steps(f)
    vertices[i, 0] = v0
    vertices[i, 1] = v1
    vertices[i, 2] = v2
    taps[i, 0] = hex_tap(uv[i], f, base, v0, s0, params.seed, params.rotation)
    taps[i, 1] = hex_tap(uv[i], f, base, v1, s1, params.seed, params.rotation)
    taps[i, 2] = hex_tap(uv[i], f, base, v2, s2, params.seed, params.rotation)
