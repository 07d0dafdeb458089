"""Triplanar and biplanar mapping and triplanar normal mapping over a G-buffer.

Surfaces without usable UVs are textured by projecting the world (or object) position onto the
three axis planes, ``p.zy`` (X plane), ``p.xz`` (Y plane) and ``p.xy`` (Z plane), and blending the
projections by the surface normal. One texture serves every projection, or one per axis
(``textures_per_axis``), or one per face of the cube of directions (``textures_per_face``: a
projection reads its ``+`` or ``-`` face's by the sign of the normal, e.g. grass on top and rock
beneath). Formulas and conventions: :mod:`warptex.kernels.triplanar`.

Differentiable parameters (``tiling``, ``sharpness``, ``offsets``) may be given as float32
``wp.array``\\ s with ``requires_grad=True``; a ``wp.Tape`` then carries gradients into them, as it
does into the textures' texels.
"""

from __future__ import annotations

import inspect
from typing import Sequence

import numpy as np
import warp as wp

from warptex import _plan
from warptex._op import run
from warptex._pack import SURFACE, footprints, out_array, packed, projection_args, sampler_args, stochastic_args, surface_pixels
from warptex._validate import as_enum, as_float, warn_renamed
from warptex.gbuffer import GBuffer, _gbuffer_device
from warptex.kernels import faces as kf
from warptex.kernels import normals as kn
from warptex.kernels import projection as kp
from warptex.kernels import triplanar as kt
from warptex.kernels.stochastic import METHOD_NONE
from warptex.options import Blend, Sampler, Space, Stochastic, _as_sampler, _as_stochastic
from warptex.texture import TextureArray


_BLEND_IDS = {Blend.WHITEOUT: kn.BLEND_WHITEOUT, Blend.UDN: kn.BLEND_UDN, Blend.RNM: kn.BLEND_RNM}


