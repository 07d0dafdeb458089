"""Projected charts: an atlas for the meshes xatlas cannot take (large scans, the crash it has on some).

xatlas grows charts by cost and flattens each with LSCM: its atlases have few seams and little
stretch, but it takes about a minute for 80 000 triangles here, more than linearly longer for
more, and it crashes (a segfault inside ``PackCharts``) on some meshes, an icosphere of 81 920
faces among them (its issue #146). This atlas is the simple, robust kind that photogrammetry
tools and box-mapping bakers make, in NumPy, in seconds for a million triangles:

1. each triangle takes the one of the six axis directions its (neighbour-smoothed) normal is
   closest to, unless its own normal faces that direction by less than :data:`MIN_FACING`;
2. the charts are the edge-connected groups of triangles of one direction; a chart of fewer than
   :data:`MIN_FACES` triangles joins a neighbour whose direction all its triangles face;
3. each chart is projected orthographically along its direction (no triangle is flipped: every
   one faces it), so areas shrink by at most ``cos 54.7°`` (1/√3) and lengths are kept along the
   plane; a chart whose projection overlaps itself (a spiral, a mushroom's rim) is cut in two by
   a plane across its longest extent until none does;
4. the charts are turned to their smallest bounding rectangle (PCA axes), scaled by one factor so
   that they fill the texture, and packed in shelves, tallest first, ``padding`` texels apart.

Texel density varies by at most √3 between triangles, and there are more seams than xatlas makes;
a bake's gutters (``warptex.bake``) hide the seams from filtering as they do xatlas's.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MERGE_FACING", "MIN_FACES", "MIN_FACING", "SMOOTHING", "projected_atlas"]

MIN_FACING = 0.1
"""The least ``n · d`` of a triangle's unit normal ``n`` and its chart's direction ``d``: every
triangle faces its projection (none flips), and none is squeezed to a sliver (1/10 of its area)."""

MIN_FACES = 24
"""Charts smaller than this join a neighbour where every triangle can (fewer, larger charts)."""

MERGE_FACING = 0.02
"""The least ``n · d`` of the triangles of a small chart that joins a neighbour: none flips, and a
fragment a scan's noise tilted may shrink further than :data:`MIN_FACING` allows a chart's own."""

SMOOTHING = 8
"""Passes of neighbour averaging of the normals that choose directions: noise on a scan, which
turns single triangles every way, does not scatter the charts."""

_DIRECTIONS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
# Each direction's plane axes (u, v) with u × v = the direction: no chart is mirrored.
_AXES = np.array([
    [[0, 0, -1], [0, 1, 0]], [[0, 0, 1], [0, 1, 0]],
    [[1, 0, 0], [0, 0, -1]], [[1, 0, 0], [0, 0, 1]],
    [[1, 0, 0], [0, 1, 0]], [[-1, 0, 0], [0, 1, 0]],
], np.float64)


def projected_atlas(vertices: np.ndarray, faces: np.ndarray, size: int, padding: int, *, overlaps=None, fill: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The projected-chart atlas of a mesh (module docstring), packed into a ``size``² texture.

    Args:
        vertices: ``[V, 3]`` float64. faces: ``[F, 3]`` int64.
        size: texels per side. padding: texels between charts (and half that from the edges).
        overlaps: ``overlaps(uv, faces) -> [F] bool``, which triangles of a packed layout overlap
            another (``warptex.unwrap`` passes its BVH test): charts are cut until none does;
            ``None``: they are not checked.
        fill: the texture's share (0-1] the charts' packed rectangles may take, for callers that
            want room to spare.

    Returns:
        ``(vertex_map, faces, uv)`` as xatlas gives them: each atlas vertex's input vertex
        ``[V']``, the faces over atlas vertices ``[F, 3]`` (face ``f`` is input face ``f``), and
        ``[V', 2]`` float32 UVs in ``[0, 1]``.

    Raises:
        ValueError: no triangle with area, or charts that cannot be packed with this padding.
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    corners = vertices[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(normal, axis=1)
    if not area.max(initial=0.0) > 0:
        raise ValueError(f"the mesh's {len(faces)} triangles have no area")
    unit = normal / np.maximum(2 * area, 1e-300)[:, None]
    pairs = _adjacent_faces(faces)
    direction = _directions(unit, area, pairs)
    chart, direction = _merge_small(_components(len(faces), pairs, direction), direction, unit, pairs)
    flat = _project(corners, direction)
    for _ in range(64):  # cut charts whose projection overlaps itself; each cut halves one
        vertex_map, new_faces, _ = _layout(chart, faces, vertices.shape[0])
        uv = np.zeros((len(vertex_map), 2), np.float64)
        uv[new_faces.reshape(-1)] = _pack(flat, chart, size, padding, fill).reshape(-1, 2)
        bad = overlaps(uv, new_faces) if overlaps is not None else None
        if bad is None or not bad.any():
            return vertex_map, new_faces, np.clip(uv, 0.0, 1.0).astype(np.float32)
        chart = _components(len(faces), pairs, _split(chart, np.unique(chart[bad]), corners))
    raise ValueError("its projected charts still overlap themselves after 64 cuts")


def _adjacent_faces(faces: np.ndarray) -> np.ndarray:
    """``[P, 2]`` pairs of faces that share an edge (each edge's faces, in the order met, chained:
    a non-manifold edge of 3 faces gives 2 pairs)."""
    edges = np.sort(np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(faces)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    same = (edges[1:] == edges[:-1]).all(axis=1)
    return np.stack([owner[:-1][same], owner[1:][same]], axis=1)


def _directions(unit: np.ndarray, area: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Each face's direction index (:data:`_DIRECTIONS`): that of its normal smoothed over its
    neighbours (:data:`SMOOTHING` passes of area-weighted averaging), or of its own normal where
    it faces the smoothed one's direction by less than :data:`MIN_FACING`."""
    smooth = unit * area[:, None]
    for _ in range(SMOOTHING):
        total = smooth.copy()
        np.add.at(total, pairs[:, 0], smooth[pairs[:, 1]])
        np.add.at(total, pairs[:, 1], smooth[pairs[:, 0]])
        smooth = total / np.maximum(np.linalg.norm(total, axis=1, keepdims=True), 1e-300)
    chosen = np.argmax(smooth @ _DIRECTIONS.T, axis=1)
    own = np.argmax(unit @ _DIRECTIONS.T, axis=1)
    facing = np.einsum("fi,fi->f", unit, _DIRECTIONS[chosen])
    return np.where(facing >= MIN_FACING, chosen, own)


