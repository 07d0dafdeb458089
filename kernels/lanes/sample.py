"""``sample``'s CPU lanes (:mod:`.`): native functions (``native/wt_sample.h``) that read a lane's
texels over one level for every sample (:func:`sample_levels_lane`), a LOD per sample, given or
from UV derivatives (:func:`sample_footprint_lane`), and any footprints
(:func:`accumulate_footprint_lane`, which every technique's lanes read with); their texel-gradient
twins are in :mod:`.scatter`.
"""

import warp as wp

from ..native import cpu_snippet
from ..texels import SamplerArgs, TextureView
from . import lane_colours, lane_floats, lane_ints


@wp.func_native(cpu_snippet("return wt_accumulate_footprint_lane(tex, smp, layers, u, v, lod, du, dv, taps, weight, add, acc);\n", "return acc;\n"))
def accumulate_footprint_lane(tex: TextureView, smp: SamplerArgs, layers: lane_ints, u: lane_floats, v: lane_floats,
                              lod: lane_floats, du: lane_floats, dv: lane_floats, taps: lane_floats, weight: lane_floats, add: wp.int32, acc: lane_colours) -> lane_colours:  # fmt: skip
    """``acc`` with, in every lane ``l`` whose ``weight[l] > 0``, ``s =``
    :func:`~warptex.kernels.filters.sample_footprint` of layer ``layers[l]`` (a valid layer) at
    ``(u[l], v[l])`` over the footprint ``(lod, du, dv, taps)[l]`` (NaN where a tap's UV or the LOD
    is not finite) added as ``acc[l] + weight[l] · s`` (``add``: a blend of projections or layers,
    ``value += w · sample``), or put in its place (not ``add``: ``value = sample``); the other
    lanes' rows as they are."""
    ...


@wp.func_native(cpu_snippet("wt_sample_levels_lane(tex, smp, uv, layers, constant_layer, level, fraction, out, base);\n"))
def sample_levels_lane(tex: TextureView, smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32,
                       level: wp.int32, fraction: float, out: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """``out[i] =`` :func:`~warptex.kernels.filters.sample_levels` at ``uv[i]`` (NaN where it is not
    finite) on ``level``, blended by ``fraction`` with the next, for the lane's pixels ``i = base ..``:
    layer ``layers[i]`` clamped to the array, or ``constant_layer`` where ``layers`` is empty."""
    ...


@wp.func_native(cpu_snippet("wt_sample_footprint_lane(tex, smp, uv, uv_dx, uv_dy, lods, layers, constant_layer, lod_source, constant_lod, out, base);\n"))
def sample_footprint_lane(tex: TextureView, smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2), lods: wp.array(dtype=float),
                          layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float, out: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """``out[i] =`` :func:`~warptex.kernels.filters.sample_footprint` at ``uv[i]`` over the footprint
    that ``lod_source`` gives (``sampling.sample_footprint_of``: ``constant_lod``, ``lods[i]`` or the
    derivatives ``uv_dx[i]``, ``uv_dy[i]``; NaN where a tap's UV or the LOD is not finite), for the
    lane's pixels ``i = base ..``: layer ``layers[i]`` clamped to the array, or ``constant_layer``
    where ``layers`` is empty."""
    ...


@wp.func_native(cpu_snippet("wt_write_lane(out, base, count, value);\n"))
def write_lane(out: wp.array2d(dtype=float), base: wp.int32, count: wp.int32, value: lane_colours):
    """Rows ``base .. base + count - 1`` of ``out``: the lane's rows of ``value`` (``out``'s 1 to 4
    channels of each, as :func:`~warptex.kernels.texels.write_channels` writes them)."""
    ...


@wp.func_native(cpu_snippet("wt_write_covered_lane(out, base, count, value, mask);\n"))
def write_covered_lane(out: wp.array2d(dtype=float), base: wp.int32, count: wp.int32, value: lane_colours, mask: wp.array(dtype=float)):
    """:func:`write_lane` of the rows of the lane's pixels ``i`` whose ``mask[i]`` is not 0, and 0 in
    the others' rows."""
    ...
