"""Public options and inputs packed into what kernels take: one place for every technique.

- :func:`sampler_args`: a :class:`~warptex.Sampler` as ``SamplerArgs`` (``"auto"`` filtering resolved),
  and :func:`sample_args`, a lookup's ``SampleArgs``;
- :func:`stochastic_args`: a :class:`~warptex.Stochastic` as ``StochasticArgs``, with the texture
  the kernels must read (a histogram's Gaussianised copy, or the texture itself);
- :func:`projection_args`: triplanar projection options as ``ProjectionArgs``;
- per-UV inputs: :func:`vec2_array`, :func:`lod_inputs`, :func:`resolve_layer`, :func:`mip_levels`,
  :func:`reshaped`;
- kernel argument structs: :func:`struct_of` (empty arrays for unused optional ones), and
  :func:`packed`, those a technique makes once per texture and options.

Every error names the public function (``func``) whose argument is wrong.
"""

from __future__ import annotations

import math
import threading
import weakref

import numpy as np
import warp as wp

from warptex._validate import as_device_array, as_float, as_float_array, param_array
from warptex._warp import active_tape, field_type
from warptex.histogram import GAUSSIAN_MEAN, LUT_RANGE
from warptex.kernels import projection as kp
from warptex.kernels import sampling as ksa
from warptex.kernels import stochastic as kst
from warptex.kernels import texels as ks
from warptex.options import Address, Filter, Method, Sampler, Stochastic
from warptex.texture import Texture, TextureArray

_FILTER_IDS = {Filter.NEAREST: ks.FILTER_NEAREST, Filter.BILINEAR: ks.FILTER_BILINEAR, Filter.TRILINEAR: ks.FILTER_TRILINEAR, Filter.ANISOTROPIC: ks.FILTER_ANISOTROPIC}
_ADDRESS_IDS = {Address.WRAP: ks.ADDRESS_WRAP, Address.CLAMP: ks.ADDRESS_CLAMP, Address.MIRROR: ks.ADDRESS_MIRROR, Address.BORDER: ks.ADDRESS_BORDER}
_METHOD_IDS = {Method.NONE: kst.METHOD_NONE, Method.HASH4: kst.METHOD_HASH4, Method.CHEAP2: kst.METHOD_CHEAP2, Method.HEX: kst.METHOD_HEX}

#: The splat maps' sampler: bilinear on level 0, clamped at the edges (texel centres read exactly).
MAP_SAMPLER = Sampler(filter=Filter.BILINEAR, address=Address.CLAMP, max_lod=0.0)


def sampler_args(func: str, sampler: Sampler, *, has_lod: bool, has_derivatives: bool | None = None) -> ks.SamplerArgs:
    """``sampler`` for kernels that have a LOD (``has_lod``; always over a G-buffer) or not, and UV
    derivatives (``has_derivatives``, default ``has_lod``) or not: ``"auto"`` is trilinear with a
    LOD, bilinear without; trilinear without a LOD, or anisotropic without derivatives, is an error."""
    filt = sampler.filter
    if filt == Filter.AUTO:
        filt = Filter.TRILINEAR if has_lod else Filter.BILINEAR
    if filt == Filter.TRILINEAR and not has_lod:
        raise ValueError(f"{func}(): filter='trilinear' needs lod= or uv_dx=/uv_dy=")
    if filt == Filter.ANISOTROPIC and not (has_lod if has_derivatives is None else has_derivatives):
        raise ValueError(f"{func}(): filter='anisotropic' needs uv_dx=/uv_dy= (the footprint's shape); a lod= alone is isotropic")
    smp = ks.SamplerArgs()
    smp.filter = _FILTER_IDS[filt]
    smp.address = _ADDRESS_IDS[sampler.address]
    smp.border = wp.vec4(*sampler.border)
    smp.lod_bias, smp.min_lod, smp.max_lod = sampler.lod_bias, sampler.min_lod, sampler.max_lod
    smp.max_aniso = float(sampler.max_aniso)
    return smp


def sample_args(func: str, texture: TextureArray, sampler: Sampler, lod_source: int, constant_lod: float, constant_layer: int) -> ksa.SampleArgs:
    """A lookup of ``texture`` through ``sampler`` with the LOD source of :func:`lod_inputs` (which
    says whether there is a LOD and UV derivatives), at level 0 (:func:`mip_levels` gives another)."""
    args = ksa.SampleArgs()
    smp = sampler_args(func, sampler, has_lod=lod_source != ks.LOD_NONE, has_derivatives=lod_source == ks.LOD_DERIVATIVES)
    args.tex, args.smp, args.lod_source, args.constant_lod, args.constant_layer = texture.view, smp, lod_source, constant_lod, constant_layer
    args.level, args.fraction = 0, 0.0
    return args


