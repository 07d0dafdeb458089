"""Meshes: loading any file trimesh reads as one checked ``trimesh.Trimesh``, its UV sets, vertex
normals and tangents, as :func:`warptex.raster.rasterize` uses them."""

from __future__ import annotations

import os
import warnings

import numpy as np
import trimesh


def load_mesh(path: str | os.PathLike) -> trimesh.Trimesh:
    """Load a mesh file (OBJ, PLY, STL, GLB/GLTF, ...) as one ``trimesh.Trimesh``.

    Scenes are flattened with their node transforms; materials and UVs are kept where trimesh can
    merge them. An STL file's triangles, stored apart, are joined at their shared corners, so
    that it is shaded smooth as other formats are. The mesh is checked as :func:`rasterize` checks it (triangles, finite vertices and
    UVs, face indices in range), so a bad file is reported as such, naming it, before anything
    is rendered.

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
    _check_signature(path)
    try:
        scene = trimesh.load(path, force="scene", process=False)  # what force="mesh" flattens; glTF normals are read from it
        loaded = scene.to_mesh() if hasattr(scene, "to_mesh") else scene.dump(concatenate=True)  # trimesh 5 / 4
    except Exception as err:  # trimesh raises many types for bad files
        raise ValueError(f"load_mesh(): cannot read {path!r} as a mesh: {' '.join(str(err).split())}") from err
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"load_mesh(): {path!r} holds no triangle mesh (got {type(loaded).__name__})")
    if len(loaded.faces) == 0:
        _no_faces(path)
    extension = os.path.splitext(path)[1].lower()
    if extension == ".obj":
        _drop_missing_materials(path, loaded)
    parts = _flattened_parts(scene, loaded)
    if parts and extension in (".glb", ".gltf"):
        _keep_gltf_normals(parts, loaded)
    if parts:
        _mark_faces_without_uvs(parts, loaded)
    if extension == ".stl":  # STL stores each triangle's corners apart:
        loaded.merge_vertices()  # shared, they get the smooth vertex normals other formats get
    checked_geometry(f"load_mesh(): {path!r}:", loaded)
    return loaded


def _drop_missing_materials(path: str, mesh: trimesh.Trimesh) -> None:
    """An OBJ whose material file (``mtllib``), or its colour image (``map_Kd``), is not there:
    trimesh gives it a placeholder material, a flat grey image, which would pass for the mesh's
    own texture. Warn, naming the missing file, and keep the UVs without a material."""
    folder = os.path.dirname(path)
    missing = []
    for words in _directives(path, "mtllib"):
        whole = " ".join(words)  # one name with spaces, or several names
        libraries = [whole] if os.path.isfile(os.path.join(folder, whole)) else words
        for library in libraries:
            library_path = os.path.join(folder, library)
            if not os.path.isfile(library_path):
                missing.append(f"its material file {library!r}")
                continue
            for image in _directives(library_path, "map_Kd"):
                # The file name comes last, after options such as "-bm 1", and may hold spaces.
                if not any(os.path.isfile(os.path.join(folder, " ".join(image[k:]))) for k in range(len(image))):
                    missing.append(f"the image {_image_name(image)!r} of {library!r}")
    if missing and isinstance(mesh.visual, trimesh.visual.TextureVisuals):
        warnings.warn(f"load_mesh(): {path!r} names {', '.join(missing)}, not found: it is loaded without its material", UserWarning, stacklevel=3)
        mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.visual.uv, material=trimesh.visual.material.SimpleMaterial(image=None))


def _flattened_parts(scene, mesh: trimesh.Trimesh) -> list[tuple[np.ndarray, trimesh.Trimesh]] | None:
    """The scene's meshes with their node transforms, ``[(transform, part)]``, in the order the
    flattened ``mesh`` holds their vertices and faces; ``None`` where it does not (a scene with
    other geometry, or flattened otherwise)."""
    if not isinstance(scene, trimesh.Scene):
        return None
    parts = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        part = scene.geometry[name]
        if not isinstance(part, trimesh.Trimesh):
            return None
        parts.append((transform, part))
    if not parts or sum(len(p.faces) for _, p in parts) != len(mesh.faces):
        return None
    vertices = np.concatenate([trimesh.transform_points(np.asarray(p.vertices, np.float64), t) for t, p in parts])
    if not np.isfinite(vertices).all():  # reported by the checks that follow
        return None
    scale = max(float(np.abs(vertices).max()), 1.0)
    if vertices.shape != np.shape(mesh.vertices) or not np.allclose(vertices, mesh.vertices, rtol=0.0, atol=1e-6 * scale):
        return None
    return parts


def _keep_gltf_normals(parts: list[tuple[np.ndarray, trimesh.Trimesh]], mesh: trimesh.Trimesh) -> None:
    """trimesh flattens a glTF scene into one mesh without the file's vertex normals, which are then
    recomputed, split at every UV seam (a baked asset, whose atlas has many, re-rendered with
    visible facets). Take them from the scene's meshes instead (:func:`_flattened_parts`), turned
    as their nodes place them."""
    normals = []
    for transform, part in parts:
        stored = getattr(getattr(part, "_cache", None), "cache", {}).get("vertex_normals")
        if stored is None or np.shape(stored) != np.shape(part.vertices):
            return
        turned = np.asarray(stored, np.float64) @ np.linalg.inv(transform[:3, :3])  # the inverse transpose, on rows
        normals.append(turned / np.maximum(np.linalg.norm(turned, axis=1, keepdims=True), 1e-300))
    mesh.vertex_normals = np.concatenate(normals)


#: ``mesh.metadata`` key of a loaded scene's faces whose UV0 are their own (:func:`mesh_uv_faces`).
OWN_UV_FACES = "warptex_own_uv_faces"


def _mark_faces_without_uvs(parts: list[tuple[np.ndarray, trimesh.Trimesh]], mesh: trimesh.Trimesh) -> None:
    """A scene some of whose parts have UVs (a truck's body) and some none (its windows): trimesh
    gives the flattened mesh UVs everywhere, those of the parts without pointing at one spot of its
    packed material. Keep which faces have UVs of their own (:func:`mesh_uv_faces`)."""
    own = np.concatenate([np.full(len(p.faces), getattr(p.visual, "uv", None) is not None and len(p.visual.uv) == len(p.vertices)) for _, p in parts])
    if not own.all() and "uv0" in mesh_uv_sets(mesh):
        mesh.metadata[OWN_UV_FACES] = own


def mesh_uv_faces(mesh: trimesh.Trimesh) -> np.ndarray:
    """Which faces ``[F]`` (bool) have UV0 coordinates of their own: none without UV0; in a loaded
    scene (:func:`load_mesh`), those of its parts that had UVs (trimesh gives the others UVs into
    its packed material, which hold their flat colour and nothing of a texture); else all."""
    if "uv0" not in mesh_uv_sets(mesh):
        return np.zeros(len(mesh.faces), bool)
    own = mesh.metadata.get(OWN_UV_FACES)
    if own is None or np.shape(own) != (len(mesh.faces),):
        return np.ones(len(mesh.faces), bool)
    return np.asarray(own, bool)


def _image_name(words: list[str]) -> str:
    """The file an MTL texture line (``map_Kd -clamp on -o 0 0 my file.png``) names: what follows
    its options, which take one word each, or up to three numbers (``-o``, ``-s``, ``-t``, ``-mm``)."""
    k = 0
    while k < len(words) - 1 and words[k].startswith("-"):
        k += 1
        if words[k - 1] in ("-o", "-s", "-t", "-mm"):
            while k < len(words) - 1 and _is_number(words[k]):
                k += 1
        else:
            k += 1
    return " ".join(words[k:])


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _directives(path: str, keyword: str) -> list[list[str]]:
    """The arguments of each of an OBJ or MTL file's ``keyword`` lines (``mtllib`` names one file
    or more; ``map_Kd`` options such as ``-bm 1`` come before its file)."""
    found = []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            words = line.split()
            if len(words) > 1 and words[0] == keyword:
                found.append(words[1:])
    return found


def up_axis(path: str | os.PathLike) -> tuple[float, float, float] | None:
    """The up axis a mesh file's format specifies: +Y for glTF (``.glb``, ``.gltf``); ``None`` for
    formats that leave it to the exporter (OBJ, PLY, STL...)."""
    return (0.0, 1.0, 0.0) if os.path.splitext(os.fspath(path))[1].lower() in (".glb", ".gltf") else None


# Formats whose files start with a signature, by extension: a file that lacks it is not that format
# (trimesh would report a failure deep inside its parser instead).
_SIGNATURES = {".glb": b"glTF"}


def _check_signature(path: str) -> None:
    expected = _SIGNATURES.get(os.path.splitext(path)[1].lower())
    if expected is None:
        return
    with open(path, "rb") as f:
        head = f.read(len(expected))
    if head != expected:
        raise ValueError(f"load_mesh(): {path!r} is not a binary glTF (.glb) file: it starts with {head!r}, "
                         f"a .glb file with {expected!r}")


def _no_faces(path: str) -> None:
    """Raise the error for a file that holds no triangles, saying what it holds instead."""
    try:
        whole = trimesh.load(path, process=False)  # a point cloud, a scene of lines...: count its vertices
        count = len(getattr(whole, "vertices", ()))
    except Exception:  # noqa: BLE001 (the face-less file is the error to report)
        count = 0
    holds = f"{count} vertices and no faces" if count else "no vertices and no faces"
    raise ValueError(f"load_mesh(): {path!r} holds {holds}; warptex renders triangle meshes")


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


def checked_geometry(prefix: str, mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``[V, 3]`` float64 and faces ``[F, 3]`` int64 of ``mesh``, or a ``ValueError``
    starting with ``prefix`` (e.g. ``"rasterize():"``): no triangles, a non-finite vertex, a
    face index out of range, a non-finite UV (which would texture its triangles with NaN)."""
    vertices = np.asarray(mesh.vertices, np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, np.int64).reshape(-1, 3)
    if len(faces) == 0 or len(vertices) == 0:
        raise ValueError(f"{prefix} the mesh is empty ({len(vertices)} vertices, {len(faces)} faces)")
    if not np.isfinite(vertices).all():
        bad = int(np.argwhere(~np.isfinite(vertices).all(axis=1))[0, 0])
        raise ValueError(f"{prefix} vertex {bad} is not finite: {vertices[bad].tolist()}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{prefix} face indices must be in [0, {len(vertices) - 1}], got [{faces.min()}, {faces.max()}]")
    for name, uv in mesh_uv_sets(mesh).items():
        finite = np.isfinite(uv).all(axis=1)
        if not finite.all():
            bad = int(np.argwhere(~finite)[0, 0])
            raise ValueError(f"{prefix} UV set {name!r} is not finite at {int((~finite).sum())} vertices, "
                             f"e.g. vertex {bad}: {uv[bad].tolist()}")
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
