"""The main job: rasterise a mesh (the procedural terrain by default), texture it, light it, save it.

The default terrain is textured with four splat-blended layers (grass, gravel, rock, snow; see
:mod:`warptex.scenes.material`), each mapped triplanar, height-blended. Other meshes get one
texture: in their UV0 when they have UVs (their own embedded base-colour texture when they carry
one), else triplanar. Every pixel takes several stratified samples (``samples``), each filtered
anisotropically at its own footprint, lit by a key light and a sky fill
(:func:`warptex.apps.shade.sun_and_sky`), and averaged with its coverage as alpha.
"""

from __future__ import annotations

import functools
import math
import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh
import warp as wp

from warptex._compile import preload
from warptex._memory import trim
from warptex.kernels import splat as kl
from warptex.kernels import raster as kr
from warptex.kernels import sampling as ks
from warptex.kernels import triplanar as kt
from warptex.camera import checked_resolution, look_at
from warptex.exr_writer import ExrWriter
from warptex.gbuffer import GBuffer, load_mesh
from warptex.mesh import mesh_uv_faces, up_axis
from warptex.gbuffer_io import GBufferWriter
from warptex.png import PngWriter
from warptex.resolve import resolve
from warptex.sampling import sample
from warptex.stochastic import stochastic as stochastic_sample
from warptex._output import check_memory, check_output_folder, output_set
from warptex.tiles import SAMPLE_BYTES, checked_memory, gbuffer_tiles
from warptex.apps.shade import SKY, sun_and_sky, to_rgb
from warptex.scenes import TERRAIN_GRID, terrain_camera
from warptex.scenes import framing_camera as default_camera
from warptex.scenes.terrain import terrain, terrain_normal_grid
from warptex.texture import Texture, TextureArray
from warptex.splat import splat
from warptex.options import Filter, Sampler
from warptex.scenes.material import LAYER_NAMES, noise_texture, terrain_layer_texels, terrain_layers, terrain_splat_maps
from warptex.triplanar import biplanar, triplanar


#: Memory of a render beside its bands, measured (peak RSS of a 64² render, the default terrain):
#: Python, Warp, the compiled kernels, the mesh and its textures; with a margin.
RENDER_BASE_BYTES = 400e6
#: Samples per pixel of a render (2 × 2, stratified): anti-aliased silhouettes and texture detail
#: with the cold start of ``warptex render`` inside 10 s on two cores.
DEFAULT_SAMPLES = 4


#: How ``render`` and ``bake`` texture a mesh: through its own UVs, or projected.
MESH_TECHNIQUES = ("uv", "triplanar", "biplanar")


def checked_technique_name(func: str, technique: str) -> None:
    """A ``ValueError`` unless ``technique`` is one of :data:`MESH_TECHNIQUES`."""
    if technique not in MESH_TECHNIQUES:
        raise ValueError(f"{func}(): technique must be one of {', '.join(MESH_TECHNIQUES)} for a mesh, got {technique!r}")


def mesh_technique(func: str, mesh: trimesh.Trimesh, technique: str | None) -> str:
    """How a mesh is textured: ``technique`` checked against it, or (``None``) ``"uv"`` where it
    has UVs (on some of its faces at least, :func:`~warptex.mesh.mesh_uv_faces`), else
    ``"triplanar"``."""
    has_uvs = bool(mesh_uv_faces(mesh).any())
    if technique is None:
        technique = "uv" if has_uvs else "triplanar"
    checked_technique_name(func, technique)
    if technique == "uv" and not has_uvs:
        raise ValueError(f"{func}(): technique 'uv' reads the mesh's UVs, and it has none; use triplanar or biplanar")
    return technique


