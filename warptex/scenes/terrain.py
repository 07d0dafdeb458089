"""Procedural terrain: a seeded heightfield mesh with ridges, valleys and terraced cliffs.

The terrain is a test scene for the texturing techniques: its UV0 stretches one splat map over the
whole surface, and its cliff faces are steep enough (well past 60°) that planar UV or world-XZ
projection visibly stretches there, so triplanar mapping has something to fix.

Layout (world space right-handed, +Y up; the grid is seen from above with +X to the right and -Z
up, like a map with north up):

- The grid has ``rows × cols`` vertices, stored row-major: vertex ``r * cols + c`` sits at
  ``x = -size_x/2 + c·size_x/(cols-1)`` and ``z = -size_z/2 + r·size_z/(rows-1)``. Row 0 is the
  far (north, ``-Z``) edge, so ``mesh.vertices[:, 1].reshape(rows, cols)`` is a height image whose
  array row 0 is the top of the picture, exactly like a texture.
- UV0: ``u = c / (cols-1)`` (0 at ``x = -size_x/2``, 1 at ``+size_x/2``) and ``v = 1 - r / (rows-1)``
  (0 at the near edge ``z = +size_z/2``, 1 at the far edge ``z = -size_z/2``), so a splat map drawn
  in UV space lies on the terrain the right way up when seen from above.
- Heights span exactly ``[0, height]``: the lowest vertex has ``y = 0`` and the highest ``y = height``.
- Faces: two triangles per grid cell, wound counter-clockwise seen from above, so every face normal
  has a positive ``y`` component.

The heights are pure NumPy gradient (Perlin) noise: fractal Brownian motion blended with ridged
multifractal noise, shaped so valleys are broad and peaks sharp, then terraced where a
low-frequency mask says so. The terraces are a smooth staircase whose risers get steeper with
``cliffs``: benches stay flat and the faces between them become cliffs.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from warptex._validate import as_float
from warptex.gbuffer import vertex_normals

__all__ = ["terrain", "terrain_normal_grid", "terrain_slope_height"]

_TABLE = 256  # lattice hash period of the gradient noise
_MAX_OCTAVES = 16


# -- noise --------------------------------------------------------------------------------------------


class _Noise:
    """Seeded 2D gradient noise: a permutation table and 256 unit gradients, both from ``seed``.

    Every octave of every layer gets its own rotation and offset from a generator seeded with
    ``(seed, layer, octave)``, so adding octaves never changes the earlier ones.
    """

    def __init__(self, seed: int):
        rng = np.random.default_rng([seed, 0])
        perm = rng.permutation(_TABLE)
        self.perm = np.concatenate([perm, perm]).astype(np.intp)
        angles = rng.uniform(0.0, 2.0 * math.pi, _TABLE)
        self.grad_x, self.grad_z = np.cos(angles), np.sin(angles)
        self.seed = seed

    def frame(self, layer: int, octave: int) -> tuple[float, float, float, float]:
        """Per-octave ``(cos, sin, offset_x, offset_z)`` of the domain rotation and shift."""
        rng = np.random.default_rng([self.seed, layer, octave])
        angle = rng.uniform(0.0, 2.0 * math.pi)
        ox, oz = rng.uniform(0.0, float(_TABLE), 2)
        return math.cos(angle), math.sin(angle), ox, oz

    def gradient(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Perlin gradient noise at ``(x, z)`` (lattice units), in ``[-sqrt(1/2), sqrt(1/2)]``."""
        x0 = np.floor(x)
        z0 = np.floor(z)
        fx = x - x0
        fz = z - z0
        ix = x0.astype(np.intp) & (_TABLE - 1)
        iz = z0.astype(np.intp) & (_TABLE - 1)
        p, gx, gz = self.perm, self.grad_x, self.grad_z
        h0 = p[ix] + iz  # row hashes of the lattice columns ix and ix + 1
        h1 = p[ix + 1] + iz
        k00, k01, k10, k11 = p[h0], p[h0 + 1], p[h1], p[h1 + 1]
        fx1 = fx - 1.0
        fz1 = fz - 1.0
        n00 = gx[k00] * fx + gz[k00] * fz
        n10 = gx[k10] * fx1 + gz[k10] * fz
        n01 = gx[k01] * fx + gz[k01] * fz1
        n11 = gx[k11] * fx1 + gz[k11] * fz1
        sx = fx * fx * fx * (fx * (fx * 6.0 - 15.0) + 10.0)
        sz = fz * fz * fz * (fz * (fz * 6.0 - 15.0) + 10.0)
        a = n00 + sx * (n10 - n00)
        b = n01 + sx * (n11 - n01)
        return a + sz * (b - a)

    def octave(self, layer: int, k: int, x: np.ndarray, z: np.ndarray, frequency: float) -> np.ndarray:
        """Octave ``k`` of ``layer``: noise of the rotated, shifted domain scaled by ``frequency``."""
        c, s, ox, oz = self.frame(layer, k)
        return self.gradient(frequency * (c * x - s * z) + ox, frequency * (s * x + c * z) + oz)


