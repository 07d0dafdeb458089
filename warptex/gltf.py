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

import contextlib
import json
import math
import os
import shutil
import struct
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh
import warp as wp
from PIL import Image

from warptex import io
from warptex._memory import trim
from warptex._output import check_output_folder, output_set
from warptex._warp import paused_tape
from warptex.bake import BAKE_BYTES, BAKE_TEXEL_BYTES, Baked, prepare_bake, tangent_space, texture_gbuffer_tiles
from warptex.gbuffer import GBuffer, load_mesh
from warptex.png import PngWriter, codes
from warptex.tiles import checked_memory
from warptex.unwrap import UVLayout


def texture_images(baked: Baked) -> dict[str, np.ndarray]:
    """The baked textures as they are written, float32 in ``[0, 1]``, ``(size, size, C)``:
    ``"color"`` (linear RGB; 1-2 channel colour as gray), ``"normal"`` (``n · 0.5 + 0.5``) and
    ``"alpha"`` (a fourth colour channel, e.g. the blended height of splat layers that keep height
    in alpha; not in the GLB, whose alpha would be opacity). Texels outside every chart and gutter
    get the mean colour of the charts and the flat normal ``(0.5, 0.5, 1)``, so that mip levels
    coarser than the gutters protect blend towards the asset's own colour, not black."""
    mask = baked.gbuffer.mask.numpy() > 0
    colour = _numpy(baked.color) if baked.color is not None else None
    images = {}
    if colour is not None:
        rgb, alpha = _colour_parts(colour)
        images["color"] = _filled(rgb, mask)
        if alpha is not None:
            images["alpha"] = _filled(alpha, mask)
    if baked.normal is not None:
        images["normal"] = _normal_image(_numpy(baked.normal), mask)
    return images


def export_gltf(baked: Baked, path: str | os.PathLike) -> list[Path]:
    """Write ``baked`` as a glTF 2.0 binary ``path`` (``.glb``) and its textures beside it as
    ``<stem>_color.png``, ``<stem>_normal.png`` and ``<stem>_alpha.png`` (those that were baked,
    see :func:`texture_images`), all at once: an error leaves the folder's previous files as
    they were (:func:`warptex._output.output_set`). :func:`warptex.bake_gltf` writes the same
    files, band by band, for atlases larger than memory.

    Returns:
        The paths written, the GLB first.

    Raises:
        TypeError: ``baked`` is not a :class:`~warptex.bake.Baked`. ValueError: ``path`` does not
            end in ``.glb``, or nothing colour-like was baked. OSError: the folder is a file.
    """
    func = "export_gltf"
    if not isinstance(baked, Baked):
        raise TypeError(f"{func}(): baked must be a warptex Baked (from warptex.bake), got {type(baked).__name__}")
    path = checked_glb_path(func, path)
    if baked.color is None and baked.normal is None:
        raise ValueError(f"{func}(): the bake has neither colour nor normals to export")
    colour = _numpy(baked.color) if baked.color is not None else None
    with output_set(path.parent) as staging:
        with AssetWriter(staging, path.name, baked.layout, baked.size, colour_channels=None if colour is None else colour.shape[-1], normal=baked.normal is not None) as writer:
            writer.write(baked.gbuffer.mask.numpy() > 0, colour, None if baked.normal is None else _numpy(baked.normal))
    return [path] + [path.parent / n for n in writer.texture_names.values()]