def mesh_material(func: str, mesh: trimesh.Trimesh, technique: str | None, texture_path, texture_layer, tiling: float | None, seed: int, sampler: Sampler, device) -> tuple[Callable[[GBuffer], wp.array], str]:
    """The colour of a G-buffer as ``warptex render`` textures a mesh, and ``warptex bake`` bakes
    it, the same for the same arguments; and what it used, in words (the line ``render`` and
    ``bake`` print).

    The texture is ``texture_path``, else the mesh's own (glTF base colour, OBJ ``map_Kd``), else a
    procedural ground. ``technique`` (:func:`mesh_technique`): ``"uv"`` (through UV0 × ``tiling``;
    default ``tiling`` 1 with the mesh's own texture, else 8), ``"triplanar"`` or ``"biplanar"``
    (``tiling`` repeats across the mesh's largest extent, default 8). Through UVs, the faces of
    parts that have none (:func:`~warptex.mesh.mesh_uv_faces`) get the texture triplanar, 8
    repeats across the mesh, unless it is the mesh's own (which holds their flat colour)."""
    chosen = technique
    technique = mesh_technique(func, mesh, technique)
    embedded = _embedded_texture(mesh) if texture_path is None else None
    if texture_path is not None:
        texture = Texture.from_file(texture_path, layer=texture_layer, device=device)
        source = f"texture {os.fspath(texture_path)}"
    else:
        texture = Texture(embedded, format="srgb8", device=device) if embedded is not None else Texture(noise_texture(seed=seed), device=device)
        source = "the mesh's own texture" if embedded is not None else f"a procedural ground texture (seed {seed})"
    why = "as asked" if chosen is not None else "it has them" if technique == "uv" else "it has no UVs"
    tiling = (1.0 if embedded is not None and technique == "uv" else 8.0) if tiling is None else float(tiling)
    if technique != "uv":
        used = f"{source}, mapped {technique} ({why}), {_repeats(tiling)} across the mesh"
        return triplanar_material(mesh, texture, tiling, sampler, device, technique=triplanar if technique == "triplanar" else biplanar), used
    used = f"{source} through the mesh's UVs ({why}), {_repeats(tiling)} across UV0"
    own = mesh_uv_faces(mesh)
    if own.all() or embedded is not None:
        return functools.partial(_through_uvs, texture=texture, tiling=tiling, sampler=sampler, device=device), used
    used += f"; mapped triplanar, {_repeats(8.0)} across the mesh, on the {int((~own).sum())} faces of its parts without UVs"
    fallback = triplanar_material(mesh, texture, 8.0, sampler, device)
    return functools.partial(_through_uvs, texture=texture, tiling=tiling, sampler=sampler, device=device, fallback=(own, fallback)), used


def _through_uvs(gbuffer: GBuffer, *, texture: Texture, tiling: float, sampler: Sampler, device, stochastic=None, fallback=None) -> wp.array:
    """``texture`` at the G-buffer's UV0 × ``tiling`` (with its derivatives: the footprint);
    with ``stochastic``, anti-tiled (:func:`~warptex.stochastic`). ``fallback``: ``(own, material)``,
    the mesh's faces with UVs of their own (bool ``[F]``) and the material of the others' pixels."""
    uv, uv_dx, uv_dy = (np.ascontiguousarray(gbuffer.uv_sets["uv0"][k].numpy() * tiling, np.float32) for k in ("uv", "uv_dx", "uv_dy"))
    if stochastic is not None:
        out = stochastic_sample(texture, uv, stochastic, uv_dx=uv_dx, uv_dy=uv_dy, sampler=sampler, device=device)
    else:
        out = sample(texture, uv, uv_dx=uv_dx, uv_dy=uv_dy, sampler=sampler, device=device)
    if fallback is None:
        return out
    own, material = fallback
    triangle = gbuffer.triangle.numpy()
    without = (triangle >= 0) & ~own[np.maximum(triangle, 0)]
    if not without.any():
        return out
    projected = (material(gbuffer) if stochastic is None else material(gbuffer, stochastic=stochastic)).numpy()
    return wp.array(np.where(without[..., None], projected, out.numpy()), dtype=wp.float32, device=out.device)


def triplanar_material(mesh: trimesh.Trimesh, texture: Texture, tiling: float, sampler: Sampler, device, technique=triplanar) -> Callable[[GBuffer], wp.array]:
    """``technique`` (:func:`~warptex.triplanar` or :func:`~warptex.biplanar`) of ``texture`` with
    ``tiling`` repeats across the mesh's largest extent, as a function of a G-buffer."""
    scale = tiling / max(float(np.max(mesh.extents)), 1e-12)
    return functools.partial(technique, texture=texture, tiling=scale, sampler=sampler, device=device)


#: Splat-map texels per terrain grid cell in the preview: smooth layer borders at the default view.
SPLAT_UPSAMPLE = 4


