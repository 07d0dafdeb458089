"""G-buffer rasterisation: one primary ray per pixel against a ``wp.Mesh`` BVH, with ray differentials.

Pixel ``(row, col)`` shoots a ray through its centre (conventions in :mod:`warptex.camera`). The
derivatives of position along screen x and y come from ray differentials (Igehy 1999) intersected
with the hit triangle's plane, so they are exact for planar geometry; UV derivatives follow from
them through the triangle's position-to-UV map.
"""

import warp as wp

from .native import use
from .normals import direction

MODULE = use("warptex.raster")


@wp.struct
class CameraView:
    """A camera as kernels see it; ``half_x``/``half_y`` are the image-plane half extents."""

    eye: wp.vec3
    forward: wp.vec3
    right: wp.vec3
    up: wp.vec3
    half_x: float
    half_y: float
    width: wp.int32
    height: wp.int32
    orthographic: wp.int32
    strata: wp.int32  # samples per pixel side (>= 1): warptex.camera.Camera.supersampled's pattern
    first_row: wp.int32  # the image row of launch row 0: a tile of rows [first_row, first_row + launch rows)


@wp.func
def stratum_shift(strata: wp.int32, k: wp.int32) -> float:
    """A sample's shift from the centre of its cell of the fine grid, in cells:
    ``((k mod s) + 0.5) / s - 0.5``, where ``k`` is its index along the *other* axis (its x shift
    follows its row stratum, its y shift its column stratum: no two samples of a pixel share a
    row or a column of the ``s² × s²`` sub-grid). 0 for one stratum."""
    s = wp.max(strata, 1)
    return (float(k % s) + 0.5) / float(s) - 0.5


@wp.func
def primary_ray(cam: CameraView, row: wp.int32, col: wp.int32):
    """Origin and direction (forward component 1) of the ray through a pixel centre, and their
    derivatives per pixel step along x and y: ``(origin, dir, d_origin_dx, d_origin_dy, d_dir_dx, d_dir_dy)``."""
    x = 2.0 * (float(col) + 0.5 - stratum_shift(cam.strata, row)) / float(cam.width) - 1.0
    y = 1.0 - 2.0 * (float(row) + 0.5 + stratum_shift(cam.strata, col)) / float(cam.height)
    offset = cam.right * (x * cam.half_x) + cam.up * (y * cam.half_y)
    step_x = cam.right * (2.0 * cam.half_x / float(cam.width))
    step_y = cam.up * (-2.0 * cam.half_y / float(cam.height))
    zero = wp.vec3(0.0)
    if cam.orthographic != 0:
        return cam.eye + offset, cam.forward, step_x, step_y, zero, zero
    return cam.eye, cam.forward + offset, zero, zero, step_x, step_y


@wp.func
def plane_differential(t: float, d: wp.vec3, n: wp.vec3, d_origin: wp.vec3, d_dir: wp.vec3) -> wp.vec3:
    """Change of the hit point ``o + t d`` on the plane with normal ``n`` for a ray change ``(d_origin, d_dir)``."""
    dp = d_origin + d_dir * t
    return dp - d * (wp.dot(dp, n) / wp.dot(d, n))


