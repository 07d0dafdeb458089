"""The default terrain's material: four procedural layers (grass, gravel, rock, snow) and splat
maps from height and slope rules, for :func:`warptex.splat`.

Every layer is generated in NumPy from periodic noise, so it tiles seamlessly, depends only on its
seed and costs about a tenth of a second at 256 × 256: gradient (Perlin) noise on a lattice that wraps around
the tile, summed over octaves (fBm, ridged), domain-warped by more of the same; and Worley
(Voronoi) cells whose feature points wrap around the tile. Colours are linear RGB; alpha holds a
height for height blending: pebbles and rock ridges high, gaps and cracks low, grass tufts
moderately high, snow high and smooth so that it covers the others.
"""

from __future__ import annotations

import numpy as np
import trimesh

from warptex.scenes.terrain import terrain_slope_height
from warptex.texture import TextureArray

LAYER_NAMES = ("grass", "gravel", "rock", "snow")


# -- periodic noise -----------------------------------------------------------------------------------
# Coordinates are tile coordinates: (u, v) in [0, 1) covers one tile, and every field below is
# periodic with period 1 in both, so the textures built from them tile.


def _tile_coordinates(size: int) -> tuple[np.ndarray, np.ndarray]:
    """``(u, v)``: the texel centres of one tile, u along columns (``[1, size]``) and v down rows
    (``[size, 1]``). They broadcast to ``[size, size]``; kept apart, whatever depends on one of
    them alone (a lattice cell, its fade) is computed once per column or row, not per texel."""
    t = (np.arange(size) + 0.5) / size
    return t[None, :], t[:, None]


def _gradient_noise(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, period: tuple[int, int]) -> np.ndarray:
    """Gradient (Perlin) noise in about [-0.7, 0.7] at lattice coordinates ``x, y``: random unit
    gradients on a ``period = (nx, ny)`` lattice that wraps, so the noise has period ``nx`` in x
    and ``ny`` in y."""
    nx, ny = period
    angle = rng.uniform(0.0, 2.0 * np.pi, (ny, nx))
    gx, gy = np.cos(angle).ravel(), np.sin(angle).ravel()
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    i0, j0 = x0.astype(np.intp) % nx, y0.astype(np.intp) % ny
    i1, j1 = (i0 + 1) % nx, (j0 + 1) % ny
    sx, sy = _fade(fx), _fade(fy)

    def corner(j, i, dx, dy):  # each corner once, its gradient by a flat index (two index arrays measured 3x slower)
        flat = j * nx + i
        return gx.take(flat) * dx + gy.take(flat) * dy

    c00, c01 = corner(j0, i0, fx, fy), corner(j0, i1, fx - 1, fy)
    c10, c11 = corner(j1, i0, fx, fy - 1), corner(j1, i1, fx - 1, fy - 1)
    top = c00 + sx * (c01 - c00)
    bottom = c10 + sx * (c11 - c10)
    return top + sy * (bottom - top)


def _fade(t: np.ndarray) -> np.ndarray:
    return t * t * t * (t * (6 * t - 15) + 10)


def _fbm(rng, u, v, cells: int, octaves: int, *, gain: float = 0.5, ridged: bool = False, stretch: tuple[int, int] = (1, 1)) -> np.ndarray:
    """Fractal sum of periodic gradient noise at tile coordinates ``u, v``: octave ``o`` has
    ``cells · 2^o`` lattice cells per tile (times ``stretch`` per axis, for streaks) and weight
    ``gain^o``. Roughly in [-1, 1]; ``ridged``: each octave is ``1 - 2|noise|`` first, in
    [-1, 1] with sharp crests at the noise's zeros."""
    total, weight, norm = np.zeros(np.broadcast_shapes(u.shape, v.shape)), 1.0, 0.0
    for octave in range(octaves):
        nx, ny = cells * 2**octave * stretch[0], cells * 2**octave * stretch[1]
        layer = _gradient_noise(rng, u * nx, v * ny, (nx, ny)) / 0.7
        total += weight * ((1.0 - 2.0 * np.abs(layer)) if ridged else layer)
        norm += weight
        weight *= gain
    return total / norm


