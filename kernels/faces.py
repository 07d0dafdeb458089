"""The faces of the cube of directions, and the texture a triplanar projection reads on each.

The choice takes the six faces' values one by one (a texture, its texel gradient): passed as one
struct, a ``FaceTextures`` was copied whole into the call, 1.4 KB per pixel (an extra ``memcpy``
per pixel, 6% of a triplanar forward's instructions).

One face order everywhere, public and kernel alike: ``+x, -x, +y, -y, +z, -z`` (:data:`FACES`), so
face ``f`` is axis ``f // 2`` seen from its ``+`` (``f`` even) or ``-`` side. Projection ``a`` reads
the ``+a`` face's texture where the (projected-space) normal has ``n[a] >= 0`` (``sign(0) = +1``,
as the mirror fix's :func:`~warptex.kernels.normals.sign_or_one`), the ``-a`` face's where it is
negative (:func:`on_face`). Where the choice flips, ``n[a] = 0``, projection ``a``'s weight is
0 (for a sharpness > 0, triplanar and biplanar alike), so the seam blends as the others do.

Kernels that read one texture per axis (both faces the same: the default) choose with
:func:`on_axis_face` instead, which never looks at the ``-`` faces: choosing by face costs 7% of a
plain triplanar sample (selecting a ``TextureView`` copies it), paid only where faces differ.
"""

from typing import Any

import warp as wp

from .texels import TexelGrad, TextureView, pick3

#: The faces in the order of every list of six (``textures_per_face``, the ``TriplanarFaces`` fields).
FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


@wp.struct
class FaceTextures:
    """A triplanar launch's six textures, one per face (:data:`FACES`); one texture may stand for
    several faces."""

    px: TextureView
    nx: TextureView
    py: TextureView
    ny: TextureView
    pz: TextureView
    nz: TextureView


@wp.struct
class FaceGrads:
    """The texel gradients of :class:`FaceTextures`' textures (a texture standing for several faces
    has one gradient array, passed for each of them; empty: not needed), and the gradients of the
    projections' tiling, offsets and sharpness, where a kernel of plain sampling takes them by hand
    (colour's all three, normal mapping's stored samples' the tiling and offsets; empty: not needed,
    or not served: ``triplanar.triplanar_kernels``)."""

    px: TexelGrad
    nx: TexelGrad
    py: TexelGrad
    ny: TexelGrad
    pz: TexelGrad
    nz: TexelGrad
    tiling: wp.array(dtype=float)
    offsets: wp.array2d(dtype=float)
    sharpness: wp.array(dtype=float)


#: The input paths of :class:`FaceGrads`' fields, relative to the :class:`FaceTextures` they differentiate.
FACE_FIELDS = ("px", "nx", "py", "ny", "pz", "nz")
#: :class:`FaceGrads`' input paths in a triplanar launch (``Kernels.grads``): plain colour's (the
#: tiling, offsets and sharpness by hand), normal mapping's stored samples' (the tiling and offsets:
#: the sharpness moves the weights, which the second step blends), and stochastic sampling's (texels only).
COLOUR_GRADS = (*(f"args.faces.{f}" for f in FACE_FIELDS), "args.proj.tiling", "args.proj.offsets", "args.proj.sharpness")
SAMPLE_GRADS = (*COLOUR_GRADS[:-1], None)
TEXEL_GRADS = (*COLOUR_GRADS[:-3], None, None, None)


@wp.func
def on_axis(px: Any, py: Any, pz: Any, axis: wp.int32):
    """Projection ``axis``' value among its ``+`` faces' (a texture or its gradient: chosen, then
    used by one call; three inlined copies of the sampling code measured slower)."""
    return pick3(px, py, pz, axis)


@wp.func
def on_face(px: Any, nx: Any, py: Any, ny: Any, pz: Any, nz: Any, axis: wp.int32, n: wp.vec3):
    """Projection ``axis``' value on the face the normal ``n`` looks at (module docstring)."""
    value = on_axis(px, py, pz, axis)
    if n[axis] < 0.0:
        value = on_axis(nx, ny, nz, axis)
    return value


@wp.func
def on_axis_face(px: Any, nx: Any, py: Any, ny: Any, pz: Any, nz: Any, axis: wp.int32, n: wp.vec3):
    """:func:`on_face` where both faces of each axis have one value: the ``+`` face's, whatever the
    normal (the ``-`` faces are not looked at)."""
    return on_axis(px, py, pz, axis)
