"""The option objects every technique takes: :class:`Sampler` (filtering and addressing, with
:class:`Filter` and :class:`Address`) and :class:`Stochastic` (anti-tiling, with :class:`Method`);
and the projections' :class:`Space` and normal mapping's :class:`Blend`.

Every technique (:func:`~warptex.sample`, :func:`~warptex.stochastic`, :func:`~warptex.triplanar`,
:func:`~warptex.biplanar`, :func:`~warptex.triplanar_normal`, :func:`~warptex.splat`,
:func:`~warptex.splat_atlas`) takes a ``sampler=``, as graphics APIs bind a sampler object to a
texture read (``None``: ``Sampler()``); the surface techniques also take ``stochastic=``. Both are
checked when made, so a bad value raises where it is written.
"""

from __future__ import annotations

import dataclasses
import enum
import math

import numpy as np

from warptex._validate import as_enum, as_float, as_float_array
from warptex.histogram import Histogram


class Filter(str, enum.Enum):
    """Texture filtering.

    - ``NEAREST``: the texel containing the UV, on the mip level nearest the LOD (level 0 without one).
    - ``BILINEAR``: bilinear interpolation of the four nearest texel centres, on the nearest level.
    - ``TRILINEAR``: bilinear on the two levels around the LOD, blended linearly; needs a LOD.
    - ``ANISOTROPIC``: up to ``Sampler.max_aniso`` trilinear taps along the major axis of the
      pixel's footprint (the ellipse of its UV derivatives), each at the LOD of the minor axis, and
      averaged: sharp where a surface is seen at a grazing angle, where trilinear blurs. Needs UV
      derivatives (every technique over a G-buffer has them); costs one trilinear tap per unit of
      the footprint's elongation, so a footprint seen face-on costs what trilinear does.
      Formulas: ``warptex.kernels.sampling.anisotropic_footprint``.
    - ``AUTO``: ``TRILINEAR`` when a LOD or UV derivatives are given (always, over a G-buffer),
      ``BILINEAR`` otherwise.
    """

    NEAREST = "nearest"
    BILINEAR = "bilinear"
    TRILINEAR = "trilinear"
    ANISOTROPIC = "anisotropic"
    AUTO = "auto"


class Address(str, enum.Enum):
    """What texel coordinates outside ``[0, 1]`` read.

    - ``WRAP``: repeat the texture (period 1 in UV).
    - ``CLAMP``: the nearest edge texel.
    - ``MIRROR``: repeat with every other copy mirrored (period 2), as OpenGL's ``MIRRORED_REPEAT``.
    - ``BORDER``: the constant ``border`` colour outside the texture (bilinear blends towards it).
    """

    WRAP = "wrap"
    CLAMP = "clamp"
    MIRROR = "mirror"
    BORDER = "border"


_NO_BORDER = (0.0, 0.0, 0.0, 0.0)  # Sampler's default border


@dataclasses.dataclass(frozen=True)
class Sampler:
    """How textures are filtered and addressed. Checked when made: a bad value raises at once.

    Attributes:
        filter: a :class:`Filter` (or its name).
        address: an :class:`Address` mode for both axes (or its name).
        border: the colour read outside the texture in ``"border"`` mode, 1 to 4 finite numbers
            (missing channels are 0).
        lod_bias: added to every level of detail before clamping.
        min_lod, max_lod: clamp of the biased LOD, then clamped to the mip chain ``[0, levels - 1]``.
        max_aniso: the most taps of the ``"anisotropic"`` filter, an int in ``[1, 64]`` (default 16,
            as GPUs offer): footprints longer than ``max_aniso`` times their width are read at a
            coarser LOD.
    """

    filter: Filter | str = Filter.AUTO
    address: Address | str = Address.WRAP
    border: tuple = _NO_BORDER
    lod_bias: float = 0.0
    min_lod: float = 0.0
    max_lod: float = math.inf
    max_aniso: int = 16

    def __post_init__(self):
        func = "Sampler"
        values = {
            "filter": as_enum(func, "filter", self.filter, Filter),
            "address": as_enum(func, "address", self.address, Address),
            "border": _border(func, self.border),
            "lod_bias": as_float(func, "lod_bias", self.lod_bias),
            "min_lod": as_float(func, "min_lod", self.min_lod, finite=False),
            "max_lod": as_float(func, "max_lod", self.max_lod, finite=False),
        }
        if isinstance(self.max_aniso, bool) or not isinstance(self.max_aniso, (int, np.integer)) or not 1 <= self.max_aniso <= 64:
            raise ValueError(f"{func}(): max_aniso must be an int in [1, 64], got {self.max_aniso!r}")
        values["max_aniso"] = int(self.max_aniso)
        if values["min_lod"] > values["max_lod"]:
            raise ValueError(f"{func}(): min_lod ({values['min_lod']}) must not exceed max_lod ({values['max_lod']})")
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def replace(self, **changes) -> Sampler:
        """A copy with ``changes`` (any of the attributes), checked as a new one is."""
        return dataclasses.replace(self, **changes)