def _warp(rng, u, v, amount: float, cells: int = 3, octaves: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``(u, v)`` displaced by ``amount`` (tile units) of periodic fBm: periodic fields read at the
    warped coordinates stay periodic, and stop looking like a lattice."""
    return u + amount * _fbm(rng, u, v, cells, octaves), v + amount * _fbm(rng, u, v, cells, octaves)


def _cells(rng, u, v, n: int, jitter: float = 0.9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Periodic Worley noise: one jittered feature point per cell of an ``n × n`` grid over the
    tile, wrapping around. Returns ``F1`` and ``F2`` (distances to the nearest and second nearest
    point, in cell widths) and the nearest point's cell index (``0 .. n²-1``, for per-cell values)."""
    points = 0.5 + jitter * (rng.random((2, n, n)) - 0.5)
    x, y = u * n, v * n
    cx, cy = np.floor(x).astype(np.intp), np.floor(y).astype(np.intp)
    shape = np.broadcast_shapes(x.shape, y.shape)
    f1, f2 = np.full(shape, np.inf), np.full(shape, np.inf)
    nearest = np.zeros(shape, np.intp)
    px, py = points[0].ravel(), points[1].ravel()
    for dy in (-1, 0, 1):
        row = (cy + dy) % n * n
        for dx in (-1, 0, 1):
            cell = row + (cx + dx) % n  # flat: two index arrays measured 3x slower
            d = np.hypot(cx + dx + px.take(cell) - x, cy + dy + py.take(cell) - y)
            np.copyto(nearest, cell, where=d < f1)
            np.minimum(f2, np.maximum(f1, d), out=f2)  # f1 if d is closer than f1 (f1 <= f2), else min(f2, d)
            np.minimum(f1, d, out=f1)
    return f1, f2, nearest


def _unit(x: np.ndarray) -> np.ndarray:
    """``x`` rescaled to [0, 1] (its minimum to 0, its maximum to 1)."""
    return (x - x.min()) / max(float(np.ptp(x)), 1e-12)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _mix(a, b, t: np.ndarray) -> np.ndarray:
    """Colours ``a`` and ``b`` (RGB) blended by ``t`` ``[H, W]``: ``[H, W, 3]``."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a + (b - a) * np.asarray(t)[..., None]


# -- the materials ------------------------------------------------------------------------------------
# Each takes a generator and the tile coordinates and returns linear RGB [H, W, 3] and height [H, W].


def _grass(rng, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Dense grass seen from above: tufts (Voronoi cells, brighter and higher towards their centres)
    made of fine blades (thin crests of warped ridged noise), yellow-green to deep green in broad
    patches with drier, straw-coloured ones, and dark soil showing between the tufts."""
    patches = _unit(_fbm(rng, *_warp(rng, u, v, 0.08), 4, 4))
    dry = _smoothstep(0.35, 0.75, _unit(_fbm(rng, u, v, 3, 4)))
    colour = _mix((0.035, 0.095, 0.012), (0.13, 0.2, 0.03), patches)
    colour = _mix(colour, (0.2, 0.17, 0.06), 0.7 * dry)

    f1, f2, cell = _cells(rng, *_warp(rng, u, v, 0.03, cells=8), 22)
    tuft = np.clip(1.0 - f1 / 0.85, 0.0, 1.0) ** 0.7 * (0.6 + 0.4 * rng.random(22 * 22)[cell])
    bu, bv = _warp(rng, u, v, 0.015, cells=16, octaves=2)
    blades = np.clip(_fbm(rng, bu, bv, 40, 2, gain=0.6, ridged=True), 0.0, 1.0) ** 3
    fine = np.clip(_fbm(rng, bu, bv, 96, 1, ridged=True), 0.0, 1.0) ** 2
    lush = np.clip(0.55 * tuft + 0.35 * blades + 0.2 * fine, 0.0, 1.0)
    tone = 0.85 + 0.3 * rng.random(22 * 22)[cell]  # each tuft a slightly different shade
    colour = _mix((0.03, 0.025, 0.012), colour * tone[..., None] * (0.6 + 0.7 * blades)[..., None], _smoothstep(0.1, 0.45, lush))
    height = 0.1 + 0.6 * lush + 0.1 * patches
    return colour, height


def _gravel(rng, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Loose gravel: rounded pebbles of warm sand, ochre, brown and beige tints with speckled
    surfaces, large ones (warped Voronoi cells, each a dome on its distance to the cell edge, its
    own size and tint) with smaller ones filling their gaps, and dark soil in the gaps left."""
    palette = np.array([(0.42, 0.33, 0.22), (0.5, 0.4, 0.27), (0.36, 0.29, 0.22), (0.3, 0.21, 0.13), (0.56, 0.48, 0.37), (0.26, 0.2, 0.14)])
    speckle = 0.8 + 0.35 * _unit(_fbm(rng, u, v, 48, 2, gain=0.7))
    stain = _fbm(rng, u, v, 6, 3)
    best_height = np.zeros(np.broadcast_shapes(u.shape, v.shape))
    best_colour = _mix((0.07, 0.05, 0.03), (0.13, 0.095, 0.06), _unit(_fbm(rng, u, v, 24, 2)))
    for n, scale in ((9, 1.0), (17, 0.8), (34, 0.55)):
        f1, f2, cell = _cells(rng, *_warp(rng, u, v, 0.25 / n, cells=8), n)
        gap = 0.05 + 0.3 * rng.random(n * n)[cell]  # per pebble: a smaller pebble leaves a wider gap
        dome = np.sqrt(np.clip((f2 - f1 - gap) / 0.45, 0.0, 1.0))
        height = scale * dome * (0.75 + 0.25 * rng.random(n * n)[cell])
        tint = palette[rng.integers(0, len(palette), n * n)[cell]] * (0.75 + 0.5 * rng.random(n * n)[cell])[..., None]
        colour = tint * (0.5 + 0.5 * dome)[..., None] * (speckle + 0.15 * stain)[..., None]
        on_top = height > best_height
        best_height = np.where(on_top, height, best_height)
        best_colour = np.where(on_top[..., None], colour, best_colour)
    return best_colour, best_height


def _rock(rng, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Layered blue-grey stone: strata (bands of varied tone with thin dark bedding lines, folded
    by low-frequency noise), ridged multifractal relief on top, and dark, branching cracks along
    the edges of warped Voronoi cells, strong in some places and absent in others. Ridges high,
    cracks and bedding lines low."""
    fold_u, fold_v = _warp(rng, u, v, 0.12, cells=2)
    bands = 11
    strata = bands * fold_v + 0.6 * _fbm(rng, u, v, 8, 3)
    band_tone = (0.7 + 0.6 * rng.random(bands))[np.floor(strata).astype(np.intp) % bands]
    bedding = _smoothstep(0.0, 0.12, np.abs(strata - np.round(strata)))
    ridges = _unit(_fbm(rng, *_warp(rng, u, v, 0.05, cells=4), 6, 5, gain=0.55, ridged=True))
    grain = _fbm(rng, u, v, 64, 2)

    crack_u, crack_v = _warp(rng, u, v, 0.06, cells=6)
    f1, f2, _ = _cells(rng, crack_u, crack_v, 5)
    g1, g2, _ = _cells(rng, crack_u, crack_v, 13)
    presence = _smoothstep(-0.1, 0.35, _fbm(rng, u, v, 3, 3))
    cracks = np.maximum(1 - _smoothstep(0.0, 0.06, f2 - f1), presence * (1 - _smoothstep(0.0, 0.05, g2 - g1)))

    base = _mix((0.12, 0.13, 0.15), (0.16, 0.155, 0.155), _smoothstep(0.3, 0.7, _unit(_fbm(rng, fold_u, fold_v, 3, 3))))
    shade = band_tone * (0.55 + 0.75 * ridges) * (0.6 + 0.4 * bedding) * (1 + 0.12 * grain) * (1 - 0.8 * cracks)
    height = np.clip(0.15 + 0.55 * ridges + 0.2 * (band_tone - 0.7) + 0.15 * bedding - 0.45 * cracks, 0.0, 1.0)
    return base * shade[..., None], height


def _snow(rng, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Old snow: bright, slightly blue-white, in soft wind-shaped drifts (warped low-frequency noise)
    with faint ripples and fine grain, bluer and darker in the hollows. Height high and smooth, so
    snow covers the other layers."""
    wu, wv = _warp(rng, u, v, 0.1, cells=2)
    drifts = _unit(_fbm(rng, wu, wv, 3, 5, gain=0.45))
    ripples = 0.5 + 0.5 * np.sin(2 * np.pi * (14 * wv + 2 * _fbm(rng, u, v, 2, 2)))
    ripples *= _smoothstep(0.0, 0.5, _fbm(rng, u, v, 3, 2))
    grain = _fbm(rng, u, v, 48, 3, gain=0.7)
    light = np.clip(0.75 * drifts + 0.15 * ripples + 0.1, 0.0, 1.0)
    colour = _mix((0.5, 0.58, 0.74), (0.88, 0.9, 0.94), light) * (1 + 0.04 * grain)[..., None]
    height = 0.5 + 0.4 * drifts + 0.05 * ripples + 0.03 * grain
    return colour, height


MATERIALS = {"grass": _grass, "gravel": _gravel, "rock": _rock, "snow": _snow}


def terrain_layers(*, size: int = 256, seed: int = 0, device=None) -> TextureArray:
    """The four layers (:data:`LAYER_NAMES`) as a ``TextureArray`` of ``[4, size, size, 4]``:
    linear RGB in [0, 1] + height in alpha (in [0, 1]). Each tiles seamlessly and depends only on
    ``seed``; all four take about 0.35 s at 256 × 256 (:func:`terrain_layer_texels`)."""
    return TextureArray(terrain_layer_texels(size=size, seed=seed), device=device)


def terrain_layer_texels(*, size: int = 256, seed: int = 0) -> np.ndarray:
    """:func:`terrain_layers`' texels, ``[4, size, size, 4]`` float32: NumPy alone (no Warp), so a
    job can make them on a thread of their own while it does its other work."""
    u, v = _tile_coordinates(size)
    layers = []
    for k, name in enumerate(LAYER_NAMES):
        colour, height = MATERIALS[name](np.random.default_rng([seed, k]), u, v)
        layers.append(np.concatenate([np.clip(colour, 0.0, 1.0), np.clip(height, 0.0, 1.0)[..., None]], axis=-1))
    return np.stack(layers).astype(np.float32)


def noise_texture(size: int = 256, *, seed: int = 0, octaves: int = 6) -> np.ndarray:
    """A tileable, earthy ground texture ``[size, size, 3]`` (linear RGB): fBm of periodic gradient noise."""
    value = _unit(_fbm(np.random.default_rng(seed), *_tile_coordinates(size), 4, octaves, gain=0.55))
    dark, mid, light = np.array([0.09, 0.07, 0.04]), np.array([0.16, 0.2, 0.07]), np.array([0.32, 0.29, 0.2])
    t = value[..., None]
    return np.where(t < 0.5, dark + (mid - dark) * (2 * t), mid + (light - mid) * (2 * t - 1)).astype(np.float32)


def terrain_splat_maps(mesh: trimesh.Trimesh, grid: tuple[int, int], *, upsample: int = 1) -> np.ndarray:
    """RGBA splat weights ``[rows, cols, 4]`` (grass, gravel, rock, snow; sum 1) of a
    :func:`warptex.terrain` mesh with ``grid = (rows, cols)`` vertices, one texel per vertex (the
    terrain's UV0 puts vertex ``(r, c)`` at texel ``(r, c)`` of a ``rows × cols`` map, up to half a
    texel at the borders).

    Rules: rock on slopes past ~35°, snow on high, gentle ground, gravel on low, flat ground
    (valley floors) and as a band below the rock, grass elsewhere; transitions are smoothsteps.

    ``upsample = k > 1`` evaluates the rules on the height and slope interpolated (bilinearly)
    between the vertices, ``k`` texels per grid cell: a ``[(rows-1)k+1, (cols-1)k+1, 4]`` map whose
    layer borders are ``k`` times finer, where a height blend would otherwise show the steps of a
    bilinear lookup of one texel per vertex (the preview does this; fits keep one per vertex).
    """
    height, slope = terrain_slope_height(mesh)
    rows, cols = grid
    if height.size != rows * cols:
        raise ValueError(f"terrain_splat_maps(): the mesh has {height.size} vertices, not a {rows}x{cols} grid")
    if isinstance(upsample, bool) or not isinstance(upsample, (int, np.integer)) or upsample < 1:
        raise ValueError(f"terrain_splat_maps(): upsample must be an int >= 1, got {upsample!r}")
    if upsample > 1:
        height, slope = (_upsampled(f.reshape(rows, cols), int(upsample)) for f in (height, slope))
        rows, cols = height.shape
    height, slope = height.reshape(-1), slope.reshape(-1)
    rock = _smoothstep(30.0, 42.0, slope)
    snow = _smoothstep(0.68, 0.8, height) * (1 - rock)
    gravel = np.maximum(_smoothstep(0.12, 0.03, height), _smoothstep(22.0, 32.0, slope)) * (1 - rock) * (1 - snow)
    grass = np.clip(1 - rock - snow - gravel, 0.0, 1.0)
    weights = np.stack([grass, gravel, rock, snow], axis=-1)
    weights /= weights.sum(axis=-1, keepdims=True)
    return weights.reshape(rows, cols, 4).astype(np.float32)


def _upsampled(field: np.ndarray, k: int) -> np.ndarray:
    """``[rows, cols]`` values at grid vertices, interpolated bilinearly to ``k`` samples per cell:
    ``[(rows-1)k+1, (cols-1)k+1]``, the vertices' values kept."""
    rows, cols = field.shape
    r = np.linspace(0.0, rows - 1.0, (rows - 1) * k + 1)
    c = np.linspace(0.0, cols - 1.0, (cols - 1) * k + 1)
    along_rows = np.stack([np.interp(r, np.arange(rows), field[:, j]) for j in range(cols)], axis=1)
    return np.stack([np.interp(c, np.arange(cols), row) for row in along_rows])