def triplanar(
    gbuffer: GBuffer,
    texture: TextureArray | None = None,
    *,
    tiling=1.0,
    sharpness=4.0,
    offsets=None,
    mirror_fix: bool = True,
    textures_per_axis: Sequence[TextureArray | None] | None = None,
    textures_per_face: Sequence[TextureArray | None] | None = None,
    layer: int = 0,
    space: Space | str = Space.WORLD,
    object_to_world=None,
    stochastic: Stochastic | str | None = None,
    sampler: Sampler | None = None,
    device=None,
    out=None,
) -> wp.array:
    """Triplanar mapping: three plane projections blended by ``pow(|n|, sharpness)``.

    Per pixel, projection ``a`` (X, Y, Z) reads its texture at
    ``uv_a = plane_a(p) · tiling_a`` with ``u`` flipped on back-facing sides (``mirror_fix``) plus
    ``offsets[a]``, at the LOD of its own footprint (the plane components of the G-buffer's
    position derivatives × tiling), and the results are blended with
    ``w = pow(|n|, sharpness) / sum``.

    Args:
        gbuffer: the :class:`~warptex.gbuffer.GBuffer` (``position``, ``normal``, their derivatives
            and ``mask`` are read), ``(H, W)``.
        texture: a :class:`Texture` or :class:`TextureArray` with ``C`` channels, used for every
            projection that ``textures_per_axis`` does not override.
        tiling: texture repeats per unit of length: a number, 3 numbers (X, Y, Z projections), or
            a float32 ``wp.array`` of shape ``(1,)`` or ``(3,)`` (receives gradients). Non-zero.
        sharpness: blend exponent ``k >= 0`` (0: equal weights; large: the dominant axis only), a
            number or a float32 ``wp.array`` of shape ``(1,)`` (receives gradients).
        offsets: UV offsets per projection, ``(3, 2)`` (e.g. ``[[0, .33], [0, 0], [.33, 0]]`` to
            decorrelate the planes), or a float32 ``wp.array`` of that shape (receives gradients).
        mirror_fix: flip ``u`` on faces that look down the negative (X, Y) or positive (Z) axis,
            so that every face reads the right way round in warptex's right-handed world.
        textures_per_axis: ``(x, y, z)``: textures for the X (side), Y (top) and Z (front)
            projections; ``None`` entries fall back to ``texture``. All need ``C`` channels and
            ``layer``; sizes may differ.
        textures_per_face: ``(+x, -x, +y, -y, +z, -z)``: a texture per face, e.g. grass on top
            (``+y``) and rock beneath (``-y``). Projection ``a`` reads the ``+a`` face's texture where
            the normal (in ``space``) has ``n[a] >= 0``, the ``-a`` face's where ``n[a] < 0``; the seam
            between them lies where projection ``a``'s weight is 0, so it blends as the others do
            (for ``sharpness > 0``). ``None`` entries fall back to ``textures_per_axis[a]``, then to
            ``texture``. Same requirements as ``textures_per_axis``; gradients reach every face's
            texels.
        layer: the layer to read from texture arrays.
        space: :class:`Space`: ``"world"`` or ``"object"`` (needs ``object_to_world``).
        object_to_world: ``(4, 4)`` affine matrix of the object, for ``space="object"``.
        stochastic: ``None`` (plain tiling), or anti-tiling for every projection: a
            :class:`~warptex.Stochastic` (or a method name, ``"hash4"``, ``"cheap2"``, ``"hex"``),
            see :func:`warptex.stochastic`. Each projection's taps share its unperturbed LOD.
            Needs a ``sampler`` address of ``"wrap"`` or ``"mirror"``; a histogram needs one
            texture for all projections and faces.
        sampler: a :class:`~warptex.Sampler` for every projection; its ``"auto"`` filter is
            trilinear (the G-buffer's derivatives give every pixel a LOD).
        device: Warp device; must be the G-buffer's and the textures'.
        out: a float32 ``wp.array`` of shape ``(H, W, C)`` on the device, to fill in place and
            return (a loop's buffer, reused call after call); ``None``: a new array. It must not
            overlap an input.

    Returns:
        ``wp.array`` of float32 (``out`` when given), shape ``(H, W, C)``: 0 where the mask is 0 or the normal is zero
        or non-finite. Recorded on the active ``wp.Tape``: gradients reach the texels,
        ``tiling``, ``sharpness`` and ``offsets`` when those are arrays that require them.
    """
    return _colour(
        "triplanar", kp.WEIGHTS_TRIPLANAR, gbuffer, texture, tiling=tiling, sharpness=sharpness, offsets=offsets, mirror_fix=mirror_fix, textures_per_axis=textures_per_axis,
        textures_per_face=textures_per_face, layer=layer, space=space, object_to_world=object_to_world, stochastic=stochastic, sampler=sampler, device=device, out=out,
    )  # fmt: skip


def biplanar(gbuffer: GBuffer, texture: TextureArray | None = None, *, sharpness=8.0, **options) -> wp.array:
    """Biplanar mapping (Quilez): only the major and median projections, at most two taps.

    The weights are ``clamp((|n_a| - 0.5773) / (1 - 0.5773), 0, 1) ^ (sharpness / 8)`` for the
    major and median axes of the normal, 0 for the minor axis, normalised. Everything else (UVs,
    mirror fix, offsets, LOD, textures per axis or per face, stochastic sampling, gradients) is as in
    :func:`triplanar`; the default ``sharpness=8`` is Quilez' (exponent 1).

    Args:
        gbuffer, texture: as for :func:`triplanar`.
        sharpness: the blend exponent ``k >= 0`` (a number or a float32 ``wp.array`` of shape
            ``(1,)``, receives gradients); the weights' exponent is ``k / 8``.
        options: :func:`triplanar`'s other keywords, with its defaults: ``tiling``, ``offsets``,
            ``mirror_fix``, ``textures_per_axis``, ``textures_per_face``, ``layer``, ``space``,
            ``object_to_world``, ``stochastic``, ``sampler``, ``device``, ``out``.

    Returns:
        As :func:`triplanar`.
    """
    options = {**_Setup.DEFAULTS, **_Setup.options("biplanar", "triplanar", options)}
    return _colour("biplanar", kp.WEIGHTS_BIPLANAR, gbuffer, texture, sharpness=sharpness, **options)


