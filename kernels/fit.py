"""Fitting: parameterisations, the blur pyramid and the image loss, as Warp kernels.

Every kernel here is differentiable by Warp's autodiff (recorded on a ``wp.Tape``); the optimiser
is Warp's own ``warp.optim.Adam``. Two Warp autodiff rules are kept throughout: vectors are only
ever built fresh from scalars (never written component by component), and a dynamic loop only
accumulates (``acc += f(inputs)``) and its running value is never read by a differentiated
expression in the same kernel (Warp's adjoint does not restore loop-carried values: ``x / Σ``
after a dynamic ``Σ`` loop would divide by the sum's initial value). So the softmax takes three
launches: the per-texel maximum (off the tape: softmax is shift-invariant), the denominator, and
the weights.

Parameterisations::

    softmax:   w_l = exp(z_l - max z) / Σ_k exp(z_k - max z)        per texel, over the L layers
    exp:       tiling = exp(log_tiling)                              positive, scale-invariant steps
    softplus:  s = log(1 + exp(x))  (= x + log(1 + exp(-x)) for x > 0, overflow-free)

Blur: a separable, zero-padded filter ``out[i, j] = Σ_k g[k] · src[i, j + k - r]`` (then along
rows), so the blurred image of a masked render and of a masked target are filtered the same way.

Entropy of the splat weights, ``Σ_texels Σ_l -w_l log w_l · scale``: an optional prior towards
the sparsest weights that render the same (:data:`entropy_kernel`).

Loss over the first ``C`` channels of each pixel, weighted by ``weight[i, j]``, accumulated in
float64::

    L2:  Σ weight · Σ_c (render - target)² · scale
    L1:  Σ weight · Σ_c sqrt((render - target)² + δ²) · scale      (δ = 1e-6: smooth at 0)
"""

import warp as wp

from .native import use

MODULE = use("warptex.fit")

LOSS_L2 = wp.constant(0)
LOSS_L1 = wp.constant(1)
L1_DELTA2 = wp.constant(1.0e-12)


@wp.kernel(module=MODULE)
def logit_max_kernel(logits: wp.array(dtype=float), num_layers: wp.int32, top: wp.array(dtype=float)):
    """``top[t] = max_l logits[l, t]``: the softmax shift of flat texel ``t``.

    Launch it off the tape (``record_tape=False``) into an array without gradients: softmax is
    shift-invariant, so the shift carries no gradient (and Warp's adjoint of a dynamic loop that
    reassigns a running maximum would be wrong).
    """
    t = wp.tid()
    texels = top.shape[0]
    best = float(-3.4e38)
    for l in range(num_layers):
        best = wp.max(best, logits[l * texels + t])
    top[t] = best


@wp.func
def softmax_weight(logits: wp.array(dtype=float), layer: wp.int32, num_layers: wp.int32, texel: wp.int32, texels: wp.int32, top: float, total: float) -> float:
    """Softmax weight of ``layer`` at flat texel ``texel`` (0 for spare channels past the last layer)."""
    w = float(0.0)
    if layer < num_layers:
        w = wp.exp(logits[layer * texels + texel] - top) / total
    return w


@wp.kernel(module=MODULE)
def softmax_total_kernel(logits: wp.array(dtype=float), top: wp.array(dtype=float), num_layers: wp.int32, total: wp.array(dtype=float)):
    """``total[t] = Σ_l exp(logits[l, t] - top[t])``, the softmax denominator of flat texel ``t``.

    A kernel of its own so that the loop only accumulates (``+=``): Warp's adjoint of a dynamic
    loop does not restore loop-carried values, so nothing may *read* ``total`` inside this kernel.
    """
    t = wp.tid()
    texels = top.shape[0]
    acc = float(0.0)
    for l in range(num_layers):
        acc += wp.exp(logits[l * texels + t] - top[t])
    total[t] = acc


@wp.kernel(module=MODULE)
def softmax_kernel(
    logits: wp.array(dtype=float),
    top: wp.array(dtype=float),
    total: wp.array(dtype=float),
    num_layers: wp.int32,
    channels: wp.int32,
    maps: wp.array3d(dtype=wp.vec4),
):
    """``maps[m, i, j]`` channel ``c`` = softmax weight of layer ``m·channels + c``.

    ``logits`` is flat ``[L, H, W]`` (layer-major); ``top`` and ``total`` per flat texel, from
    :data:`logit_max_kernel` and :data:`softmax_total_kernel`; ``maps`` has shape ``(M, H, W)``;
    channels at or past ``channels`` (and past the last layer) are written 0.
    """
    m, i, j = wp.tid()
    w = maps.shape[2]
    texels = maps.shape[1] * w
    texel = i * w + j
    shift = top[texel]
    s = total[texel]
    base = m * channels
    w0 = softmax_weight(logits, base, num_layers, texel, texels, shift, s)
    w1 = float(0.0)
    w2 = float(0.0)
    w3 = float(0.0)
    if channels > 1:
        w1 = softmax_weight(logits, base + 1, num_layers, texel, texels, shift, s)
    if channels > 2:
        w2 = softmax_weight(logits, base + 2, num_layers, texel, texels, shift, s)
    if channels > 3:
        w3 = softmax_weight(logits, base + 3, num_layers, texel, texels, shift, s)
    maps[m, i, j] = wp.vec4(w0, w1, w2, w3)


