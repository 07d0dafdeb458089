"""Texture-space G-buffers for baking: every texel of a UV atlas as the surface point it shows.

The atlas's triangles are laid in the ``z = 0`` plane at their UVs and ray-cast from above, one
ray through each texel centre, with the orthographic primary rays of :mod:`.raster` (a camera at
``(0.5, 0.5, 1)`` looking down ``-z`` over the unit square puts texel ``(row, col)``'s ray at
``((col + 0.5) / W, 1 - (row + 0.5) / H)``, warptex's texel-centre convention). A hit gives the
texel's triangle. Texels near a chart that no triangle covers (the gutter) take the triangle of
the nearest covered texel (jump flooding), and every texel with a triangle is then evaluated on
that triangle's plane: barycentrics of the texel centre in the triangle's UVs (outside the
triangle for gutter texels, which continue the surface past the chart's edge), world position,
normals, and the position derivatives per texel step from the triangle's UV-to-world Jacobian.
"""

import warp as wp

from .native import use
from .normals import direction
from .raster import CameraView, primary_ray

MODULE = use("warptex.bake")

# Texels whose jump-flood seed is farther than any gutter keep this squared distance.
FAR = wp.constant(1.0e30)


@wp.kernel(enable_backward=False, module=MODULE)
def chart_kernel(uv_mesh: wp.uint64, face_ids: wp.array(dtype=wp.int32), view: CameraView, triangle: wp.array2d(dtype=wp.int32), seed: wp.array2d(dtype=wp.int32)):
    """The atlas triangle under each texel centre (``face_ids[hit]``, -1 for none); covered texels
    are their own jump-flood seed (``row * W + col``, ``row`` the atlas row ``view.first_row +``
    the launch row), the others -1."""
    row, col = wp.tid()
    atlas_row = view.first_row + row
    o, d, do_dx, do_dy, dd_dx, dd_dy = primary_ray(view, atlas_row, col)
    hit = wp.mesh_query_ray(uv_mesh, o, d, 2.0)
    f = wp.int32(-1)
    s = wp.int32(-1)
    if hit.result:
        f = face_ids[hit.face]
        s = atlas_row * view.width + col
    triangle[row, col] = f
    seed[row, col] = s


@wp.func
def seed_distance2(row: wp.int32, col: wp.int32, s: wp.int32, width: wp.int32) -> float:
    """Squared distance in texels from ``(row, col)`` to seed texel ``s`` (``FAR`` for none)."""
    if s < 0:
        return FAR
    dr = float(s / width - row)
    dc = float(s % width - col)
    return dr * dr + dc * dc


@wp.kernel(enable_backward=False, module=MODULE)
def flood_kernel(seed_in: wp.array2d(dtype=wp.int32), step: wp.int32, first_row: wp.int32, offset: wp.int32, seed_out: wp.array2d(dtype=wp.int32)):
    """One jump-flooding pass (Rong and Tan 2006) over a band of atlas rows (row 0 of ``seed_in``
    is atlas row ``first_row``): each texel keeps the nearest of its own seed and the seeds of the
    8 texels ``step`` away that the band holds. Launch row ``row`` is ``seed_in``'s row ``offset +
    row`` and ``seed_out``'s row ``row`` (a launch over some of the band's rows, into their slice)."""
    launch_row, col = wp.tid()
    row = offset + launch_row
    height = seed_in.shape[0]
    width = seed_in.shape[1]
    best = seed_in[row, col]
    best_d = seed_distance2(first_row + row, col, best, width)
    for i in range(-1, 2):
        for j in range(-1, 2):
            r = row + i * step
            c = col + j * step
            if r >= 0 and r < height and c >= 0 and c < width:
                s = seed_in[r, c]
                d = seed_distance2(first_row + row, col, s, width)
                if d < best_d:
                    best = s
                    best_d = d
    seed_out[launch_row, col] = best


@wp.func
def uv_barycentric(p: wp.vec2, a: wp.vec2, b: wp.vec2, c: wp.vec2) -> wp.vec3:
    """Barycentric coordinates of ``p`` in the UV triangle ``(a, b, c)`` (negative outside it)."""
    e1 = b - a
    e2 = c - a
    q = p - a
    inv = 1.0 / (e1[0] * e2[1] - e1[1] * e2[0])
    u = (q[0] * e2[1] - q[1] * e2[0]) * inv
    v = (e1[0] * q[1] - e1[1] * q[0]) * inv
    return wp.vec3(1.0 - u - v, u, v)


