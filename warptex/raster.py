"""Rasterising a mesh into a :class:`~warptex.gbuffer.GBuffer`: primary rays against Warp's BVH."""

from __future__ import annotations

import os

import numpy as np
import trimesh
import warp as wp

from warptex._threads import rows_side_by_side
from warptex._validate import checked_device
from warptex.camera import Camera
from warptex.gbuffer import GBuffer
from warptex.kernels import raster as kr
from warptex.mesh import checked_geometry, load_mesh, mesh_uv_sets, vertex_normals, vertex_tangents


def _checked_mesh(func: str, mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, faces and smooth vertex normals of a valid mesh, or a ``TypeError``/``ValueError``."""
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"{func}(): mesh must be a trimesh.Trimesh or a path, got {type(mesh).__name__}")
    vertices, faces = checked_geometry(f"{func}():", mesh)
    return vertices, faces, vertex_normals(mesh)


#: Scenes whose vertices and cameras lie within this distance of the world origin are rasterised
#: in world coordinates; farther ones relative to the camera (``rasterize``'s ``origin``). float32
#: keeps 1/4096 of a unit (a quarter of a millimetre in metres) out to here.
ORIGIN_RANGE = 2.0**12


def _camera_view(camera: Camera, origin: np.ndarray, first_row: int = 0) -> kr.CameraView:
    view = kr.CameraView()
    view.eye = wp.vec3(*np.asarray(camera.eye - origin, np.float32))  # subtracted in float64
    view.forward, view.right, view.up = (wp.vec3(*np.asarray(v, np.float32)) for v in (camera.forward, camera.right, camera.up))
    view.half_x, view.half_y = camera.half_extent
    view.height, view.width = camera.resolution
    view.orthographic = int(camera.orthographic)
    view.strata = camera.strata
    view.first_row = first_row
    return view


def _origin(func: str, origin, vertices: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """The float64 point the G-buffer's positions are relative to (see :func:`rasterize`)."""
    if origin is None:
        extent = max(float(np.abs(vertices).max()), max(float(np.abs(c.eye).max()) for c in cameras))
        return np.zeros(3) if extent <= ORIGIN_RANGE else np.asarray(cameras[0].eye, np.float64).copy()
    try:
        point = np.asarray(origin, np.float64).reshape(-1)
    except (TypeError, ValueError):
        point = np.full(1, np.nan)
    if point.shape != (3,) or not np.isfinite(point).all():
        raise ValueError(f"{func}(): origin must be None or 3 finite numbers, got {origin!r}")
    return point


def rasterize(mesh, camera, *, samples: int = 1, origin=None, rows=None, device=None) -> GBuffer:
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
        samples: stratified samples per pixel, 1, 4, 9, 16, ... (``s²``; pattern in
            :meth:`warptex.camera.Camera.supersampled`). With ``s > 1`` the G-buffer holds every
            sample, each pixel's as an ``s × s`` block (arrays ``(H·s, W·s)``), its derivatives
            those of one sample's footprint, so textures are filtered at that footprint; render it
            with any technique and average the blocks with :func:`warptex.resolve` for an
            anti-aliased image with fractional coverage at the silhouettes (what a photo shows,
            so fits against photos want it too).
        origin: the world point, float64, that the G-buffer's positions are relative to
            (camera-relative rendering): vertices and eyes are taken relative to it in float64
            before they become float32, so a scene far from the world origin (map coordinates in
            the millions) keeps its precision. ``None``: the world origin for scenes within
            :data:`ORIGIN_RANGE` of it, else the (first) camera's eye. Kept as ``g.origin``.
        rows: ``(start, stop)``: only the image rows ``start <= row < stop`` (of every view), a
            G-buffer of ``stop - start`` rows (``s``-times that with ``samples``) whose pixels are
            those rows of the whole image's, bit for bit; ``None``: every row. :func:`gbuffer_tiles`
            cuts an image into such bands.
        device: Warp device for the BVH, the launches and the resulting arrays.

    Returns:
        The G-buffer, with one UV set per set of the mesh (see :func:`mesh_uv_sets`); its
        ``camera`` is the camera (supersampled: :meth:`~warptex.camera.Camera.supersampled`), or
        the tuple of cameras of a batch.
    """
    scene, cameras, batch = prepare("rasterize", mesh, camera, samples=samples, origin=origin, device=device)
    return scene.rasterize(cameras, checked_rows("rasterize", rows, cameras[0].pixel_resolution[0]), batch=batch)


def checked_rows(func: str, rows, height: int) -> tuple[int, int]:
    """``rows`` as ``(start, stop)`` with ``0 <= start < stop <= height`` (``None``: every row), or
    a ``ValueError`` naming ``func``."""
    if rows is None:
        return 0, height
    try:
        start, stop = (int(v) if isinstance(v, (int, np.integer)) and not isinstance(v, bool) else None for v in rows)
    except (TypeError, ValueError):
        start = stop = None
    if start is None or stop is None or not 0 <= start < stop <= height:
        raise ValueError(f"{func}(): rows must be (start, stop) with 0 <= start < stop <= {height} (the image's rows), got {rows!r}")
    return start, stop


def prepare(func: str, mesh, camera, *, samples: int = 1, origin=None, device=None) -> tuple["Scene", list[Camera], bool]:
    """``(scene, cameras, batch)``: ``mesh`` prepared for rasterising through ``camera`` (one or a
    sequence, supersampled by ``samples``), every argument checked as :func:`rasterize` checks it."""
    if isinstance(camera, Camera):
        cameras, batch = [camera], False
    elif isinstance(camera, (list, tuple)) and camera and all(isinstance(c, Camera) for c in camera):
        cameras, batch = list(camera), True
    else:
        raise TypeError(f"{func}(): camera must be a warptex Camera or a non-empty sequence of them, got {type(camera).__name__}")
    if samples != 1:
        try:
            cameras = [c.supersampled(samples) for c in cameras]
        except ValueError as err:
            raise ValueError(f"{func}(): {str(err).split(': ', 1)[1]}") from None
    resolution = cameras[0].resolution
    for k, c in enumerate(cameras):
        if c.resolution != resolution:
            raise ValueError(f"{func}(): the cameras of a batch must share one resolution; camera 0 has {resolution}, camera {k} {c.resolution}")
    trimesh_mesh = load_mesh(mesh) if isinstance(mesh, (str, os.PathLike)) else mesh
    vertices, faces, normals = _checked_mesh(func, trimesh_mesh)
    origin = _origin(func, origin, vertices, cameras)
    return Scene(func, vertices, faces, normals, mesh_uv_sets(trimesh_mesh), origin, checked_device(func, device)), cameras, batch


class Scene:
    """A mesh ready to rasterise on a device: its BVH, vertex arrays and tangents, made once and
    used for every band of rows and every view (building the BVH of a large mesh takes longer than
    tracing a band)."""

    def __init__(self, func: str, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, uv_sets: dict, origin: np.ndarray, device):
        self.origin, self.device = origin, device
        vertices = vertices - origin  # float64, before float32
        # Zero-area triangles have no plane (no normal, no differentials): they are left out of the
        # BVH, and hits report the index of the face in the full mesh.
        area2 = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
        face_ids = np.flatnonzero(area2 > 0)
        if len(face_ids) == 0:
            raise ValueError(f"{func}(): all {len(faces)} triangles of the mesh are degenerate (zero area)")
        self.points = wp.array(vertices.astype(np.float32), dtype=wp.vec3, device=device)
        self.indices = wp.array(faces.reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
        self.hit_indices = wp.array(faces[face_ids].reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
        self.face_ids = wp.array(face_ids.astype(np.int32), dtype=wp.int32, device=device)
        self.normals = wp.array(normals.astype(np.float32), dtype=wp.vec3, device=device)
        self.bvh = wp.Mesh(points=self.points, indices=self.hit_indices)
        self.uv_sets = {
            name: (wp.array(uv, dtype=wp.vec2, device=device), wp.array(vertex_tangents(vertices, faces, normals, uv), dtype=wp.vec4, device=device))
            for name, uv in uv_sets.items()
        }

    def rasterize(self, cameras: list[Camera], rows: tuple[int, int], *, batch: bool = False) -> GBuffer:
        """The G-buffer of image rows ``rows`` (``(start, stop)``, in pixels of the image) of every
        camera (supersampled ones: ``strata``-times as many rows of samples)."""
        device, s = self.device, cameras[0].strata
        shape = (len(cameras), (rows[1] - rows[0]) * s, cameras[0].resolution[1])  # the kernels' (views, rows, W)
        # Unfilled: the kernels write every element, a miss its background.
        g = GBuffer._unfilled(shape if batch else shape[1:], uv_sets=self.uv_sets, camera=tuple(cameras) if batch else cameras[0], samples=s * s, origin=self.origin, device=device)

        def batched(a: wp.array) -> wp.array:
            return a.reshape(shape)

        barycentric = wp.empty(shape, dtype=wp.vec3, device=device)
        outputs = [batched(a) for a in (g.position, g.normal, g.geometric_normal, g.depth, g.mask, g.triangle)] + [barycentric, batched(g.position_dx), batched(g.position_dy)]
        sets = {name: [batched(g.uv_sets[name][k]) for k in ("uv", "uv_dx", "uv_dy", "tangent")] for name in self.uv_sets}

        def trace(a: int, b: int) -> None:  # launch rows a..b of every view: the same pixels as one launch
            views = wp.array([_camera_view(c, self.origin, rows[0] * s + a) for c in cameras], dtype=kr.CameraView, device=device)
            part = [o[:, a:b] for o in outputs]
            wp.launch(kr.raster_kernel, dim=(shape[0], b - a, shape[2]), inputs=[self.bvh.id, self.points, self.hit_indices, self.face_ids, self.normals, views], outputs=part, device=device, record_tape=False)
            triangle, barycentric_part, normal, dx, dy = part[5], part[6], part[1], part[7], part[8]
            for name, (uv, tangents) in self.uv_sets.items():
                wp.launch(
                    kr.uv_kernel,
                    dim=(shape[0], b - a, shape[2]),
                    inputs=[self.points, self.indices, uv, tangents, triangle, barycentric_part, normal, dx, dy],
                    outputs=[o[:, a:b] for o in sets[name]],
                    device=device,
                    record_tape=False,
                )

        rows_side_by_side(shape[1], trace, device, (kr.raster_kernel, kr.uv_kernel))
        return g