def terrain_textures(mesh: trimesh.Trimesh, seed: int, device, texels: np.ndarray | None = None) -> tuple[TextureArray, TextureArray]:
    """The default terrain's layers and (finer, :data:`SPLAT_UPSAMPLE`) splat maps; the layers'
    ``texels`` (:func:`~warptex.scenes.material.terrain_layer_texels`) made here unless given (a
    render makes them on a second thread from its start: they are NumPy's work alone)."""
    maps = terrain_splat_maps(mesh, TERRAIN_GRID, upsample=SPLAT_UPSAMPLE)
    layers = terrain_layers(seed=seed, device=device) if texels is None else TextureArray(texels, device=device)
    return layers, TextureArray(maps[None], mipmaps=False, device=device)


def terrain_material(mesh: trimesh.Trimesh, tiling: float | None, seed: int, sampler: Sampler, device, textures=None) -> Callable[[GBuffer], wp.array]:
    """The default terrain's splat material as a function of a G-buffer: four layers mapped
    triplanar, height-blended, repeating ``tiling`` times per world unit (default 1/6); its
    ``textures`` (:func:`terrain_textures`) made here unless given."""
    layers, maps = terrain_textures(mesh, seed, device) if textures is None else textures
    tiling = 1.0 / 6.0 if tiling is None else float(tiling)
    return functools.partial(splat, layers=layers, splat_maps=maps, tiling=tiling, projection="triplanar", height_blend=0.2, sampler=sampler, device=device)


def terrain_used(tiling: float) -> str:
    """What the default terrain's material uses, in words (:func:`terrain_material`)."""
    return f"the default terrain: {len(LAYER_NAMES)} procedural layers ({', '.join(LAYER_NAMES)}) splat-blended by height, each mapped triplanar, {_per_unit(tiling)}"


def _per_unit(tiling: float) -> str:
    return f"one repeat per {1.0 / tiling:.4g} units" if tiling < 1.0 else f"{_repeats(tiling)} per unit"


def _repeats(tiling: float) -> str:
    return f"{tiling:.4g} repeat{'' if tiling == 1.0 else 's'}"


#: Passes of terrain_normal_grid's [1, 2, 1] filter over the preview terrain's vertex normals.
NORMAL_SMOOTHING = 2


def _smooth_normals(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The terrain with its vertex normals smoothed (:func:`terrain_normal_grid`): interpolated
    across each triangle, the raw ones kink along every cell's diagonal, a sawtooth on the
    cliffs; smoothed, neighbouring triangles' normals differ too little to show it. The geometry
    stays as it is."""
    smooth = mesh.copy()
    smooth.vertex_normals = terrain_normal_grid(mesh, TERRAIN_GRID, smoothing=NORMAL_SMOOTHING).reshape(-1, 3)
    return smooth


def _embedded_texture(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """The mesh's colour texture as 8-bit sRGB codes (an ``srgb8`` texture's): glTF's base colour,
    or an OBJ material's ``map_Kd``; ``None`` without one."""
    material = getattr(mesh.visual, "material", None)
    image = getattr(material, "baseColorTexture", None)
    if image is None:
        image = getattr(material, "image", None)
    if image is None:
        return None
    return np.asarray(image.convert("RGB"))


def _kernels(terrain: bool, device) -> list:
    """The kernels a render runs on ``device``: rasterisation, mip chains, and the splat or sampling ones."""
    used = [kr.raster_kernel, ks.downsample_kernel]
    if terrain:
        return used + [kl.splat_kernels(capacity=kl.capacity(len(LAYER_NAMES)), stochastic=False).launched(device)]
    return used + [ks.sample_kernels(level=False).launched(device), kt.triplanar_kernels(normal=False, stochastic=False, faces=False).launched(device)]