def _components(count: int, pairs: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Labels ``[count]`` (0..C-1, in order of first face) of the groups of faces joined by
    ``pairs`` whose ``key`` agrees: union-find by hooking to the smaller label and jumping
    pointers, in NumPy."""
    link = pairs[key[pairs[:, 0]] == key[pairs[:, 1]]]
    label = np.arange(count)
    while True:
        a, b = label[link[:, 0]], label[link[:, 1]]
        low = np.minimum(a, b)
        before = label.copy()
        np.minimum.at(label, a, low)
        np.minimum.at(label, b, low)
        while True:  # pointer jumping: every face to its group's root
            jumped = label[label]
            if (jumped == label).all():
                break
            label = jumped
        if (label == before).all():
            break
    return np.unique(label, return_inverse=True)[1]


def _merge_small(chart: np.ndarray, direction: np.ndarray, unit: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Charts of fewer than :data:`MIN_FACES` faces take the direction of their largest neighbour
    that every one of their faces faces by more than :data:`MERGE_FACING`: ``(chart, direction)``
    anew."""
    faced = unit @ _DIRECTIONS.T > MERGE_FACING  # [F, 6]: which directions each face may be projected along
    for _ in range(8):
        count = chart.max() + 1
        sizes = np.bincount(chart, minlength=count)
        chart_direction = np.zeros(count, np.int64)
        chart_direction[chart] = direction
        # Per chart and direction, whether all its faces face it.
        allowed = np.stack([np.bincount(chart, weights=~faced[:, d], minlength=count) == 0 for d in range(6)], axis=1)
        across = pairs[chart[pairs[:, 0]] != chart[pairs[:, 1]]]
        across = np.concatenate([across, across[:, ::-1]])
        src, dst = chart[across[:, 0]], chart[across[:, 1]]
        keep = (sizes[src] < MIN_FACES) & allowed[src, chart_direction[dst]]  # small charts, neighbours they may join
        src, dst = src[keep], dst[keep]
        if len(src) == 0:
            break
        order = np.lexsort((-sizes[dst], src))  # by small chart, its largest neighbour first
        src, dst = src[order], dst[order]
        first = np.concatenate([[True], src[1:] != src[:-1]])
        target = np.full(count, -1)
        target[src[first]] = chart_direction[dst[first]]
        move = target[chart] >= 0
        direction = np.where(move, target[chart], direction)
        chart = _components(len(chart), pairs, direction)
    return chart, direction


def _project(corners: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``[F, 3, 2]``: each face's corners on its direction's plane (world units)."""
    axes = _AXES[direction]  # [F, 2, 3]
    return np.einsum("fci,fai->fca", corners, axes)


def _split(chart: np.ndarray, cut: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """A key that cuts each chart of ``cut`` in two by the plane through its faces' median
    centroid across its longest extent: the faces of the far half get a new key."""
    key = chart.copy()
    centre = corners.mean(axis=1)
    fresh = chart.max() + 1
    for c in cut:
        faces = np.flatnonzero(chart == c)
        points = centre[faces]
        axis = int(np.argmax(points.max(axis=0) - points.min(axis=0)))
        far = points[:, axis] > np.median(points[:, axis])
        if far.all() or not far.any():  # all on one plane: split by index
            far = np.arange(len(faces)) >= len(faces) // 2
        key[faces[far]] = fresh
        fresh += 1
    return key


def _layout(chart: np.ndarray, faces: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(vertex_map, faces, key)``: one atlas vertex for each input vertex in each chart."""
    key = chart[:, None] * count + faces  # [F, 3]
    unique, inverse = np.unique(key.reshape(-1), return_inverse=True)
    return unique % count, inverse.reshape(-1, 3), unique


def _pack(flat: np.ndarray, chart: np.ndarray, size: int, padding: int, fill: float) -> np.ndarray:
    """The corners ``[F, 3, 2]`` packed into the unit square: each chart turned to its principal
    axes, all scaled by the largest factor for which shelf packing (tallest first) fits them
    ``padding`` texels apart, ``ceil(padding / 2)`` from the edges, in ``fill`` of the square."""
    count = chart.max() + 1
    points = flat.reshape(-1, 2)
    owner = np.repeat(chart, 3)
    # Turn each chart to its principal axes (its covariance's eigenvectors), longest along x.
    mean = np.zeros((count, 2))
    np.add.at(mean, owner, points)
    mean /= np.bincount(owner, minlength=count)[:, None]
    d = points - mean[owner]
    cov = np.zeros((count, 2, 2))
    np.add.at(cov, owner, d[:, :, None] * d[:, None, :])
    _, vectors = np.linalg.eigh(cov)  # ascending: column 1 is the major axis
    rotation = np.stack([vectors[:, :, 1], vectors[:, :, 0]], axis=1)  # rows: major, minor
    rotation[np.linalg.det(rotation) < 0, 1] *= -1  # a turn, never a mirror
    turned = np.einsum("pij,pj->pi", rotation[owner], d)
    low = np.full((count, 2), np.inf)
    high = np.full((count, 2), -np.inf)
    np.minimum.at(low, owner, turned)
    np.maximum.at(high, owner, turned)
    extent = np.maximum(high - low, 0.0)
    border = (padding + 1) // 2
    usable = size - 2 * border
    if usable <= 0:
        raise ValueError(f"a {size}² texture has no room inside {border} texels of border")
    total = float((extent[:, 0] * extent[:, 1]).sum())
    scale = math.sqrt(fill * usable * usable / max(total, 1e-300))  # texels per world unit: an upper bound
    order = np.argsort(-extent[:, 1], kind="stable")
    for _ in range(60):
        origin = _shelves(extent[order] * scale, padding, usable)
        if origin is not None:
            break
        scale *= 0.97
    else:
        raise ValueError(f"its {count} projected charts cannot be packed into {size}² texels with {padding} texels of padding between them; use a larger size or less padding")
    place = np.empty((count, 2))
    place[order] = origin
    texel = (turned - low[owner]) * scale + place[owner] + border
    return (texel / size).reshape(-1, 3, 2)


def _shelves(boxes: np.ndarray, padding: int, width: float) -> np.ndarray | None:
    """Lower-left corners of ``boxes`` (``[n, 2]`` texels, tallest first) placed left to right in
    shelves ``width`` wide, ``padding`` apart; ``None`` when they do not fit in ``width`` high."""
    out = np.empty_like(boxes)
    x = y = shelf = 0.0
    for k, (w, h) in enumerate(boxes.tolist()):
        if w > width:
            return None
        if x > 0 and x + w > width:
            x, y, shelf = 0.0, y + shelf + padding, 0.0
        out[k] = x, y
        x += math.ceil(w) + padding
        shelf = max(shelf, math.ceil(h))
    return out if y + shelf <= width else None
