"""``sample``'s CPU lanes (:mod:`.lanes`): the native helpers of its lane kernels, one LOD for every
sample (:func:`sample_levels_lane`) or a LOD per sample, given or from UV derivatives
(:func:`sample_footprint_lane`); their texel-gradient twins are in :mod:`.lane_scatter`.
"""

import warp as wp

from .lanes import FOOTPRINT_CPP, cpu_snippet
from .texels import LOD_CONSTANT, LOD_DERIVATIVES, LOD_PER_SAMPLE, SamplerArgs, TextureView

# sampling.sample_footprint_of and texels.resolve_layer for the lane's pixels base .. base + count - 1
# (the tail repeats pixel base and is not read): `reads`, read 0 of a lane_reads matrix (weight 1), and
# each pixel's layer (clamped where it is read). After FOOTPRINT_CPP; shared by the forward below and
# its texel gradient (.lane_scatter) and the stochastic lanes (.stochastic_sample).
SAMPLE_READS_CPP = r"""
const int n = uv.shape[0];
const int count = n - base < WT_L ? n - base : WT_L;
float raw[2][WT_L];
wt_rows(uv, base, count, 2, raw);
wt_vf U, V;
__builtin_memcpy(&U, raw[0], sizeof(U));
__builtin_memcpy(&V, raw[1], sizeof(V));
wt_footprint_lanes fp = {(wt_vf)0.0f, (wt_vf)0.0f, (wt_vf)0.0f, (wt_vf)1.0f};  // footprint.point_footprint(0)
if (lod_source == %(derivatives)d) {  // footprint.texture_footprint
    float dx[2][WT_L], dy[2][WT_L];
    wt_rows(uv_dx, base, count, 2, dx);
    wt_rows(uv_dy, base, count, 2, dy);
    wt_vf DX[2], DY[2];
    for (int e = 0; e < 2; ++e) __builtin_memcpy(&DX[e], dx[e], sizeof(wt_vf)), __builtin_memcpy(&DY[e], dy[e], sizeof(wt_vf));
    fp = wt_footprint(smp, DX[0], DX[1], DY[0], DY[1], (float)wt_int(tex.level_width, 0), (float)wt_int(tex.level_height, 0));
} else if (lod_source == %(per_sample)d) {
    float lod[1][WT_L];
    wt_rows(lods, base, count, 1, lod);
    __builtin_memcpy(&fp.lod, lod[0], sizeof(wt_vf));
} else if (lod_source == %(constant)d) {
    fp.lod = constant_lod;
}
int lane_layer[WT_L], in_lane[WT_L];
for (int l = 0; l < WT_L; ++l) {
    lane_layer[l] = layers.shape[0] > 0 ? wt_int(layers, base + (l < count ? l : 0)) : constant_layer;
    in_lane[l] = l < count ? -1 : 0;
}
wt_vi read;
__builtin_memcpy(&read, in_lane, sizeof(read));
wp::mat_t<21, WT_L, float> reads;
wt_put_read(reads, 0, read, U, V, fp, (wt_vf)1.0f);
""" % {"derivatives": int(LOD_DERIVATIVES), "per_sample": int(LOD_PER_SAMPLE), "constant": int(LOD_CONSTANT)}



_SAMPLE_LEVELS = r"""
// Pixels base .. base + count - 1 of the launch (the lane's tail repeats pixel base, not stored).
const int n = uv.shape[0];
const int count = n - base < WT_L ? n - base : WT_L;
float u[WT_L], v[WT_L], fractions[WT_L];
int levels[WT_L], layer[WT_L];
bool finite[WT_L];
float raw[2][WT_L];
wt_rows(uv, base, count, 2, raw);
for (int l = 0; l < WT_L; ++l) {  // texels.finite_uv_lod: a non-finite UV reads (0, 0), its output NaN
    finite[l] = __builtin_fabsf(raw[0][l]) <= wt_float_max && __builtin_fabsf(raw[1][l]) <= wt_float_max;
    u[l] = finite[l] ? raw[0][l] : 0.0f;
    v[l] = finite[l] ? raw[1][l] : 0.0f;
    levels[l] = level;
    fractions[l] = fraction;
    layer[l] = constant_layer;
}
if (layers.shape[0] > 0) {  // texels.resolve_layer
    for (int l = 0; l < WT_L; ++l) layer[l] = wp::clamp(wt_int(layers, base + (l < count ? l : 0)), 0, tex.num_layers - 1);
}
wt_f4 result[WT_L];
wt_sample_levels_any(tex, smp, u, v, levels, fractions, layer, result);
char* ob = (char*)out.data;  // texels.write_channels
const wt_f4 nan4 = __builtin_nanf("");
const int channels = out.shape[1];
if (channels == 4 && out.strides[1] == 4) {
    for (int l = 0; l < count; ++l) {
        const wt_f4 r = finite[l] ? result[l] : nan4;
        __builtin_memcpy(ob + (long long)(base + l) * out.strides[0], &r, 16);
    }
} else {
    for (int l = 0; l < count; ++l) {
        const wt_f4 r = finite[l] ? result[l] : nan4;
        char* row = ob + (long long)(base + l) * out.strides[0];
        for (int c = 0; c < channels; ++c) *(float*)(row + (long long)c * out.strides[1]) = r[c];
    }
}
"""


@wp.func_native(cpu_snippet(_SAMPLE_LEVELS))
def sample_levels_lane(tex: TextureView, smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32,
                       level: wp.int32, fraction: float, out: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """``out[i] =`` :func:`~warptex.kernels.filters.sample_levels` at ``uv[i]`` (NaN where it is not
    finite) on ``level``, blended by ``fraction`` with the next, for the lane's pixels ``i = base ..``:
    layer ``layers[i]`` clamped to the array, or ``constant_layer`` where ``layers`` is empty."""
    ...


_SAMPLE = FOOTPRINT_CPP + SAMPLE_READS_CPP + r"""
wp::mat_t<WT_L, 4, float> value;
wt_accumulate_footprint(tex, smp, lane_layer, reads.data[0], reads.data[3], reads.data[6], reads.data[12], reads.data[15], reads.data[18], reads.data[9], 0, value);
char* ob = (char*)out.data;  // texels.write_channels
const int channels = out.shape[1];
for (int l = 0; l < count; ++l) {
    char* row = ob + (long long)(base + l) * out.strides[0];
    if (channels == 4 && out.strides[1] == 4) __builtin_memcpy(row, value.data[l], 16);
    else for (int c = 0; c < channels; ++c) *(float*)(row + (long long)c * out.strides[1]) = value.data[l][c];
}
"""


@wp.func_native(cpu_snippet(_SAMPLE))
def sample_footprint_lane(tex: TextureView, smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2), lods: wp.array(dtype=float),
                          layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float, out: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """``out[i] =`` :func:`~warptex.kernels.filters.sample_footprint` at ``uv[i]`` over the footprint
    that ``lod_source`` gives (``sampling.sample_footprint_of``: ``constant_lod``, ``lods[i]`` or the
    derivatives ``uv_dx[i]``, ``uv_dy[i]``; NaN where a tap's UV or the LOD is not finite), for the
    lane's pixels ``i = base ..``: layer ``layers[i]`` clamped to the array, or ``constant_layer``
    where ``layers`` is empty."""
    ...