def _border(func: str, border) -> tuple:
    """``Sampler.border`` as 4 Python floats (float32 values; missing channels 0)."""
    if border is _NO_BORDER:  # the default, without NumPy (a Sampler per call is common)
        return border
    colour = as_float_array(func, "border", border).reshape(-1)
    if not 1 <= colour.size <= 4 or not np.isfinite(colour).all():
        raise ValueError(f"{func}(): border must be 1 to 4 finite numbers, got {border!r}")
    return tuple(float(c) for c in np.pad(colour, (0, 4 - colour.size)))


_DEFAULTS = Sampler()


def _as_sampler(func: str, sampler) -> Sampler:
    """``sampler=`` of a technique: a :class:`Sampler`, or ``None`` for the defaults."""
    if sampler is None:
        return _DEFAULTS
    if not isinstance(sampler, Sampler):
        raise TypeError(f"{func}(): sampler must be a warptex.Sampler or None, got {type(sampler).__name__}")
    return sampler


class Method(str, enum.Enum):
    """Stochastic sampling technique.

    - ``NONE``: plain sampling (one tap), for comparisons.
    - ``HASH4``: per-cell hashed offset (and optional mirror) at the four cells around the UV,
      blended by ``smoothstep(blend[0], blend[1], frac(uv))`` (Quilez, "texture repetition",
      technique 1). 4 taps at most, 1 in the cell interiors with the default window.
    - ``CHEAP2``: two taps whose offsets are chosen by a low-frequency value noise, blended by its
      fraction (Quilez technique 3). 2 taps at most.
    - ``HEX``: three taps on a triangle grid with per-vertex offsets (and optional rotation),
      barycentric weights with a contrast exponent; with a :class:`~warptex.Histogram`, Heitz &
      Neyret's variance-preserving blend in Gaussianised space (Heitz & Neyret 2018; Mikkelsen 2022).
    """

    NONE = "none"
    HASH4 = "hash4"
    CHEAP2 = "cheap2"
    HEX = "hex"


_DEFAULT_BLEND = {Method.HASH4: (0.25, 0.75), Method.CHEAP2: (0.2, 0.8)}


