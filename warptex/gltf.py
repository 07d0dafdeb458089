"""glTF 2.0 export of a baked asset: one ``.glb`` that Blender, Unity, Unreal, Godot and web viewers
open, and its textures as PNG files beside it.

The GLB is written by trimesh: the mesh with its atlas UVs (``TEXCOORD_0``), vertex normals, a
metallic-roughness material (metallic 0, roughness 1) with ``baseColorTexture`` (sRGB PNG) and,
when a normal map was baked, ``normalTexture`` (linear PNG, OpenGL/glTF convention: green along
+v) with the vertex tangents it was baked against (``TANGENT``; trimesh writes extra vertex
attributes with a leading underscore, which one rename in its JSON tree makes glTF's own). The
textures are sampled trilinear and clamped to the edge (:data:`SAMPLER`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from warptex import io
from warptex._output import check_output_folder, output_set
from warptex.bake import Baked
from warptex.gbuffer import load_mesh


def texture_images(baked: Baked) -> dict[str, np.ndarray]:
    """The baked textures as they are written, float32 in ``[0, 1]``, ``(size, size, C)``:
    ``"color"`` (linear RGB; 1-2 channel colour as gray), ``"normal"`` (``n · 0.5 + 0.5``) and
    ``"alpha"`` (a fourth colour channel, e.g. the blended height of splat layers that keep height
    in alpha; not in the GLB, whose alpha would be opacity). Texels outside every chart and gutter
    get the mean colour of the charts and the flat normal ``(0.5, 0.5, 1)``, so that mip levels
    coarser than the gutters protect blend towards the asset's own colour, not black."""
    mask = baked.gbuffer.mask.numpy() > 0
    images = {}
    if baked.color is not None:
        colour = _numpy(baked.color)
        rgb = colour[..., :3] if colour.shape[-1] >= 3 else np.repeat(colour[..., :1], 3, axis=-1)
        images["color"] = _filled(rgb, mask)
        if colour.shape[-1] >= 4:
            images["alpha"] = _filled(colour[..., 3:4], mask)
    if baked.normal is not None:
        images["normal"] = np.where(mask[..., None], _numpy(baked.normal) * 0.5 + 0.5, np.array([0.5, 0.5, 1.0], np.float32))
    return images


def export_gltf(baked: Baked, path: str | os.PathLike) -> list[Path]:
    """Write ``baked`` as a glTF 2.0 binary ``path`` (``.glb``) and its textures beside it as
    ``<stem>_color.png``, ``<stem>_normal.png`` and ``<stem>_alpha.png`` (those that were baked,
    see :func:`texture_images`), all at once: an error leaves the folder's previous files as
    they were (:func:`warptex._output.output_set`).

    Returns:
        The paths written, the GLB first.

    Raises:
        TypeError: ``baked`` is not a :class:`~warptex.bake.Baked`. ValueError: ``path`` does not
            end in ``.glb``, or nothing colour-like was baked. OSError: the folder is a file.
    """
    func = "export_gltf"
    if not isinstance(baked, Baked):
        raise TypeError(f"{func}(): baked must be a warptex Baked (from warptex.bake), got {type(baked).__name__}")
    path = Path(os.fspath(path))
    if path.suffix.lower() != ".glb":
        raise ValueError(f"{func}(): path must end in .glb, got {str(path)!r}")
    check_output_folder(func, path.parent)
    if baked.color is None and baked.normal is None:
        raise ValueError(f"{func}(): the bake has neither colour nor normals to export")
    images = texture_images(baked)
    names = {kind: f"{path.stem}_{kind}.png" for kind in images}
    with output_set(path.parent) as staging:
        for kind, image in images.items():
            io.write_png(staging / names[kind], image, data=kind != "color", bits=16 if kind == "alpha" else 8)
        material = trimesh.visual.material.PBRMaterial(
            name=path.stem,
            baseColorTexture=_image(staging / names["color"]) if "color" in names else None,
            normalTexture=_image(staging / names["normal"]) if "normal" in names else None,
            metallicFactor=0.0,
            roughnessFactor=1.0,
        )
        mesh = baked.layout.trimesh()
        mesh.visual = trimesh.visual.TextureVisuals(uv=baked.layout.uv, material=material)
        if "normal" in names:
            mesh.vertex_attributes["TANGENT"] = baked.layout.tangents().astype(np.float32)
        glb = trimesh.exchange.gltf.export_glb(mesh, include_normals=True, tree_postprocessor=_postprocess)
        (staging / path.name).write_bytes(glb)
    return [path] + [path.parent / n for n in names.values()]


def load_gltf(path: str | os.PathLike) -> tuple[trimesh.Trimesh, dict[str, np.ndarray]]:
    """A glTF file holding one mesh (as :func:`export_gltf` writes it), with its vertex normals
    kept (:func:`warptex.load_mesh` flattens scenes, which recomputes them), and its material's
    textures: ``{"color": [H, W, C] linear float32, "normal": [H, W, 3] data in [0, 1]}`` (those
    it has). The mesh's node transform is applied.

    Raises:
        ValueError: the file does not hold exactly one triangle mesh.
    """
    func = "load_gltf"
    mesh = load_mesh(path)  # the checks and errors of every mesh file
    scene = trimesh.load(os.fspath(path), process=False)
    parts = list(scene.graph.nodes_geometry) if isinstance(scene, trimesh.Scene) else []
    if len(parts) != 1:
        raise ValueError(f"{func}(): {os.fspath(path)!r} holds {len(parts)} mesh instances, not 1")
    transform, name = scene.graph[parts[0]]
    single = scene.geometry[name]
    normals = np.asarray(single.vertex_normals, np.float64) @ np.linalg.inv(transform[:3, :3])
    mesh.vertex_normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    material = getattr(mesh.visual, "material", None)
    textures = {}
    for kind, attribute, data in (("color", "baseColorTexture", False), ("normal", "normalTexture", True)):
        image = getattr(material, attribute, None)
        if image is not None:
            codes = np.asarray(image.convert("RGB"), np.float32) / 255.0
            textures[kind] = codes if data else io.srgb_to_linear(codes)
    return mesh, textures


#: The textures' glTF sampler: trilinear, clamped to the edge. An atlas is not a tiling texture:
#: repeating it would read the opposite border's texels at charts that touch an edge.
SAMPLER = {"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}


def _postprocess(tree: dict) -> None:
    """The JSON tree trimesh made, finished: its ``_TANGENT`` vertex attribute (trimesh writes extra
    attributes as ``_NAME``) becomes glTF's ``TANGENT``, and every texture gets :data:`SAMPLER`."""
    for mesh in tree.get("meshes", []):
        for primitive in mesh.get("primitives", []):
            attributes = primitive.get("attributes", {})
            if "_TANGENT" in attributes:
                attributes["TANGENT"] = attributes.pop("_TANGENT")
    tree["samplers"] = [dict(SAMPLER)]
    for texture in tree.get("textures", []):
        texture["sampler"] = 0


def _image(path: Path) -> Image.Image:
    image = Image.open(path)
    image.load()
    return image


def _numpy(values) -> np.ndarray:
    return np.asarray(values.numpy(), np.float32)


def _filled(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``values`` with the texels outside ``mask`` set to the mean of those inside."""
    mean = values[mask].mean(axis=0) if mask.any() else np.zeros(values.shape[-1], np.float32)
    return np.where(mask[..., None], values, mean).astype(np.float32)
