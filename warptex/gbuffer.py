"""G-buffers: per-pixel surface attributes rasterised from a mesh, the input of every technique."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
import trimesh
import warp as wp

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

    Every array has shape ``(H, W)``. Pixels the mesh does not cover have ``mask = 0``,
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
        camera: the camera that produced it (``None`` when loaded without one).
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
    camera: Camera | None = None

    @property
    def resolution(self) -> tuple[int, int]:
        return tuple(self.mask.shape)

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


def rasterize(mesh, camera: Camera, *, device=None) -> GBuffer:
    """Rasterise ``mesh`` seen by ``camera`` into a :class:`GBuffer` (primary rays against a BVH).

    Degenerate (zero-area) triangles are never hit; a camera inside the mesh sees its back faces
    (normals flipped to face the camera); a camera that sees nothing gives an all-empty G-buffer.

    Args:
        mesh: a ``trimesh.Trimesh`` or a path that :func:`load_mesh` reads. Meshes without normals
            get smooth (area-weighted) vertex normals.
        camera: from :func:`warptex.camera.look_at` or :func:`warptex.camera.orthographic`.
        device: Warp device for the BVH, the launches and the resulting arrays.

    Returns:
        The G-buffer, with one UV set per set of the mesh (see :func:`mesh_uv_sets`).
    """
    if not isinstance(camera, Camera):
        raise TypeError(f"rasterize(): camera must be a warptex Camera, got {type(camera).__name__}")
    trimesh_mesh = load_mesh(mesh) if isinstance(mesh, (str, os.PathLike)) else mesh
    vertices, faces, normals = _checked_mesh(trimesh_mesh)
    uv_sets = mesh_uv_sets(trimesh_mesh)
    device = wp.get_device(device)
    resolution = camera.resolution

    # Zero-area triangles have no plane (no normal, no differentials): they are left out of the
    # BVH, and hits report the index of the face in the full mesh.
    area2 = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    face_ids = np.flatnonzero(area2 > 0)
    if len(face_ids) == 0:
        raise ValueError(f"rasterize(): all {len(faces)} triangles of the mesh are degenerate (zero area)")
    points = wp.array(vertices.astype(np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(faces.reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
    hit_indices = wp.array(faces[face_ids].reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
    bvh = wp.Mesh(points=points, indices=hit_indices)
    g = GBuffer.empty(resolution, uv_sets=uv_sets, camera=camera, device=device)
    barycentric = wp.zeros(resolution, dtype=wp.vec3, device=device)
    wp.launch(
        kr.raster_kernel,
        dim=resolution,
        inputs=[
            bvh.id,
            points,
            hit_indices,
            wp.array(face_ids.astype(np.int32), dtype=wp.int32, device=device),
            wp.array(normals.astype(np.float32), dtype=wp.vec3, device=device),
            _camera_view(camera),
        ],
        outputs=[g.position, g.normal, g.geometric_normal, g.depth, g.mask, g.triangle, barycentric, g.position_dx, g.position_dy],
        device=device,
        record_tape=False,
    )
    for name, uv in uv_sets.items():
        out = g.uv_sets[name]
        tangents = vertex_tangents(vertices, faces, normals, uv)
        wp.launch(
            kr.uv_kernel,
            dim=resolution,
            inputs=[
                points,
                indices,
                wp.array(uv, dtype=wp.vec2, device=device),
                wp.array(tangents, dtype=wp.vec4, device=device),
                g.triangle,
                barycentric,
                g.normal,
                g.position_dx,
                g.position_dy,
            ],
            outputs=[out["uv"], out["uv_dx"], out["uv_dy"], out["tangent"]],
            device=device,
            record_tape=False,
        )
    return g
