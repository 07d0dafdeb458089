"""CPU lanes, part 2: texel gradients for a lane of pixels (the ``scatter_*`` twins of :mod:`.lanes`,
as :mod:`.scatter` is of :mod:`.filters`).

A lane's taps and weights are computed for every pixel first, then added pixel by pixel and read by
read, in the order the scalar kernels add them: the same texels get the same sums in the same order,
so the gradients are the same bits, and the same tile marks (``scatter.mark_rows``) are made.
"""

import warp as wp

from .lanes import FOOTPRINT_CPP, cpu_snippet, lane_colours, lane_ints, lane_reads, lane_taps
from .sample_lanes import SAMPLE_READS_CPP
from .texels import TILE_SHIFT, SamplerArgs, TexelGrad, TextureView

# scatter.scatter_levels for the lane: reads r = 0 .. reads - 1 (up to WT_MAX_READS) of every lane pixel, read r
# from tex[r] into grad[r], the levels and fractions given (module docstring).
_SCATTER_CORE = r"""
enum { WT_TILE_SHIFT = %(tile_shift)d, WT_MAX_READS = 12 };
struct wt_taps { int start, w, i0, i1, j0, j1; float fx, fy; };  // a lane pixel's taps of one level
struct wt_lane_taps { int start[WT_L], w[WT_L], i0[WT_L], i1[WT_L], j0[WT_L], j1[WT_L]; float fx[WT_L], fy[WT_L]; };  // the lane's, a row per field
typedef float wt_lane_f[WT_L];
typedef int wt_lane_i[WT_L];
typedef bool wt_lane_b[WT_L];
typedef wt_f4 wt_lane_f4[WT_L];
auto wt_scatter_levels = [&](const int address, const int reads, const auto* const* tex, const auto* const* grad, const auto& smp, const wt_lane_f* u, const wt_lane_f* v,
                             const wt_lane_i* level, const wt_lane_f* fraction, const wt_lane_i* layer, const wt_lane_b* active, const wt_lane_f4* g) __attribute__((always_inline)) {
    wt_lane_taps taps[WT_MAX_READS][2];  // [read][fine, coarse], field by field, so that the loop below vectorises
    bool blend = false;  // a lane reads two levels (trilinear)
    for (int r = 0; r < reads; ++r)
        for (int l = 0; l < WT_L; ++l) blend |= smp.filter != WT_NEAREST && active[r][l] && fraction[r][l] > 0.0f;
    for (int r = 0; r < reads; ++r) {
        for (int pass = 0; pass < (blend ? 2 : 1); ++pass) {
            int k[WT_L], lw[WT_L], lh[WT_L], ls[WT_L];  // each lane's level, its size and offset
            for (int l = 0; l < WT_L; ++l) k[l] = pass == 0 || fraction[r][l] <= 0.0f ? level[r][l] : level[r][l] + 1;
            wt_level_sizes(*tex[r], k, lw, lh, ls);
            wt_lane_taps& t = taps[r][pass];
            for (int l = 0; l < WT_L; ++l) {  // filters.nearest_tap / bilinear_taps
                const float ru = wt_reduce(u[r][l], address), rv = wt_reduce(v[r][l], address);
                const int w = lw[l], h = lh[l];
                t.w[l] = w;
                t.start[l] = ls[l] + layer[r][l] * h * w;
                if (smp.filter == WT_NEAREST) {
                    t.i0[l] = wt_address((int)wp::floor(ru * (float)w), w, address);
                    t.j0[l] = wt_address((int)wp::floor((1.0f - rv) * (float)h), h, address);
                } else {
                    const float x = ru * (float)w - 0.5f;
                    const float y = (1.0f - rv) * (float)h - 0.5f;
                    const float x0 = wp::floor(x);
                    const float y0 = wp::floor(y);
                    t.i0[l] = wt_address((int)x0, w, address);
                    t.i1[l] = wt_address((int)x0 + 1, w, address);
                    t.j0[l] = wt_address((int)y0, h, address);
                    t.j1[l] = wt_address((int)y0 + 1, h, address);
                    t.fx[l] = x - x0;
                    t.fy[l] = y - y0;
                }
            }
        }
    }
    auto tap = [&](int r, int pass, int l) __attribute__((always_inline)) -> wt_taps {
        const wt_lane_taps& t = taps[r][pass];
        return {t.start[l], t.w[l], t.i0[l], t.i1[l], t.j0[l], t.j1[l], t.fx[l], t.fy[l]};
    };
    // Each read's gradient array as a pointer and strides, taken once: the adds' stores could alias
    // the array structs, which the compiler would then read again after every add.
    struct wt_target { char* texels; long long stride; char* tiles; long long tile_stride; bool marks; };
    wt_target targets[WT_MAX_READS];
    for (int r = 0; r < reads; ++r)
        targets[r] = {(char*)grad[r]->texels.data, (long long)grad[r]->texels.strides[0], (char*)grad[r]->tiles.data, (long long)grad[r]->tiles.strides[0], grad[r]->tiles.shape[0] > 0};
    auto add = [&](const wt_target& gr, const wt_taps& t, int x, int y, const wt_f4 value) __attribute__((always_inline)) {  // scatter.scatter_texel
        if (address != WT_BORDER || (x >= 0 && y >= 0)) {  // only the border mode has taps outside
            float* p = (float*)(gr.texels + (long long)(t.start + y * t.w + x) * gr.stride);
            for (int c = 0; c < 4; ++c) p[c] = p[c] + value[c];
        }
    };
    auto mark = [&](const wt_target& gr, const wt_taps& t, int j) __attribute__((always_inline)) {  // scatter.mark_rows
        const int row = t.start + j * t.w;
        int* tile = (int*)(gr.tiles + (long long)(row >> WT_TILE_SHIFT) * gr.tile_stride);
        const int reach = (((row & ((1 << WT_TILE_SHIFT) - 1)) + 2 * t.w - 1) >> WT_TILE_SHIFT) + 1;
        if (*tile < reach) *tile = reach;
    };
    auto bilinear = [&](const wt_target& gr, const wt_taps& t, const wt_f4 value) __attribute__((always_inline)) {  // scatter.scatter_bilinear
        const wt_f4 top = value * (1.0f - t.fy);
        const wt_f4 bottom = value * t.fy;
        add(gr, t, t.i0, t.j0, top * (1.0f - t.fx));
        add(gr, t, t.i1, t.j0, top * t.fx);
        add(gr, t, t.i0, t.j1, bottom * (1.0f - t.fx));
        add(gr, t, t.i1, t.j1, bottom * t.fx);
        if (gr.marks) {
            if (t.j0 >= 0) mark(gr, t, t.j0);
            if (t.j1 >= 0 && (t.j0 < 0 || t.j1 < t.j0 || t.j1 > t.j0 + 1)) mark(gr, t, t.j1);
        }
    };
    for (int l = 0; l < WT_L; ++l) {
        for (int r = 0; r < reads; ++r) {
            if (!active[r][l]) continue;
            const wt_target& gr = targets[r];
            if (smp.filter == WT_NEAREST) {
                const wt_taps t = tap(r, 0, l);
                add(gr, t, t.i0, t.j0, g[r][l]);
                if (gr.marks && t.j0 >= 0) mark(gr, t, t.j0);
            } else {  // scatter.scatter_levels: the coarser level first
                wt_f4 finer = g[r][l];
                if (fraction[r][l] > 0.0f) {
                    finer = g[r][l] * (1.0f - fraction[r][l]);
                    bilinear(gr, tap(r, 1, l), g[r][l] * fraction[r][l]);
                }
                bilinear(gr, tap(r, 0, l), finer);
            }
        }
    }
};
auto wt_scatter_levels_any = [&](const int reads, const auto* const* tex, const auto* const* grad, const auto& smp, const wt_lane_f* u, const wt_lane_f* v,
                                 const wt_lane_i* level, const wt_lane_f* fraction, const wt_lane_i* layer, const wt_lane_b* active, const wt_lane_f4* g) __attribute__((always_inline)) {
    switch (smp.address) {
        case WT_WRAP: wt_scatter_levels(WT_WRAP, reads, tex, grad, smp, u, v, level, fraction, layer, active, g); break;
        case WT_CLAMP: wt_scatter_levels(WT_CLAMP, reads, tex, grad, smp, u, v, level, fraction, layer, active, g); break;
        case WT_MIRROR: wt_scatter_levels(WT_MIRROR, reads, tex, grad, smp, u, v, level, fraction, layer, active, g); break;
        default: wt_scatter_levels(WT_BORDER, reads, tex, grad, smp, u, v, level, fraction, layer, active, g); break;
    }
};
""" % {"tile_shift": TILE_SHIFT}