@wp.kernel(enable_backward=False, module=MODULE)
def raster_kernel(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    indices: wp.array(dtype=wp.int32),
    face_ids: wp.array(dtype=wp.int32),
    vertex_normals: wp.array(dtype=wp.vec3),
    cams: wp.array(dtype=CameraView),
    position: wp.array3d(dtype=wp.vec3),
    normal: wp.array3d(dtype=wp.vec3),
    geometric_normal: wp.array3d(dtype=wp.vec3),
    depth: wp.array3d(dtype=float),
    mask: wp.array3d(dtype=float),
    triangle: wp.array3d(dtype=wp.int32),
    barycentric: wp.array3d(dtype=wp.vec3),
    position_dx: wp.array3d(dtype=wp.vec3),
    position_dy: wp.array3d(dtype=wp.vec3),
):
    """Closest hit per pixel of every view (``cams[view]``: arrays are ``(views, rows, W)``, one
    launch for a batch of cameras, launch row ``row`` being image row ``cam.first_row + row``);
    normals face the camera (flipped on back faces, shading normals bent). ``indices`` holds the
    triangles in the BVH, ``face_ids`` their index in the mesh. Misses get the background values
    (zeros, ``depth = inf``, ``triangle = -1``): every output element is written, so the caller's
    arrays need no fill."""
    view, row, col = wp.tid()
    cam = cams[view]
    o, d, do_dx, do_dy, dd_dx, dd_dy = primary_ray(cam, cam.first_row + row, col)
    hit = wp.mesh_query_ray(mesh, o, d, 1.0e30)
    if hit.result:
        f = hit.face
        i = indices[3 * f]
        j = indices[3 * f + 1]
        k = indices[3 * f + 2]
        b = wp.vec3(hit.u, hit.v, 1.0 - hit.u - hit.v)
        p = o + d * hit.t
        ng = direction(wp.cross(points[j] - points[i], points[k] - points[i]))  # |cross|² overflows past edges of ~3e9
        ns = vertex_normals[i] * b[0] + vertex_normals[j] * b[1] + vertex_normals[k] * b[2]
        if wp.length(ns) > 1.0e-12:
            ns = wp.normalize(ns)
        else:
            ns = ng
        if wp.dot(ns, ng) < 0.0:  # a triangle wound against its neighbours (its vertex normals point
            ns = -ns  # out of its back): shade it from its front, as its neighbours are
        if wp.dot(ng, d) > 0.0:  # the back of the triangle faces the camera
            ng = -ng
            ns = -ns
        # Interpolated normals can turn away from the viewer near silhouettes; bend them just
        # enough to face it (cos 0.01 with the view direction), as renderers do.
        towards = -wp.normalize(d)
        facing = wp.dot(ns, towards)
        if facing < 0.01:
            ns = wp.normalize(ns + towards * (0.01 - facing))
        position[view, row, col] = p
        normal[view, row, col] = ns
        geometric_normal[view, row, col] = ng
        depth[view, row, col] = wp.dot(p - cam.eye, cam.forward)
        mask[view, row, col] = 1.0
        triangle[view, row, col] = face_ids[f]
        barycentric[view, row, col] = b
        position_dx[view, row, col] = plane_differential(hit.t, d, ng, do_dx, dd_dx)
        position_dy[view, row, col] = plane_differential(hit.t, d, ng, do_dy, dd_dy)
    else:  # the background, here rather than by a fill of the arrays first: the threads write it as they go
        position[view, row, col] = wp.vec3(0.0)
        normal[view, row, col] = wp.vec3(0.0)
        geometric_normal[view, row, col] = wp.vec3(0.0)
        depth[view, row, col] = wp.inf
        mask[view, row, col] = 0.0
        triangle[view, row, col] = -1
        barycentric[view, row, col] = wp.vec3(0.0)
        position_dx[view, row, col] = wp.vec3(0.0)
        position_dy[view, row, col] = wp.vec3(0.0)


@wp.func
def barycentric_change(e1: wp.vec3, e2: wp.vec3, dp: wp.vec3) -> wp.vec2:
    """Coefficients ``(a, b)`` with ``dp = a e1 + b e2`` for ``dp`` in the triangle's plane."""
    n = wp.cross(e1, e2)
    inv = 1.0 / wp.dot(n, n)
    return wp.vec2(wp.dot(wp.cross(dp, e2), n) * inv, wp.dot(wp.cross(e1, dp), n) * inv)


