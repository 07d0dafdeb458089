"""Scenes that the command line, the benchmarks and the tests share: the procedural terrain, its
material, and the camera the default render looks at it from.

- :mod:`.terrain`: :func:`~warptex.scenes.terrain.terrain`, a seeded heightfield mesh with cliffs;
- :mod:`.material`: its four procedural layers and splat maps, and periodic noise textures;
- :func:`framing_camera`: the default view of any mesh (``warptex render --mesh``, the bake benchmark).

They are built from the library and NumPy alone, so anything may import them; the applications
(:mod:`warptex.apps`) are never imported by the library, the benchmarks or these scenes.
"""

from __future__ import annotations

import numpy as np

from warptex.camera import Camera, look_at, orthographic
from warptex.raster import rasterize

#: The default terrain's vertex grid, one splat texel per vertex.
TERRAIN_GRID = (129, 129)


def framing_camera(mesh, resolution, fov_y: float = 45.0, *, up=None) -> Camera:
    """A three-quarter view of the mesh's front, a little from above and the right, far enough that
    its bounding sphere fits the view: ``warptex render``'s default camera.

    Files do not say where a model's front is, and not all are +Y up as glTF's are (Blender's
    axes, Z up and facing -Y, are common): the front is taken to be the side, of the six along
    the axes, that shows the most triangles (a face, a head's features, a building's facade rather
    than its roof), found by rasterising the views small, in one launch. Seen from ±Y, the
    model is taken to be Z-up (that view is then its front, with +Z up).

    ``up``: the model's up axis where the file says it (glTF: +Y, by its specification): the
    front is then one of the four sides around it, and the view comes from above, never from
    underneath (a car's wheels show more triangles than its roof).
    """
    centre, radius = mesh.bounds.mean(axis=0), max(float(np.linalg.norm(mesh.extents)) / 2, 1e-9)
    axes = np.concatenate([np.eye(3), -np.eye(3)])[[2, 0, 5, 3, 1, 4]]  # +Z first: glTF's front wins ties
    if up is None:
        ups = [(0.0, 0.0, 1.0) if abs(a[1]) > 0.5 else (0.0, 1.0, 0.0) for a in axes]
    else:
        up = np.asarray(up, np.float64)
        if up.shape != (3,) or not np.isfinite(up).all() or np.linalg.norm(up) == 0:
            raise ValueError(f"framing_camera(): up must be 3 finite numbers, not all 0, got {up.tolist()}")
        up = up / np.linalg.norm(up)
        axes = np.array([a for a in axes if abs(float(a @ up)) < 0.5])  # the sides around an axis-aligned up
        if len(axes) != 4:
            raise ValueError(f"framing_camera(): up must be along an axis (±X, ±Y or ±Z), got {up.tolist()}")
        ups = [tuple(up)] * len(axes)
    views = [orthographic(centre + a * 2 * radius, centre, up=u, height=2 * radius, resolution=(48, 48)) for a, u in zip(axes, ups)]
    triangles = rasterize(mesh, views).triangle.numpy()
    shown = [len(np.unique(t[t >= 0])) for t in triangles]
    k = int(np.argmax(shown))
    front, up = axes[k], np.asarray(ups[k])
    direction = front + 0.45 * up + 0.35 * np.cross(up, front)  # lifted, and from the model's right
    half_fov = np.radians(fov_y) / 2 * min(1.0, resolution[1] / resolution[0])
    distance = 1.05 * radius / np.sin(half_fov)
    return look_at(centre + direction / np.linalg.norm(direction) * distance, centre, up, fov_y=fov_y, resolution=resolution)


def terrain_camera(resolution, fov_y: float = 45.0) -> Camera:
    """The default scene's camera: over the near corner of the default terrain, looking across it."""
    return look_at((-30.0, 34.0, 40.0), (2.0, 2.0, -4.0), fov_y=fov_y, resolution=resolution)


def terrain_cameras(resolution, count: int = 2):
    """``count`` (1–3) cameras on the default terrain: the default three-quarter view; a view
    straight down (orthographic, the whole terrain); the opposite corner looking back."""
    cams = [
        terrain_camera(resolution),
        orthographic((0.0, 60.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), height=66.0 * max(1.0, resolution[0] / resolution[1]), resolution=resolution),
        look_at((30.0, 34.0, -40.0), (-2.0, 2.0, 4.0), resolution=resolution),
    ]
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 1 <= count <= len(cams):
        raise ValueError(f"terrain_cameras(): count must be 1 to {len(cams)}, got {count!r}")
    return cams[:count]