def mip_levels(lod: float, smp: ks.SamplerArgs, num_levels: int) -> tuple[int, float]:
    """``(level, fraction)`` that ``lod`` reads through ``smp``: the kernels' ``mip_levels`` in the
    same float32 arithmetic, so a uniform LOD reads exactly the levels the per-sample kernel would."""
    f32 = np.float32
    level = f32(lod) + f32(smp.lod_bias)
    level = min(max(f32(smp.min_lod), level), f32(smp.max_lod))  # wp.clamp(x, a, b) = fmin(fmax(a, x), b)
    level = min(max(f32(0.0), level), f32(num_levels - 1))
    if smp.filter >= ks.FILTER_TRILINEAR:  # and the anisotropic filter's taps
        base = np.floor(level)
        return int(base), float(f32(level - base))
    return int(np.floor(level + f32(0.5))), 0.0


def stochastic_args(func: str, option: Stochastic, texture: TextureArray, sampler: Sampler) -> tuple[kst.StochasticArgs, TextureArray]:
    """``(args, sampled)``: ``option`` for kernels, and the texture they must sample:
    ``histogram.texture`` when the option has a histogram (checked against ``texture``), else
    ``texture``. Any method but ``"none"`` needs a periodic address mode."""
    if option.method != Method.NONE and sampler.address not in (Address.WRAP, Address.MIRROR):
        raise ValueError(f"{func}(): stochastic sampling needs address 'wrap' or 'mirror' (a periodic texture), got {sampler.address.value!r}")
    args = kst.StochasticArgs()
    args.method = _METHOD_IDS[option.method]
    args.seed = wp.uint32(option.seed)
    args.blend_lo, args.blend_hi = option.blend_window
    args.mirror = int(option.mirror)
    args.noise_frequency, args.noise_levels = option.noise_frequency, option.noise_levels
    args.contrast, args.rotation = option.contrast, option.rotation
    args.histogram, args.mean, args.lut_size, args.lut_levels, args.decorrelate = 0, GAUSSIAN_MEAN, 0, 0, 0
    args.lut_lo, args.lut_hi = LUT_RANGE
    args.channels = texture.channels
    # Unused arrays are empty rather than null: wp.Tape walks every array field of a struct.
    args.lut = empty_array(float, 1, texture.device)
    args.basis = empty_array(wp.mat33, 1, texture.device)
    args.centre = empty_array(wp.vec3, 1, texture.device)
    histogram = option.histogram
    if histogram is None:
        return args, texture
    h = histogram.texture
    have = (h.num_layers, h.height, h.width, h.channels)
    want = (texture.num_layers, texture.height, texture.width, texture.channels)
    if have != want:
        raise ValueError(f"{func}(): the stochastic histogram was built for (layers, H, W, C) = {have}, the texture is {want}")
    if h.device != texture.device:
        raise ValueError(f"{func}(): the stochastic histogram is on {h.device} but the texture is on {texture.device}")
    args.histogram, args.lut, args.lut_size, args.lut_levels = 1, histogram.lut, histogram.lut_size, histogram.levels
    if histogram.decorrelate:
        args.decorrelate, args.basis, args.centre = 1, histogram.basis, histogram.centre
    return args, h


def projection_args(func: str, *, tiling, sharpness, offsets, mirror_fix, weights, object_to_world=None, origin=None, address=None, device=None) -> kp.ProjectionArgs:
    """The projection options of a triplanar technique (or of splat layers mapped triplanar),
    checked and packed; ``object_to_world`` (a 4×4 affine matrix) projects object space.
    ``origin``: the G-buffer's float64 origin (its positions are relative to it), added to the
    plane UVs in float64 (``kernels.projection.origin_uv``), folded by whole periods for the
    ``address`` modes that repeat (wrap, mirror)."""
    proj = kp.ProjectionArgs()
    proj.tiling = param_array(func, "tiling", tiling, ((1,), (3,)), device, nonzero=True)
    proj.sharpness = param_array(func, "sharpness", sharpness, ((1,),), device, nonnegative=True)
    proj.offsets = param_array(func, "offsets", np.zeros((3, 2)) if offsets is None else offsets, ((3, 2),), device)
    proj.mirror_fix = int(bool(mirror_fix))
    proj.weights = weights
    to_object, normal_to_object, normal_to_world = _space_matrices(func, object_to_world)
    proj.world_to_object = wp.mat44(*to_object.reshape(-1))
    proj.normal_to_object = wp.mat33(*normal_to_object.reshape(-1))
    proj.normal_to_world = wp.mat33(*normal_to_world.reshape(-1))
    proj.object_space = int(object_to_world is not None)
    _pack_origin(proj, origin, to_object, address)
    return proj