def _colour(func, weights, gbuffer, texture, *, device, out, **options) -> wp.array:
    """Colour mapping, every option given: a small call repeated on the same objects reruns its launch (``warptex._plan``)."""
    device = _gbuffer_device(func, gbuffer, device)
    key = _args_key(weights, gbuffer, texture, device, **options)
    plan = key if (out is None or type(out) is wp.array) and _plan.usable() else None
    objects = (gbuffer, texture, *(getattr(gbuffer, name) for name in SURFACE)) if plan is not None else ()
    done = _plan.rerun(plan, objects, gbuffer.resolution, out=out) if plan is not None else None
    if done is not None:
        return done
    setup = _Setup(func, weights, gbuffer, texture, **options, device=device, out=out, key=key)
    with _plan.recording(plan, objects, out=out, hold=(setup.args,)):
        return setup.launch(setup.channels)


def triplanar_normal(
    gbuffer: GBuffer,
    normal_map: TextureArray | None = None,
    *,
    tiling=1.0,
    sharpness=4.0,
    offsets=None,
    mirror_fix: bool = True,
    textures_per_axis: Sequence[TextureArray | None] | None = None,
    textures_per_face: Sequence[TextureArray | None] | None = None,
    layer: int = 0,
    blend: Blend | str = Blend.WHITEOUT,
    strength: float = 1.0,
    flip_green: bool = False,
    biplanar: bool | None = None,
    space: Space | str = Space.WORLD,
    object_to_world=None,
    stochastic: Stochastic | str | None = None,
    sampler: Sampler | None = None,
    device=None,
    out=None,
) -> wp.array:
    """Triplanar normal mapping (Golus): unit world-space normals perturbed by a tangent-space map.

    Each projection reads the normal map where :func:`triplanar` would read colour, decodes it
    (``[0, 1]`` data; flat is ``(0.5, 0.5, 1)``; two-channel maps rebuild ``z``), scales its
    ``x, y`` by ``strength``, flips ``x`` with the mirror fix, blends it with the surface normal
    in that projection's frame (:class:`Blend`), swizzles it back to world axes (``.zyx``,
    ``.xzy``, ``.xyz``), and the weighted sum is normalised. A flat map returns the surface normal
    exactly. Each tangent frame ``(dp/du, dp/dv, n)`` is right-handed, as OpenGL-style (green up)
    maps expect.

    Args:
        normal_map: a texture of 2 to 4 channels holding a tangent-space normal map as data (load
            it with ``Texture.from_file(path, data=True)``, not sRGB-decoded).
        blend: :class:`Blend`: ``"whiteout"``, ``"udn"`` or ``"rnm"``.
        strength: ``>= 0``; scales the map's slopes (0: flat, 1: as authored).
        flip_green: for DirectX-style (green down) maps.
        biplanar: deprecated: call :func:`biplanar_normal`, which weights the projections as
            :func:`biplanar` does (with Quilez' ``sharpness=8`` by default).
        stochastic: as for :func:`triplanar`, without ``mirror`` or ``rotation`` (they would turn
            the map's slopes without turning its tangent frame).
        textures_per_axis, textures_per_face: normal maps per projection or per face, as the
            colour textures of :func:`triplanar` (each face's map is read in that face's frame).
        Other arguments: as for :func:`triplanar`.

    Returns:
        ``wp.array`` of float32, shape ``(H, W, 3)``: unit normals, ``(0, 0, 0)`` where the mask
        is 0 or the surface normal is zero or non-finite. Differentiable like :func:`triplanar`.
    """
    if biplanar is not None:
        warn_renamed("triplanar_normal(biplanar=...)", "warptex.biplanar_normal(...) for biplanar weights")
    options = dict(tiling=tiling, offsets=offsets, mirror_fix=mirror_fix, textures_per_axis=textures_per_axis, textures_per_face=textures_per_face, layer=layer,
                   space=space, object_to_world=object_to_world, stochastic=stochastic, sampler=sampler, device=device, out=out)  # fmt: skip
    weights = kp.WEIGHTS_BIPLANAR if biplanar else kp.WEIGHTS_TRIPLANAR
    return _normal_mapping("triplanar_normal", weights, gbuffer, normal_map, sharpness=sharpness, blend=blend, strength=strength, flip_green=flip_green, **options)