_INV_RANGE = 1.0 / math.sqrt(0.5)  # maps gradient noise to [-1, 1]


def _fbm(noise: _Noise, x, z, octaves, lacunarity, gain, layer) -> np.ndarray:
    """Fractal Brownian motion in ``[-1, 1]``: octaves summed with amplitudes ``gain**k``."""
    total = np.zeros_like(x)
    amplitude, frequency, norm = 1.0, 1.0, 0.0
    for k in range(octaves):
        total += amplitude * noise.octave(layer, k, x, z, frequency)
        norm += amplitude
        amplitude *= gain
        frequency *= lacunarity
    return total * (_INV_RANGE / norm)


def _ridged(noise: _Noise, x, z, octaves, lacunarity, gain, layer) -> np.ndarray:
    """Ridged multifractal in ``[0, 1]``: ``(1 - |n|)²`` per octave, each weighted by the previous.

    Sharp crests where the noise crosses zero; the feedback weight keeps fine detail on the ridges
    and out of the valleys (Musgrave's construction).
    """
    total = np.zeros_like(x)
    weight = np.ones_like(x)
    amplitude, frequency, norm = 1.0, 1.0, 0.0
    for k in range(octaves):
        signal = 1.0 - np.abs(noise.octave(layer, k, x, z, frequency) * _INV_RANGE)
        signal = signal * signal * weight
        weight = np.clip(signal * 2.0, 0.0, 1.0)
        total += amplitude * signal
        norm += amplitude
        amplitude *= gain
        frequency *= lacunarity
    return total / norm


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _normalise(h: np.ndarray) -> np.ndarray:
    lo, hi = float(h.min()), float(h.max())
    return (h - lo) / (hi - lo) if hi > lo else np.zeros_like(h)