@wp.func
def entropy_term(w: float, valid: bool) -> float:
    """``-w·log(w)`` (0 for an unused channel; ``w`` floored at 1e-30 inside the log)."""
    e = float(0.0)
    if valid:
        e = -w * wp.log(wp.max(w, 1.0e-30))
    return e


@wp.kernel(module=MODULE)
def entropy_kernel(maps: wp.array3d(dtype=wp.vec4), num_layers: wp.int32, channels: wp.int32, scale: float, loss: wp.array(dtype=wp.float64)):
    """Adds ``scale · Σ_c -w_c log w_c`` of splat-map texel ``maps[m, i, j]`` to ``loss[0]``: the
    entropy of the weights, summed over the maps, i.e. per texel over the layers."""
    m, i, j = wp.tid()
    v = maps[m, i, j]
    base = m * channels
    e = entropy_term(v[0], base < num_layers)
    e += entropy_term(v[1], channels > 1 and base + 1 < num_layers)
    e += entropy_term(v[2], channels > 2 and base + 2 < num_layers)
    e += entropy_term(v[3], channels > 3 and base + 3 < num_layers)
    wp.atomic_add(loss, 0, wp.float64(e * scale))


@wp.kernel(module=MODULE)
def exp_kernel(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    """``out = exp(x)``: log-scale parameters (tiling)."""
    i = wp.tid()
    out[i] = wp.exp(x[i])


@wp.kernel(module=MODULE)
def softplus_kernel(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    """``out = log(1 + exp(x)) = max(x, 0) + log1p(exp(-|x|))``: no overflow for large ``x``, no
    underflow to 0 for very negative ``x``."""
    i = wp.tid()
    v = x[i]
    e = float(0.0)  # exp(-|x|), from a branch each side so the adjoint is exact at 0 too
    if v > 0.0:
        e = wp.exp(-v)
    else:
        e = wp.exp(v)
    tail = wp.log(1.0 + e)
    if e < 1.0e-4:  # log1p(e) ≈ e - e²/2, where 1 + e rounds to 1 in float32
        tail = e - 0.5 * e * e
    if v > 0.0:
        out[i] = v + tail
    else:
        out[i] = tail


@wp.kernel(module=MODULE)
def blur_kernel(src: wp.array3d(dtype=float), taps: wp.array(dtype=float), step_i: wp.int32, step_j: wp.int32, dst: wp.array3d(dtype=float)):
    """One pass of a separable filter along ``(step_i, step_j)``, ``(0, 1)`` for rows (x) or
    ``(1, 0)`` for columns (y): ``dst[i, j, c] = Σ_k taps[k] · src[i + (k - r)·step_i, j + (k - r)·step_j, c]``,
    zero outside the image."""
    i, j, c = wp.tid()
    radius = (taps.shape[0] - 1) // 2
    acc = float(0.0)
    for k in range(taps.shape[0]):
        ii = i + (k - radius) * step_i
        jj = j + (k - radius) * step_j
        if ii >= 0 and ii < src.shape[0] and jj >= 0 and jj < src.shape[1]:
            acc += taps[k] * src[ii, jj, c]
    dst[i, j, c] = acc


@wp.kernel(module=MODULE)
def mask_kernel(src: wp.array3d(dtype=float), mask: wp.array2d(dtype=float), dst: wp.array3d(dtype=float)):
    """``dst = src · mask`` per pixel."""
    i, j, c = wp.tid()
    dst[i, j, c] = src[i, j, c] * mask[i, j]


@wp.kernel(module=MODULE)
def image_loss_kernel(
    render: wp.array3d(dtype=float),
    target: wp.array3d(dtype=float),
    weight: wp.array2d(dtype=float),
    kind: wp.int32,
    scale: float,
    loss: wp.array(dtype=wp.float64),
):
    """Adds ``scale · weight · Σ_c ρ(render - target)`` of pixel ``(i, j)`` to ``loss[0]`` (float64).

    The channels compared are the target's (the render may have more, e.g. a height channel).
    """
    i, j = wp.tid()
    wgt = weight[i, j]
    if wgt != 0.0:
        acc = float(0.0)
        for c in range(target.shape[2]):
            d = render[i, j, c] - target[i, j, c]
            if kind == LOSS_L2:
                acc += d * d
            else:
                acc += wp.sqrt(d * d + L1_DELTA2)
        wp.atomic_add(loss, 0, wp.float64(acc * wgt * scale))
