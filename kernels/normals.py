"""Tangent-space normal maps: decoding, and blending with a surface normal (whiteout, UDN, RNM).

The blends work in a frame whose ``z`` axis is the surface's main direction: the tangent-space
normal ``t`` (x along ``u``, y along ``v``, z out of the surface) and the base normal ``b`` are
both expressed there. ``b.z`` may be negative (a surface facing down its axis); every blend keeps
the result on ``b``'s side. References: Barré-Brisebois and Hill, "Blending in Detail" (2012);
Golus, "Normal Mapping for a Triplanar Shader" (2017).
"""

import warp as wp

from .texels import FLOAT_MAX

BLEND_WHITEOUT = wp.constant(0)
BLEND_UDN = wp.constant(1)
BLEND_RNM = wp.constant(2)


@wp.struct
class NormalMapArgs:
    """How a normal map is read: ``channels`` (2 to 4), the slopes' ``strength``, ``flip_green``
    for DirectX-style maps, and the ``blend`` with the surface normal (``BLEND_*``)."""

    channels: wp.int32
    strength: float
    flip_green: wp.int32
    blend: wp.int32


@wp.func
def unsquared(n: wp.vec3) -> wp.vec3:
    """``n`` divided by its largest component: its direction, with a length in [1, sqrt(3)] whose
    square cannot overflow. For the rare vectors past ~1.8e19, whose ``|n|²`` is inf; callers test
    ``wp.length(n) > FLOAT_MAX`` first (as :func:`direction` does), so that ordinary vectors keep
    their bits and their cost."""
    return n / wp.max(wp.vec3(wp.abs(n[0]), wp.abs(n[1]), wp.abs(n[2])))


@wp.func
def direction(v: wp.vec3) -> wp.vec3:
    """``wp.normalize(v)`` (the same bits), also for a ``v`` past ~1.8e19, whose ``|v|²``
    overflows and which ``wp.normalize`` would turn into 0: that one is scaled down first."""
    result = wp.normalize(v)
    if wp.length(v) > FLOAT_MAX:
        result = wp.normalize(unsquared(v))
    return result


@wp.func
def decode_normal(texel: wp.vec4, channels: wp.int32, strength: float, flip_green: wp.int32) -> wp.vec3:
    """Tangent-space normal of a normal-map texel stored as ``[0, 1]`` data (flat = ``(0.5, 0.5, 1)``).

    Two-channel maps (BC5-style) rebuild ``z = sqrt(1 - x² - y²)``. ``flip_green`` negates ``y``
    for DirectX-style maps. ``strength`` scales ``x, y`` (0 gives the flat normal, 1 the map as
    authored); the result is normalised (zero if the texel decodes to zero).
    """
    x = texel[0] * 2.0 - 1.0
    y = texel[1] * 2.0 - 1.0
    if flip_green != 0:
        y = -y
    z = 0.0
    if channels >= 3:
        z = texel[2] * 2.0 - 1.0
    else:
        r = 1.0 - x * x - y * y
        if r > 0.0:
            z = wp.sqrt(r)
    t = wp.vec3(x * strength, y * strength, z)
    result = wp.vec3(0.0)
    if wp.length(t) > 0.0:
        result = wp.normalize(t)
    return result


@wp.func
def sign_or_one(x: float) -> float:
    """``sign(x)`` with ``sign(0) = +1``."""
    s = 1.0
    if x < 0.0:
        s = -1.0
    return s


@wp.func
def blend_projected(t: wp.vec3, b: wp.vec3, blend: wp.int32) -> wp.vec3:
    """Blend tangent-space normal ``t`` onto base normal ``b`` (same frame); not normalised.

    - whiteout: ``(t.xy + b.xy, t.z · b.z)``
    - UDN: ``(t.xy + b.xy, b.z)``
    - RNM: reoriented normal mapping with ``n1 = (b.xy, |b.z| + 1)``, ``n2 = (-t.xy, t.z)``,
      ``r = n1 · dot(n1, n2) / n1.z - n2``, and ``r.z`` given ``b.z``'s sign.

    A flat ``t = (0, 0, 1)`` returns ``b`` exactly for all three.
    """
    r = wp.vec3(t[0] + b[0], t[1] + b[1], t[2] * b[2])
    if blend == BLEND_UDN:
        r = wp.vec3(t[0] + b[0], t[1] + b[1], b[2])
    elif blend == BLEND_RNM:
        n1 = wp.vec3(b[0], b[1], wp.abs(b[2]) + 1.0)
        n2 = wp.vec3(-t[0], -t[1], t[2])
        r = n1 * (wp.dot(n1, n2) / n1[2]) - n2
        r = wp.vec3(r[0], r[1], r[2] * sign_or_one(b[2]))
    return r