@wp.kernel(enable_backward=False, module=MODULE)
def uv_kernel(
    points: wp.array(dtype=wp.vec3),
    indices: wp.array(dtype=wp.int32),
    uvs: wp.array(dtype=wp.vec2),
    vertex_tangents: wp.array(dtype=wp.vec4),
    triangle: wp.array3d(dtype=wp.int32),
    barycentric: wp.array3d(dtype=wp.vec3),
    normal: wp.array3d(dtype=wp.vec3),
    position_dx: wp.array3d(dtype=wp.vec3),
    position_dy: wp.array3d(dtype=wp.vec3),
    uv: wp.array3d(dtype=wp.vec2),
    uv_dx: wp.array3d(dtype=wp.vec2),
    uv_dy: wp.array3d(dtype=wp.vec2),
    tangent: wp.array3d(dtype=wp.vec4),
):
    """Interpolated UVs, their screen-space derivatives, and the tangent frame of one UV set.

    The tangent is the interpolated vertex tangent made orthogonal to the shading normal, with
    the bitangent sign in ``w`` (bitangent = ``w * cross(normal, tangent)``).
    """
    view, row, col = wp.tid()
    f = triangle[view, row, col]
    frame = wp.vec4(0.0)  # the tangent where the pixel is a miss, or its tangent degenerate
    if f < 0:  # a miss: the background, zeros (every element is written: the arrays need no fill)
        uv[view, row, col] = wp.vec2(0.0)
        uv_dx[view, row, col] = wp.vec2(0.0)
        uv_dy[view, row, col] = wp.vec2(0.0)
    else:
        i = indices[3 * f]
        j = indices[3 * f + 1]
        k = indices[3 * f + 2]
        b = barycentric[view, row, col]
        uv[view, row, col] = uvs[i] * b[0] + uvs[j] * b[1] + uvs[k] * b[2]
        e1 = points[j] - points[i]
        e2 = points[k] - points[i]
        t1 = uvs[j] - uvs[i]
        t2 = uvs[k] - uvs[i]
        ax = barycentric_change(e1, e2, position_dx[view, row, col])
        ay = barycentric_change(e1, e2, position_dy[view, row, col])
        uv_dx[view, row, col] = t1 * ax[0] + t2 * ax[1]
        uv_dy[view, row, col] = t1 * ay[0] + t2 * ay[1]
        tv = vertex_tangents[i] * b[0] + vertex_tangents[j] * b[1] + vertex_tangents[k] * b[2]
        n = normal[view, row, col]
        t = wp.vec3(tv[0], tv[1], tv[2])
        t = t - n * wp.dot(n, t)
        if wp.length(t) > 1.0e-12:
            sign = 1.0
            if tv[3] < 0.0:
                sign = -1.0
            t = wp.normalize(t)
            frame = wp.vec4(t[0], t[1], t[2], sign)
    tangent[view, row, col] = frame


# Resolving a supersampled image: each ``s × s`` block of samples averaged into one pixel (a box
# filter over the pixel), and the gradient of that average. In the rasteriser's Warp module, and
# in this file: a Warp module's hash covers every kernel it holds, so kernels that a process may
# or may not import would give the module one hash per process (``warptex fit``, which resolves
# nothing, compiled its own rasteriser beside the one ``warptex render`` had cached).
@wp.kernel(enable_backward=False, module=MODULE)
def resolve_kernel(image: wp.array3d(dtype=float), strata: wp.int32, out: wp.array3d(dtype=float)):
    """``out[i, j, c]``: the mean of ``image[i s + a, j s + b, c]`` over ``a, b < s``."""
    i, j, c = wp.tid()
    total = float(0.0)
    for a in range(strata):
        for b in range(strata):
            total = total + image[i * strata + a, j * strata + b, c]
    out[i, j, c] = total / float(strata * strata)


@wp.kernel(enable_backward=False, module=MODULE)
def resolve_adjoint_kernel(adj_out: wp.array3d(dtype=float), strata: wp.int32, adj_image: wp.array3d(dtype=float)):
    """The gradient of :func:`resolve_kernel`: each sample gets ``1 / s²`` of its pixel's."""
    i, j, c = wp.tid()
    adj_image[i, j, c] = adj_image[i, j, c] + adj_out[i // strata, j // strata, c] / float(strata * strata)
