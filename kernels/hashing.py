"""Small integer hashes for procedural randomness that is identical on every device.

The hash is ``pcg4d`` from Jarzynski & Olano, "Hash Functions for GPU Rendering" (JCGT 9(3),
2020): four 32-bit unsigned lanes go through one linear congruential step and two rounds of
cross-lane multiply-adds around a xor-shift. It uses only wrapping ``uint32`` multiplication,
addition, xor and shifts, so CPU and CUDA (and the NumPy reference in the tests) produce the same
bits for the same input; no floating-point operation is involved until the final conversion,
which is exact.

Conventions used by warptex:

* lanes ``(x, y, seed, stream)``: two signed integer lattice coordinates (reinterpreted as
  ``uint32`` two's complement, so ``-1`` is ``0xFFFFFFFF``), the user's seed, and a small stream
  number that keeps the random values of different techniques independent;
* a ``uint32`` becomes a float in ``[0, 1)`` from its top 24 bits, ``(h >> 8) * 2**-24``, which
  float32 represents exactly.
"""

import warp as wp

PCG_MULTIPLIER = wp.constant(wp.uint32(1664525))
PCG_INCREMENT = wp.constant(wp.uint32(1013904223))
SHIFT_16 = wp.constant(wp.uint32(16))
SHIFT_8 = wp.constant(wp.uint32(8))
INV_2_24 = wp.constant(1.0 / 16777216.0)

# The streams (the fourth lane) of warptex's uses: one each, so their random values are independent.
STREAM_HASH4_CELL = wp.constant(0)  # stochastic hash4: each cell's offset
STREAM_CHEAP2_OFFSET = wp.constant(1)  # stochastic cheap2: the offsets its noise picks among
STREAM_CHEAP2_NOISE = wp.constant(2)  # stochastic cheap2: the value noise
STREAM_HEX_VERTEX = wp.constant(3)  # stochastic hex: each triangle-grid vertex's offset and angle


@wp.func
def pcg4d(a: wp.uint32, b: wp.uint32, c: wp.uint32, d: wp.uint32) -> wp.vec4ui:
    """``pcg4d`` (Jarzynski & Olano 2020): four ``uint32`` in, four well-mixed ``uint32`` out.

    ``v = v * 1664525 + 1013904223``; ``v.x += v.y*v.w; v.y += v.z*v.x; v.z += v.x*v.y;
    v.w += v.y*v.z``; ``v ^= v >> 16``; the four multiply-adds again. All arithmetic wraps mod 2^32
    and each lane update uses the lanes as already updated.
    """
    x = a * PCG_MULTIPLIER + PCG_INCREMENT
    y = b * PCG_MULTIPLIER + PCG_INCREMENT
    z = c * PCG_MULTIPLIER + PCG_INCREMENT
    w = d * PCG_MULTIPLIER + PCG_INCREMENT
    x += y * w
    y += z * x
    z += x * y
    w += y * z
    x = x ^ (x >> SHIFT_16)
    y = y ^ (y >> SHIFT_16)
    z = z ^ (z >> SHIFT_16)
    w = w ^ (w >> SHIFT_16)
    x += y * w
    y += z * x
    z += x * y
    w += y * z
    return wp.vec4ui(x, y, z, w)


@wp.func
def uint_to_unit(h: wp.uint32) -> float:
    """A ``uint32`` as a float in ``[0, 1)`` from its top 24 bits (exact in float32)."""
    return float(h >> SHIFT_8) * INV_2_24


@wp.func
def hash4_unit(x: wp.int32, y: wp.int32, seed: wp.uint32, stream: wp.int32) -> wp.vec4:
    """Four independent uniform numbers in ``[0, 1)`` for the lattice point ``(x, y)``.

    ``pcg4d(uint32(x), uint32(y), seed, uint32(stream))`` lane by lane through :func:`uint_to_unit`.
    """
    h = pcg4d(wp.uint32(x), wp.uint32(y), seed, wp.uint32(stream))
    return wp.vec4(uint_to_unit(h[0]), uint_to_unit(h[1]), uint_to_unit(h[2]), uint_to_unit(h[3]))