def run_render(
    out_dir: str | os.PathLike = "out",
    *,
    mesh_path=None,
    texture_path=None,
    texture_layer: str | None = None,
    technique: str | None = None,
    resolution=(512, 512),
    eye=None,
    target=None,
    up=None,
    fov_y: float = 45.0,
    tiling: float | None = None,
    seed: int = 0,
    samples: int = DEFAULT_SAMPLES,
    filter: Filter | str = Filter.ANISOTROPIC,
    memory: int | None = None,
    progress: bool | None = None,
    report: Callable[[str], None] | None = None,
    device=None,
) -> list[Path]:
    """Render a mesh and write ``render.png``, ``albedo.png``, ``normals.png``, ``render.exr`` and ``gbuffer.exr``.

    The image is made in bands of rows (:func:`warptex.gbuffer_tiles`), each rasterised, textured,
    lit, resolved and written before the next, so memory stays near ``memory`` whatever the
    resolution; the pixels are the same bits at any band height.

    Args:
        out_dir: output folder (created if missing).
        mesh_path: a mesh file; ``None`` renders the procedural terrain (:func:`warptex.scenes.terrain.terrain`).
        texture_path: the texture; default: the mesh's embedded texture, else a procedural ground texture.
        texture_layer: the layer of an EXR texture to read (:func:`warptex.io.read_image`'s ``layer``).
        technique: for a mesh, ``"uv"``, ``"triplanar"`` or ``"biplanar"`` (:func:`mesh_material`;
            default: through its UVs where it has them, else triplanar), as ``warptex bake`` bakes
            it; the terrain is always splat-blended (``"splat"``).
        resolution: ``(height, width)``.
        eye, target: camera position and look-at point (default: a three-quarter view framing the mesh).
        up: the world direction shown upward (default: +Y, or -Z looking straight down; see
            :func:`warptex.camera.look_at`).
        fov_y: vertical field of view, degrees.
        tiling: how often the texture repeats, in a unit that depends on the mesh. The default
            terrain: layer repeats per world unit (default 1/6, one repeat per 6 units). A mesh with
            UVs: repeats across UV0 (default 1 with its embedded texture, else 8). A mesh without
            UVs, mapped triplanar: repeats across the mesh's largest extent (default 8).
        seed: terrain and procedural texture seed.
        samples: stratified samples per pixel, 1, 4, 9, 16, ... (:func:`warptex.rasterize`): the
            image is anti-aliased, silhouettes get fractional coverage (``render.exr``'s alpha),
            and textures are filtered at one sample's footprint. ``gbuffer.exr`` holds one sample
            per pixel (its centre), the size of the images.
        filter: the texture filter (:class:`~warptex.Filter`); default anisotropic, which keeps
            surfaces seen at grazing angles (the distant terrain) sharp where trilinear blurs them.
        memory: bytes a band's work may take (default :data:`warptex.tiles.DEFAULT_MEMORY`,
            256 MiB); the job takes about this plus the textures and ~300 MB of code.
        progress: show a progress bar (``None``: only on a terminal).
        report: called once, before the image is made, with a line saying what the render uses:
            texture, mapping and why, tiling, camera position (``warptex render`` prints it).
        device: Warp device.

    Returns:
        The paths written.
    """
    from tqdm import tqdm  # a progress bar over the rows: the first run also compiles kernels for seconds

    func = "run_render"
    check_output_folder(func, out_dir)
    if texture_layer is not None and texture_path is None:
        raise ValueError(f"{func}(): texture_layer={texture_layer!r} names a layer of the texture file, but no texture_path is given")
    if technique is not None and mesh_path is None and texture_path is None:
        if technique != "splat":
            raise ValueError(f"{func}(): the default terrain is splat-blended; technique {technique!r} needs a mesh (--mesh)")
        technique = None
    elif technique is not None:  # before the mesh is loaded
        checked_technique_name(func, technique)
    sampler = Sampler(filter=filter)
    h, w = resolution = checked_resolution(func, resolution)
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1 or math.isqrt(int(samples)) ** 2 != samples:
        raise ValueError(f"{func}(): samples must be a square number of samples per pixel (1, 4, 9, 16, ...), got {samples!r}")
    memory = checked_memory(func, memory)
    band = min(memory, SAMPLE_BYTES * samples * h * w)
    check_memory(func, f"a {h}x{w} render of {samples} samples per pixel", RENDER_BASE_BYTES + band, hint="use a smaller --memory")
    if tiling is not None and not (np.isfinite(tiling) and tiling > 0):
        raise ValueError(f"{func}(): tiling must be a finite number > 0, got {tiling!r}")
    bar = tqdm(total=h, desc="render", unit="row", disable=False if progress else None if progress is None else True)
    is_terrain = mesh_path is None and texture_path is None
    with ThreadPoolExecutor(1) as pool:  # the terrain layers' NumPy (0.5 s) beside all the rest up to the material
        texels = pool.submit(terrain_layer_texels, seed=seed) if is_terrain else None
        bar.set_postfix_str("kernels")
        preload(_kernels(is_terrain, device), device)  # a cold start compiles them side by side
        bar.set_postfix_str("mesh")
        mesh = terrain(resolution=TERRAIN_GRID, seed=seed) if mesh_path is None else load_mesh(mesh_path)
        framing = terrain_camera(resolution, fov_y) if mesh_path is None else default_camera(mesh, resolution, fov_y, up=up_axis(mesh_path))
        if eye is None and target is None and up is None:
            camera = framing
        else:
            eye = framing.eye if eye is None else eye
            target = mesh.bounds.mean(axis=0) if target is None else target
            camera = look_at(eye, target, up, fov_y=fov_y, resolution=resolution)
        bar.set_postfix_str("textures")
        shaded = _smooth_normals(mesh) if mesh_path is None else mesh  # the splat rules keep the terrain's own normals
        tiles = gbuffer_tiles(shaded, camera, samples=samples, memory=memory, device=device)
        textures = terrain_textures(mesh, seed, device, texels.result()) if is_terrain else None
    if is_terrain:
        material = terrain_material(mesh, tiling, seed, sampler, device, textures=textures)
        used = terrain_used(material.keywords["tiling"])
    else:
        material, used = mesh_material(func, mesh, technique, texture_path, texture_layer, tiling, seed, sampler, device)
    if report is not None:
        report(f"{used}; camera at {','.join(f'{x:.4g}' for x in np.asarray(camera.eye, np.float64))}")

    names = ["render.png", "albedo.png", "normals.png", "render.exr", "gbuffer.exr"]
    bar.set_postfix_str("")
    with output_set(out_dir) as staging, ExitStack() as files:  # all five files appear together, or none do
        colour = [files.enter_context(PngWriter(staging / n, h, w, 3, data=n == "normals.png")) for n in names[:3]]
        linear = files.enter_context(ExrWriter(staging / names[3], h, w, ("R", "G", "B", "A")))
        centres = None
        for tile in tiles:
            lit, albedo, normal, alpha = _shaded_pixels(tile.gbuffer, material, samples, device)
            colour[0].write(lit + (1.0 - alpha) * SKY)
            colour[1].write(albedo + (1.0 - alpha) * SKY)
            colour[2].write(normal)  # over black
            # premultiplied linear RGBA, alpha the pixel's coverage: the sky is transparent black, so it composites over anything
            linear.write(np.concatenate([lit, alpha], axis=-1))
            centre = tile.gbuffer if samples == 1 else tile.rasterize(1)  # gbuffer.exr: one sample per pixel
            if centres is None:
                centres = files.enter_context(GBufferWriter(staging / names[4], h, w, uv_sets=list(centre.uv_sets), origin=centre.origin))
            centres.write(centre)
            bar.update(tile.rows.stop - tile.rows.start)
            del tile, centre, lit, albedo, normal, alpha  # before the next tile is made: one tile's arrays at a time
            trim()
    bar.close()
    return [Path(out_dir) / name for name in names]


def _shaded_pixels(g: GBuffer, material: Callable[[GBuffer], wp.array], samples: int, device) -> tuple[np.ndarray, ...]:
    """A tile's lit colour, albedo and normals (premultiplied by coverage) and its coverage, each
    ``(rows, W, C)``: its samples textured, lit by the sun and the sky, and resolved to pixels."""
    albedo = to_rgb(material(g))
    lit = sun_and_sky(g, albedo)
    # Premultiplied samples (0 where the mesh is missed), resolved to pixels in one launch:
    # colours whose alpha is the pixel's coverage, so silhouettes blend with the sky.
    covered = g.mask.numpy()[..., None]
    normal = g.normal.numpy() * 0.5 + 0.5
    pixels = resolve(np.concatenate([lit * covered, albedo * covered, normal * covered, covered], axis=-1), samples, device=device).numpy()
    return pixels[..., 0:3], pixels[..., 3:6], pixels[..., 6:9], pixels[..., 9:10]