@wp.kernel(enable_backward=False, module=MODULE)
def surface_kernel(
    points: wp.array(dtype=wp.vec3),
    indices: wp.array(dtype=wp.int32),
    corner_uvs: wp.array(dtype=wp.vec2),
    vertex_normals: wp.array(dtype=wp.vec3),
    chart: wp.array2d(dtype=wp.int32),
    seed: wp.array2d(dtype=wp.int32),
    gutter: float,
    chart_row: wp.int32,
    first_row: wp.int32,
    height: wp.int32,
    position: wp.array2d(dtype=wp.vec3),
    normal: wp.array2d(dtype=wp.vec3),
    geometric_normal: wp.array2d(dtype=wp.vec3),
    depth: wp.array2d(dtype=float),
    mask: wp.array2d(dtype=float),
    triangle: wp.array2d(dtype=wp.int32),
    barycentric: wp.array2d(dtype=wp.vec3),
    position_dx: wp.array2d(dtype=wp.vec3),
    position_dy: wp.array2d(dtype=wp.vec3),
    coverage: wp.array2d(dtype=float),
):
    """Each texel as the point of its triangle's plane at the texel centre: the texel's own
    triangle (``chart``), else, within ``gutter`` texels of its jump-flood seed, the seed's.

    ``corner_uvs[3 f + c]`` is corner ``c`` of face ``f`` in the atlas. Shading normals are the
    vertex normals interpolated with the barycentrics clamped to the triangle (gutter texels
    continue the edge's normal), the geometric normal is the face's, turned to the shading
    normal's side; ``position_dx``/``position_dy`` are ``dp/du / W`` and ``-dp/dv / H`` (one texel
    right, one texel down). Outputs of texels without a triangle are left as the caller wrote them.

    The outputs are a band of the atlas's ``height`` rows, from row ``first_row`` on; ``chart`` and
    ``seed`` hold the rows from ``chart_row`` on: the band's and those within ``gutter`` of it.
    """
    row, col = wp.tid()
    width = chart.shape[1]
    atlas_row = first_row + row
    f = chart[atlas_row - chart_row, col]
    covered = 1.0
    if f < 0:
        covered = 0.0
        s = seed[atlas_row - chart_row, col]
        if s >= 0 and seed_distance2(atlas_row, col, s, width) <= gutter * gutter:
            f = chart[s / width - chart_row, s % width]
    if f >= 0:
        i = indices[3 * f]
        j = indices[3 * f + 1]
        k = indices[3 * f + 2]
        ta = corner_uvs[3 * f]
        tb = corner_uvs[3 * f + 1]
        tc = corner_uvs[3 * f + 2]
        uv = wp.vec2((float(col) + 0.5) / float(width), 1.0 - (float(atlas_row) + 0.5) / float(height))
        b = uv_barycentric(uv, ta, tb, tc)
        e1 = points[j] - points[i]
        e2 = points[k] - points[i]
        t1 = tb - ta
        t2 = tc - ta
        inv = 1.0 / (t1[0] * t2[1] - t1[1] * t2[0])
        dp_du = (e1 * t2[1] - e2 * t1[1]) * inv
        dp_dv = (e2 * t1[0] - e1 * t2[0]) * inv
        bc = wp.vec3(wp.max(b[0], 0.0), wp.max(b[1], 0.0), wp.max(b[2], 0.0))
        bc = bc / (bc[0] + bc[1] + bc[2])
        ng = direction(wp.cross(e1, e2))
        ns = vertex_normals[i] * bc[0] + vertex_normals[j] * bc[1] + vertex_normals[k] * bc[2]
        if wp.length(ns) > 1.0e-12:
            ns = wp.normalize(ns)
        else:
            ns = ng
        if wp.dot(ns, ng) < 0.0:
            ng = -ng
        position[row, col] = points[i] * b[0] + points[j] * b[1] + points[k] * b[2]
        normal[row, col] = ns
        geometric_normal[row, col] = ng
        depth[row, col] = 0.0
        mask[row, col] = 1.0
        triangle[row, col] = f
        barycentric[row, col] = b
        position_dx[row, col] = dp_du / float(width)
        position_dy[row, col] = dp_dv * (-1.0 / float(height))
        coverage[row, col] = covered