def bake_gltf(
    mesh,
    path: str | os.PathLike,
    technique: Callable[[GBuffer], wp.array] | None = None,
    *,
    normal: Callable[[GBuffer], wp.array] | None = None,
    size: int = 2048,
    padding: int | None = None,
    gutter: int | None = None,
    view_size: int = 512,
    force_atlas: bool = False,
    keep_uvs: bool = False,
    atlas: str = "auto",
    memory: int | None = None,
    progress: bool | None = None,
    device=None,
) -> list[Path]:
    """:func:`~warptex.bake` and :func:`export_gltf` in one, band by band: the atlas is evaluated
    in bands of rows (:func:`~warptex.texture_gbuffer_tiles`) whose work takes about ``memory``
    bytes, and each band's textures go to their files before the next is made, so an atlas of
    any size bakes in about ``memory`` plus the mesh and its textures. The files are those
    ``export_gltf(bake(...))`` writes for the same arguments, byte for byte.

    Args:
        mesh, technique, normal, size, padding, gutter, view_size, force_atlas, keep_uvs, atlas, device:
            as for :func:`~warptex.bake`.
        path: the ``.glb`` to write; the textures go beside it (:func:`export_gltf`).
        memory: bytes a band's work may take (default :data:`warptex.tiles.DEFAULT_MEMORY`).
        progress: a progress bar over the atlas's rows on stderr (``None``: on a terminal only).

    Returns:
        The paths written, the GLB first.
    """
    from tqdm import tqdm

    func = "bake_gltf"
    path = checked_glb_path(func, path)
    memory = checked_memory(func, memory)
    layout, gutter, device = prepare_bake(
        func, mesh, technique, normal, size=size, padding=padding, gutter=gutter, view_size=view_size, force_atlas=force_atlas, keep_uvs=keep_uvs, atlas=atlas, device=device,
        needed=lambda n: BAKE_BYTES[0] + min(memory, BAKE_TEXEL_BYTES * n * n), hint="use a smaller memory budget (--memory)",
    )
    tiles = texture_gbuffer_tiles(layout, size, gutter=gutter, memory=memory, device=device)
    bar = tqdm(total=size, desc="bake", unit="row", disable=False if progress else None if progress is None else True)
    writer = None
    try:
        with output_set(path.parent) as staging:
            try:
                for tile in tiles:
                    with paused_tape():
                        colour = technique(tile.gbuffer).numpy() if technique is not None else None
                        normals = tangent_space(tile.gbuffer, normal(tile.gbuffer)).numpy() if normal is not None else None
                    if writer is None:
                        writer = AssetWriter(staging, path.name, layout, size, colour_channels=None if colour is None else colour.shape[-1], normal=normals is not None)
                    writer.write(tile.gbuffer.mask.numpy() > 0, colour, normals)
                    bar.update(tile.rows.stop - tile.rows.start)
                    del tile, colour, normals  # one band's arrays at a time
                    trim()
                bar.set_postfix_str("glTF")
                writer.close()
            finally:  # (before output_set removes the staging folder the writer's files are in)
                if writer is not None:
                    writer._release()
    finally:
        bar.close()
    return [path] + [path.parent / n for n in writer.texture_names.values()]


def checked_glb_path(func: str, path) -> Path:
    """``path`` as a ``Path`` ending in ``.glb`` in a folder that can be written, or an error naming ``func``."""
    path = Path(os.fspath(path))
    if path.suffix.lower() != ".glb":
        raise ValueError(f"{func}(): path must end in .glb, got {str(path)!r}")
    check_output_folder(func, path.parent)
    return path