_SCATTER_LEVELS = _SCATTER_CORE + r"""
// scatter_sample_level's reads: pixel base + l (finite UVs only), its layer, one level for all.
const int n = uv.shape[0];
const int count = n - base < WT_L ? n - base : WT_L;
float u[1][WT_L], v[1][WT_L], fractions[1][WT_L];
int levels[1][WT_L], layer[1][WT_L];
bool active[1][WT_L];
wt_f4 g[1][WT_L];
float p[2][WT_L];
wt_rows(uv, base, count, 2, p);
for (int l = 0; l < WT_L; ++l) {
    const int k = base + (l < count ? l : 0);
    const bool finite = __builtin_fabsf(p[0][l]) <= wt_float_max && __builtin_fabsf(p[1][l]) <= wt_float_max;
    active[0][l] = l < count && finite;
    u[0][l] = active[0][l] ? p[0][l] : 0.0f;
    v[0][l] = active[0][l] ? p[1][l] : 0.0f;
    levels[0][l] = level;
    fractions[0][l] = fraction;
    layer[0][l] = layers.shape[0] > 0 ? wp::clamp(wt_int(layers, k), 0, tex.num_layers - 1) : constant_layer;  // texels.resolve_layer
    wt_f4 a = {0.0f, 0.0f, 0.0f, 0.0f};  // texels.read_channels
    const char* row = (const char*)adj.data + (long long)k * adj.strides[0];
    for (int c = 0; c < adj.shape[1] && c < 4; ++c) a[c] = *(const float*)(row + (long long)c * adj.strides[1]);
    g[0][l] = a;
}
const decltype(tex)* texs[1] = {&tex};
const decltype(grad)* grads[1] = {&grad};
wt_scatter_levels_any(1, texs, grads, smp, u, v, levels, fractions, layer, active, g);
"""


