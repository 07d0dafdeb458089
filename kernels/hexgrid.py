"""The hex technique's triangle grid (Heitz & Neyret 2018; Mikkelsen 2022): the triangle around a
UV, its barycentric weights, and each vertex's randomly offset (and rotated) tap.

Offsets and angles come from :func:`~warptex.kernels.hashing.hash4_unit` with the stream
``STREAM_HEX_VERTEX``, so results are deterministic per seed on every device.
"""

import warp as wp

from . import hashing
from .hashing import STREAM_HEX_VERTEX

# Triangle grid: p = uv * HEX_SCALE (Heitz & Neyret's 2 sqrt(3): triangle sides of 1/(2 sqrt 3) in
# UV); skewed coordinates s = (p.x - p.y / sqrt 3, 2 p.y / sqrt 3); vertex (i, j) sits at
# p = (i + j / 2, j sqrt(3) / 2).
HEX_SCALE = wp.constant(3.4641016151377544)
INV_SQRT3 = wp.constant(0.5773502691896258)
HALF_SQRT3 = wp.constant(0.8660254037844386)
PI = wp.constant(3.141592653589793)


@wp.func
def hex_grid(uv: wp.vec2):
    """Enclosing triangle of ``uv * HEX_SCALE``: barycentric weights, the position in the
    triangle, and the vertices' lattice ids.

    Returns ``(w, f, v0, v1, v2)``: ``w`` a ``vec3`` summing to 1, ``f`` the skewed coordinates'
    fractions (``uv``'s offset from vertex ``b``), ``vk`` the ``vec2i`` of the vertex weighted by
    ``w[k]``. Lower triangle ``f.x + f.y < 1``: vertices ``b, b+(1,0), b+(0,1)`` with
    ``(1-f.x-f.y, f.x, f.y)``; upper: ``b+(1,1), b+(1,0), b+(0,1)`` with ``(f.x+f.y-1, 1-f.y, 1-f.x)``.
    """
    # In float64: for large UVs the skewed coordinates are large but their fractions must be exact.
    px = wp.float64(uv[0]) * wp.float64(HEX_SCALE)
    py = wp.float64(uv[1]) * wp.float64(HEX_SCALE)
    sx = px - py * wp.float64(INV_SQRT3)
    sy = wp.float64(2.0) * wp.float64(INV_SQRT3) * py
    bx = wp.floor(sx)
    by = wp.floor(sy)
    f = wp.vec2(float(sx - bx), float(sy - by))
    i = lattice_id(bx)
    j = lattice_id(by)
    w = wp.vec3(1.0 - f[0] - f[1], f[0], f[1])
    v0 = wp.vec2i(i, j)
    if f[0] + f[1] >= 1.0:
        w = wp.vec3(f[0] + f[1] - 1.0, 1.0 - f[1], 1.0 - f[0])
        v0 = wp.vec2i(i + 1, j + 1)
    return w, f, v0, wp.vec2i(i + 1, j), wp.vec2i(i, j + 1)


@wp.func
def lattice_id(b: wp.float64) -> wp.int32:
    """A floored skewed coordinate as an int32 lattice id; past 2^30 (UVs beyond ~3e8, where float32
    UVs are 32 apart) wrapped modulo 2^30, so that neither it nor its neighbour overflows int32."""
    limit = wp.float64(1073741824.0)
    if b >= limit or b < -limit:
        b = b - wp.floor(b / limit) * limit
    return int(b)


@wp.func
def hex_centre64(v: wp.vec2i) -> wp.vec2d:
    """UV of triangle-grid vertex ``v``, ``(i + j / 2, j sqrt(3) / 2) / HEX_SCALE``, in float64."""
    scale = wp.float64(HEX_SCALE)
    return wp.vec2d((wp.float64(v[0]) + wp.float64(0.5) * wp.float64(v[1])) / scale, wp.float64(HALF_SQRT3) * wp.float64(v[1]) / scale)


@wp.func
def hex_tap(uv: wp.vec2, f: wp.vec2, base: wp.vec2, v: wp.vec2i, step: wp.vec2, seed: wp.uint32, rotation: float) -> wp.vec2:
    """Tap UV of vertex ``v``: ``R(θ) (uv - c) + c + o`` (reduced by :func:`periodic_base`).

    ``o = (h.x, h.y)``, ``θ = (2 h.z - 1) π rotation`` from ``hash4_unit(v, seed, STREAM_HEX_VERTEX)``,
    ``c`` the vertex centre (:func:`hex_centre64`), ``uv - c`` taken in float64. Past ``|uv| = 1e8``,
    where the vertex ids may have wrapped (:func:`lattice_id`), ``uv - c`` comes instead from the
    skewed offset ``f - step`` of ``uv`` from the vertex (``step``: the vertex's lattice step from
    ``b``, see :func:`hex_grid`) mapped back to UV, ``(x + y / 2, y sqrt(3) / 2) / HEX_SCALE``,
    which stays small however large ``uv``.
    """
    h = hashing.hash4_unit(v[0], v[1], seed, STREAM_HEX_VERTEX)
    tap = base + wp.vec2(h[0], h[1])
    if rotation != 0.0:
        d = wp.vec2(0.0)
        if wp.abs(uv[0]) < 1.0e8 and wp.abs(uv[1]) < 1.0e8:
            # uv - centre in float64: both are large for large UVs, their difference is not.
            c = hex_centre64(v)
            d = wp.vec2(float(wp.float64(uv[0]) - c[0]), float(wp.float64(uv[1]) - c[1]))
        else:
            x = f[0] - step[0]
            y = f[1] - step[1]
            d = wp.vec2(x + 0.5 * y, HALF_SQRT3 * y) / HEX_SCALE
        theta = (2.0 * h[2] - 1.0) * PI * rotation
        cs = wp.cos(theta)
        sn = wp.sin(theta)
        tap += wp.vec2(cs * d[0] - sn * d[1], sn * d[0] + cs * d[1]) - d
    return tap


@wp.func
def hex_steps(f: wp.vec2):
    """The lattice steps from ``b`` of the three vertices of :func:`hex_grid`, in its order."""
    first = wp.vec2(0.0, 0.0)
    if f[0] + f[1] >= 1.0:
        first = wp.vec2(1.0, 1.0)
    return first, wp.vec2(1.0, 0.0), wp.vec2(0.0, 1.0)


@wp.func
def hex_weights(w: wp.vec3, contrast: float) -> wp.vec3:
    """Barycentric weights raised to ``contrast`` and normalised to sum 1. A contrast of 1 (the
    default) takes them as they are, without ``pow``: the same values (``powf(x, 1)`` is ``x`` for
    every float here, checked exhaustively), and most of the CPU lanes' hex taps' time went to it."""
    p = wp.vec3(0.0)
    for k in range(3):
        if w[k] > 0.0:  # pow's adjoint takes log(w): keep exact zeros out of it
            if contrast == 1.0:
                p[k] = w[k]
            else:
                p[k] = wp.pow(w[k], contrast)
    return p / (p[0] + p[1] + p[2])
