"""The faces of the cube of directions, and the texture a triplanar projection reads on each.

One face order everywhere, public and kernel alike: ``+x, -x, +y, -y, +z, -z`` (:data:`FACES`), so
face ``f`` is axis ``f // 2`` seen from its ``+`` (``f`` even) or ``-`` side. Projection ``a`` reads
the ``+a`` face's texture where the (projected-space) normal has ``n[a] >= 0`` (``sign(0) = +1``,
as the mirror fix's :func:`~warptex.kernels.normals.sign_or_one`), the ``-a`` face's where it is
negative (:func:`face_texture`). Where the choice flips, ``n[a] = 0``, projection ``a``'s weight is
0 (for a sharpness > 0, triplanar and biplanar alike), so the seam blends as the others do.

Kernels that read one texture per axis (both faces the same: the default) choose with
:func:`axis_texture` instead, which never looks at the ``-`` faces: choosing by face costs 7% of a
plain triplanar sample (selecting a ``TextureView`` copies it), paid only where faces differ.
"""

import warp as wp

from .texels import TexelGrad, TextureView

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
    has one gradient array, passed for each of them; empty: not needed)."""

    px: TexelGrad
    nx: TexelGrad
    py: TexelGrad
    ny: TexelGrad
    pz: TexelGrad
    nz: TexelGrad


#: The input paths of :class:`FaceGrads`' fields, relative to the :class:`FaceTextures` they differentiate.
FACE_FIELDS = ("px", "nx", "py", "ny", "pz", "nz")


@wp.func
def axis_texture(faces: FaceTextures, axis: wp.int32) -> TextureView:
    """Projection ``axis``' texture on its ``+`` face (chosen, then sampled by one call: three
    inlined copies of the sampling code measured slower)."""
    tex = faces.px
    if axis == 1:
        tex = faces.py
    elif axis == 2:
        tex = faces.pz
    return tex


@wp.func
def face_texture(faces: FaceTextures, axis: wp.int32, n: wp.vec3) -> TextureView:
    """Projection ``axis``' texture on the face the normal ``n`` looks at (module docstring)."""
    tex = axis_texture(faces, axis)
    if n[axis] < 0.0:
        tex = faces.nx
        if axis == 1:
            tex = faces.ny
        elif axis == 2:
            tex = faces.nz
    return tex


@wp.func
def face_texture_per_axis(faces: FaceTextures, axis: wp.int32, n: wp.vec3) -> TextureView:
    """:func:`face_texture` where both faces of each axis have one texture: :func:`axis_texture`."""
    return axis_texture(faces, axis)


@wp.func
def axis_grad(grads: FaceGrads, axis: wp.int32):
    """The texel gradient of :func:`axis_texture`'s texture."""
    grad = grads.px
    if axis == 1:
        grad = grads.py
    elif axis == 2:
        grad = grads.pz
    return grad


@wp.func
def face_grad(grads: FaceGrads, axis: wp.int32, n: wp.vec3):
    """The texel gradient of :func:`face_texture`'s texture."""
    grad = axis_grad(grads, axis)
    if n[axis] < 0.0:
        grad = grads.nx
        if axis == 1:
            grad = grads.ny
        elif axis == 2:
            grad = grads.nz
    return grad


@wp.func
def face_grad_per_axis(grads: FaceGrads, axis: wp.int32, n: wp.vec3):
    """The texel gradient of :func:`face_texture_per_axis`'s texture."""
    return axis_grad(grads, axis)
