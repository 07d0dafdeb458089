"""G-buffers: per-pixel surface attributes rasterised from a mesh, the input of every technique."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
import trimesh
import warp as wp

from warptex._validate import as_float_array
from warptex.camera import Camera
from warptex.kernels import raster as kr

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
        return GBuffer(**arrays, uv_sets=sets, camera=camera)

    @property
    def device(self):
        return self.mask.device

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
    def empty(cls, resolution, *, uv_sets=(), camera=None, device=None) -> "GBuffer":
        """A G-buffer where no pixel is covered (the background values)."""
        device = wp.get_device(device)
        arrays = {name: wp.zeros(resolution, dtype=dtype, device=device) for name, dtype in FIELDS.items()}
        arrays["depth"].fill_(float("inf"))
        arrays["triangle"].fill_(-1)
        sets = {s: {k: wp.zeros(resolution, dtype=t, device=device) for k, t in UV_FIELDS.items()} for s in uv_sets}
        return cls(**arrays, uv_sets=sets, camera=camera)

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
            view = (p - camera.eye) @ camera.forward if camera is not None else np.ones((h, w))
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
        return cls(**arrays, uv_sets=sets, camera=camera)


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


def gbuffer_device(func: str, gbuffer, device) -> wp.context.Device:
    """The device a technique launches on over ``gbuffer``: ``device`` if given (it must be the
    G-buffer's), else the G-buffer's; a ``TypeError`` if ``gbuffer`` is not a :class:`GBuffer`."""
    if not isinstance(gbuffer, GBuffer):
        raise TypeError(f"{func}(): gbuffer must be a warptex GBuffer, got {type(gbuffer).__name__}")
    device = wp.get_device(device) if device is not None else gbuffer.device
    if gbuffer.device != device:
        raise ValueError(f"{func}(): the G-buffer is on {gbuffer.device} but device is {device}")
    return device


def load_mesh(path: str | os.PathLike) -> trimesh.Trimesh:
    """Load a mesh file (OBJ, PLY, STL, GLB/GLTF, ...) as one ``trimesh.Trimesh``.

    Scenes are flattened with their node transforms; materials and UVs are kept where trimesh can
    merge them. The mesh is checked as :func:`rasterize` checks it (triangles, finite vertices,
    face indices in range), so a bad file is reported as such, naming it.

    Raises:
        FileNotFoundError: no such file. ValueError: a folder, or a file that holds no usable mesh.
        TypeError: ``path`` is not a path.
    """
    try:
        path = os.fspath(path)
    except TypeError:
        raise TypeError(f"load_mesh(): path must be str or os.PathLike, got {type(path).__name__}") from None
    if os.path.isdir(path):
        raise ValueError(f"load_mesh(): {path!r} is a folder, not a mesh file")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"load_mesh(): file not found: {path!r}")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as err:  # trimesh raises many types for bad files
        raise ValueError(f"load_mesh(): cannot read {path!r} as a mesh: {' '.join(str(err).split())}") from err
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"load_mesh(): {path!r} holds no triangle mesh (got {type(loaded).__name__})")
    checked_geometry(f"load_mesh(): {path!r}:", loaded)
    return loaded


def mesh_uv_sets(mesh: trimesh.Trimesh) -> dict[str, np.ndarray]:
    """The mesh's UV sets as ``{name: [V, 2] float32}``: ``"uv0"`` from its texture visuals, then
    any 2-wide per-vertex attribute whose name starts with ``uv`` or ``texcoord``."""
    sets = {}
    uv = getattr(mesh.visual, "uv", None)
    if uv is not None and len(uv) == len(mesh.vertices):
        sets["uv0"] = np.asarray(uv, np.float32)
    for name, values in mesh.vertex_attributes.items():
        values = np.asarray(values)
        if name.lower().startswith(("uv", "texcoord")) and values.shape == (len(mesh.vertices), 2):
            sets.setdefault(name.lower(), values.astype(np.float32))
    return sets


def vertex_tangents(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Per-vertex tangents ``[V, 4]`` (xyz unit, w = bitangent sign), accumulated per face (Lengyel).

    Vertices whose faces have degenerate UVs get a tangent perpendicular to the normal.
    """
    p = vertices[faces]
    t = uv[faces].astype(np.float64)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    r = np.where(np.abs(det) > 1e-20, 1.0 / np.where(det == 0, 1, det), 0.0)[:, None]
    sdir = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
    tdir = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
    tan, bit = np.zeros_like(vertices), np.zeros_like(vertices)
    for corner in range(3):
        np.add.at(tan, faces[:, corner], sdir)
        np.add.at(bit, faces[:, corner], tdir)
    tan -= normals * (normals * tan).sum(-1, keepdims=True)
    length = np.linalg.norm(tan, axis=-1, keepdims=True)
    fallback = np.cross(normals, np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    tan = np.where(length > 1e-12, tan / np.maximum(length, 1e-300), fallback)
    sign = np.where((np.cross(normals, tan) * bit).sum(-1) < 0.0, -1.0, 1.0)
    return np.concatenate([tan, sign[:, None]], axis=-1).astype(np.float32)


def _checked_mesh(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, faces and smooth vertex normals of a valid mesh, or a ``TypeError``/``ValueError``."""
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"rasterize(): mesh must be a trimesh.Trimesh or a path, got {type(mesh).__name__}")
    vertices, faces = checked_geometry("rasterize():", mesh)
    return vertices, faces, vertex_normals(mesh)


def checked_geometry(prefix: str, mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``[V, 3]`` float64 and faces ``[F, 3]`` int64 of ``mesh``, or a ``ValueError``
    starting with ``prefix`` (e.g. ``"rasterize():"``): no triangles, a non-finite vertex, a
    face index out of range."""
    vertices = np.asarray(mesh.vertices, np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, np.int64).reshape(-1, 3)
    if len(faces) == 0 or len(vertices) == 0:
        raise ValueError(f"{prefix} the mesh is empty ({len(vertices)} vertices, {len(faces)} faces)")
    if not np.isfinite(vertices).all():
        bad = int(np.argwhere(~np.isfinite(vertices).all(axis=1))[0, 0])
        raise ValueError(f"{prefix} vertex {bad} is not finite: {vertices[bad].tolist()}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{prefix} face indices must be in [0, {len(vertices) - 1}], got [{faces.min()}, {faces.max()}]")
    return vertices, faces


def vertex_normals(mesh: trimesh.Trimesh) -> np.ndarray:
    """Unit vertex normals ``[V, 3]``: the mesh's own when it carries them, else smooth area-weighted ones.

    (Computed here rather than by trimesh, whose fallback without SciPy logs a traceback.)
    """
    vertices = np.asarray(mesh.vertices, np.float64)
    faces = np.asarray(mesh.faces, np.int64)
    cache = getattr(getattr(mesh, "_cache", None), "cache", {})
    if "vertex_normals" in cache and np.shape(cache["vertex_normals"]) == vertices.shape:
        normals = np.asarray(cache["vertex_normals"], np.float64)
    else:
        p = vertices[faces]
        face_normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # length = 2 × area
        normals = np.zeros_like(vertices)
        for corner in range(3):
            np.add.at(normals, faces[:, corner], face_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 0, normals / np.maximum(length, 1e-300), 0.0)


def _camera_view(camera: Camera) -> kr.CameraView:
    view = kr.CameraView()
    view.eye, view.forward, view.right, view.up = (wp.vec3(*np.asarray(v, np.float32)) for v in (camera.eye, camera.forward, camera.right, camera.up))
    view.half_x, view.half_y = camera.half_extent
    view.height, view.width = camera.resolution
    view.orthographic = int(camera.orthographic)
    return view


def rasterize(mesh, camera, *, device=None) -> GBuffer:
    """Rasterise ``mesh`` seen by ``camera`` into a :class:`GBuffer` (primary rays against a BVH).

    Degenerate (zero-area) triangles are never hit; a camera inside the mesh sees its back faces
    (normals flipped to face the camera); a camera that sees nothing gives an all-empty G-buffer.

    Args:
        mesh: a ``trimesh.Trimesh`` or a path that :func:`load_mesh` reads. Meshes without normals
            get smooth (area-weighted) vertex normals.
        camera: from :func:`warptex.camera.look_at` or :func:`warptex.camera.orthographic`; or a
            sequence of ``V`` cameras of one resolution, rasterised in one launch against one BVH
            into a batched G-buffer of ``(V, H, W)`` arrays, which every technique takes (its
            outputs are ``(V, H, W, C)``).
        device: Warp device for the BVH, the launches and the resulting arrays.

    Returns:
        The G-buffer, with one UV set per set of the mesh (see :func:`mesh_uv_sets`); its
        ``camera`` is the camera, or the tuple of cameras of a batch.
    """
    func = "rasterize"
    if isinstance(camera, Camera):
        cameras, batch = [camera], False
    elif isinstance(camera, (list, tuple)) and camera and all(isinstance(c, Camera) for c in camera):
        cameras, batch = list(camera), True
    else:
        raise TypeError(f"{func}(): camera must be a warptex Camera or a non-empty sequence of them, got {type(camera).__name__}")
    resolution = cameras[0].resolution
    for k, c in enumerate(cameras):
        if c.resolution != resolution:
            raise ValueError(f"{func}(): the cameras of a batch must share one resolution; camera 0 has {resolution}, camera {k} {c.resolution}")
    trimesh_mesh = load_mesh(mesh) if isinstance(mesh, (str, os.PathLike)) else mesh
    vertices, faces, normals = _checked_mesh(trimesh_mesh)
    uv_sets = mesh_uv_sets(trimesh_mesh)
    device = wp.get_device(device)
    shape = (len(cameras), *resolution)  # the kernels' (views, H, W)

    # Zero-area triangles have no plane (no normal, no differentials): they are left out of the
    # BVH, and hits report the index of the face in the full mesh.
    area2 = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    face_ids = np.flatnonzero(area2 > 0)
    if len(face_ids) == 0:
        raise ValueError(f"{func}(): all {len(faces)} triangles of the mesh are degenerate (zero area)")
    points = wp.array(vertices.astype(np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(faces.reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
    hit_indices = wp.array(faces[face_ids].reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
    bvh = wp.Mesh(points=points, indices=hit_indices)
    g = GBuffer.empty(shape if batch else resolution, uv_sets=uv_sets, camera=tuple(cameras) if batch else camera, device=device)

    def batched(a: wp.array) -> wp.array:
        return a.reshape(shape)

    barycentric = wp.zeros(shape, dtype=wp.vec3, device=device)
    wp.launch(
        kr.raster_kernel,
        dim=shape,
        inputs=[
            bvh.id,
            points,
            hit_indices,
            wp.array(face_ids.astype(np.int32), dtype=wp.int32, device=device),
            wp.array(normals.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array([_camera_view(c) for c in cameras], dtype=kr.CameraView, device=device),
        ],
        outputs=[batched(a) for a in (g.position, g.normal, g.geometric_normal, g.depth, g.mask, g.triangle)] + [barycentric, batched(g.position_dx), batched(g.position_dy)],
        device=device,
        record_tape=False,
    )
    for name, uv in uv_sets.items():
        out = g.uv_sets[name]
        tangents = vertex_tangents(vertices, faces, normals, uv)
        wp.launch(
            kr.uv_kernel,
            dim=shape,
            inputs=[
                points,
                indices,
                wp.array(uv, dtype=wp.vec2, device=device),
                wp.array(tangents, dtype=wp.vec4, device=device),
                batched(g.triangle),
                barycentric,
                batched(g.normal),
                batched(g.position_dx),
                batched(g.position_dy),
            ],
            outputs=[batched(out[k]) for k in ("uv", "uv_dx", "uv_dy", "tangent")],
            device=device,
            record_tape=False,
        )
    return g