def _pack_origin(proj: kp.ProjectionArgs, origin, to_object: np.ndarray, address) -> None:
    """The origin in the projected space, exact in float64: object space moves it by the whole
    affine map, whose translation then leaves the float32 matrix."""
    origin = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    if not origin.any():
        proj.origin_mode = kp.ORIGIN_NONE
        return
    projected = to_object[:3, :3] @ origin + to_object[:3, 3]
    linear = to_object.copy()
    linear[:3, 3] = 0.0
    proj.world_to_object = wp.mat44(*linear.reshape(-1))
    proj.origin = wp.vec3d(*projected)
    proj.origin_mode = kp.ORIGIN_FOLDED if Address(address or "wrap") in (Address.WRAP, Address.MIRROR) else kp.ORIGIN_EXACT


def _space_matrices(func: str, object_to_world):
    """``(world_to_object 4×4, normal world→object 3×3, normal object→world 3×3)``: identities in
    world space (``object_to_world is None``)."""
    if object_to_world is None:
        eye = np.eye(4)
        return eye, eye[:3, :3], eye[:3, :3]
    m = np.asarray(as_float_array(func, "object_to_world", object_to_world), np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise ValueError(f"{func}(): object_to_world must be a finite 4x4 matrix, got shape {m.shape}")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise ValueError(f"{func}(): object_to_world must be affine (last row 0, 0, 0, 1), got {m[3].tolist()}")
    linear = m[:3, :3]
    if abs(np.linalg.det(linear)) < 1e-12:
        raise ValueError(f"{func}(): object_to_world is singular")
    # Normals transform by the inverse transpose of the position transform.
    return np.linalg.inv(m), linear.T, np.linalg.inv(linear).T


# -- per-UV inputs (sample, stochastic) ------------------------------------------------------------


def vec2_array(func: str, name: str, value, device) -> wp.array:
    """``value`` as a contiguous ``wp.array`` of ``vec2`` (a view when it already is one)."""
    if isinstance(value, wp.array):
        if value.dtype != wp.vec2:
            raise TypeError(f"{func}(): {name} must be a wp.array of wp.vec2, got dtype {wp.types.type_repr(value.dtype)}")
        return as_device_array(func, name, value, device, beside="the texture is")
    arr = as_float_array(func, name, value)
    if arr.ndim < 1 or arr.shape[-1] != 2:
        raise ValueError(f"{func}(): {name} must have shape (..., 2), got {arr.shape}")
    return wp.array(np.ascontiguousarray(arr), dtype=wp.vec2, device=device)


def _per_sample(func: str, name: str, value, shape, dtype, device) -> wp.array:
    """A per-sample array of ``dtype`` matching the sample ``shape``."""
    if isinstance(value, wp.array):
        if value.dtype != dtype or value.shape != shape or value.device != device:
            raise ValueError(
                f"{func}(): {name} must be a wp.array of {wp.types.type_repr(dtype)} with shape {shape} "
                f"on {device}, got {wp.types.type_repr(value.dtype)} {value.shape} on {value.device}"
            )
        return value
    np_dtype = np.float32 if dtype == wp.float32 else np.int32
    arr = np.asarray(value)
    if dtype == wp.int32 and not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{func}(): {name} must hold integers, got dtype {arr.dtype}")
    if dtype == wp.float32:
        arr = as_float_array(func, name, arr)
    if arr.shape != shape:
        raise ValueError(f"{func}(): {name} must have shape {shape} (one per UV), got {arr.shape}")
    return wp.array(np.ascontiguousarray(arr, dtype=np_dtype), dtype=dtype, device=device)


def lod_inputs(func: str, lod, uv_dx, uv_dy, shape, device):
    """``(lod_source, constant_lod, lods, uv_dx, uv_dy)`` for a kernel, flattened, validated."""
    count = math.prod(shape)
    if lod is not None and (uv_dx is not None or uv_dy is not None):
        raise ValueError(f"{func}(): pass either lod= or uv_dx=/uv_dy=, not both")
    if (uv_dx is None) != (uv_dy is None):
        raise ValueError(f"{func}(): uv_dx and uv_dy must be given together")
    if uv_dx is not None:
        dx = vec2_array(func, "uv_dx", uv_dx, device)
        dy = vec2_array(func, "uv_dy", uv_dy, device)
        for name, d in (("uv_dx", dx), ("uv_dy", dy)):
            if d.shape != shape:
                raise ValueError(f"{func}(): {name} must have the shape of uv {shape}, got {d.shape}")
        return ks.LOD_DERIVATIVES, 0.0, None, reshaped(dx, (count,)), reshaped(dy, (count,))
    if isinstance(lod, (int, float, np.integer, np.floating)) and not isinstance(lod, bool):
        return ks.LOD_CONSTANT, as_float(func, "lod", lod), None, None, None
    if lod is not None:
        lods = reshaped(_per_sample(func, "lod", lod, shape, wp.float32, device), (count,))
        return ks.LOD_PER_SAMPLE, 0.0, lods, None, None
    return ks.LOD_NONE, 0.0, None, None, None


def resolve_layer(func: str, texture: TextureArray, layer, shape, device):
    """``(constant_layer, per_sample_layers_or_None)`` for ``layer``, validated against ``texture``;
    per-sample layers come flattened to one entry per UV, as the kernels read them."""
    if layer is None:
        if isinstance(texture, Texture) or texture.num_layers == 1:
            return 0, None
        raise ValueError(f"{func}(): layer is required for a TextureArray of {texture.num_layers} layers")
    if isinstance(layer, (int, np.integer)) and not isinstance(layer, bool):
        if not 0 <= layer < texture.num_layers:
            raise ValueError(f"{func}(): layer must be in [0, {texture.num_layers - 1}], got {layer}")
        return int(layer), None
    return 0, reshaped(_per_sample(func, "layer", layer, shape, wp.int32, device), (math.prod(shape),))


def out_array(func: str, out, shape: tuple, device) -> wp.array | None:
    """The caller's ``out=``, checked: ``None``, or a contiguous float32 ``wp.array`` of exactly
    ``shape`` on ``device``; returned as ``(pixels, channels)`` rows, as the kernels write them.
    Checked before any work, so a wrong one changes nothing."""
    if out is None:
        return None
    if not isinstance(out, wp.array):
        raise TypeError(f"{func}(): out must be a wp.array of float32, got {type(out).__name__}")
    if out.dtype != wp.float32 or tuple(out.shape) != tuple(shape) or out.device != device or not out.is_contiguous:
        got = f"{'a non-contiguous ' if not out.is_contiguous else ''}{wp.types.type_repr(out.dtype)} {tuple(out.shape)} on {out.device}"
        raise ValueError(f"{func}(): out must be a contiguous float32 wp.array of shape {tuple(shape)} on {device}, got {got}")
    return reshaped(out, (math.prod(shape[:-1]), shape[-1]))


def reshaped(array: wp.array, shape: tuple) -> wp.array:
    """``array`` with ``shape``: itself where it has it already (a new view costs a call ~30 us of
    Python on cold caches, as the one a lookup's 1-D UVs and output made)."""
    return array if array.shape == shape else array.reshape(shape)


#: The G-buffer arrays a projection reads (:func:`surface_pixels`).
SURFACE = ("position", "position_dx", "position_dy", "normal", "mask")


def surface_pixels(func: str, gbuffer, device) -> kp.SurfacePixels:
    """The G-buffer's surface arrays as the kernels read them (flat), checked
    (:meth:`~warptex.GBuffer.require`) and kept with the G-buffer while its arrays stay the same
    objects (whose shapes and types cannot change). Not under a recording tape: a recorded launch
    keeps its struct for the backward pass, which no later call may share."""
    arrays = tuple(getattr(gbuffer, name, None) for name in SURFACE)
    kept = gbuffer.__dict__.get("_surface_pixels")
    if kept is not None and all(a is b for a, b in zip(kept[0], arrays)) and active_tape() is None:
        return kept[1]
    gbuffer.require(func, *SURFACE)
    count = gbuffer.pixel_count
    pixels = struct_of(kp.SurfacePixels, device, **{name: a.reshape((count,)) for name, a in zip(SURFACE, arrays)})
    if active_tape() is None:
        gbuffer.__dict__["_surface_pixels"] = (arrays, pixels)  # views of its own arrays: nothing outlives it
    return pixels


def struct_of(struct_t, device, **fields):
    """A ``struct_t`` instance with ``fields`` set (or ``struct_t`` itself, an instance, filled in
    place: a struct nested in another, which assigning would copy field by field); an array field
    given as ``None`` (an unused optional input) gets an empty array of its type, which kernels test
    with ``shape[0] > 0``."""
    value = struct_t if wp.types.is_struct(struct_t) else struct_t()
    for name, field in fields.items():
        if field is None:
            ftype = field_type(value, name)
            field = empty_array(ftype.dtype, ftype.ndim, device)
        setattr(value, name, field)
    return value


# What a technique packs for an owner (a texture) and options, made once while the owner lives:
# packing a call's argument structs was most of its Python, and a call's Python runs on cold
# caches between kernels that stream tens of MB (sample() on 256 UVs after a pass over 64 MB:
# 320-410 us, of which the structs and their field-by-field copies were about half).
_packed: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# Re-entrant: an entry dropped under it can drop the last reference to an array another entry's
# key holds weakly, whose callback (same thread) takes it again to drop that entry too.
_packed_lock = threading.RLock()
#: Entries kept per owner: a fit sweeping an option (a LOD) through many values makes a new one
#: each call; the oldest goes first.
MAX_PACKED_PER_OWNER = 16


def packed(owner, key, build, *, weakly=()):
    """``build()``, made once per ``owner`` and hashable ``key`` while ``owner`` lives, and shared.

    ``key`` must name everything ``build`` reads beside ``owner``'s fixed state (a texture's view
    never changes), and what it returns is never changed afterwards: kernels only read their
    argument structs. ``weakly``: other objects ``build`` reads (``None`` for one not given),
    named in the key by weak reference: what ``build`` returns may hold their arrays, so the
    entry is dropped when any of them goes rather than keep them alive (a loop that makes new
    splat maps each call). ``build``'s errors are raised each call (nothing is kept)."""
    if weakly:
        key = _weak_key(owner, key, weakly)
    table = _packed.get(owner)
    value = None if table is None else table.get(key)
    if value is None:
        value = build()
        with _packed_lock:
            table = _packed.setdefault(owner, {})
            if len(table) >= MAX_PACKED_PER_OWNER:
                del table[next(iter(table))]
            table[key] = value
    return value


def _weak_key(owner, key: tuple, objects) -> tuple:
    """``key`` with ``objects`` by weak reference (equal while their objects live, as the objects
    are), each dropping the entry stored under the key when its object goes."""
    owner_ref = weakref.ref(owner)

    def gone(_ref) -> None:
        owner, tables, lock = owner_ref(), _packed, _packed_lock  # (module globals are None at interpreter exit)
        table = tables.get(owner) if owner is not None and tables is not None else None
        if table is not None:
            with lock:
                table.pop(full, None)

    full = (*key, *(None if o is None else weakref.ref(o, gone) for o in objects))
    return full


_empties: dict = {}


def empty_array(dtype, ndim: int, device) -> wp.array:
    """An empty ``ndim``-dimensional array of ``dtype`` on ``device``, where a kernel's argument is
    unused (kernels test ``shape[0] > 0``). One per kind, shared: it holds nothing to write, and
    making a new one cost every call a few microseconds (an API call made four)."""
    device = wp.get_device(device)
    key = (dtype, ndim, device.alias)
    array = _empties.get(key)
    if array is None:
        array = _empties[key] = wp.empty(shape=(0,) * ndim, dtype=dtype, device=device)
    return array


# Bilinear footprints one lookup reads, by filter mode (anisotropic: per tap along the major axis).
_FILTER_FOOTPRINTS = {int(ks.FILTER_NEAREST): 1, int(ks.FILTER_BILINEAR): 1, int(ks.FILTER_TRILINEAR): 2, int(ks.FILTER_ANISOTROPIC): 2}
_METHOD_TAPS = {int(kst.METHOD_NONE): 1, int(kst.METHOD_HASH4): 4, int(kst.METHOD_CHEAP2): 2, int(kst.METHOD_HEX): 3}


def footprints(smp: ks.SamplerArgs, stoch: kst.StochasticArgs | None = None, lookups: int = 1) -> int:
    """The bilinear footprints a pixel reads at most: ``lookups`` lookups (projections, layers) of
    ``smp``'s filter, each of ``stoch``'s taps. What a pixel's backward pass costs against the
    gradient it shares with every other pixel (``warptex._threads.grad_bounds``)."""
    per_lookup = _FILTER_FOOTPRINTS[int(smp.filter)] * (max(1, int(smp.max_aniso)) if int(smp.filter) == int(ks.FILTER_ANISOTROPIC) else 1)
    return lookups * per_lookup * (1 if stoch is None else _METHOD_TAPS[int(stoch.method)])