@wp.func
def separated(a0: wp.vec2, a1: wp.vec2, a2: wp.vec2, b0: wp.vec2, b1: wp.vec2, b2: wp.vec2, tolerance: float) -> wp.int32:
    """1 if an edge normal of triangle ``a`` separates ``b`` from it, or lets them overlap by no
    more than ``tolerance`` (so triangles that share an edge or a corner count as separated)."""
    result = wp.int32(0)
    for e in range(3):
        p = a0
        q = a1
        r = a2
        if e == 1:
            p = a1
            q = a2
            r = a0
        elif e == 2:
            p = a2
            q = a0
            r = a1
        edge = q - p
        length = wp.length(edge)
        if length > 0.0:
            axis = wp.vec2(-edge[1], edge[0]) / length
            lo_a = wp.min(wp.dot(p, axis), wp.dot(r, axis))
            hi_a = wp.max(wp.dot(p, axis), wp.dot(r, axis))
            pb0 = wp.dot(b0, axis)
            pb1 = wp.dot(b1, axis)
            pb2 = wp.dot(b2, axis)
            lo_b = wp.min(pb0, wp.min(pb1, pb2))
            hi_b = wp.max(pb0, wp.max(pb1, pb2))
            if wp.min(hi_a, hi_b) - wp.max(lo_a, lo_b) <= tolerance:
                result = 1
    return result


@wp.func
def uv_triangle(uv_points: wp.array(dtype=wp.vec3), uv_indices: wp.array(dtype=wp.int32), t: wp.int32):
    """The corners of triangle ``t`` of the UV mesh (``z = 0``) as ``vec2`` values."""
    a = uv_points[uv_indices[3 * t]]
    b = uv_points[uv_indices[3 * t + 1]]
    c = uv_points[uv_indices[3 * t + 2]]
    return wp.vec2(a[0], a[1]), wp.vec2(b[0], b[1]), wp.vec2(c[0], c[1])


@wp.kernel(enable_backward=False, module=MODULE)
def overlap_kernel(uv_mesh: wp.uint64, uv_points: wp.array(dtype=wp.vec3), uv_indices: wp.array(dtype=wp.int32), tolerance: float, overlaps: wp.array(dtype=wp.int32)):
    """For each triangle of the UV mesh, a later triangle (in the BVH's order) whose interior
    overlaps its own by more than ``tolerance`` (separating-axis test), or -1."""
    t = wp.tid()
    a0, a1, a2 = uv_triangle(uv_points, uv_indices, t)
    lower = wp.vec3(wp.min(a0[0], wp.min(a1[0], a2[0])), wp.min(a0[1], wp.min(a1[1], a2[1])), -1.0)
    upper = wp.vec3(wp.max(a0[0], wp.max(a1[0], a2[0])), wp.max(a0[1], wp.max(a1[1], a2[1])), 1.0)
    found = wp.int32(-1)
    query = wp.mesh_query_aabb(uv_mesh, lower, upper)
    other = wp.int32(0)
    while wp.mesh_query_aabb_next(query, other):
        if other > t and found < 0:
            b0, b1, b2 = uv_triangle(uv_points, uv_indices, other)
            if separated(a0, a1, a2, b0, b1, b2, tolerance) == 0 and separated(b0, b1, b2, a0, a1, a2, tolerance) == 0:
                found = other
    overlaps[t] = found


@wp.kernel(module=MODULE)
def tangent_frame_kernel(
    vectors: wp.array2d(dtype=float),
    normal: wp.array(dtype=wp.vec3),
    tangent: wp.array(dtype=wp.vec4),
    mask: wp.array(dtype=float),
    to_world: wp.int32,
    out: wp.array2d(dtype=float),
):
    """Unit vectors ``(count, 3)`` from world space into the tangent frame ``(T, B, N)`` of a UV
    set (``to_world`` 0), or from tangent space back to world space (1): ``N`` the shading normal,
    ``T`` the tangent (xyz, orthogonal to ``N``), ``B = w · cross(N, T)``, as glTF defines the frame
    of a normal texture. Results are normalised; left at 0 where the mask is 0 or the frame is
    missing."""
    p = wp.tid()
    t4 = tangent[p]
    t = wp.vec3(t4[0], t4[1], t4[2])
    n = normal[p]
    if mask[p] > 0.0 and wp.length(t) > 0.0:
        b = wp.cross(n, t) * t4[3]
        v = wp.vec3(vectors[p, 0], vectors[p, 1], vectors[p, 2])
        r = wp.vec3(wp.dot(v, t), wp.dot(v, b), wp.dot(v, n))
        if to_world != 0:
            r = t * v[0] + b * v[1] + n * v[2]
        if wp.length(r) > 0.0:
            r = wp.normalize(r)
            out[p, 0] = r[0]
            out[p, 1] = r[1]
            out[p, 2] = r[2]