@dataclasses.dataclass(frozen=True)
class Stochastic:
    """Stochastic sampling that breaks visible tiling: the options of :func:`~warptex.stochastic`,
    and ``stochastic=`` of :func:`~warptex.triplanar`, :func:`~warptex.biplanar`,
    :func:`~warptex.triplanar_normal` and :func:`~warptex.splat` (where a bare method name, e.g.
    ``stochastic="hex"``, takes every default). Every projection (triplanar) or layer (splat) is
    then sampled with the technique, each with the LOD of its own unperturbed footprint.

    Attributes:
        method: a :class:`Method`: ``"hash4"``, ``"cheap2"``, ``"hex"`` or ``"none"``.
        seed: an int in ``[0, 2**32)``; every seed gives a different, reproducible arrangement.
        blend: hash4 and cheap2: the smoothstep window ``(lo, hi)``, ``0 <= lo < hi <= 1``; ``None``:
            ``(0.25, 0.75)`` for hash4, ``(0.2, 0.8)`` for cheap2. Wider blends more (softer,
            blurrier seams), narrower blends less (sharper, more visible seams).
        mirror: hash4 and cheap2: mirror each tap randomly per axis (more variety; wrong for
            directional textures such as bricks or lit relief).
        contrast: hex: exponent of the barycentric weights (>= 1); 1 is Heitz & Neyret's linear
            weights, larger values (Mikkelsen suggests up to 7) shrink the blend zones between tiles.
        rotation: hex: random rotation of each tile about its centre, a strength in ``[0, 1]``
            (``True`` = 1: any angle); 0 disables it. Only for isotropic textures.
        noise_frequency: cheap2: cells of the value noise per UV unit; lower changes offsets less often.
        noise_levels: cheap2: how many offsets the noise sweeps through, ``l = noise * noise_levels``.
        histogram: hex: a :class:`~warptex.Histogram` from :func:`~warptex.prepare_histogram` of
            the texture being sampled; the blend then preserves its histogram (mean, contrast), and
            gradients reach ``histogram.texture``. Without it the taps blend linearly, which loses
            contrast where they mix.
    """

    method: Method | str = Method.HASH4
    seed: int = 0
    blend: tuple | None = None
    mirror: bool = False
    contrast: float = 1.0
    rotation: float = 0.0
    noise_frequency: float = 0.5
    noise_levels: float = 8.0
    histogram: Histogram | None = None

    def __post_init__(self):
        func = "Stochastic"
        m = as_enum(func, "method", self.method, Method)
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise TypeError(f"{func}(): seed must be an int, got {type(self.seed).__name__}")
        if not 0 <= self.seed < 1 << 32:
            raise ValueError(f"{func}(): seed must be in [0, 2**32), got {self.seed}")
        window = None
        if self.blend is not None:
            window = as_float_array(func, "blend", self.blend).reshape(-1)
            if window.size != 2 or not np.isfinite(window).all() or not 0.0 <= window[0] < window[1] <= 1.0:
                raise ValueError(f"{func}(): blend must be two numbers (lo, hi) with 0 <= lo < hi <= 1, got {self.blend!r}")
            window = (float(window[0]), float(window[1]))
        if not isinstance(self.mirror, (bool, np.bool_)):
            raise TypeError(f"{func}(): mirror must be a bool, got {type(self.mirror).__name__}")
        contrast = as_float(func, "contrast", self.contrast)
        if contrast < 1.0:
            raise ValueError(f"{func}(): contrast must be >= 1 (1: plain barycentric weights), got {contrast}")
        rotation = float(self.rotation) if isinstance(self.rotation, (bool, np.bool_)) else as_float(func, "rotation", self.rotation)
        if not 0.0 <= rotation <= 1.0:
            raise ValueError(f"{func}(): rotation must be a bool or a strength in [0, 1], got {self.rotation!r}")
        frequency = as_float(func, "noise_frequency", self.noise_frequency)
        levels = as_float(func, "noise_levels", self.noise_levels)
        if frequency <= 0.0 or levels <= 0.0:
            raise ValueError(f"{func}(): noise_frequency and noise_levels must be positive, got {frequency} and {levels}")
        if self.histogram is not None:
            if not isinstance(self.histogram, Histogram):
                raise TypeError(f"{func}(): histogram must be a Histogram from prepare_histogram(), got {type(self.histogram).__name__}")
            if m != Method.HEX:
                raise ValueError(f"{func}(): histogram= is used by method='hex' only, got method={m.value!r}")
        values = {"method": m, "seed": int(self.seed), "blend": window, "mirror": bool(self.mirror), "contrast": contrast,
                  "rotation": rotation, "noise_frequency": frequency, "noise_levels": levels}  # fmt: skip
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def replace(self, **changes) -> Stochastic:
        """A copy with ``changes`` (any of the attributes), checked as a new one is."""
        return dataclasses.replace(self, **changes)

    @property
    def blend_window(self) -> tuple[float, float]:
        """``blend``, or the method's default window when it is ``None``."""
        return self.blend if self.blend is not None else _DEFAULT_BLEND.get(self.method, (0.25, 0.75))


def _as_stochastic(func: str, option) -> Stochastic:
    """``stochastic=`` of a technique: ``None`` (method ``"none"``), a :class:`Method` name, or a
    :class:`Stochastic`."""
    if option is None:
        return Stochastic(method=Method.NONE)
    if isinstance(option, (str, Method)):
        try:
            return Stochastic(method=option)
        except ValueError as err:
            raise ValueError(f"{func}(): stochastic: {err}") from None
    if not isinstance(option, Stochastic):
        raise TypeError(f"{func}(): stochastic must be None, a method name or a warptex.Stochastic, got {type(option).__name__}")
    return option


_RENAMED = {'as_sampler': '_as_sampler', 'as_stochastic': '_as_stochastic'}  # old public spellings, kept for one release


def __getattr__(name: str):
    from warptex._validate import renamed_attribute

    return renamed_attribute(__name__, name, _RENAMED, globals())


class Space(str, enum.Enum):
    """Which coordinates are projected.

    - ``WORLD``: the G-buffer's world-space positions and normals.
    - ``OBJECT``: object space, given the object's ``object_to_world`` 4×4 matrix: the texture
      then moves with the object.
    """

    WORLD = "world"
    OBJECT = "object"


class Blend(str, enum.Enum):
    """How a projected tangent-space normal is combined with the surface normal.

    - ``WHITEOUT``: ``(t.xy + n.xy, t.z · n.z)``, keeps detail on curved surfaces (the default).
    - ``UDN``: ``(t.xy + n.xy, n.z)``, cheaper, flattens strong detail slightly.
    - ``RNM``: reoriented normal mapping, rotates the map onto the surface normal exactly.
    """

    WHITEOUT = "whiteout"
    UDN = "udn"
    RNM = "rnm"