@wp.func_native(cpu_snippet(_SCATTER_LEVELS))
def scatter_levels_lane(tex: TextureView, grad: TexelGrad, smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32,
                        level: wp.int32, fraction: float, adj: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """:func:`~warptex.kernels.scatter.scatter_levels` of the gradient ``adj[i]`` for the lane's
    pixels ``i = base ..`` whose ``uv[i]`` is finite (:func:`~.sample_lanes.sample_levels_lane`'s reads)."""
    ...


# Up to twelve reads per lane pixel, read r from tex[r] into grad[r], at the rows u[r], v[r], lod[r]
# and weight w[r] of a value per lane pixel (a lane_reads matrix's: a pixel's projections, or two of
# them: a pixel's faces; a lane_taps matrix's: a stochastic lookup's taps, or three of them: a
# stochastic triplanar pixel's); a read adds where its weight is positive and its UV and LOD are
# finite (scatter.scatter_lod), and only into a gradient that is needed. It adds its share of the
# pixel's gradient g[l] (read r's own, gr[r], where per_read; else gr[0]): w · g where weigh (a blend
# of projections or taps), g itself where not.
_SCATTER_LOD_CORE = _SCATTER_CORE + r"""
auto wt_scatter_rows = [&](const auto* const* texs, const auto* const* grads, const auto& smp, const int nreads, const int* layers, const float* const* u_rows,
                           const float* const* v_rows, const float* const* lod_rows, const float* const* w_rows, const int weigh,
                           const wp::mat_t<WT_L, 4, float>* const* gr, const int per_read) __attribute__((always_inline)) {
    float us[WT_MAX_READS][WT_L], vs[WT_MAX_READS][WT_L], fractions[WT_MAX_READS][WT_L];
    int levels[WT_MAX_READS][WT_L], layer[WT_MAX_READS][WT_L];
    bool active[WT_MAX_READS][WT_L];
    wt_f4 gs[WT_MAX_READS][WT_L];
    wt_vi lane_layers;
    __builtin_memcpy(&lane_layers, layers, sizeof(lane_layers));
    for (int r = 0; r < nreads; ++r) {  // a lane of reads at a time (vector selects, the same values as the scalar formulas)
        wt_vf u, v, lod, w;
        __builtin_memcpy(&u, u_rows[r], sizeof(u));
        __builtin_memcpy(&v, v_rows[r], sizeof(v));
        __builtin_memcpy(&lod, lod_rows[r], sizeof(lod));
        __builtin_memcpy(&w, w_rows[r], sizeof(w));
        const wt_vi needed = grads[r]->texels.shape[0] > 0 ? -1 : 0;
        const wt_vi ok = needed & (w > 0.0f) & (wt_vabs(u) <= wt_float_max) & (wt_vabs(v) <= wt_float_max) & (wt_vabs(lod) <= wt_float_max);
        const wt_vf zero = 0.0f;
        const wt_vf ur = wt_sel(ok, u, zero), vr = wt_sel(ok, v, zero);
        wt_vi level;
        wt_vf fraction;
        wt_mip_levels_lane(*texs[r], smp, wt_sel(ok, lod, zero), level, fraction);
        const int top = texs[r]->num_layers - 1;  // wp::clamp(layer, 0, top)
        wt_vi lr = lane_layers & ~(lane_layers < 0);
        const wt_vi over = lr > top;
        lr = ((lr & ~over) | (top & over)) & ok;
        __builtin_memcpy(us[r], &ur, sizeof(ur));
        __builtin_memcpy(vs[r], &vr, sizeof(vr));
        __builtin_memcpy(levels[r], &level, sizeof(level));
        __builtin_memcpy(fractions[r], &fraction, sizeof(fraction));
        __builtin_memcpy(layer[r], &lr, sizeof(lr));
        for (int l = 0; l < WT_L; ++l) {
            active[r][l] = ok[l] != 0;
            const wp::mat_t<WT_L, 4, float>& g = *gr[per_read ? r : 0];
            const wt_f4 gl = {g.data[l][0], g.data[l][1], g.data[l][2], g.data[l][3]};
            gs[r][l] = weigh ? w[l] * gl : gl;
        }
    }
    wt_scatter_levels_any(nreads, texs, grads, smp, us, vs, levels, fractions, layer, active, gs);
};
// wt_scatter_rows of the reads of a lane_reads matrix `at`.
auto wt_scatter_lod_of = [&](const auto* const* texs, const auto* const* grads, const auto& smp, const int nreads, const int* layers, const wp::mat_t<21, WT_L, float>& at,
                             const int weigh, const wp::mat_t<WT_L, 4, float>* const* gr, const int per_read) __attribute__((always_inline)) {
    const float* u[3] = {at.data[0], at.data[1], at.data[2]};
    const float* v[3] = {at.data[3], at.data[4], at.data[5]};
    const float* lod[3] = {at.data[6], at.data[7], at.data[8]};
    const float* w[3] = {at.data[9], at.data[10], at.data[11]};
    wt_scatter_rows(texs, grads, smp, nreads, layers, u, v, lod, w, weigh, gr, per_read);
};
// Every read's share of one gradient g[l] per lane pixel.
auto wt_scatter_lod = [&](const auto* const* texs, const auto* const* grads, const auto& smp, const int nreads, const int* layers, const wp::mat_t<21, WT_L, float>& at,
                          const int weigh, const wp::mat_t<WT_L, 4, float>& g) __attribute__((always_inline)) {
    const wp::mat_t<WT_L, 4, float>* gr[1] = {&g};
    wt_scatter_lod_of(texs, grads, smp, nreads, layers, at, weigh, gr, 0);
};
"""

_SCATTER_READS = _SCATTER_LOD_CORE + r"""
const decltype(tex0)* texs[3] = {&tex0, &tex1, &tex2};
const decltype(grad0)* grads[3] = {&grad0, &grad1, &grad2};
const wp::mat_t<WT_L, 4, float>* gr[3] = {&g0, &g1, &g2};
wt_scatter_lod_of(texs, grads, smp, 3, layers.c, reads, 0, gr, 1);
"""


@wp.func_native(cpu_snippet(_SCATTER_READS))
def scatter_reads_lanes(tex0: TextureView, tex1: TextureView, tex2: TextureView, grad0: TexelGrad, grad1: TexelGrad, grad2: TexelGrad, smp: SamplerArgs,
                        layers: lane_ints, reads: lane_reads, g0: lane_colours, g1: lane_colours, g2: lane_colours):  # fmt: skip
    """:func:`scatter_lod_lanes` of three reads with a gradient each: read ``r`` of every lane
    pixel ``l`` adds ``g_r[l]`` itself (not weighted) into ``grad_r``, where its weight in
    ``reads`` is positive, pixel by pixel and read by read as the scalar kernels add them."""
    ...


_SCATTER_LOD = _SCATTER_LOD_CORE + r"""
const decltype(tex0)* texs[3] = {&tex0, &tex1, &tex2};
const decltype(grad0)* grads[3] = {&grad0, &grad1, &grad2};
wt_scatter_lod(texs, grads, smp, count, layers.c, reads, weigh, g);
"""


@wp.func_native(cpu_snippet(_SCATTER_LOD))
def scatter_lod_lanes(tex0: TextureView, tex1: TextureView, tex2: TextureView, grad0: TexelGrad, grad1: TexelGrad, grad2: TexelGrad, smp: SamplerArgs, count: wp.int32,
                      layers: lane_ints, reads: lane_reads, weigh: wp.int32, g: lane_colours):  # fmt: skip
    """:func:`~warptex.kernels.scatter.scatter_lod` of each read ``r = 0 .. count - 1`` of every lane
    pixel ``l``'s share of its gradient ``g[l]`` (``w · g[l]``, ``w`` the read's weight, where
    ``weigh``; ``g[l]`` where not): read ``r`` of ``tex_r`` (layer ``layers[l]``) at its UV and LOD
    in ``reads`` (:data:`~.lanes.lane_reads`), into ``grad_r`` (nothing where it is empty), where its
    weight is positive, pixel by pixel and read by read as the scalar kernels add them."""
    ...


_SCATTER_SAMPLE = FOOTPRINT_CPP + _SCATTER_LOD_CORE + SAMPLE_READS_CPP + r"""
wp::mat_t<WT_L, 4, float> g;  // texels.read_channels of the lane's output gradients
for (int l = 0; l < WT_L; ++l) {
    const char* row = (const char*)adj.data + (long long)(base + (l < count ? l : 0)) * adj.strides[0];
    for (int c = 0; c < 4; ++c) g.data[l][c] = c < adj.shape[1] ? *(const float*)(row + (long long)c * adj.strides[1]) : 0.0f;
}
const decltype(tex)* texs[1] = {&tex};
const decltype(grad)* grads[1] = {&grad};
wt_scatter_lod(texs, grads, smp, 1, lane_layer, reads, 0, g);
"""


@wp.func_native(cpu_snippet(_SCATTER_SAMPLE))
def scatter_footprint_lane(tex: TextureView, grad: TexelGrad, smp: SamplerArgs, uv: wp.array(dtype=wp.vec2), uv_dx: wp.array(dtype=wp.vec2), uv_dy: wp.array(dtype=wp.vec2),
                           lods: wp.array(dtype=float), layers: wp.array(dtype=wp.int32), constant_layer: wp.int32, lod_source: wp.int32, constant_lod: float,
                           adj: wp.array2d(dtype=float), base: wp.int32):  # fmt: skip
    """:func:`~warptex.kernels.scatter.scatter_footprint` of the gradient ``adj[i]`` for the lane's
    pixels ``i = base ..`` (:func:`~.sample_lanes.sample_footprint_lane`'s reads), one-tap footprints only
    (every filter but the anisotropic one)."""
    ...


_SCATTER_TAPS = _SCATTER_LOD_CORE + r"""
// scatter_stochastic's one-tap footprints for the lane: tap k of pixel l at (u_k, v_k), rows 3k, 3k + 1
// of `taps`, all at the pixel's LOD (row 12), adds w_k · g[l] (w_k: row 3k + 2) into `grad` where
// w_k > 0, pixel by pixel and tap by tap (scatter.scatter_lod of each).
const float* u[4] = {taps.data[0], taps.data[3], taps.data[6], taps.data[9]};
const float* v[4] = {taps.data[1], taps.data[4], taps.data[7], taps.data[10]};
const float* w[4] = {taps.data[2], taps.data[5], taps.data[8], taps.data[11]};
const float* lod[4] = {taps.data[12], taps.data[12], taps.data[12], taps.data[12]};
const decltype(tex)* texs[4] = {&tex, &tex, &tex, &tex};
const decltype(grad)* grads[4] = {&grad, &grad, &grad, &grad};
const wp::mat_t<WT_L, 4, float>* gr[1] = {&g};
wt_scatter_rows(texs, grads, smp, 4, layers.c, u, v, lod, w, 1, gr, 0);
"""


_SCATTER_FACE_READS = _SCATTER_LOD_CORE + r"""
// A texture per face: each projection's read on its + face (rows of `plus`) and on its - face (rows of
// `minus`; a pixel reads one of the two), in the order x+, x-, y+, y-, z+, z-, each adding w · g[l].
const decltype(tex_px)* texs[6] = {&tex_px, &tex_nx, &tex_py, &tex_ny, &tex_pz, &tex_nz};
const decltype(grad_px)* grads[6] = {&grad_px, &grad_nx, &grad_py, &grad_ny, &grad_pz, &grad_nz};
const float *u[6], *v[6], *lod[6], *w[6];
for (int r = 0; r < 6; ++r) {
    const auto& at = r % 2 == 0 ? plus : minus;
    const int axis = r / 2;
    u[r] = at.data[axis], v[r] = at.data[3 + axis], lod[r] = at.data[6 + axis], w[r] = at.data[9 + axis];
}
const wp::mat_t<WT_L, 4, float>* gr[1] = {&g};
wt_scatter_rows(texs, grads, smp, 6, layers.c, u, v, lod, w, 1, gr, 0);
"""


@wp.func_native(cpu_snippet(_SCATTER_FACE_READS))
def scatter_face_reads_lanes(tex_px: TextureView, tex_nx: TextureView, tex_py: TextureView, tex_ny: TextureView, tex_pz: TextureView, tex_nz: TextureView,
                             grad_px: TexelGrad, grad_nx: TexelGrad, grad_py: TexelGrad, grad_ny: TexelGrad, grad_pz: TexelGrad, grad_nz: TexelGrad,
                             smp: SamplerArgs, layers: lane_ints, plus: lane_reads, minus: lane_reads, g: lane_colours):  # fmt: skip
    """:func:`scatter_lod_lanes` with a texture per face: every lane pixel ``l`` adds each
    projection's share ``w · g[l]`` into the gradient of the face it reads (``plus``, ``minus``:
    ``projection_lanes.triplanar_reads_lane``'s reads of the two sides), where ``w`` is positive,
    pixel by pixel and projection by projection as the scalar kernels add them."""
    ...


_SCATTER_PROJECTION_TAPS = _SCATTER_LOD_CORE + r"""
// scatter_stochastic of each projection's one-tap footprints, projection by projection (tap k of
// projection a: rows 3k, 3k + 1 of taps_a, its LOD row 12, weight row 3k + 2), each adding w_k · g_a[l]
// into grad_a, pixel by pixel and read by read as the scalar colour gradient adds them.
const decltype(taps0)* taps[3] = {&taps0, &taps1, &taps2};
const decltype(tex0)* axis_texs[3] = {&tex0, &tex1, &tex2};
const decltype(grad0)* axis_grads[3] = {&grad0, &grad1, &grad2};
const wp::mat_t<WT_L, 4, float>* axis_g[3] = {&g0, &g1, &g2};
const float *u[12], *v[12], *lod[12], *w[12];
const decltype(tex0)* texs[12];
const decltype(grad0)* grads[12];
const wp::mat_t<WT_L, 4, float>* gr[12];
for (int a = 0; a < 3; ++a) {
    for (int k = 0; k < 4; ++k) {
        const int r = 4 * a + k;
        u[r] = taps[a]->data[3 * k], v[r] = taps[a]->data[3 * k + 1], w[r] = taps[a]->data[3 * k + 2], lod[r] = taps[a]->data[12];
        texs[r] = axis_texs[a], grads[r] = axis_grads[a], gr[r] = axis_g[a];
    }
}
wt_scatter_rows(texs, grads, smp, 12, layers.c, u, v, lod, w, 1, gr, 1);
"""


@wp.func_native(cpu_snippet(_SCATTER_PROJECTION_TAPS))
def scatter_projection_taps_lanes(tex0: TextureView, tex1: TextureView, tex2: TextureView, grad0: TexelGrad, grad1: TexelGrad, grad2: TexelGrad, smp: SamplerArgs, layers: lane_ints,
                                  taps0: lane_taps, taps1: lane_taps, taps2: lane_taps, g0: lane_colours, g1: lane_colours, g2: lane_colours):  # fmt: skip
    """:func:`~warptex.kernels.stochastic.scatter_stochastic` of a stochastic triplanar lane's three
    projections: every tap in ``taps_a`` (:func:`~.stochastic_sample.projection_taps_lane`) of lane
    pixel ``l`` adds its weight times ``g_a[l]`` (the projection's share of the pixel's gradient)
    into ``grad_a``, where the weight is positive, pixel by pixel in projection and tap order."""
    ...


@wp.func_native(cpu_snippet(_SCATTER_TAPS))
def scatter_taps_lane(tex: TextureView, grad: TexelGrad, smp: SamplerArgs, layers: lane_ints, taps: lane_taps, g: lane_colours):
    """:func:`~warptex.kernels.stochastic.scatter_stochastic` of one-tap footprints for the lane:
    every stochastic tap in ``taps`` (:data:`~.lanes.lane_taps`) of lane pixel ``l`` adds its weight
    times ``g[l]`` into ``grad`` (layer ``layers[l]``, clamped), where the weight is positive."""
    ...
