"""``warptex bake``: texture a mesh as ``warptex render`` does, bake it into a UV atlas, export glTF.

The mesh (the procedural terrain by default) gets the material ``render`` gives it, or the one the
options name: one texture mapped triplanar or biplanar (optionally anti-tiled, with a normal map),
or splat-blended layers. :func:`warptex.bake_gltf` evaluates it over the texture-space G-buffer
of the mesh's atlas (its own UV0 when usable, else xatlas), band by band, and writes
``asset.glb`` with ``asset_color.png`` (and ``asset_normal.png``, ``asset_alpha.png``) beside it,
all at once.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from warptex._compile import preload
from warptex._output import check_memory, check_output_folder
from warptex.apps.render import mesh_material, mesh_technique, terrain_material, terrain_used
from warptex.bake import BAKE_BYTES, BAKE_TEXEL_BYTES
from warptex.gbuffer import load_mesh
from warptex.gltf import bake_gltf
from warptex.tiles import checked_memory
from warptex.kernels import bake as kb
from warptex.kernels import splat as kl
from warptex.kernels import raster as kr
from warptex.kernels import sampling as ks
from warptex.kernels import stochastic_sample as kss
from warptex.kernels import triplanar as kt
from warptex.splat import splat
from warptex.options import Filter, Sampler
from warptex.scenes import TERRAIN_GRID
from warptex.scenes.terrain import terrain
from warptex.texture import Texture, TextureArray
from warptex.triplanar import biplanar_normal, triplanar_normal
from warptex.unwrap import _checked_size

TECHNIQUES = ("uv", "triplanar", "biplanar", "splat")


def _choose_technique(func: str, technique, mesh_path, texture_path, layer_paths, splat_path, normal_map_path) -> str:
    """The technique to bake, with the options checked against it before any work."""
    if (layer_paths is None) != (splat_path is None) and mesh_path is not None:
        raise ValueError(f"{func}(): --layers and --splat go together (layer images and the splat map that weighs them in UV0)")
    if technique is None and (layer_paths is not None or (mesh_path is None and texture_path is None)):
        technique = "splat"
    elif technique is None and normal_map_path is not None:
        technique = "triplanar"  # a normal map is mapped as a projection
    if technique is None:
        return None  # as render textures the mesh: through its UVs where it has them (mesh_material)
    if technique not in TECHNIQUES:
        raise ValueError(f"{func}(): technique must be one of {', '.join(TECHNIQUES)}, got {technique!r}")
    if technique == "splat":
        if mesh_path is not None and layer_paths is None:
            raise ValueError(f"{func}(): technique 'splat' needs layers: pass --layers L1 L2 ... and --splat MAP (or no --mesh, for the terrain's own)")
        if texture_path is not None:
            raise ValueError(f"{func}(): --texture is for triplanar and biplanar; splat reads --layers")
        if normal_map_path is not None:
            raise ValueError(f"{func}(): --normal-map works with triplanar and biplanar, not splat")
    elif layer_paths is not None:
        raise ValueError(f"{func}(): --layers and --splat are for technique 'splat', not {technique!r}")
    elif technique == "uv" and normal_map_path is not None:
        raise ValueError(f"{func}(): --normal-map works with triplanar and biplanar, not uv")
    return technique


def _kernels(technique: str, stochastic, normal_mapped: bool, num_layers: int, device) -> list:
    """The kernels a bake runs on ``device``: the texture-space G-buffer's, mip chains, and the technique's."""
    used = [kb.chart_kernel, kr.uv_kernel, ks.downsample_kernel]
    if technique == "splat":
        return used + [kl.splat_kernels(capacity=kl.capacity(num_layers), stochastic=stochastic is not None).launched(device)]
    if technique == "uv":
        return used + [(kss.stochastic_kernels() if stochastic is not None else ks.sample_kernels(level=False)).launched(device)]
    used.append(kt.triplanar_kernels(normal=False, stochastic=stochastic is not None, faces=False).launched(device))
    if normal_mapped:
        used.append(kt.triplanar_kernels(normal=True, stochastic=stochastic is not None, faces=False).launched(device))
    return used


def run_bake(
    out_path: str | os.PathLike = "out/asset.glb",
    *,
    mesh_path=None,
    texture_path=None,
    layer_paths=None,
    splat_path=None,
    normal_map_path=None,
    technique: str | None = None,
    stochastic: str | None = None,
    size: int = 2048,
    padding: int | None = None,
    gutter: int | None = None,
    tiling: float | None = None,
    seed: int = 0,
    filter: Filter | str = Filter.ANISOTROPIC,
    atlas: str = "auto",
    keep_uvs: bool = False,
    memory: int | None = None,
    progress: bool | None = None,
    report=None,
    device=None,
) -> list[Path]:
    """Bake a mesh's texturing and write ``out_path`` (``.glb``) and its textures beside it.

    Args:
        out_path: the GLB to write; ``<stem>_color.png`` etc. go beside it.
        mesh_path: a mesh file; ``None``: the procedural terrain with its splat layers.
        texture_path: the texture (default: the mesh's own, else a procedural ground texture).
        layer_paths, splat_path: layer images (RGBA, height in alpha) and the RGBA splat map in
            UV0 that weighs them (4 layers per map), for ``technique="splat"``.
        normal_map_path: a tangent-space normal map (data), mapped like the texture and baked
            into ``<stem>_normal.png`` and the GLB's normal texture.
        technique: ``"uv"``, ``"triplanar"``, ``"biplanar"`` or ``"splat"`` (default: splat for
            the terrain or with layers; triplanar with a normal map; else as ``warptex render``
            textures the mesh, :func:`warptex.apps.render.mesh_material`: through its UVs where it
            has them, with its own texture where it has one).
        stochastic: anti-tiling for the texture or layers (``"hash4"``, ``"cheap2"``, ``"hex"``).
        size: atlas texels per side. padding, gutter: see :func:`warptex.bake.bake`.
        tiling: as for ``warptex render`` (texture repeats across the mesh's largest extent,
            default 8; layers: repeats per world unit, default 1/6).
        seed: terrain and procedural texture seed. filter: the texture filter.
        atlas: how a mesh without usable UVs is unwrapped (:func:`warptex.unwrap`).
        keep_uvs: bake into the mesh's own UVs even where they overlap or parts have none
            (else they are replaced by an atlas, with a warning saying why).
        memory: bytes a band of the atlas may take (:func:`warptex.bake_gltf`, which bakes in
            bands: memory stays near this whatever the size). progress: a progress bar (``None``:
            on a terminal). report: called once, before the bake, with a line saying what it
            bakes (texture, mapping and why, tiling; ``warptex bake`` prints it). device: Warp device.

    Returns:
        The paths written, the GLB first.
    """
    func = "run_bake"
    out_path = Path(out_path)
    if out_path.suffix.lower() != ".glb":
        raise ValueError(f"{func}(): the output must be a .glb file, got {str(out_path)!r}")
    check_output_folder(func, out_path.parent)
    technique = _choose_technique(func, technique, mesh_path, texture_path, layer_paths, splat_path, normal_map_path)
    size = _checked_size(func, size)
    memory = checked_memory(func, memory)
    check_memory(func, f"a {size}x{size} bake", BAKE_BYTES[0] + min(memory, BAKE_TEXEL_BYTES * size * size), device, hint="use a smaller --memory")
    if tiling is not None and not (np.isfinite(tiling) and tiling > 0):
        raise ValueError(f"{func}(): tiling must be a finite number > 0, got {tiling!r}")
    sampler = Sampler(filter=filter)
    mesh = terrain(resolution=TERRAIN_GRID, seed=seed) if mesh_path is None else load_mesh(mesh_path)
    chosen = technique
    if technique is None:  # as render: through the mesh's UVs where it has them
        technique = mesh_technique(func, mesh, None)
    preload(_kernels(technique, stochastic, normal_map_path is not None, len(layer_paths or ()) or 4, device), device)  # compiled side by side on a cold start

    normal = None
    if technique == "splat" and mesh_path is None:
        colour = terrain_material(mesh, tiling, seed, sampler, device)
        used = terrain_used(colour.keywords["tiling"])
    elif technique == "splat":
        layers = TextureArray.from_files(layer_paths, channels=4, device=device)
        maps = TextureArray.from_files([splat_path], data=True, channels=4, mipmaps=False, device=device)
        colour = functools.partial(splat, layers=layers, splat_maps=maps, tiling=1.0 / 6.0 if tiling is None else tiling, projection="triplanar", height_blend=0.2, sampler=sampler, device=device)
        used = f"{len(layer_paths)} layers splat-blended by height by {splat_path} in UV0, each mapped triplanar, {colour.keywords['tiling']:.4g} repeats per unit"
    else:
        colour, used = mesh_material(func, mesh, chosen, texture_path, None, tiling, seed, sampler, device)
        if normal_map_path is not None:
            maps = Texture.from_file(normal_map_path, data=True, channels=3, device=device)
            mapping = triplanar_normal if technique == "triplanar" else biplanar_normal  # the colour's weights (and default sharpness)
            normal = functools.partial(mapping, normal_map=maps, tiling=colour.keywords["tiling"], stochastic=stochastic, sampler=sampler, device=device)
            used += f"; normal map {normal_map_path}, mapped alike"
    colour = functools.partial(colour, stochastic=stochastic) if stochastic else colour
    if report is not None:
        report(f"{used}{f'; anti-tiled ({stochastic})' if stochastic else ''}")
    return bake_gltf(mesh, out_path, colour, normal=normal, size=size, padding=padding, gutter=gutter, atlas=atlas, keep_uvs=keep_uvs, memory=memory, progress=progress, device=device)
