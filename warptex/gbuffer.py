"""G-buffers: per-pixel surface attributes rasterised from a mesh, the input of every technique."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warptex._validate import as_float_array, checked_device
from warptex.camera import Camera

#: Per-pixel fields of a :class:`GBuffer` with their Warp dtypes (UV sets are kept apart).
FIELDS = {
    "position": wp.vec3,
    "normal": wp.vec3,
    "geometric_normal": wp.vec3,
    "depth": wp.float32,
    "mask": wp.float32,
    "triangle": wp.int32,
    "position_dx": wp.vec3,
    "position_dy": wp.vec3,
}
#: Per-pixel fields of every UV set.
UV_FIELDS = {"uv": wp.vec2, "uv_dx": wp.vec2, "uv_dy": wp.vec2, "tangent": wp.vec4}


@dataclass
class GBuffer:
    """Per-pixel surface attributes of an ``(H, W)`` image, as ``wp.array``\\ s on one device.

    Every array has shape ``(H, W)``, or ``(V, H, W)`` for a batch of ``V`` views of one size
    (:func:`rasterize` with several cameras), which every technique renders in one call;
    :meth:`view` is one of them. Pixels the mesh does not cover have ``mask = 0``,
    ``triangle = -1``, ``depth = inf`` and zeros elsewhere.

    Attributes:
        position: world-space hit point, ``vec3``.
        normal: interpolated shading normal, unit length, facing the camera, ``vec3``.
        geometric_normal: the hit triangle's unit normal, facing the camera, ``vec3``.
        depth: distance along the camera's forward axis (view-space depth), float32.
        mask: 1.0 where the mesh covers the pixel centre, else 0.0, float32.
        triangle: index of the hit triangle in the mesh's faces, -1 for none, int32.
        position_dx, position_dy: change of ``position`` per pixel step along x (right) and
            y (down), from ray differentials against the hit triangle's plane, ``vec3``.
        uv_sets: ``{name: {"uv", "uv_dx", "uv_dy", "tangent"}}`` for every UV set of the mesh
            (``"uv0"`` first): coordinates (``vec2``), their per-pixel derivatives (``vec2``),
            and the tangent (``vec4``: unit xyz orthogonal to ``normal``, bitangent sign in w).
        camera: the camera that produced it (``None`` when loaded without one; a tuple of cameras
            for a batch).
        samples: samples per image pixel (1, 4, 9, ...): a supersampled G-buffer
            (:func:`~warptex.rasterize` with ``samples=``) holds each pixel's stratified samples in
            an ``s × s`` block (``s² = samples``), so its arrays are ``s``-times the image's size;
            :func:`~warptex.resolve` averages a technique's output over the blocks.
        origin: float64 ``(3,)`` world point that ``position`` is relative to (camera-relative
            rendering, for scenes far from the world origin): the world position is
            ``origin + position`` (:meth:`world_position`). Techniques that project the position
            (triplanar, world-XZ and triplanar layers) add it exactly, in float64.
    """

    position: wp.array
    normal: wp.array
    geometric_normal: wp.array
    depth: wp.array
    mask: wp.array
    triangle: wp.array
    position_dx: wp.array
    position_dy: wp.array
    uv_sets: dict[str, dict[str, wp.array]] = field(default_factory=dict)
    camera: Camera | tuple[Camera, ...] | None = None
    samples: int = 1
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        self.origin = np.array(self.origin, np.float64).reshape(-1)
        if self.origin.shape != (3,) or not np.isfinite(self.origin).all():
            raise ValueError(f"GBuffer: origin must be 3 finite numbers, got {self.origin.tolist()}")
        root = math.isqrt(self.samples) if isinstance(self.samples, (int, np.integer)) and not isinstance(self.samples, bool) and self.samples > 0 else 0
        if root == 0 or root * root != self.samples:
            raise ValueError(f"GBuffer: samples must be a square number (1, 4, 9, ...), got {self.samples!r}")

    def world_position(self) -> np.ndarray:
        """World-space positions as float64 NumPy, ``origin + position`` (0 where uncovered)."""
        p = self.position.numpy().astype(np.float64)
        return np.where(self.mask.numpy()[..., None] > 0, p + self.origin, 0.0)

    @property
    def resolution(self) -> tuple[int, ...]:
        """The arrays' shape: ``(H, W)``, or ``(V, H, W)`` for a batch of views."""
        return tuple(self.mask.shape)

    @property
    def pixel_count(self) -> int:
        """Pixels in all: ``H·W``, or ``V·H·W`` for a batch of views."""
        return math.prod(self.resolution)

    @property
    def num_views(self) -> int | None:
        """``V`` for a batch of views, ``None`` for one ``(H, W)`` G-buffer."""
        return self.resolution[0] if len(self.resolution) == 3 else None

    def view(self, k: int) -> "GBuffer":
        """View ``k`` of a batch, an ``(H, W)`` G-buffer sharing the batch's memory."""
        if self.num_views is None:
            raise ValueError("GBuffer.view(): this G-buffer is one (H, W) view, not a batch")
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < self.num_views:
            raise ValueError(f"GBuffer.view(): k must be an int in [0, {self.num_views - 1}], got {k!r}")
        arrays = {name: getattr(self, name)[int(k)] for name in FIELDS}
        sets = {s: {f: a[int(k)] for f, a in fields.items()} for s, fields in self.uv_sets.items()}
        camera = self.camera[int(k)] if isinstance(self.camera, tuple) else self.camera
        return GBuffer(**arrays, uv_sets=sets, camera=camera, samples=self.samples, origin=self.origin)

    def rows(self, start: int, stop: int) -> "GBuffer":
        """Rows ``start <= row < stop`` of an ``(H, W)`` G-buffer, sharing its memory (a band of
        whole rows is contiguous in every array)."""
        if self.num_views is not None:
            raise ValueError("GBuffer.rows(): the G-buffer is a batch of views; take one first (gbuffer.view(k))")
        height = self.resolution[0]
        if not (isinstance(start, (int, np.integer)) and isinstance(stop, (int, np.integer)) and 0 <= start < stop <= height):
            raise ValueError(f"GBuffer.rows(): rows must satisfy 0 <= start < stop <= {height}, got {start}, {stop}")
        arrays = {name: getattr(self, name)[int(start) : int(stop)] for name in FIELDS}
        sets = {s: {f: a[int(start) : int(stop)] for f, a in fields.items()} for s, fields in self.uv_sets.items()}
        return GBuffer(**arrays, uv_sets=sets, camera=self.camera, samples=self.samples, origin=self.origin)

    @property
    def device(self):
        return self.mask.device

    def to(self, device) -> "GBuffer":
        """This G-buffer on ``device`` (e.g. ``"cuda:0"``): a copy of every array there, or
        ``self`` when it is there already. Rasterise once and texture on either device with the
        same pixels: the CPU and CUDA rasterisers agree only to float rounding."""
        device = checked_device("GBuffer.to", device)
        if device == self.device:
            return self
        arrays = {name: wp.clone(getattr(self, name), device=device) for name in FIELDS}
        sets = {s: {f: wp.clone(a, device=device) for f, a in fields.items()} for s, fields in self.uv_sets.items()}
        return GBuffer(**arrays, uv_sets=sets, camera=self.camera, samples=self.samples, origin=self.origin)

    def uv(self, name: str = "uv0") -> dict[str, wp.array]:
        """The arrays of UV set ``name`` (``uv``, ``uv_dx``, ``uv_dy``, ``tangent``)."""
        if name not in self.uv_sets:
            have = ", ".join(self.uv_sets) or "none"
            raise ValueError(f"GBuffer.uv(): no UV set named {name!r}; the G-buffer has {have}")
        return self.uv_sets[name]

    def require(self, func: str, *names: str) -> None:
        """Check that the named fields are contiguous ``(H, W)`` arrays of their dtype on the
        G-buffer's device (``"uv0.uv"`` names a UV-set field), raising an error that names ``func``."""
        shape, device = self.resolution, self.device
        for name in names:
            if "." in name:
                set_name, key = name.split(".", 1)
                if set_name not in self.uv_sets:
                    have = ", ".join(self.uv_sets) or "none"
                    raise ValueError(f"{func}(): the G-buffer has no UV set {set_name!r} (it has {have})")
                arr, dtype = self.uv_sets[set_name].get(key), UV_FIELDS[key]
            else:
                arr, dtype = getattr(self, name), FIELDS[name]
            if not isinstance(arr, wp.array) or arr.dtype != dtype or arr.shape != shape or not arr.is_contiguous:
                got = f"{wp.types.type_repr(arr.dtype)} {arr.shape}" if isinstance(arr, wp.array) else type(arr).__name__
                raise ValueError(f"{func}(): gbuffer.{name} must be a contiguous wp.array of {wp.types.type_repr(dtype)} with shape {shape}, got {got}")
            if arr.device != device:
                raise ValueError(f"{func}(): gbuffer.{name} is on {arr.device}, the rest of the G-buffer on {device}")

    def numpy(self) -> dict[str, np.ndarray]:
        """Every array as NumPy, UV fields named ``"<set>.<field>"`` (e.g. ``"uv0.uv_dx"``)."""
        out = {name: getattr(self, name).numpy() for name in FIELDS}
        for set_name, arrays in self.uv_sets.items():
            out.update({f"{set_name}.{k}": v.numpy() for k, v in arrays.items()})
        return out

    @classmethod
    def empty(cls, resolution, *, uv_sets=(), camera=None, samples=1, origin=(0.0, 0.0, 0.0), device=None) -> "GBuffer":
        """A G-buffer where no pixel is covered (the background values)."""
        g = cls._unfilled(resolution, uv_sets=uv_sets, camera=camera, samples=samples, origin=origin, device=device)
        for a in [getattr(g, name) for name in FIELDS] + [a for arrays in g.uv_sets.values() for a in arrays.values()]:
            a.zero_()
        g.depth.fill_(float("inf"))
        g.triangle.fill_(-1)
        return g

    @classmethod
    def _unfilled(cls, resolution, *, uv_sets=(), camera=None, samples=1, origin=(0.0, 0.0, 0.0), device=None) -> "GBuffer":
        """A G-buffer of uninitialised arrays, for a caller whose kernels write every element (the
        rasteriser: a fill first was 7% of a warm ``warptex render``, one thread writing what the
        kernels' threads write again)."""
        device = wp.get_device(device)
        arrays = {name: wp.empty(resolution, dtype=dtype, device=device) for name, dtype in FIELDS.items()}
        sets = {s: {k: wp.empty(resolution, dtype=t, device=device) for k, t in UV_FIELDS.items()} for s in uv_sets}
        return cls(**arrays, uv_sets=sets, camera=camera, samples=samples, origin=origin)

    @classmethod
    def from_arrays(
        cls,
        position,
        normal,
        mask=None,
        *,
        uv=None,
        position_dx=None,
        position_dy=None,
        uv_dx=None,
        uv_dy=None,
        tangent=None,
        geometric_normal=None,
        depth=None,
        triangle=None,
        flip_y: bool = False,
        camera: Camera | None = None,
        origin=(0.0, 0.0, 0.0),
        samples: int = 1,
        device=None,
    ) -> "GBuffer":
        """A G-buffer from another renderer's per-pixel arrays (nvdiffrast, pytorch3d, Blender
        passes, your own rasteriser), so that every technique can texture its images.

        Arrays are NumPy, ``wp.array`` or anything with ``.detach().cpu().numpy()`` (a torch
        tensor), ``(H, W, C)`` (or ``(H, W)`` for one channel), row 0 at the top of the image;
        they are copied (no gradient flows back to them):

        Args:
            position: world-space positions ``(H, W, 3)``; sets the resolution.
            normal: shading normals ``(H, W, 3)``, normalised here (not flipped to face a camera).
            mask: coverage ``(H, W)``, a pixel is covered where > 0.5 (nvdiffrast:
                ``rast[..., 3] > 0``); default: where position and normal are finite and the
                normal is not zero.
            uv: UV set ``"uv0"`` ``(H, W, 2)``, optional.
            position_dx, position_dy, uv_dx, uv_dy: change per pixel step right (x) and down (y).
                **When left out they are estimated** from the covered screen-space neighbours
                (:func:`screen_derivatives`): central differences, a one-sided difference at the
                mask's edge or where the two sides disagree by more than 2× (a depth or UV seam),
                0 on isolated pixels. Exact derivatives (nvdiffrast's ``interpolate`` with
                ``diff_attrs``, ordered du/dx, du/dy, dv/dx, dv/dy: ``uv_dx = uv_da[..., [0, 2]]``,
                ``uv_dy = uv_da[..., [1, 3]]``) pick
                better mip levels at silhouettes and seams.
            tangent: ``(H, W, 4)`` tangents for UV-space normal maps; default 0.
            geometric_normal: default ``normal``. depth: default view depth from ``camera``, else
                1. triangle: triangle ids ``(H, W)``; default 0 where covered.
            flip_y: the arrays' row 0 is the *bottom* row (OpenGL / nvdiffrast): rows are
                reversed, and ``position_dy``/``uv_dy`` negated (their "y" pointed up).
            camera: kept on the G-buffer; gives the default depth.
            origin: the world point ``position`` is relative to (float64; see :class:`GBuffer`).
            samples: samples per pixel when the arrays hold ``s × s`` blocks of stratified
                samples per image pixel (:class:`GBuffer`); 1 for one per pixel.
            device: Warp device of the arrays.

        Uncovered pixels get the background values (zeros, ``depth = inf``, ``triangle = -1``).

        Raises:
            ValueError: shapes that disagree with ``position``'s ``(H, W)`` or have the wrong
                channel count, or non-finite values on covered pixels.
            TypeError: values that are not numbers.
        """
        func = "GBuffer.from_arrays"
        p = _host_array(func, "position", position, 3, flip_y)
        h, w = p.shape[:2]

        def get(name, value, channels, negate=False):
            if value is None:
                return None
            a = _host_array(func, name, value, channels, flip_y, (h, w))
            return -a if negate and flip_y else a

        n = get("normal", normal, 3)
        covered = (np.isfinite(p).all(-1) & np.isfinite(n).all(-1) & (np.abs(n).max(-1) > 0)) if mask is None else get("mask", mask, 1)[..., 0] > 0.5
        fields = {
            "position": p,
            "normal": n,
            "geometric_normal": get("geometric_normal", geometric_normal, 3),
            "depth": get("depth", depth, 1),
            "triangle": get("triangle", triangle, 1),
            "position_dx": get("position_dx", position_dx, 3),
            "position_dy": get("position_dy", position_dy, 3, negate=True),
        }
        uv_fields = {"uv": get("uv", uv, 2), "uv_dx": get("uv_dx", uv_dx, 2), "uv_dy": get("uv_dy", uv_dy, 2, negate=True), "tangent": get("tangent", tangent, 4)}
        if uv_fields["uv"] is None and any(v is not None for v in uv_fields.values()):
            raise ValueError(f"{func}(): uv_dx, uv_dy and tangent describe a UV set: pass uv too")
        for name, values in [*fields.items(), *uv_fields.items()]:
            if values is not None and not np.isfinite(values[covered]).all():
                bad = np.argwhere(covered & ~np.isfinite(values).all(-1))[0]
                raise ValueError(f"{func}(): {name} is not finite at covered pixel (row {bad[0]}, column {bad[1]}): {values[tuple(bad)].tolist()}")

        fields["normal"] = _unit_rows(fields["normal"])
        fields["geometric_normal"] = fields["normal"] if fields["geometric_normal"] is None else _unit_rows(fields["geometric_normal"])
        if fields["depth"] is None:
            view = (p + origin - camera.eye) @ camera.forward if camera is not None else np.ones((h, w))
            fields["depth"] = np.asarray(view, np.float32)[..., None]
        if fields["triangle"] is None:
            fields["triangle"] = np.zeros((h, w, 1))
        for name in ("position", "uv"):
            source = fields if name == "position" else uv_fields
            if source[name] is None:
                continue
            estimated = screen_derivatives(source[name], covered)
            for k, suffix in enumerate(("_dx", "_dy")):
                if source[name + suffix] is None:
                    source[name + suffix] = estimated[k]
        if uv_fields["uv"] is not None and uv_fields["tangent"] is None:
            uv_fields["tangent"] = np.zeros((h, w, 4))

        device = wp.get_device(device)
        background = {"depth": np.inf, "triangle": -1}

        def to_warp(name, values, dtype):
            values = np.where(covered[..., None], values, background.get(name, 0.0))
            if dtype in (wp.float32, wp.int32):
                return wp.array(np.ascontiguousarray(values[..., 0], np.int32 if dtype == wp.int32 else np.float32), dtype=dtype, device=device)
            return wp.array(np.ascontiguousarray(values, np.float32), dtype=dtype, device=device)

        fields["mask"] = covered[..., None].astype(np.float32)
        arrays = {name: to_warp(name, fields[name], dtype) for name, dtype in FIELDS.items()}
        sets = {"uv0": {k: to_warp(k, uv_fields[k], t) for k, t in UV_FIELDS.items()}} if uv_fields["uv"] is not None else {}
        return cls(**arrays, uv_sets=sets, camera=camera, samples=samples, origin=origin)


