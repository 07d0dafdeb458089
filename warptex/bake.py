"""Baking: any technique evaluated over a texture-space G-buffer, into a mesh's UV atlas.

A texture-space G-buffer is an ordinary :class:`~warptex.GBuffer` whose pixels are the texels of
the atlas (:mod:`warptex.kernels.bake` builds it): every technique runs on it unchanged, the
``warptex.torch`` ones included, and its result *is* the baked texture. Each texel holds the
surface point at its centre, the normals there, the position derivatives along one texel step
right and down (from its triangle's UV-to-world Jacobian: filters see the footprint of one texel),
the mesh's own UV sets (so splat maps in UV0 work) and the atlas's as UV set ``"atlas"``.

**Gutters.** Texels within ``gutter`` texels of a chart that no triangle covers take the nearest
chart texel's triangle and are evaluated on its plane past the chart's edge, so they continue the
texture across the seam instead of copying its edge. A mip level ``L`` filter at a chart's edge
reads texels up to ``2^(L+1)`` texels outside it (a level-``L`` texel spans ``2^L``; bilinear reads
the next one), so ``gutter = 2^(L+1)`` keeps level ``L`` free of background. :func:`default_gutter`
takes ``L`` as the level a surface facing the camera reads when the asset fills a
``view_size``-pixel view, plus one for surfaces turned up to 60° away under trilinear filtering.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
import trimesh
import warp as wp

from warptex._output import check_memory
from warptex._threads import rows_side_by_side
from warptex._warp import paused_tape
from warptex.raster import checked_rows
from warptex.tiles import Tile, checked_memory, tile_rows
from warptex.gbuffer import GBuffer, checked_geometry, _gbuffer_device, load_mesh, mesh_uv_sets, vertex_normals, vertex_tangents
from warptex.kernels import bake as kb
from warptex.kernels import raster as kr
from warptex.mesh import mesh_uv_faces
from warptex.unwrap import ATLAS_FILL, ATLAS_METHODS, UVLayout, bakeable_faces, _checked_size, face_areas, unusable_reason, unwrap

#: Peak memory of a bake, measured (peak RSS, bunny, 512² to 4096²): ~300 MB plus ~400 B per texel
#: (texture-space G-buffer, the technique's outputs, PNG encoding); with a margin.
BAKE_BYTES = (400e6, 520.0)
#: What a tiled bake's work takes per texel of a band (:func:`texture_gbuffer_tiles`), measured.
BAKE_TEXEL_BYTES = 400
#: What a flood window takes per texel: each texel's triangle and jump-flood seed, twice (int32).
FLOOD_TEXEL_BYTES = 12


@dataclass
class Baked:
    """A mesh baked into textures (:func:`bake`).

    Attributes:
        layout: the :class:`~warptex.unwrap.UVLayout` baked into (mesh with atlas UVs).
        gbuffer: the texture-space :class:`~warptex.GBuffer`, ``(size, size)``.
        coverage: ``(size, size)`` float32 ``wp.array``: 1 on texels inside a chart, 0 in gutters
            and outside; ``gbuffer.mask`` is 1 on both charts and gutters.
        color: ``(size, size, C)`` float32 ``wp.array`` of the colour technique (linear), or
            ``None``; 0 outside charts and gutters. Recorded on the active tape.
        normal: ``(size, size, 3)`` float32 ``wp.array``: unit tangent-space normals in the
            atlas's frame (x along u, y along v, z out of the surface; glTF's), or ``None``.
        gutter: the gutter width in texels.
    """

    layout: UVLayout
    gbuffer: GBuffer
    coverage: wp.array
    color: wp.array | None
    normal: wp.array | None
    gutter: int

    @property
    def size(self) -> int:
        return self.gbuffer.resolution[0]


def default_gutter(mesh: trimesh.Trimesh, size: int, *, view_size: int = 512, uv_fill: float = ATLAS_FILL) -> int:
    """Gutter texels that keep background out of the mip levels read when ``mesh`` is seen whole
    in a ``view_size``-pixel view (module docstring): ``2^(L+1)``, ``L = ceil(log2(t)) + 1``, ``t``
    the texels per pixel on a facing surface (``uv_fill``: the share of the texture the charts
    cover), the view spanning the mesh's bounding sphere; at least 2."""
    area = float(mesh.area)
    radius = float(np.linalg.norm(mesh.extents)) / 2
    if not (area > 0 and radius > 0):
        return 2
    texels_per_pixel = math.sqrt(uv_fill * size * size / area) * 2 * radius / view_size
    level = max(0, math.ceil(math.log2(max(texels_per_pixel, 1e-9)))) + 1
    return max(2, 2 ** (level + 1))