class AssetWriter:
    """A baked asset written band by band into a staging folder: the GLB ``name`` and its textures
    ``<stem>_color.png``, ``_normal.png``, ``_alpha.png`` (:func:`texture_images`).

    The normal map goes straight into its PNG. The colour and alpha fill the texels outside every
    chart with the charts' mean, known only after the last band: their codes wait in hidden files
    of the staging folder (3 and 2 bytes a texel) and the coverage in memory (a bit a texel), and
    :meth:`close` writes the PNGs from them, then the GLB with the PNG files' bytes as its images.
    The mean is a sum of per-row float64 sums (``math.fsum``): the same bits however the rows
    were cut.
    """

    def __init__(self, staging: Path, name: str, layout: UVLayout, size: int, *, colour_channels: int | None, normal: bool):
        self.staging, self.layout, self.size = Path(staging), layout, size
        self.glb = self.staging / name
        kinds = []
        if colour_channels is not None:
            kinds += ["color"] + (["alpha"] if colour_channels >= 4 else [])
        kinds += ["normal"] if normal else []
        self.texture_names = {kind: f"{Path(name).stem}_{kind}.png" for kind in kinds}
        self._rows = 0
        self._covered = np.zeros((size, (size + 7) // 8), np.uint8)  # the chart-and-gutter mask, a bit a texel
        self._count = 0
        self._sums = {kind: [] for kind in ("color", "alpha") if kind in kinds}  # per-row float64 sums
        self._codes = {kind: open(self.staging / f".{kind}.codes", "w+b") for kind in self._sums}  # noqa: SIM115 (closed by _release)
        self._normal = PngWriter(self.staging / self.texture_names["normal"], size, size, 3, data=True) if normal else None

    def write(self, mask: np.ndarray, colour: np.ndarray | None, normal: np.ndarray | None) -> None:
        """The next rows: their chart-and-gutter ``mask`` ``(n, size)`` bool, the colour ``(n, size,
        C)`` (linear) and the unit tangent-space ``normal`` ``(n, size, 3)``, as the bake has them."""
        rows = slice(self._rows, self._rows + len(mask))
        self._covered[rows] = np.packbits(mask, axis=1)
        self._rows = rows.stop
        self._count += int(mask.sum())
        if colour is not None:
            nans = int(np.isnan(colour).sum())
            if nans:
                raise ValueError(f"AssetWriter.write(): the baked colour has {nans} NaN value(s) in rows {rows.start}..{rows.stop - 1}; a PNG has no NaN")
            rgb, alpha = _colour_parts(colour)
            for kind, values, bits in (("color", rgb, 8), ("alpha", alpha, 16)):
                if kind in self._sums:
                    self._sums[kind].append(np.where(mask[..., None], values, 0.0).sum(axis=1, dtype=np.float64))
                    self._codes[kind].write(codes(values, data=kind != "color", bits=bits).tobytes())
        if self._normal is not None:
            self._normal.write(_normal_image(normal, mask))

    def close(self) -> None:
        """Write the colour and alpha PNGs, then the GLB (every row must have been written)."""
        try:
            if self._rows != self.size:
                raise ValueError(f"AssetWriter.close(): {self._rows} of {self.size} rows were written")
            if self._normal is not None:
                self._normal.close()
            for kind in self._sums:
                self._write_filled(kind, 8 if kind == "color" else 16)
            _write_glb(self.glb, self.layout, {kind: self.staging / name for kind, name in self.texture_names.items() if kind != "alpha"})
        finally:
            self._release()

    def _write_filled(self, kind: str, bits: int) -> None:
        """The PNG of ``kind``: its codes read back band by band, those of texels outside the
        charts and gutters set to the code of the charts' mean."""
        sums = np.concatenate(self._sums[kind])  # [size, C]: each row's sum of each channel
        mean = np.array([math.fsum(sums[:, c]) for c in range(sums.shape[1])]) / max(self._count, 1)
        data = kind != "color"
        fill = codes(mean.astype(np.float32)[None, None, :], data=data, bits=bits)[0, 0]
        dtype = np.uint8 if bits == 8 else np.uint16
        row_bytes = self.size * len(fill) * np.dtype(dtype).itemsize
        source = self._codes[kind]
        source.seek(0)
        step = max(1, (8 << 20) // row_bytes)  # rows read at once: 8 MB
        with PngWriter(self.staging / self.texture_names[kind], self.size, self.size, len(fill), bits=bits, data=data) as png:
            for start in range(0, self.size, step):
                n = min(step, self.size - start)
                band = np.frombuffer(source.read(n * row_bytes), dtype=dtype).reshape(n, self.size, len(fill)).copy()
                inside = np.unpackbits(self._covered[start : start + n], axis=1, count=self.size).astype(bool)
                band[~inside] = fill
                png.write_codes(band)

    def _release(self) -> None:
        for f in self._codes.values():
            f.close()
            with contextlib.suppress(FileNotFoundError):  # its folder may be gone (an error's clean-up)
                os.remove(f.name)
        self._codes = {}
        if self._normal is not None:
            self._normal.abort()  # nothing once closed

    def __enter__(self) -> "AssetWriter":
        return self

    def __exit__(self, kind, error, trace) -> None:
        if error is None:
            self.close()
        else:
            self._release()


def _write_glb(path: Path, layout: UVLayout, textures: dict[str, Path]) -> None:
    """The GLB of ``layout``: trimesh lays out the mesh, its atlas UVs, normals, tangents (with a
    normal map) and material, with 1 × 1 placeholders for the textures, and the binary chunk is
    then written anew, view by view, each texture's view holding its PNG file's bytes, copied
    from disk (an 8192² texture never passes through memory whole)."""
    material = trimesh.visual.material.PBRMaterial(  # placeholders that differ (trimesh shares equal images)
        name=path.stem,
        baseColorTexture=Image.new("RGB", (1, 1), (0, 0, 0)) if "color" in textures else None,
        normalTexture=Image.new("RGB", (1, 1), (128, 128, 255)) if "normal" in textures else None,
        metallicFactor=0.0,
        roughnessFactor=1.0,
    )
    mesh = layout.trimesh()
    mesh.visual = trimesh.visual.TextureVisuals(uv=layout.uv, material=material)
    if "normal" in textures:
        mesh.vertex_attributes["TANGENT"] = layout.tangents().astype(np.float32)
    glb = trimesh.exchange.gltf.export_glb(mesh, include_normals=True, tree_postprocessor=_postprocess)
    json_length = struct.unpack_from("<I", glb, 12)[0]
    tree = json.loads(glb[20 : 20 + json_length])
    binary = memoryview(glb)[20 + json_length + 8 :]
    material = tree["materials"][0]
    sources = {}  # bufferView index -> the file that replaces it
    for kind, ref in (("color", material.get("pbrMetallicRoughness", {}).get("baseColorTexture")), ("normal", material.get("normalTexture"))):
        if kind in textures:
            sources[tree["images"][tree["textures"][ref["index"]]["source"]]["bufferView"]] = textures[kind]
    pieces, offset = [], 0  # (bytes or a path, length), each view's start aligned to 4 bytes
    for k, view in enumerate(tree["bufferViews"]):
        length = os.path.getsize(sources[k]) if k in sources else view["byteLength"]
        data = sources[k] if k in sources else binary[view.get("byteOffset", 0) : view.get("byteOffset", 0) + length]
        view["byteOffset"], view["byteLength"] = offset, length
        pad = -length % 4
        pieces.append((data, length, pad))
        offset += length + pad
    tree["buffers"] = [{"byteLength": offset}]
    text = json.dumps(tree, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(text) + 8 + offset))
        f.write(struct.pack("<I4s", len(text), b"JSON") + text)
        f.write(struct.pack("<I4s", offset, b"BIN\0"))
        for data, length, pad in pieces:
            if isinstance(data, Path):
                with open(data, "rb") as src:
                    shutil.copyfileobj(src, f, 8 << 20)
            else:
                f.write(data)
            f.write(bytes(pad))


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
            stored = np.asarray(image.convert("RGB"), np.float32) / 255.0
            textures[kind] = stored if data else io.srgb_to_linear(stored)
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


def _numpy(values) -> np.ndarray:
    return np.asarray(values.numpy(), np.float32)


def _colour_parts(colour: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """A baked colour ``(..., C)`` as RGB (1-2 channels as gray) and its fourth channel (``None`` without one)."""
    rgb = colour[..., :3] if colour.shape[-1] >= 3 else np.repeat(colour[..., :1], 3, axis=-1)
    return rgb, colour[..., 3:4] if colour.shape[-1] >= 4 else None


def _normal_image(normal: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Unit tangent-space normals as a normal map's values, ``n · 0.5 + 0.5``, flat outside ``mask``."""
    return np.where(mask[..., None], normal * 0.5 + 0.5, np.array([0.5, 0.5, 1.0], np.float32))


def _filled(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``values`` with the texels outside ``mask`` set to the mean of those inside."""
    mean = values[mask].mean(axis=0) if mask.any() else np.zeros(values.shape[-1], np.float32)
    return np.where(mask[..., None], values, mean).astype(np.float32)
