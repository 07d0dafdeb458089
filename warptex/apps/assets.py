"""``warptex assets``: the sample inputs the docs' snippets read, made from the procedural
scenes that ship with warptex (nothing is downloaded): the default terrain's four layers and its
splat map.

- ``grass.png``, ``gravel.png``, ``rock.png``, ``snow.png``: 256 × 256 RGBA, colour (sRGB) with the
  layer's height in alpha (:func:`warptex.scenes.material.terrain_layers`), tileable;
- ``splat.png``: the default terrain's splat map, 129 × 129 RGBA weights of the four layers, in
  that order (data: no sRGB; :func:`warptex.scenes.material.terrain_splat_maps`).
"""

from __future__ import annotations

import os
from pathlib import Path

from warptex import io
from warptex._output import check_output_folder, output_set
from warptex.scenes import TERRAIN_GRID
from warptex.scenes.material import LAYER_NAMES, terrain_layers, terrain_splat_maps
from warptex.scenes.terrain import terrain

ASSET_NAMES = tuple(f"{name}.png" for name in LAYER_NAMES) + ("splat.png",)


def run_assets(out_dir: str | os.PathLike = "assets", *, seed: int = 0) -> list[Path]:
    """Write the sample assets (module docstring) into ``out_dir``, all together or none.

    Args:
        out_dir: output folder (created if missing).
        seed: the terrain's and the layers' seed (0: those of ``warptex render``).

    Returns:
        The paths written.
    """
    check_output_folder("run_assets", out_dir)
    layers = terrain_layers(seed=seed).numpy()  # [4, 256, 256, 4], linear colour + height
    maps = terrain_splat_maps(terrain(resolution=TERRAIN_GRID, seed=seed), TERRAIN_GRID)
    with output_set(out_dir) as staging:
        for name, layer in zip(LAYER_NAMES, layers):
            io.write_png(staging / f"{name}.png", layer)  # colour sRGB-encoded; alpha (height) as is
        io.write_png(staging / "splat.png", maps, data=True)
    return [Path(out_dir) / name for name in ASSET_NAMES]