def screen_derivatives(values: np.ndarray, covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Change of per-pixel ``values`` ``(H, W, C)`` per pixel step right (x) and down (y), estimated
    from covered neighbours: the central difference where both neighbours along the axis are
    covered and their one-sided differences agree within 2× (by length); else the shorter one-sided
    difference (a silhouette, a depth jump or a UV seam lies on the other side); 0 where neither
    neighbour is covered. ``(d/dx, d/dy)``, each ``(H, W, C)`` float32."""
    v = np.asarray(values, np.float64)
    out = []
    for axis in (1, 0):
        ahead = [slice(None)] * 2
        behind = [slice(None)] * 2
        ahead[axis], behind[axis] = slice(1, None), slice(None, -1)
        step = v[tuple(ahead)] - v[tuple(behind)]
        ok = covered[tuple(ahead)] & covered[tuple(behind)]
        forward = np.full_like(v, np.nan)
        backward = np.full_like(v, np.nan)
        forward[tuple(behind)] = np.where(ok[..., None], step, np.nan)  # v[i+1] - v[i], at i
        backward[tuple(ahead)] = np.where(ok[..., None], step, np.nan)  # v[i] - v[i-1], at i
        f_len = np.linalg.norm(forward, axis=-1, keepdims=True)
        b_len = np.linalg.norm(backward, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            agree = (f_len <= 2 * b_len) & (b_len <= 2 * f_len)
        shorter = np.where(np.isnan(f_len) | (b_len < f_len), backward, forward)
        d = np.where(agree, 0.5 * (forward + backward), shorter)
        out.append(np.where(np.isfinite(d) & covered[..., None], d, 0.0).astype(np.float32))
    return out[0], out[1]


def _unit_rows(v: np.ndarray) -> np.ndarray:
    """Each vector of ``v`` ``(..., 3)`` normalised; zero vectors stay zero."""
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(length > 0, v / np.where(length > 0, length, 1), 0)


def _host_array(func: str, name: str, value, channels: int, flip_y: bool, shape=None) -> np.ndarray:
    """``value`` (NumPy, ``wp.array``, or a tensor with ``.detach().cpu().numpy()``) as float64
    ``(H, W, channels)``, rows reversed when ``flip_y``; ``shape``: the ``(H, W)`` it must have."""
    if isinstance(value, wp.array):
        value = value.numpy()
    elif hasattr(value, "detach") and hasattr(value, "cpu"):
        value = value.detach().cpu().numpy()
    if isinstance(value, np.ndarray) and value.dtype == bool:  # a coverage mask
        value = value.astype(np.float32)
    a = as_float_array(func, name, value)
    if a.ndim == 2 and channels == 1:
        a = a[..., None]
    expected = "(H, W)" if channels == 1 else f"(H, W, {channels})"
    if a.ndim != 3 or a.shape[-1] != channels or 0 in a.shape or (shape is not None and a.shape[:2] != tuple(shape)):
        want = expected if shape is None else expected.replace("H, W", f"{shape[0]}, {shape[1]}")
        raise ValueError(f"{func}(): {name} must have shape {want}, got {a.shape}")
    a = a.astype(np.float64)  # derivatives are estimated from these
    return a[::-1].copy() if flip_y else a


def _gbuffer_device(func: str, gbuffer, device) -> wp.context.Device:
    """The device a technique launches on over ``gbuffer``: ``device`` if given (it must be the
    G-buffer's), else the G-buffer's; a ``TypeError`` if ``gbuffer`` is not a :class:`GBuffer`."""
    if not isinstance(gbuffer, GBuffer):
        raise TypeError(f"{func}(): gbuffer must be a warptex GBuffer, got {type(gbuffer).__name__}")
    device = wp.get_device(device) if device is not None else gbuffer.device
    if gbuffer.device != device:
        raise ValueError(f"{func}(): the G-buffer is on {gbuffer.device} but device is {device}")
    return device


# Mesh loading and rasterising live in their own modules; their names stay importable from here
# (rasterize on first use: warptex.raster imports this module).
from warptex.mesh import checked_geometry, load_mesh, mesh_uv_sets, vertex_normals, vertex_tangents  # noqa: E402,F401


_RENAMED = {"gbuffer_device": "_gbuffer_device"}  # old public spellings, kept for one release


def __getattr__(name: str):
    if name == "rasterize":
        from warptex.raster import rasterize

        return rasterize
    from warptex._validate import renamed_attribute

    return renamed_attribute(__name__, name, _RENAMED, globals())
