"""UV layouts for baking: a mesh's own first UV set when it is usable, else an xatlas atlas.

A UV set is usable for baking when every UV lies inside the texture (``[0, 1]``) and no two
triangles overlap in UV space (mirrored or stacked charts would have to share texels): each UV
triangle is tested against those whose bounds it meets (a BVH of the UV triangles, see
:func:`warptex.kernels.bake.overlap_kernel`) with the separating-axis test, so triangles that only
share an edge or a corner do not count. Otherwise the mesh is unwrapped by
`xatlas <https://github.com/jpcy/xatlas>`_ into charts packed ``padding`` texels apart, in a
process of its own (``warptex._xatlas_child``: xatlas crashes on some meshes, and must not take
the caller with it), or, for meshes too large for xatlas or where it crashed, into projected
charts (:mod:`warptex.charts`).
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass

import numpy as np
import trimesh
import warp as wp

from warptex.charts import projected_atlas
from warptex.gbuffer import checked_geometry, mesh_uv_sets, vertex_normals, vertex_tangents
from warptex.mesh import mesh_uv_faces
from warptex.kernels import bake as kb

# Two UV triangles overlap when they penetrate by more than this (UV units, 1/50 of a texel at
# 1024²): rounding where triangles share an edge stays far below it.
OVERLAP_TOLERANCE = 2e-5
# xatlas is asked for an atlas this much of the texture's area would hold, and for this much more
# padding than asked: its packing fills 40-50% of the square before padding on the meshes tried, and
# an atlas up to this much larger than the texture is scaled down into it without losing padding.
ATLAS_FILL = 0.45
PADDING_MARGIN = 1.15  # also in warptex._xatlas_child
#: The ways :func:`unwrap` makes an atlas.
ATLAS_METHODS = ("auto", "xatlas", "projection")


@dataclass
class UVLayout:
    """A mesh as it is baked: its triangles with atlas UVs, split where the atlas has seams.

    Attributes:
        vertices: ``[V', 3]`` float64 world positions.
        faces: ``[F, 3]`` int64, face ``f`` is the input mesh's face ``f``.
        uv: ``[V', 2]`` float32 atlas UVs in ``[0, 1]`` (warptex's convention: v up).
        normals: ``[V', 3]`` float64 unit vertex normals (the input mesh's; ``+z`` for a vertex of
            zero-area faces only, which has none).
        vertex_map: ``[V']`` int64, the input vertex each vertex comes from.
        source: ``"mesh"`` (the mesh's own UV0), ``"xatlas"`` or ``"projection"`` (projected
            charts, :mod:`warptex.charts`).
        reason: why the mesh's UVs were not used (``""`` when they were).
        padding: texels between charts (an atlas), ``None`` for the mesh's own UVs.
        mesh: the input mesh.
        note: why projected charts rather than xatlas's (``""`` otherwise).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    normals: np.ndarray
    vertex_map: np.ndarray
    source: str
    reason: str = ""
    padding: int | None = None
    mesh: trimesh.Trimesh | None = None
    note: str = ""

    def trimesh(self) -> trimesh.Trimesh:
        """The layout as a ``trimesh.Trimesh`` with its normals and atlas UVs (no texture yet)."""
        mesh = trimesh.Trimesh(self.vertices, self.faces, vertex_normals=self.normals, process=False)
        mesh.visual = trimesh.visual.TextureVisuals(uv=self.uv)
        return mesh

    def tangents(self) -> np.ndarray:
        """``[V', 4]`` float32 vertex tangents of the atlas UVs (xyz unit, w the bitangent sign), as
        the rasteriser computes them (:func:`warptex.gbuffer.vertex_tangents`): the frame a baked
        normal map is in, and the GLB's ``TANGENT``."""
        return vertex_tangents(self.vertices, self.faces, self.normals, self.uv)


def _checked_size(func: str, size) -> int:
    """The bake size as an int in ``[2, 16384]``, or a ``TypeError``/``ValueError`` naming ``func``."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
        raise TypeError(f"{func}(): size must be an int (texels per side), got {type(size).__name__}")
    if not 2 <= size <= 16384:
        raise ValueError(f"{func}(): size must be in [2, 16384] texels (engines load textures of at most 16384²), got {size}")
    return int(size)


def unusable_reason(uv: np.ndarray | None, vertices: np.ndarray, faces: np.ndarray, *, own_faces: np.ndarray | None = None, device=None) -> str:
    """Why the UV set ``uv`` ``[V, 2]`` cannot be baked into (``""`` if it can): missing, outside
    ``[0, 1]`` (:func:`unkeepable_reason`), faces with area that have no UVs of their own
    (``own_faces``, bool ``[F]``: :func:`warptex.mesh.mesh_uv_faces`), or two triangles
    overlapping (named by their face indices)."""
    reason = unkeepable_reason(uv, vertices, faces)
    if reason:
        return reason
    has_area = _has_area(vertices, faces)
    if own_faces is not None:
        without = np.flatnonzero(has_area & ~np.asarray(own_faces, bool))
        if len(without):
            return f"{len(without)} of its {len(faces)} faces have no UVs of their own (parts without texture coordinates, e.g. face {without[0]})"
    found = overlapping_faces(np.asarray(uv, np.float64), faces, has_area, device=device)
    hits = np.flatnonzero(found >= 0)
    if len(hits):
        return f"its UV charts overlap ({len(hits)} triangles, e.g. faces {hits[0]} and {found[hits[0]]})"
    return ""


def unkeepable_reason(uv: np.ndarray | None, vertices: np.ndarray, faces: np.ndarray) -> str:
    """Why the UV set ``uv`` cannot be baked into even on request (``""`` if it can, overlapping or
    not): missing, not finite, outside ``[0, 1]``, or no triangle with UV area."""
    if uv is None:
        return "the mesh has no UVs"
    uv = np.asarray(uv, np.float64)
    if not np.isfinite(uv).all():
        return "its UVs are not all finite"
    used = uv[np.unique(faces)]
    if used.min() < 0.0 or used.max() > 1.0:
        return f"its UVs leave the texture (they span [{used.min():.3g}, {used.max():.3g}], not inside [0, 1])"
    if len(bakeable_faces(vertices, faces, uv)) == 0:
        return "every UV triangle has zero area"
    return ""


def overlapping_faces(uv: np.ndarray, faces: np.ndarray, has_area: np.ndarray, *, device=None) -> np.ndarray:
    """For each face ``[F]``, a later face (by index) whose UV triangle overlaps its own by more
    than :data:`OVERLAP_TOLERANCE`, or -1 (also for faces without world area, ``~has_area``, or
    UV area, which hold no texel): a BVH of the UV triangles and the separating-axis test
    (:func:`warptex.kernels.bake.overlap_kernel`)."""
    _, texture = face_areas(np.zeros((len(uv), 3)), faces, uv)
    ids = np.flatnonzero(has_area & (texture > 0))
    found = np.full(len(faces), -1, np.int64)
    if len(ids) == 0:
        return found
    device = wp.get_device(device)
    points = wp.array(np.concatenate([uv, np.zeros((len(uv), 1))], axis=1).astype(np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(faces[ids].reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
    bvh = wp.Mesh(points=points, indices=indices)
    overlaps = wp.empty(len(ids), dtype=wp.int32, device=device)
    wp.launch(kb.overlap_kernel, dim=len(ids), inputs=[bvh.id, points, indices, OVERLAP_TOLERANCE], outputs=[overlaps], device=device, record_tape=False)
    other = overlaps.numpy()
    hit = other >= 0
    found[ids[hit]] = ids[other[hit]]
    return found


def unwrap(mesh: trimesh.Trimesh, *, size: int = 2048, padding: int = 8, force_atlas: bool = False, keep_uvs: bool = False, atlas: str = "auto", device=None) -> UVLayout:
    """The UV layout to bake ``mesh`` into: its first UV set (``"uv0"``) when usable (see the
    module docstring), else (or with ``force_atlas``) an automatic atlas.

    Args:
        mesh: a ``trimesh.Trimesh``.
        size: texels per side of the texture the atlas is made for.
        padding: texels between the atlas's charts (the gutters live there), ``>= 0``.
        force_atlas: make an atlas even when the mesh's UVs are usable.
        keep_uvs: keep the mesh's UVs even where charts overlap (their triangles then share
            texels) or parts have none of their own; refused where they cannot hold a bake at
            all (:func:`unkeepable_reason`: missing, outside ``[0, 1]``).
        atlas: how an atlas is made: ``"xatlas"`` (few seams, little stretch; a minute for
            80 000 faces), ``"projection"`` (charts projected along six axes,
            :mod:`warptex.charts`: seconds for a million faces), or ``"auto"`` (default): xatlas
            up to :data:`XATLAS_FACES` faces, and projected charts for larger meshes or where
            xatlas crashes; ``UVLayout.source`` and ``UVLayout.note`` say which and why.
        device: Warp device for the overlap test.

    Raises:
        TypeError, ValueError: a bad argument, or a mesh that cannot be unwrapped (no triangle
            with area, non-finite vertices, xatlas leaving a triangle without UV area, charts
            that do not fit ``size`` with ``padding``).
    """
    func = "unwrap"
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"{func}(): mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
    size = _checked_size(func, size)
    if isinstance(padding, bool) or not isinstance(padding, (int, np.integer)) or padding < 0:
        raise ValueError(f"{func}(): padding must be an int >= 0 (texels between charts), got {padding!r}")
    if atlas not in ATLAS_METHODS:
        raise ValueError(f"{func}(): atlas must be one of {', '.join(map(repr, ATLAS_METHODS))}, got {atlas!r}")
    vertices, faces = checked_geometry(f"{func}():", mesh)
    normals = vertex_normals(mesh)
    # A vertex of zero-area faces only has no normal; glTF wants unit ones, and no face with area
    # can show it: any unit vector does.
    normals[np.linalg.norm(normals, axis=1) == 0] = (0.0, 0.0, 1.0)
    own = mesh_uv_sets(mesh).get("uv0")
    if keep_uvs:
        if force_atlas:
            raise ValueError(f"{func}(): keep_uvs and force_atlas ask for opposite things; pass one")
        reason = unkeepable_reason(own, vertices, faces)
        if reason:
            raise ValueError(f"{func}(): the mesh's own UVs cannot be kept: {reason}")
    else:
        reason = unusable_reason(own, vertices, faces, own_faces=mesh_uv_faces(mesh), device=device) or ("an atlas was asked for" if force_atlas else "")
    if not reason:
        return UVLayout(vertices, faces, own, normals, np.arange(len(vertices)), "mesh", mesh=mesh)
    vertex_map, new_faces, uv, source, note = _atlas(func, vertices, faces, size, int(padding), atlas, device)
    return UVLayout(vertices[vertex_map], new_faces, uv, normals[vertex_map], vertex_map, source, reason, int(padding), mesh, note)


def face_areas(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Each face's area ``[F]`` in the world, and in UV space (``None`` without ``uv``), float64."""
    p = np.asarray(vertices, np.float64)[faces]
    world = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    if uv is None:
        return world, None
    t = np.asarray(uv, np.float64)[faces]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    return world, 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _has_area(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``[F]`` bool: the faces with world area (beyond rounding: 1e-12 of the largest)."""
    world, _ = face_areas(vertices, faces)
    return world > 1e-12 * max(world.max(), 1e-300)


def bakeable_faces(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Indices of the faces with area both in the world and in UV space: the others hold no texel
    (no UV area) or no surface (no world area: no normal, no Jacobian)."""
    world, texture = face_areas(vertices, faces, uv)
    return np.flatnonzero((world > 1e-12 * max(world.max(), 1e-300)) & (texture > 0))


#: Meshes of more faces get projected charts (:mod:`warptex.charts`) rather than xatlas's: xatlas
#: took 55 s for 81 920 faces here (a noisy icosphere) and longer than linearly for more; the
#: projected atlas of a million faces takes seconds.
XATLAS_FACES = 50_000
#: The longest xatlas may take (seconds) on :data:`XATLAS_FACES` faces before a bake falls back to
#: projected charts; smaller meshes get less (:func:`xatlas_timeout`).
XATLAS_TIMEOUT = 600.0
#: The least it may take: a mesh of a few faces takes xatlas a fraction of a second.
XATLAS_MIN_TIMEOUT = 60.0


def xatlas_timeout(faces: int) -> float:
    """Seconds xatlas may take on ``faces`` faces: :data:`XATLAS_TIMEOUT` at :data:`XATLAS_FACES`,
    scaled as its time grows (faster than linearly), and at least :data:`XATLAS_MIN_TIMEOUT`."""
    return max(XATLAS_MIN_TIMEOUT, XATLAS_TIMEOUT * (faces / XATLAS_FACES) ** 1.5)
#: The script that runs xatlas, in a process of its own.
_CHILD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "_xatlas_child.py")


def _atlas(func: str, vertices: np.ndarray, faces: np.ndarray, size: int, padding: int, method: str, device) -> tuple[np.ndarray, np.ndarray, np.ndarray, str, str]:
    """``(vertex_map, faces, uv, source, note)``: xatlas's atlas or projected charts, as
    ``method`` says (``"auto"``: xatlas up to :data:`XATLAS_FACES` faces), and why the projected
    charts where xatlas was not used."""
    note = ""
    if method == "xatlas" or (method == "auto" and len(faces) <= XATLAS_FACES):
        try:
            return (*_xatlas(func, vertices, faces, size, padding), "xatlas", "")
        except _XatlasFailed as err:
            if method == "xatlas":
                raise ValueError(f"{func}(): {err}; unwrap with atlas='projection' (warptex bake: --atlas projection)") from None
            note = str(err)
    elif method == "auto":
        note = f"it has {len(faces)} faces, more than xatlas unwraps in reasonable time ({XATLAS_FACES})"

    has_area = _has_area(vertices, faces)
    try:
        vertex_map, new_faces, uv = projected_atlas(vertices, faces, size, padding, overlaps=lambda uv, f: overlapping_faces(uv, f, has_area, device=device) >= 0)
    except ValueError as err:
        raise ValueError(f"{func}(): projected charts cannot unwrap this mesh: {err}") from None
    return vertex_map, new_faces, uv, "projection", note


class _XatlasFailed(Exception):
    """xatlas's process died or took too long (not a refusal of the mesh, which is a ValueError)."""


def _xatlas(func: str, vertices: np.ndarray, faces: np.ndarray, size: int, padding: int):
    """xatlas's atlas of the mesh scaled into a ``size``² texture: ``(vertex_map, faces, uv)``,
    made in a process of its own (:mod:`warptex._xatlas_child`)."""
    try:
        import xatlas  # noqa: F401 (checked here, used by the child process)
    except ImportError as err:  # a dependency; only a broken install lacks it
        raise ImportError(f"{func}(): the mesh needs an automatic UV atlas, which needs the xatlas package (pip install xatlas)") from err
    # Charts do not depend on scale: a unit-sized copy keeps xatlas's arithmetic in range (it
    # asserts and stalls on coordinates near 1e30 and drops triangles of area near 1e-60).
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    unit = (vertices - lo) / max(float(np.linalg.norm(hi - lo)), 1e-300)
    world, _ = face_areas(unit, faces)
    area = float(world.sum())
    if not area > 1e-12:
        raise ValueError(f"{func}(): xatlas cannot unwrap this mesh: its {len(faces)} triangles have no area")
    texels_per_unit = math.sqrt(ATLAS_FILL * size * size / area)
    with tempfile.TemporaryDirectory(prefix="warptex-xatlas-") as folder:
        given, made = os.path.join(folder, "in.npz"), os.path.join(folder, "out.npz")
        np.savez(given, vertices=unit.astype(np.float32), faces=faces.astype(np.uint32), texels_per_unit=texels_per_unit, padding=padding, size=size)
        timeout = xatlas_timeout(len(faces))
        for attempt in range(2):
            try:
                done = subprocess.run([sys.executable, _CHILD, given, made], capture_output=True, text=True, timeout=timeout)
                break
            except subprocess.TimeoutExpired:
                # Twice in a test run here, xatlas's process stalled on an 80-face sphere that it
                # unwraps in 0.15 s (not seen again in 500 unwraps, loaded or not): once more,
                # before falling back to projected charts. xatlas gives the same atlas every time.
                if attempt == 1:
                    raise _XatlasFailed(f"xatlas did not finish within {timeout:g} s, twice") from None
        if done.returncode != 0 or not os.path.exists(made):
            how = f"crashed ({_signal_name(-done.returncode)})" if done.returncode < 0 else f"failed (exit status {done.returncode}: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else 'no message'})"
            raise _XatlasFailed(f"xatlas {how} on this mesh")
        with np.load(made) as out:
            result = {k: out[k] for k in out.files}
    if "error" in result:
        raise ValueError(f"{func}(): {result['error']}")
    vertex_map, new_faces, uv = result["vertex_map"], result["faces"], result["uv"]
    # xatlas gives u = x / width, v = y / height; one scale for both keeps texels square.
    uv = ((uv * np.array([result["width"], result["height"]], np.float64) + result["border"]) / result["extent"]).astype(np.float32)
    new_faces = new_faces.astype(np.int64)
    if len(new_faces) != len(faces) or not (vertex_map[new_faces] == faces).all():
        raise ValueError(f"{func}(): xatlas cannot unwrap this mesh: it changed the mesh's triangles")
    _, texture = face_areas(unit[vertex_map], new_faces, uv)
    lost = np.flatnonzero(~np.isfinite(uv[new_faces]).all(axis=(1, 2)) | ((texture <= 0) & (world > 1e-9)))
    if len(lost):
        raise ValueError(f"{func}(): xatlas cannot unwrap this mesh: {len(lost)} triangles with area got no UV area (e.g. face {lost[0]})")
    return vertex_map.astype(np.int64), new_faces, np.clip(uv, 0.0, 1.0)


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


_RENAMED = {'checked_size': '_checked_size'}  # old public spellings, kept for one release


def __getattr__(name: str):
    from warptex._validate import renamed_attribute

    return renamed_attribute(__name__, name, _RENAMED, globals())
