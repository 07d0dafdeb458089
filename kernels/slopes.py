"""What the hand-written gradients of triplanar and biplanar mapping add for the parameters every
pixel shares: each projection read's share of the tiling's, offsets' and sharpness' gradients
(:func:`add_plane_slopes`), from the read's slopes (:func:`~.projection.plane_sample_slope`) and the
weights' slopes along the sharpness (:func:`projection_weights_slope`: the weight functions of
:mod:`.projection` differentiated step by step, as Warp's generated adjoint takes them).
"""

import warp as wp

from .faces import FaceGrads
from .projection import BIPLANAR_EDGE, WEIGHT_EPS, WEIGHTS_BIPLANAR, ProjectionArgs, biplanar_axes, biplanar_spread, plane_sample_slope, power_weight, projection_tiling
from .texels import SamplerArgs, TextureView


@wp.func
def power_slope(r: float, exponent: float) -> float:
    """``d r^exponent / d exponent`` as :func:`~.projection.adj_power_weight` takes it:
    ``r^exponent ln r`` for ``r > 0``, 0 at ``r = 0``."""
    s = 0.0
    if r > 0.0:
        s = power_weight(r, exponent) * wp.log(r)
    return s


@wp.func
def normalised_slope(w: wp.vec3, dw: wp.vec3) -> wp.vec3:
    """The slope of ``w / max(w[0] + w[1] + w[2], WEIGHT_EPS)`` for the slope ``dw`` of ``w``."""
    total = w[0] + w[1] + w[2]
    d = dw / WEIGHT_EPS
    if total >= WEIGHT_EPS:
        d = (dw - w * ((dw[0] + dw[1] + dw[2]) / total)) / total
    return d


@wp.func
def triplanar_weights_slope(n: wp.vec3, sharpness: float) -> wp.vec3:
    """``d w / d sharpness`` of :func:`~.projection.triplanar_weights` ``w``, the same steps
    differentiated."""
    a = wp.vec3(wp.abs(n[0]), wp.abs(n[1]), wp.abs(n[2]))
    m = wp.max(a)
    d = wp.vec3(0.0)
    if wp.isfinite(n) and m > 0.0:
        w = wp.vec3(power_weight(a[0] / m, sharpness), power_weight(a[1] / m, sharpness), power_weight(a[2] / m, sharpness))
        d = normalised_slope(w, wp.vec3(power_slope(a[0] / m, sharpness), power_slope(a[1] / m, sharpness), power_slope(a[2] / m, sharpness)))
    return d


@wp.func
def biplanar_pair_slope(major: float, median: float, exponent: float):
    """``(w, d w / d exponent)`` of :func:`~.projection.biplanar_pair` ``w``, the same steps
    differentiated."""
    b0 = wp.clamp((major - BIPLANAR_EDGE) / (1.0 - BIPLANAR_EDGE), 0.0, 1.0)
    b1 = wp.clamp((median - BIPLANAR_EDGE) / (1.0 - BIPLANAR_EDGE), 0.0, 1.0)
    w = wp.vec2(power_weight(b0, exponent), power_weight(b1, exponent))
    d = wp.vec2(power_slope(b0, exponent), power_slope(b1, exponent))
    if w[0] + w[1] < WEIGHT_EPS:
        m = wp.max(b0, b1)
        w = wp.vec2(1.0, 1.0)
        d = wp.vec2(0.0, 0.0)
        if m > 0.0:
            w = wp.vec2(power_weight(b0 / m, exponent), power_weight(b1 / m, exponent))
            d = wp.vec2(power_slope(b0 / m, exponent), power_slope(b1 / m, exponent))
    return w, d


@wp.func
def biplanar_weights_slope(n: wp.vec3, sharpness: float) -> wp.vec3:
    """``d w / d sharpness`` of :func:`~.projection.biplanar_weights` ``w``, the same steps
    differentiated (its exponent is ``sharpness / 8``)."""
    d = wp.vec3(0.0)
    major, median, minor = biplanar_axes(n)
    if minor >= 0:
        pair, slope = biplanar_pair_slope(major, median, sharpness / 8.0)
        d = normalised_slope(biplanar_spread(pair, minor), biplanar_spread(slope, minor)) / 8.0
    return d


@wp.func
def projection_weights_slope(proj: ProjectionArgs, n: wp.vec3) -> wp.vec3:
    """``d w / d sharpness`` of :func:`~.projection.projection_weights` ``w``: the sharpness'
    gradient of a blend ``Σ w[a] · read[a]`` is ``Σ dot(g, read[a]) · d w[a] / d sharpness``."""
    d = wp.vec3(0.0)
    if proj.weights == WEIGHTS_BIPLANAR:
        d = biplanar_weights_slope(n, proj.sharpness[0])
    else:
        d = triplanar_weights_slope(n, proj.sharpness[0])
    return d


@wp.func
def add_plane_slopes(tex: TextureView, layer: wp.int32, proj: ProjectionArgs, smp: SamplerArgs, grads: FaceGrads, axis: wp.int32, p: wp.vec3, n: wp.vec3, dpdx: wp.vec3, dpdy: wp.vec3, wg: wp.vec4, g: wp.vec4, dw: float):
    """Adds plain projection read ``axis``' share of the tiling's, offsets' and sharpness' gradients
    into ``grads`` where they are needed (not empty), from the read's slopes
    (:func:`~.projection.plane_sample_slope`): ``dot(wg, d read / d tiling)`` and
    ``dot(wg, d read / d uv)`` for the read's gradient ``wg``, and ``dw · dot(g, read)`` for the
    blend's gradient ``g`` and the slope ``dw`` of the read's weight along the sharpness."""
    if grads.tiling.shape[0] > 0 or grads.offsets.shape[0] > 0 or grads.sharpness.shape[0] > 0:
        value, slope, d_u, d_v = plane_sample_slope(tex, layer, proj, axis, p, n, dpdx, dpdy, projection_tiling(proj, axis), smp)
        if grads.tiling.shape[0] > 0:
            wp.atomic_add(grads.tiling, wp.min(axis, grads.tiling.shape[0] - 1), wp.dot(wg, slope))
        if grads.offsets.shape[0] > 0:
            wp.atomic_add(grads.offsets, axis, 0, wp.dot(wg, d_u))
            wp.atomic_add(grads.offsets, axis, 1, wp.dot(wg, d_v))
        if grads.sharpness.shape[0] > 0:
            wp.atomic_add(grads.sharpness, 0, dw * wp.dot(g, value))