def texture_gbuffer(layout: UVLayout, size: int, *, gutter: int = 8, rows=None, device=None) -> tuple[GBuffer, wp.array]:
    """The texture-space G-buffer of ``layout`` of ``size`` × ``size`` texels (module docstring).

    Args:
        layout: from :func:`~warptex.unwrap.unwrap`.
        size: texels per side.
        gutter: texels around the charts evaluated past their edges (``>= 0``).
        rows: ``(start, stop)``: only those rows of the atlas, bit for bit as the whole atlas has
            them (:func:`texture_gbuffer_tiles` cuts an atlas into such bands); ``None``: all.
        device: Warp device.

    Returns:
        ``(gbuffer, coverage)``: the :class:`~warptex.GBuffer` (``mask`` 1 on chart and gutter
        texels, ``depth`` 0 there; derivatives per texel step), and the ``(size, size)`` float32
        chart coverage (0 in gutters); ``(stop - start, size)`` with ``rows``.
    """
    space = TextureSpace("texture_gbuffer", layout, size, gutter, device)
    return space.gbuffer(checked_rows("texture_gbuffer", rows, space.size))


def texture_gbuffer_tiles(layout: UVLayout, size: int, *, gutter: int = 8, memory: int | None = None, device=None):
    """The texture-space G-buffer of ``layout`` (:func:`texture_gbuffer`) in bands of rows whose
    work takes at most ``memory`` bytes (default :data:`warptex.tiles.DEFAULT_MEMORY`), for bakes
    larger than memory: each band's texels are the whole atlas's, bit for bit.

    Every argument is checked, and the UV mesh's BVH built, before the first band is made.

    Returns:
        An iterator of tiles (:class:`~warptex.tiles.Tile`: ``rows``, ``gbuffer``, ``index``,
        ``count``), each with its band's chart ``coverage``.
    """
    func = "texture_gbuffer_tiles"
    memory = checked_memory(func, memory)
    space = TextureSpace(func, layout, size, gutter, device)
    # Half the budget for the bands' work, half for the flood windows that several bands share:
    # a band flooded on its own would flood its halo again (4× its rows at 8192², gutter 64).
    bands = tile_rows(space.size, BAKE_TEXEL_BYTES * space.size, memory // 2)
    window = (memory // 2) // (FLOOD_TEXEL_BYTES * space.size) - 2 * space.halo
    return _tiles(space, bands, window)


def _tiles(space: "TextureSpace", bands: list[tuple[int, int]], window: int):
    """The bands' tiles, flooded a window of consecutive bands at a time (of at most ``window``
    rows, at least one band)."""
    first = 0
    while first < len(bands):
        last = first
        while last + 1 < len(bands) and bands[last + 1][1] - bands[first][0] <= window:
            last += 1
        flooded = space.flood((bands[first][0], bands[last][1]))
        for k in range(first, last + 1):
            g, coverage = space.surface(bands[k], flooded)
            yield Tile(slice(*bands[k]), g, k, len(bands), coverage)
        del flooded
        first = last + 1


class TextureSpace:
    """An atlas ready to be evaluated band by band: the BVH of its UV triangles and the mesh's
    arrays on a device, made once (``func`` names the caller in errors)."""

    def __init__(self, func: str, layout: UVLayout, size: int, gutter: int, device):
        self.size = _checked_size(func, size)
        if isinstance(gutter, bool) or not isinstance(gutter, (int, np.integer)) or gutter < 0:
            raise ValueError(f"{func}(): gutter must be an int >= 0 (texels), got {gutter!r}")
        self.gutter = int(gutter)
        self.device = device = wp.get_device(device)
        faces = np.asarray(layout.faces, np.int64)
        world = np.asarray(layout.vertices, np.float64)
        face_ids = bakeable_faces(world, faces, layout.uv)
        if len(face_ids) == 0:
            raise ValueError(f"{func}(): no triangle has area both in the world and in the atlas")
        uv_points = np.concatenate([layout.uv, np.zeros((len(layout.uv), 1))], axis=1).astype(np.float32)
        self._bvh_points = wp.array(uv_points, dtype=wp.vec3, device=device)
        self._bvh = wp.Mesh(points=self._bvh_points, indices=wp.array(faces[face_ids].reshape(-1).astype(np.int32), dtype=wp.int32, device=device))
        self._face_ids = wp.array(face_ids.astype(np.int32), dtype=wp.int32, device=device)
        self._points = wp.array(world.astype(np.float32), dtype=wp.vec3, device=device)
        self._indices = wp.array(faces.reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
        self._corner_uvs = wp.array(layout.uv[faces].reshape(-1, 2).astype(np.float32), dtype=wp.vec2, device=device)
        self._normals = wp.array(np.asarray(layout.normals, np.float32), dtype=wp.vec3, device=device)
        # Every UV set is interpolated as the rasteriser does it (kernels.raster.uv_kernel), over the
        # layout's vertices; the mesh's own sets with the tangents of the mesh's own topology, so that
        # an atlas seam splits none of their tangents.
        sets = mesh_uv_sets(layout.mesh) if layout.mesh is not None else {}
        vertex_map = np.asarray(layout.vertex_map, np.int64)
        jobs = [(name, uv[vertex_map], vertex_tangents(np.asarray(layout.mesh.vertices, np.float64), vertex_map[faces], vertex_normals(layout.mesh), uv)[vertex_map]) for name, uv in sets.items()]
        jobs.append(("atlas", layout.uv, layout.tangents()))
        self._uv_sets = {name: (wp.array(np.asarray(uv, np.float32), dtype=wp.vec2, device=device), wp.array(tangents, dtype=wp.vec4, device=device)) for name, uv, tangents in jobs}
        # Jump flooding: steps 2^k down to 1 reach any texel up to 2^(k+1) - 1 away, and a texel's
        # seed after them depends only on the texels that far from it: a band evaluated with that
        # many rows more on each side (the halo) floods exactly as the whole atlas does.
        self._steps = []
        step = 1 << max(0, math.ceil(math.log2(self.gutter + 1)) - 1) if self.gutter > 0 else 0
        while step >= 1:
            self._steps.append(step)
            step //= 2
        self.halo = max(sum(self._steps), self.gutter)

    def gbuffer(self, rows: tuple[int, int]) -> tuple[GBuffer, wp.array]:
        """``(gbuffer, coverage)`` of atlas rows ``rows`` (``(start, stop)``)."""
        return self.surface(rows, self.flood(rows))

    def _view(self, first_row: int) -> kr.CameraView:
        """The orthographic camera over the unit square whose rays pass through the texel centres,
        its launch row 0 atlas row ``first_row`` (:mod:`warptex.kernels.bake`)."""
        view = kr.CameraView()
        view.eye, view.forward, view.right, view.up = wp.vec3(0.5, 0.5, 1.0), wp.vec3(0.0, 0.0, -1.0), wp.vec3(1.0, 0.0, 0.0), wp.vec3(0.0, 1.0, 0.0)
        view.half_x, view.half_y, view.height, view.width, view.orthographic, view.strata, view.first_row = 0.5, 0.5, self.size, self.size, 1, 1, first_row
        return view

    def flood(self, rows: tuple[int, int]) -> tuple[wp.array, wp.array, int]:
        """``(chart, seed, first)``: each texel's triangle and jump-flood seed, for atlas rows
        ``rows`` and :attr:`halo` rows beyond them on each side (from atlas row ``first`` on),
        those of ``rows`` exactly as the whole atlas floods them."""
        device, size = self.device, self.size
        lo, hi = max(0, rows[0] - self.halo), min(size, rows[1] + self.halo)
        chart = wp.empty((hi - lo, size), dtype=wp.int32, device=device)
        seed = wp.empty((hi - lo, size), dtype=wp.int32, device=device)
        launch = dict(device=device, record_tape=False)

        def cast(a: int, b: int) -> None:  # rows a..b of the window
            wp.launch(kb.chart_kernel, dim=(b - a, size), inputs=[self._bvh.id, self._face_ids, self._view(lo + a)], outputs=[chart[a:b], seed[a:b]], **launch)

        rows_side_by_side(hi - lo, cast, device, (kb.chart_kernel,))
        if self._steps:
            other = wp.empty_like(seed)
            for step in self._steps:

                def flood(a: int, b: int) -> None:
                    wp.launch(kb.flood_kernel, dim=(b - a, size), inputs=[seed, step, lo, a], outputs=[other[a:b]], **launch)

                rows_side_by_side(hi - lo, flood, device, (kb.flood_kernel,))
                seed, other = other, seed
        return chart, seed, lo

    def surface(self, rows: tuple[int, int], flooded: tuple[wp.array, wp.array, int]) -> tuple[GBuffer, wp.array]:
        """``(gbuffer, coverage)`` of atlas rows ``rows``, within the rows :meth:`flood` made ``flooded``."""
        device, size = self.device, self.size
        chart, seed, lo = flooded
        start, stop = rows
        launch = dict(device=device, record_tape=False)
        shape = (stop - start, size)
        g = GBuffer.empty(shape, uv_sets=[*self._uv_sets], device=device)
        barycentric = wp.zeros(shape, dtype=wp.vec3, device=device)
        coverage = wp.zeros(shape, dtype=float, device=device)

        def evaluate(a: int, b: int) -> None:  # rows a..b of the band
            outputs = [g.position, g.normal, g.geometric_normal, g.depth, g.mask, g.triangle, barycentric, g.position_dx, g.position_dy, coverage]
            inputs = [self._points, self._indices, self._corner_uvs, self._normals, chart, seed, float(self.gutter), lo, start + a, size]
            wp.launch(kb.surface_kernel, dim=(b - a, size), inputs=inputs, outputs=[o[a:b] for o in outputs], **launch)
            part = (1, b - a, size)  # the UV kernel's (views, rows, W)
            for name, (uv, tangents) in self._uv_sets.items():
                out = g.uv_sets[name]
                wp.launch(
                    kr.uv_kernel,
                    dim=part,
                    inputs=[self._points, self._indices, uv, tangents, *(x[a:b].reshape(part) for x in (g.triangle, barycentric, g.normal, g.position_dx, g.position_dy))],
                    outputs=[out[k][a:b].reshape(part) for k in ("uv", "uv_dx", "uv_dy", "tangent")],
                    **launch,
                )

        rows_side_by_side(stop - start, evaluate, device, (kb.surface_kernel, *([kr.uv_kernel] if self._uv_sets else [])))
        return g, coverage


def tangent_space(gbuffer: GBuffer, normals: wp.array, *, uv_set: str = "atlas", to_world: bool = False, device=None) -> wp.array:
    """World-space unit normals ``(H, W, 3)`` (e.g. :func:`~warptex.triplanar_normal`'s) as
    tangent-space normals in ``uv_set``'s frame (x along u, y along v, z out: glTF's
    ``normalTexture`` before its ``n · 0.5 + 0.5`` encoding), or back with ``to_world``.

    The frame is the G-buffer's: ``N`` its shading normal, ``T`` the UV set's tangent, ``B =
    w · cross(N, T)``. Recorded on the active tape (gradients reach ``normals``); 0 where the
    mask is 0.
    """
    func = "tangent_space"
    device = _gbuffer_device(func, gbuffer, device)
    gbuffer.require(func, "normal", "mask", f"{uv_set}.tangent")
    shape = (*gbuffer.resolution, 3)
    if not isinstance(normals, wp.array) or normals.dtype != wp.float32 or tuple(normals.shape) != shape or not normals.is_contiguous:
        got = f"{wp.types.type_repr(normals.dtype)} {normals.shape}" if isinstance(normals, wp.array) else type(normals).__name__
        raise ValueError(f"{func}(): normals must be a contiguous float32 wp.array of shape {shape}, got {got}")
    count = gbuffer.pixel_count
    out = wp.zeros((count, 3), dtype=float, device=device, requires_grad=normals.requires_grad)
    inputs = [normals.reshape((count, 3)), gbuffer.normal.reshape((count,)), gbuffer.uv(uv_set)["tangent"].reshape((count,)), gbuffer.mask.reshape((count,)), int(bool(to_world))]
    wp.launch(kb.tangent_frame_kernel, dim=count, inputs=inputs, outputs=[out], device=device)
    return out.reshape(shape)


def bake(
    mesh,
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
    device=None,
) -> Baked:
    """Bake a technique into textures of the mesh's UV atlas (its own UV0 when usable, else an
    xatlas atlas: :func:`~warptex.unwrap.unwrap`).

    ``technique`` and ``normal`` are called with the texture-space G-buffer, e.g.
    ``functools.partial(wt.triplanar, texture=brick, tiling=20.0)`` and
    ``functools.partial(wt.triplanar_normal, normal_map=brick_n, tiling=20.0)``; anything that
    takes a G-buffer works (splat layers, stochastic sampling, your own composition). Each is first
    called on an empty 2 × 2 G-buffer with the mesh's UV sets (not recorded on a tape), so that a
    bad argument (a splat without layers, a missing UV set) is reported before the mesh is
    unwrapped or baked.

    Args:
        mesh: a ``trimesh.Trimesh`` or a mesh file (:func:`~warptex.load_mesh`).
        technique: ``gbuffer -> (H, W, C) wp.array`` of colour (linear), or ``None``.
        normal: ``gbuffer -> (H, W, 3) wp.array`` of unit world-space normals, baked as a
            tangent-space normal map (:func:`tangent_space`), or ``None``.
        size: texels per side, in ``[2, 16384]``.
        padding: texels between xatlas's charts; default ``gutter``: neighbouring charts' gutters
            then meet midway, and background is left only farther than ``gutter`` from every chart.
        gutter: texels filled around each chart; default :func:`default_gutter` for ``view_size``.
        view_size: pixels across which the asset is meant to be seen whole (sets the default gutter).
        force_atlas: make an atlas even when the mesh's UVs are usable.
        keep_uvs: bake into the mesh's own UVs even where they overlap or parts have none
            (:func:`~warptex.unwrap.unwrap`); without it such UVs are replaced by an atlas, with a
            ``UserWarning`` saying why.
        atlas: how an atlas is made: ``"auto"``, ``"xatlas"`` or ``"projection"``
            (:func:`~warptex.unwrap.unwrap`).
        device: Warp device.

    Returns:
        :class:`Baked`. Gradients of a loss on ``color``/``normal`` reach whatever the techniques
        differentiate (texels, tiling, sharpness, splat maps...) through the active ``wp.Tape``.

    Raises:
        TypeError, ValueError: bad arguments, a technique that rejects its inputs, a mesh that
            xatlas cannot unwrap. MemoryError: a size past this machine's memory.
    """
    func = "bake"
    layout, gutter, device = prepare_bake(func, mesh, technique, normal, size=size, padding=padding, gutter=gutter, view_size=view_size, force_atlas=force_atlas, keep_uvs=keep_uvs, atlas=atlas, device=device, needed=lambda n: BAKE_BYTES[0] + BAKE_BYTES[1] * n * n, hint="use a smaller size, or warptex.bake_gltf, which bakes in bands")
    g, coverage = texture_gbuffer(layout, size, gutter=gutter, device=device)
    color = technique(g) if technique is not None else None
    normal_map = tangent_space(g, normal(g)) if normal is not None else None
    return Baked(layout, g, coverage, color, normal_map, gutter)


def prepare_bake(func: str, mesh, technique, normal, *, size, padding, gutter, view_size, force_atlas, keep_uvs=False, atlas, device, needed: Callable[[int], float], hint: str) -> tuple[UVLayout, int, wp.context.Device]:
    """What a bake checks and makes before its texels: ``(layout, gutter, device)``. Every
    argument is checked (``needed(size)``: the bytes the bake will take, against what is
    available) and the techniques tried on an empty G-buffer before the mesh is unwrapped."""
    mesh = load_mesh(mesh) if not isinstance(mesh, trimesh.Trimesh) else mesh
    checked_geometry(f"{func}():", mesh)
    size = _checked_size(func, size)
    for name, value in (("view_size", view_size), ("gutter", gutter), ("padding", padding)):
        low = 1 if name == "view_size" else 0
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low):
            raise ValueError(f"{func}(): {name} must be an int >= {low}, got {value!r}")
    for name, f in (("technique", technique), ("normal", normal)):
        if f is not None and not callable(f):
            raise TypeError(f"{func}(): {name} must be a function of a G-buffer (e.g. functools.partial(warptex.triplanar, ...)), got {type(f).__name__}")
    if technique is None and normal is None:
        raise ValueError(f"{func}(): nothing to bake: pass a technique, a normal technique or both")
    if atlas not in ATLAS_METHODS:
        raise ValueError(f"{func}(): atlas must be one of {', '.join(map(repr, ATLAS_METHODS))}, got {atlas!r}")
    check_memory(func, f"a {size}x{size} bake", needed(size), device, hint=hint)
    device = wp.get_device(device)
    uv_sets = mesh_uv_sets(mesh)
    _dry_run(func, technique, normal, uv_sets, device)

    own = uv_sets.get("uv0")
    vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    if keep_uvs:  # refused by unwrap where they cannot be, before any texel is made
        unusable = ""
    else:
        unusable = unusable_reason(own, vertices, faces, own_faces=mesh_uv_faces(mesh), device=device)
    if own is not None and unusable and not force_atlas:  # an artist's UVs, replaced: say why
        warnings.warn(f"{func}(): the mesh's own UVs are not used: {unusable}; it is baked into a new atlas (keep_uvs, --keep-uvs: keep them)", UserWarning, stacklevel=3)
    force_atlas = bool(force_atlas) or bool(unusable)
    fill = ATLAS_FILL if force_atlas or own is None else max(float(face_areas(mesh.vertices, mesh.faces, own)[1].sum()), 1e-6)
    gutter = default_gutter(mesh, size, view_size=view_size, uv_fill=fill) if gutter is None else int(gutter)
    layout = unwrap(mesh, size=size, padding=gutter if padding is None else int(padding), force_atlas=force_atlas, keep_uvs=keep_uvs, atlas=atlas, device=device)
    return layout, gutter, device


def _dry_run(func: str, technique, normal, uv_sets: dict, device) -> None:
    """Call the techniques on an empty 2 × 2 G-buffer: their argument checks run before any work."""
    empty = GBuffer.empty((2, 2), uv_sets=[*uv_sets, "atlas"], device=device)
    with paused_tape():
        for name, f in (("technique", technique), ("normal", normal)):
            if f is None:
                continue
            out = f(empty)
            if not isinstance(out, wp.array) or out.ndim != 3 or out.shape[:2] != (2, 2) or (name == "normal" and out.shape[2] != 3):
                want = "(H, W, 3) world-space normals" if name == "normal" else "an (H, W, C) wp.array"
                raise TypeError(f"{func}(): {name} must return {want} for an (H, W) G-buffer, got {type(out).__name__} of shape {getattr(out, 'shape', None)}")