@wp.func
def to_world(r: wp.vec3, axis: wp.int32) -> wp.vec3:
    """From projection ``axis``' frame (plane coordinates, then the axis) back to world axes:
    ``r.zyx`` for X, ``r.xzy`` for Y, ``r`` for Z."""
    w = r
    if axis == 0:
        w = wp.vec3(r[2], r[1], r[0])
    elif axis == 1:
        w = wp.vec3(r[0], r[2], r[1])
    return w


# -- hand-written gradients (of the normal made from stored samples: normal_blend.normal_from_samples_grad) --


@wp.func
def normalize_grad(v: wp.vec3, g: wp.vec3) -> wp.vec3:
    """The gradient of ``wp.normalize(v)`` for the result's gradient ``g``, as Warp's own adjoint
    makes it: ``(g - u (u · g)) / |v|`` with ``u`` the result; 0 where ``v`` is 0."""
    result = wp.vec3(0.0)
    d = wp.length(v)
    if d > 0.0:
        invd = 1.0 / d
        u = wp.normalize(v)
        result = g * invd - u * wp.dot(u, g) * invd
    return result


@wp.func
def direction_grad(v: wp.vec3, g: wp.vec3) -> wp.vec3:
    """The gradient of :func:`direction` (a finite ``v``) for the result's gradient ``g``. Past
    ~1.8e19 the direction is that of ``v`` scaled by ``1 / m``, ``m`` its largest component, and
    the same function of ``v`` (the scale cancels): its gradient is the scaled vector's over ``m``."""
    result = normalize_grad(v, g)
    if wp.length(v) > FLOAT_MAX:
        result = normalize_grad(unsquared(v), g) / wp.max(wp.vec3(wp.abs(v[0]), wp.abs(v[1]), wp.abs(v[2])))
    return result


@wp.func
def decode_normal_grad(texel: wp.vec4, channels: wp.int32, strength: float, flip_green: wp.int32, g: wp.vec3) -> wp.vec4:
    """The gradient of :func:`decode_normal` in the texel for the result's gradient ``g`` (its
    ``w`` 0: not read; a two-channel map's ``z`` rebuilt from ``x`` and ``y`` adds into theirs)."""
    x = texel[0] * 2.0 - 1.0
    y = texel[1] * 2.0 - 1.0
    if flip_green != 0:
        y = -y
    z = 0.0
    r = 1.0 - x * x - y * y
    if channels >= 3:
        z = texel[2] * 2.0 - 1.0
    elif r > 0.0:
        z = wp.sqrt(r)
    gt = normalize_grad(wp.vec3(x * strength, y * strength, z), g)
    gx = gt[0] * strength
    gy = gt[1] * strength
    gz = 0.0
    if channels >= 3:
        gz = gt[2]
    elif r > 0.0:  # z = sqrt(1 - x² - y²)
        gx = gx - gt[2] * x / z
        gy = gy - gt[2] * y / z
    if flip_green != 0:
        gy = -gy
    return wp.vec4(gx * 2.0, gy * 2.0, gz * 2.0, 0.0)


@wp.func
def blend_projected_grad(b: wp.vec3, blend: wp.int32, g: wp.vec3) -> wp.vec3:
    """The gradient of :func:`blend_projected` in the tangent-space normal ``t`` (not in the base
    normal ``b``) for the result's gradient ``g``: every blend is linear in ``t``."""
    gt = wp.vec3(g[0], g[1], g[2] * b[2])
    if blend == BLEND_UDN:
        gt = wp.vec3(g[0], g[1], 0.0)
    elif blend == BLEND_RNM:
        n1 = wp.vec3(b[0], b[1], wp.abs(b[2]) + 1.0)
        gr = wp.vec3(g[0], g[1], g[2] * sign_or_one(b[2]))
        gn2 = n1 * (wp.dot(n1, gr) / n1[2]) - gr  # r = n1 (n1 · n2) / n1.z - n2
        gt = wp.vec3(-gn2[0], -gn2[1], gn2[2])
    return gt
