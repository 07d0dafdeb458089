"""xatlas in a process of its own: ``python _xatlas_child.py IN.npz OUT.npz``.

xatlas 0.0.11 crashes (a segfault in ``PackCharts``) on some meshes, an icosphere of 81 920 faces
among them; in the caller's process that would end it with no message. So
:func:`warptex.unwrap.unwrap` runs it here, a script run by path (it imports NumPy and xatlas
only, not warptex and Warp: it starts in ~0.2 s), and falls back to projected charts when this
process dies. ``IN`` holds ``vertices`` (unit-sized, float32), ``faces`` (uint32),
``texels_per_unit``, ``padding`` and ``size``; ``OUT`` gets ``vertex_map``, ``faces``, ``uv``
(xatlas's, in texels), ``width``, ``height`` and ``extent``, or ``error`` (a message) when xatlas
refuses the mesh or cannot pack it at this size.
"""

import math
import sys

import numpy as np

PADDING_MARGIN = 1.15  # warptex.unwrap.PADDING_MARGIN


def atlas(vertices: np.ndarray, faces: np.ndarray, texels_per_unit: float, padding: int, size: int) -> dict:
    import xatlas

    asked = math.ceil(padding * PADDING_MARGIN)
    border = (asked + 1) // 2  # charts keep half the padding from the texture's edges: room for their gutters
    for _ in range(8):
        result = xatlas.Atlas()
        try:
            result.add_mesh(vertices, faces)
            options = xatlas.PackOptions()
            options.padding, options.bilinear, options.texels_per_unit = asked, True, texels_per_unit
            result.generate(xatlas.ChartOptions(), options)
        except RuntimeError as err:
            return {"error": f"xatlas cannot unwrap this mesh: {err}"}
        if result.atlas_count != 1:
            return {"error": f"xatlas cannot unwrap this mesh: it made {result.atlas_count} atlases, not 1"}
        extent = max(result.width, result.height) + 2 * border
        if extent <= size * PADDING_MARGIN:
            vertex_map, new_faces, uv = result[0]
            return {"vertex_map": vertex_map, "faces": new_faces, "uv": uv, "width": result.width, "height": result.height, "extent": extent, "border": border}
        texels_per_unit *= min(0.9, 0.97 * size / extent)  # too large to keep the padding when scaled down: again, smaller
    return {"error": f"xatlas cannot pack this mesh's charts into {size}² texels with {padding} texels of padding between them; use a larger size or less padding"}


def main(source: str, target: str) -> None:
    given = np.load(source)
    out = atlas(given["vertices"], given["faces"], float(given["texels_per_unit"]), int(given["padding"]), int(given["size"]))
    np.savez(target, **{k: np.asarray(v) for k, v in out.items()})


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