def biplanar_normal(
    gbuffer: GBuffer, normal_map: TextureArray | None = None, *, sharpness=8.0, blend: Blend | str = Blend.WHITEOUT, strength: float = 1.0, flip_green: bool = False, **options
) -> wp.array:
    """Biplanar normal mapping: :func:`triplanar_normal` with the projections weighted as
    :func:`biplanar` weights them (the major and median axes only, at most two taps).

    Args:
        gbuffer, normal_map, blend, strength, flip_green: as for :func:`triplanar_normal`.
        sharpness: as for :func:`biplanar` (default 8: Quilez' exponent 1).
        options: :func:`triplanar`'s other keywords, with its defaults: ``tiling``, ``offsets``,
            ``mirror_fix``, ``textures_per_axis``, ``textures_per_face``, ``layer``, ``space``,
            ``object_to_world``, ``stochastic`` (as for :func:`triplanar_normal`), ``sampler``,
            ``device``, ``out``.

    Returns:
        As :func:`triplanar_normal`.
    """
    options = _Setup.options("biplanar_normal", "triplanar_normal", options)
    return _normal_mapping("biplanar_normal", kp.WEIGHTS_BIPLANAR, gbuffer, normal_map, sharpness=sharpness, blend=blend, strength=strength, flip_green=flip_green, **options)


# -- internals --------------------------------------------------------------------------------------


def _normal_mapping(func, weights, gbuffer, normal_map, *, blend, strength, flip_green, stochastic=None, **options) -> wp.array:
    """Normal mapping with the projections weighted by ``weights`` (``kp.WEIGHTS_*``): the body of
    :func:`triplanar_normal` and :func:`biplanar_normal`."""
    blend_id = _BLEND_IDS[as_enum(func, "blend", blend, Blend)]
    strength = as_float(func, "strength", strength)
    if strength < 0:
        raise ValueError(f"{func}(): strength must be >= 0, got {strength}")
    option = _as_stochastic(func, stochastic)
    if option.mirror or option.rotation:
        raise ValueError(f"{func}(): stochastic mirror and rotation would turn a normal map's slopes without its tangent frame; use neither")
    normal = (blend_id, strength, bool(flip_green))
    full = {**_Setup.DEFAULTS, **options, "stochastic": option}
    device = _gbuffer_device(func, gbuffer, full.pop("device"))
    key = _args_key(weights, gbuffer, normal_map, device, **{k: v for k, v in full.items() if k != "out"})
    setup = _Setup(func, weights, gbuffer, normal_map, **full, device=device, key=None if key is None else (*key, "normal", *normal), normal=normal)
    return setup.launch(3)