def _heights01(x, z, *, seed, octaves, lacunarity, gain, ridge, cliffs, feature_size, terraces):
    """Heights in ``[0, 1]`` on the world-space grid ``(x, z)`` (any matching shapes)."""
    noise = _Noise(seed)
    px, pz = x / feature_size, z / feature_size
    # Gentle domain warp: bends ridges and terrace lines so nothing looks grid- or contour-aligned.
    wx = _fbm(noise, px, pz, 3, 2.0, 0.5, layer=1)
    wz = _fbm(noise, px, pz, 3, 2.0, 0.5, layer=2)
    px, pz = px + 0.35 * wx, pz + 0.35 * wz

    # Large-scale relief decides where the mountains stand; rolling hills everywhere, ridged
    # crests (sharp, branching ridge lines) rising with the relief.
    relief = 0.5 + 0.5 * _fbm(noise, 0.7 * px, 0.7 * pz, 3, 2.0, 0.5, layer=3)
    hills = 0.5 + 0.5 * _fbm(noise, px, pz, octaves, lacunarity, 0.8 * gain, layer=4)
    crests = _ridged(noise, px, pz, octaves, lacunarity, gain, layer=5)
    uplift = _smoothstep(0.35, 0.75, relief)
    mountains = (1.0 - ridge) * hills + ridge * crests
    base = _normalise(0.6 * relief + 0.25 * hills + 0.9 * uplift * mountains)
    # Broad valley floors, sharper peaks.
    base = base ** 1.6

    if cliffs > 0.0:
        # A smooth staircase f -> f^p / (f^p + (1-f)^p) per step: nearly flat benches, risers p
        # times steeper than the slope underneath. Terrace lines are shifted by low-frequency noise,
        # and a mask fades the terraces out over part of the map and over the lowest ground.
        p = 1.0 + 4.0 * cliffs
        shift = 0.5 * _fbm(noise, 0.7 * px, 0.7 * pz, 2, 2.0, 0.5, layer=6)
        t = base * terraces + shift
        f = t - np.floor(t)
        fp = f ** p
        step = fp / (fp + (1.0 - f) ** p)
        mask = _smoothstep(-0.1, 0.25, _fbm(noise, 0.45 * px, 0.45 * pz, 2, 2.0, 0.5, layer=7))
        mask *= _smoothstep(0.1, 0.3, base)
        base = base + 0.85 * mask * (step - f) / terraces
    return _normalise(base)


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Smooth vertex normals, ``[V, 3]`` unit vectors: face normals weighted by the corner angles.

    The same weighting as ``trimesh``'s own ``vertex_normals``, but vectorised with ``bincount``:
    trimesh's fallback without SciPy loops in Python and takes seconds on a 513 × 513 grid.
    """
    tri = vertices[faces]  # [F, 3 corners, 3]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    unit = cross / np.linalg.norm(cross, axis=-1, keepdims=True)
    e_next = np.roll(tri, -1, axis=1) - tri  # corner k -> k+1
    e_prev = np.roll(tri, 1, axis=1) - tri  # corner k -> k-1
    cos = np.einsum("fkc,fkc->fk", e_next, e_prev) / (
        np.linalg.norm(e_next, axis=-1) * np.linalg.norm(e_prev, axis=-1)
    )
    angles = np.arccos(np.clip(cos, -1.0, 1.0))  # [F, 3]
    flat = faces.ravel()
    summed = np.stack(
        [np.bincount(flat, weights=(angles * unit[:, k : k + 1]).ravel(), minlength=len(vertices)) for k in range(3)],
        axis=-1,
    )
    return summed / np.linalg.norm(summed, axis=-1, keepdims=True)


# -- validation ---------------------------------------------------------------------------------------


def _int(name: str, value, low: int, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"terrain(): {name} must be an int, got {type(value).__name__}")
    if value < low or (high is not None and value > high):
        bound = f"at least {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"terrain(): {name} must be {bound}, got {value}")
    return int(value)


def _pair(name: str, value) -> tuple:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        return value, value
    if len(value) != 2:
        raise ValueError(f"terrain(): {name} must be a number or a pair, got {len(value)} values")
    return value[0], value[1]


def _positive(name: str, value) -> float:
    return _bounded(name, value, lambda f: f > 0.0, "positive")


def _bounded(name: str, value, ok, bound: str) -> float:
    """``value`` as a finite float satisfying ``ok``; otherwise a ValueError quoting ``bound``."""
    f = as_float("terrain", name, value)
    if not ok(f):
        raise ValueError(f"terrain(): {name} must be {bound}, got {f}")
    return f


# -- public API ---------------------------------------------------------------------------------------


def terrain(
    size=(64.0, 64.0),
    resolution=(129, 129),
    seed: int = 0,
    *,
    height: float = 14.0,
    octaves: int = 6,
    lacunarity: float = 2.0,
    gain: float = 0.5,
    ridge: float = 0.6,
    cliffs: float = 1.0,
    terraces: int = 5,
    feature_size: float = 24.0,
) -> trimesh.Trimesh:
    """A seeded procedural terrain: a heightfield mesh on the XZ plane, centred at the origin, +Y up.

    Vertex layout, UVs and winding are described in the module docstring: row-major grid with row 0
    at ``z = -size_z/2``, ``u`` along +X, ``v`` along -Z, counter-clockwise faces seen from above.
    The same arguments always give bit-identical vertices.

    Args:
        size: world extent ``(size_x, size_z)``, or one number for a square; finite, positive.
        resolution: vertex counts ``(rows, cols)`` (rows along Z, columns along X), or one int for a
            square grid; each at least 2.
        seed: non-negative int choosing the noise.
        height: vertical relief in world units: heights span exactly ``[0, height]``; finite,
            ``>= 0`` (0 gives a flat plane).
        octaves: noise octaves, 1–16; more adds finer detail.
        lacunarity: frequency ratio between octaves, ``>= 1``.
        gain: amplitude ratio between octaves, in ``(0, 1]``; higher is rougher.
        ridge: blend weight of ridged noise (sharp crests) against smooth fBm hills, in ``[0, 1]``.
        cliffs: terrace sharpness, ``>= 0``: 0 disables terracing; at 1 a terrace riser is about
            4× steeper than the ground beneath it (cliff faces well past 60° at the defaults) while
            the benches between risers flatten out; larger is sharper.
        terraces: number of terrace steps over the height range, ``>= 1``.
        feature_size: wavelength of the coarsest octave in world units; finite, positive.

    Returns:
        ``trimesh.Trimesh`` built with ``process=False``: ``vertices`` ``[rows*cols, 3]`` float64,
        ``faces`` ``[2*(rows-1)*(cols-1), 3]`` int64, ``visual`` a ``TextureVisuals`` with UV0
        ``[rows*cols, 2]``, and ``metadata["terrain"]`` a dict of the (normalised) arguments.

    Raises:
        TypeError: an argument has the wrong type (e.g. a float resolution or a string size).
        ValueError: an argument is out of range or not finite.
    """
    size_x, size_z = (_positive(f"size[{i}]", v) for i, v in enumerate(_pair("size", size)))
    rows, cols = (_int(f"resolution[{i}]", v, 2) for i, v in enumerate(_pair("resolution", resolution)))
    seed = _int("seed", seed, 0)
    height = _bounded("height", height, lambda f: f >= 0.0, ">= 0")
    octaves = _int("octaves", octaves, 1, _MAX_OCTAVES)
    lacunarity = _bounded("lacunarity", lacunarity, lambda f: f >= 1.0, ">= 1")
    gain = _bounded("gain", gain, lambda f: 0.0 < f <= 1.0, "in (0, 1]")
    ridge = _bounded("ridge", ridge, lambda f: 0.0 <= f <= 1.0, "in [0, 1]")
    cliffs = _bounded("cliffs", cliffs, lambda f: f >= 0.0, ">= 0")
    terraces = _int("terraces", terraces, 1)
    feature_size = _positive("feature_size", feature_size)

    xs = np.linspace(-size_x / 2.0, size_x / 2.0, cols)
    zs = np.linspace(-size_z / 2.0, size_z / 2.0, rows)
    x, z = np.meshgrid(xs, zs)  # [rows, cols]
    h01 = _heights01(
        x, z, seed=seed, octaves=octaves, lacunarity=lacunarity, gain=gain, ridge=ridge,
        cliffs=cliffs, feature_size=feature_size, terraces=terraces,
    )
    vertices = np.stack([x, h01 * height, z], axis=-1).reshape(-1, 3)

    u, v = np.meshgrid(np.linspace(0.0, 1.0, cols), np.linspace(1.0, 0.0, rows))
    uv = np.stack([u, v], axis=-1).reshape(-1, 2)

    # Cell (r, c): a = (r, c), b = (r, c+1), c = (r+1, c), d = (r+1, c+1); r+1 is nearer (+Z).
    # Triangles (a, c, b) and (b, c, d) are counter-clockwise seen from +Y.
    idx = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], axis=1).reshape(-1, 3)

    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=faces,
        vertex_normals=_vertex_normals(vertices, faces),
        visual=trimesh.visual.TextureVisuals(uv=uv),
        process=False,
    )
    mesh.metadata["terrain"] = {
        "size": (size_x, size_z),
        "resolution": (rows, cols),
        "seed": seed,
        "height": height,
        "octaves": octaves,
        "lacunarity": lacunarity,
        "gain": gain,
        "ridge": ridge,
        "cliffs": cliffs,
        "terraces": terraces,
        "feature_size": feature_size,
    }
    return mesh


def terrain_slope_height(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex normalised height and slope, the inputs of height/slope splat rules.

    Args:
        mesh: any ``trimesh.Trimesh`` with +Y up (e.g. from :func:`terrain`).

    Returns:
        ``(height01, slope_deg)``, both ``[V]`` float64: ``height01 = (y - min y) / (max y - min y)``
        (all zeros when the mesh is flat) and ``slope_deg = acos(n_y)`` in ``[0, 180]`` degrees from
        the unit vertex normals (0 = flat ground, 90 = vertical wall).

    Raises:
        TypeError: ``mesh`` is not a ``trimesh.Trimesh``.
        ValueError: ``mesh`` has no vertices.
    """
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"terrain_slope_height(): mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.vertices) == 0:
        raise ValueError("terrain_slope_height(): mesh has no vertices")
    height01 = _normalise(np.asarray(mesh.vertices[:, 1], dtype=np.float64))
    slope = np.degrees(np.arccos(np.clip(vertex_normals(mesh)[:, 1], -1.0, 1.0)))
    return height01, slope