class _Setup:
    """The checked, packed inputs of the public functions, and their launch."""

    #: The keyword options every projection function takes (``biplanar``'s ``**options``).
    OPTIONS = ("tiling", "offsets", "mirror_fix", "textures_per_axis", "textures_per_face", "layer", "space", "object_to_world", "stochastic", "sampler", "device", "out")
    DEFAULTS = {name: inspect.signature(triplanar).parameters[name].default for name in OPTIONS}  #: triplanar()'s

    @staticmethod
    def options(func: str, like: str, options: dict) -> dict:
        """``options`` (a ``**options`` of ``func``), or a ``TypeError`` naming the first unknown one."""
        unknown = sorted(set(options) - set(_Setup.OPTIONS))
        if unknown:
            raise TypeError(f"{func}() got an unexpected keyword argument {unknown[0]!r} (its options are {like}()'s: {', '.join(_Setup.OPTIONS)})")
        return options

    def __init__(
        self, func, weights, gbuffer, texture, *, tiling=1.0, sharpness=4.0, offsets=None, mirror_fix=True, textures_per_axis=None, textures_per_face=None,
        layer=0, space=Space.WORLD, object_to_world=None, stochastic=None, sampler=None, device=None, out=None, key=None, normal=None,
    ):  # fmt: skip
        device = _gbuffer_device(func, gbuffer, device)
        self.func, self.gbuffer, self.device, self.out = func, gbuffer, device, out
        self.count = gbuffer.pixel_count
        self.pixels = surface_pixels(func, gbuffer, device)
        options = {"tiling": tiling, "sharpness": sharpness, "offsets": offsets, "mirror_fix": mirror_fix, "textures_per_axis": textures_per_axis, "textures_per_face": textures_per_face,
                   "layer": layer, "space": space, "object_to_world": object_to_world, "stochastic": stochastic, "sampler": sampler}  # fmt: skip
        build = lambda: _packed_args(func, weights, gbuffer, texture, device, normal=normal, **options)  # noqa: E731
        # key (_args_key, with normal's values): the same texture, options and origin, checked and packed by an earlier call.
        self.args, self.channels, self.stochastic, self.faces, self.linear = build() if key is None else packed(texture, key, build)
        self.normal = normal is not None

    def launch(self, channels: int) -> wp.array:
        """Run colour mapping (or normal mapping, where the setup has a normal map's options) into a
        new ``(H, W, channels)`` array, or the caller's ``out``."""
        into = out_array(self.func, self.out, (*self.gbuffer.resolution, channels), self.device)
        kernels = kt.triplanar_kernels(normal=self.normal, stochastic=self.stochastic, faces=self.faces)
        result = run(kernels, self.count, args=self.args, pixels=self.pixels, out=((self.count, channels), float) if into is None else into, device=self.device,
                     linear=self.linear, covered=self.pixels.mask, footprints=footprints(self.args.smp, self.args.stoch, lookups=3))
        return self.out if into is not None else result.reshape((*self.gbuffer.resolution, channels))


def _packed_args(func, weights, gbuffer, texture, device, *, tiling, sharpness, offsets, mirror_fix, textures_per_axis, textures_per_face, layer, space,
                 object_to_world, stochastic, sampler, normal=None) -> tuple:  # fmt: skip
    """``(args, channels, stochastic, faces, linear)``: the checked options packed for the kernels
    (with ``normal``, ``(blend, strength, flip_green)``: a normal map's)."""
    textures = _textures(func, texture, textures_per_axis, textures_per_face, layer, device)
    object_to_world = _object_to_world(func, space, object_to_world)
    proj = projection_args(func, tiling=tiling, sharpness=sharpness, offsets=offsets, mirror_fix=mirror_fix, weights=weights, object_to_world=object_to_world,
                           origin=gbuffer.origin, address=_as_sampler(func, sampler).address, device=device)  # fmt: skip
    option, sampler = _as_stochastic(func, stochastic), _as_sampler(func, sampler)
    if option.histogram is not None and not all(t is textures[0] for t in textures):
        raise ValueError(f"{func}(): a stochastic histogram needs one texture for every projection (textures_per_axis or textures_per_face differ)")
    stoch, sampled = stochastic_args(func, option, textures[0], sampler)
    if sampled is not textures[0]:  # a histogram: every projection reads its Gaussianised texture
        textures = [sampled] * len(textures)
    args = kt.TriplanarArgs()
    for name, t in zip(kf.FACE_FIELDS, textures):  # into the struct's own faces (assigning a struct copies it field by field)
        setattr(args.faces, name, t.view)
    args.layer, args.proj, args.smp, args.stoch = layer, proj, sampler_args(func, sampler, has_lod=True), stoch
    if normal is not None:
        if textures[0].channels < 2:
            raise ValueError(f"{func}(): a normal map needs 2 to 4 channels, got {textures[0].channels}")
        nm = args.normal_map  # filled in place, as args.faces
        nm.channels, nm.blend, nm.strength, nm.flip_green = textures[0].channels, normal[0], normal[1], int(normal[2])
    faces = any(textures[2 * a] is not textures[2 * a + 1] for a in range(3))  # a face of some axis differs from its opposite
    return args, textures[0].channels, stoch.method != METHOD_NONE, faces, stoch.histogram == 0  # a histogram blend is not linear in the texels


def _args_key(weights, gbuffer, texture, device, *, tiling, sharpness, offsets, mirror_fix, textures_per_axis, textures_per_face, layer, space, object_to_world, stochastic, sampler):
    """The key under which colour mapping's packed arguments are kept with the texture
    (``warptex._pack.packed``: a small call otherwise spends most of its time packing the same Warp
    structs again), or ``None`` where they are not kept: one texture, options given as plain values
    (an array option may receive gradients, and may change in place), no histogram, hashable
    option objects."""
    if textures_per_axis is not None or textures_per_face is not None or object_to_world is not None or offsets is not None or not isinstance(texture, TextureArray):
        return None
    plain = all(type(v) in (int, float) or isinstance(v, (np.floating, np.integer)) for v in (tiling, sharpness)) and (type(layer) is int or isinstance(layer, np.integer))
    if not plain or getattr(stochastic, "histogram", None) is not None:  # (a float layer is refused, by a call that packs anew)
        return None
    try:
        key = ("triplanar", weights, float(tiling), float(sharpness), bool(mirror_fix), int(layer), space, stochastic, sampler, tuple(gbuffer.origin.tolist()), str(device))
        hash(key)
    except TypeError:  # an unhashable option: packed anew each call
        return None
    return key


def _textures(func, texture, per_axis, per_face, layer, device) -> list[TextureArray]:
    """The six faces' textures (in the order of ``warptex.kernels.faces.FACES``: +x, -x, +y, -y, +z,
    -z), checked: a face's own texture, else its axis', else ``texture``."""
    per_axis = _per(func, "textures_per_axis", per_axis, 3, "X, Y, Z projections")
    faces_given = per_face is not None
    per_face = _per(func, "textures_per_face", per_face, 6, "+X, -X, +Y, -Y, +Z, -Z faces")
    chosen, names = [], []
    for f, face in enumerate(kf.FACES):
        axis, sign = f // 2, face[0]
        own = per_face[f] is not None
        t = per_face[f] if own else texture if per_axis[axis] is None else per_axis[axis]
        name = f"{sign}{'XYZ'[axis]}" if own else "XYZ"[axis]
        what = f"the {name} face" if own else f"the {name} projection"
        if t is None:
            if faces_given:
                raise ValueError(f"{func}(): no texture for the {sign}{'XYZ'[axis]} face: pass texture=, textures_per_axis or all six textures_per_face")
            raise ValueError(f"{func}(): no texture for the {name} projection: pass texture= or all three textures_per_axis")
        if not isinstance(t, TextureArray):
            raise TypeError(f"{func}(): {what}'s texture must be a Texture or TextureArray, got {type(t).__name__}")
        if t.device != device:
            raise ValueError(f"{func}(): {what}'s texture is on {t.device} but the G-buffer on {device}")
        if chosen and t.channels != chosen[0].channels:
            raise ValueError(f"{func}(): all projections need the same channel count; {names[0]} has {chosen[0].channels}, {name} has {t.channels}")
        if isinstance(layer, bool) or not isinstance(layer, (int, np.integer)) or not 0 <= layer < t.num_layers:
            raise ValueError(f"{func}(): layer must be an int in [0, {t.num_layers - 1}] for {what}'s texture, got {layer!r}")
        chosen.append(t)
        names.append(name)
    return chosen


def _per(func, name, value, count, what) -> Sequence:
    """``value`` (a sequence of ``count`` textures or ``None``s, or ``None``) as a sequence."""
    if value is None:
        return (None,) * count
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != count:
        raise ValueError(f"{func}(): {name} must be a sequence of {count} textures ({what}) or None, got {value!r}")
    return value


def _object_to_world(func, space, object_to_world):
    """The object's matrix for ``space="object"`` (required then), ``None`` for world space."""
    if as_enum(func, "space", space, Space) == Space.WORLD:
        if object_to_world is not None:
            raise ValueError(f"{func}(): object_to_world is only used with space='object'")
        return None
    if object_to_world is None:
        raise ValueError(f"{func}(): space='object' needs object_to_world, the object's 4x4 matrix")
    return object_to_world