def terrain_normal_grid(mesh: trimesh.Trimesh, grid: tuple[int, int], *, smoothing: int = 1) -> np.ndarray:
    """Smooth shading normals of a :func:`terrain` mesh as a ``[rows, cols, 3]`` grid, one per
    vertex, for bilinear lookup in UV0 (vertex ``(r, c)`` at ``u = c / (cols-1)``,
    ``v = 1 - r / (rows-1)``).

    Interpolated across each triangle, vertex normals bend along the diagonal that splits every
    grid cell: on a cliff, whose face spans a cell or two, that shows the triangles as a sawtooth.
    Looked up bilinearly over the cells instead, and smoothed by ``smoothing`` passes of a
    ``[1, 2, 1] / 4`` filter (edges repeated), they vary as smoothly as the heightfield does.

    Raises:
        ValueError: the mesh is not a ``rows × cols`` grid, or ``smoothing`` is negative.
    """
    rows, cols = grid
    if len(mesh.vertices) != rows * cols:
        raise ValueError(f"terrain_normal_grid(): the mesh has {len(mesh.vertices)} vertices, not a {rows}x{cols} grid")
    if isinstance(smoothing, bool) or not isinstance(smoothing, (int, np.integer)) or smoothing < 0:
        raise ValueError(f"terrain_normal_grid(): smoothing must be an int >= 0, got {smoothing!r}")
    n = vertex_normals(mesh).reshape(rows, cols, 3)
    for _ in range(int(smoothing)):
        for axis in (0, 1):
            padded = np.concatenate([n.take([0], axis), n, n.take([-1], axis)], axis=axis)
            k = n.shape[axis]
            n = 0.25 * padded.take(range(0, k), axis) + 0.5 * n + 0.25 * padded.take(range(2, k + 2), axis)
    return (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
