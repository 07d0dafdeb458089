// Splat layers for a lane of pixels: what each lane pixel reads of a layer (splat_layers.layer_read
// restated: its UV, footprint and weight of each read, a lane at a time), the layer's texels read
// over those footprints, and their gradients added into the layer's texels.
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_footprint.h"
#include "wt_projection.h"
#include "wt_scatter.h"
#include "wt_taps.h"

// What each lane pixel l (pixel base + l of the launch) with weighted[l] > 0 reads of layer j of tex
// (face layers change only the array layer a read samples: wt_read_layers):
// splat_layers.layer_read's UV, footprint and weight of each read k at the pixel's
// point (its UV0 and their derivatives, or its surface; tri_w: its triplanar weights), into the
// rows of a lane_reads matrix (0 for the other pixels), a lane at a time. The rows of the reads
// a layer does not have (1 and 2 but with the triplanar projection) are left as they are: its
// callers read only the reads it has.
// twin: splat_layers.layer_read
template <class Tex, class Reads, class UV, class Surface, class TriW, class Out>
WT_INLINE void wt_layer_reads_into(const Tex& tex, const Reads& reads, int j, const float* weighted, const UV& uv0,
                                   const UV& uv0_dx, const UV& uv0_dy, const Surface& surface, int base, int count,
                                   const TriW& tri_w, Out& out) {
    const auto& params = reads.params;
    const float t = wt_float(params.tiling, wp::min(j, params.tiling.shape[0] - 1));  // layer_tiling
    wt_vf w;
    __builtin_memcpy(&w, weighted, sizeof(w));
    const wt_vi read = w > 0.0f;
    const wt_vf zero = 0.0f, one = 1.0f;
    wt_footprint_lanes fp;
    if (params.projection == WT_PROJECT_UV) {  // UV0 × tiling, its footprint from UV0's derivatives × tiling
        wt_vf uv[2], dx[2], dy[2];
        wt_row_vectors(uv0, base, count, 2, uv);
        wt_row_vectors(uv0_dx, base, count, 2, dx);
        wt_row_vectors(uv0_dy, base, count, 2, dy);
        fp = wt_footprint(reads.smp, dx[0] * t, dx[1] * t, dy[0] * t, dy[1] * t, (float)wt_int(tex.level_width, 0),
                          (float)wt_int(tex.level_height, 0));
        wt_put_read(out, 0, read, uv[0] * t, uv[1] * t, fp, one);
    } else {
        wt_vf P[3], DX[3], DY[3], u, v;
        wt_row_vectors(surface.position, base, count, 3, P);
        wt_row_vectors(surface.position_dx, base, count, 3, DX);
        wt_row_vectors(surface.position_dy, base, count, 3, DY);
        if (params.projection == WT_PROJECT_WORLD_XZ) {  // the Y projection seen from above
            const wt_vf up[3] = {zero, one, zero};
            wt_plane_reads(reads.proj, reads.smp, 1, t, tex, P, up, DX, DY, u, v, fp);
            wt_put_read(out, 0, read, u, v, fp, one);
        } else {  // PROJECT_TRIPLANAR: the three projections, weighted by tri_w
            wt_vf N[3];
            wt_row_vectors(surface.normal, base, count, 3, N);
            for (int k = 0; k < 3; ++k) {
                float weight[WT_L];
                for (int l = 0; l < WT_L; ++l) weight[l] = tri_w.data[l][k];
                wt_vf wk;
                __builtin_memcpy(&wk, weight, sizeof(wk));
                wt_plane_reads(reads.proj, reads.smp, k, t, tex, P, N, DX, DY, u, v, fp);
                wt_put_read(out, k, read, u, v, fp, wk);
            }
        }
    }
}

// splat_layers.face_layer for the lane: layer[k][l], the array layer that read k of layer j samples
// at lane pixel l: j itself, or with face layers (projection triplanar) that of the face projection
// k sees, + where the pixel's normal has n[k] >= 0, else - (the lane's tail repeats pixel base).
// twin: splat_layers.face_layer
template <class Params, class Surface> WT_INLINE void wt_read_layers(const Params& params, const Surface& surface,
                                                                     int j, int base, int count, int layer[3][WT_L]) {
    if (params.face_layers.shape[0] == 0 || params.projection != WT_PROJECT_TRIPLANAR) {
        for (int k = 0; k < 3; ++k)
            for (int l = 0; l < WT_L; ++l) layer[k][l] = j;
        return;
    }
    float n[3][WT_L];
    wt_rows(surface.normal, base, count, 3, n);
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < WT_L; ++l)
            layer[k][l] = wt_int(params.face_layers, j * 6 + 2 * k + (n[k][l] < 0.0f ? 1 : 0));
}

// What a forward lane keeps for the gradient lane, SplatPixels.saved (lanes.splat.lane_saved), per
// pixel (L layers): the values, layer j's colour in columns 4 j .. 4 j + 3 and, with height layers,
// its height in column 4 L + j (wt_kept_width columns in all); then, where the tiling needs its
// gradient, their slopes along it, laid out the same. Texture 0 is the colour layers, 1 the
// height layers (splat_layers.pick).
template <class Params> WT_INLINE int wt_kept_width(const Params& params) {
    return (params.height_mode == WT_HEIGHT_ARRAY ? 5 : 4) * params.num_layers;
}
template <class Params> WT_INLINE int wt_kept_column(const Params& params, int texture, bool slope, int j) {
    return (slope ? wt_kept_width(params) : 0) + (texture == 0 ? 4 * j : 4 * params.num_layers + j);
}
template <class Params, class Saved> WT_INLINE bool wt_kept_slopes(const Params& params, const Saved& saved) {
    return saved.shape[1] >= 2 * wt_kept_width(params);
}

// wt_layer_values_lane's value where the tiling needs its gradient, and what that gradient reads,
// kept from the same taps: splat_layers.read_layer_slope of layer j of tex at each lane pixel l
// with weighted[l] > 0 (plain sampling), each read k of the array layer wt_read_layers gives it
// (face layers). Per read k of wt_layer_reads_into with a positive weight w: value += w · v and
// slope += w · (d/du · du/dt + d/dv · dv/dt + d/dlod · dlod/dt
// + d/dspread / t), of the read's wt_footprint_slopes and layer_read_slopes' UV and LOD slopes along
// the tiling t. The value and the slope of texture keep - 1 go into saved's row base + l
// (wt_kept_column; a height layer's first channel): the gradient's blend reads the values read
// with the slopes, which may differ from the forward's in the last bit (a footprint of several
// taps is divided by its taps, where the forward multiplies by their reciprocal) or the sign of a
// zero.
// Row l of the result: read_layer's value (wt_layer_values_lane's).
// twin: splat_layers.read_layer_slope
template <class Tex, class Reads, class Floats, class UV, class Surface, class TriW, class Saved>
WT_INLINE wt_lane_colours wt_layer_values_slopes(const Tex& tex, const Reads& reads, int j, const Floats& weighted,
                                                 const UV& uv0, const UV& uv0_dx, const UV& uv0_dy,
                                                 const Surface& surface, int base, int count, const TriW& tri_w,
                                                 int keep, const Saved& saved) {
    const auto& params = reads.params;
    const auto& proj = reads.proj;
    const float t = wt_float(params.tiling, wp::min(j, params.tiling.shape[0] - 1));  // layer_tiling
    wt_lane_read_rows at;  // the reads' rows, all that is read
    wt_layer_reads_into(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, at);
    int layer[3][WT_L];
    wt_read_layers(params, surface, j, base, count, layer);
    const int triplanar = params.projection == WT_PROJECT_TRIPLANAR;
    const float width = (float)wt_int(tex.level_width, 0), height = (float)wt_int(tex.level_height, 0);
    wt_row p[3], n[3], dx[3], dy[3];  // the lane's point: UV0 and its derivatives, or its surface
    if (params.projection == WT_PROJECT_UV) {
        wt_rows(uv0, base, count, 2, p);
        wt_rows(uv0_dx, base, count, 2, dx);
        wt_rows(uv0_dy, base, count, 2, dy);
    } else {
        wt_rows(surface.position, base, count, 3, p);
        wt_rows(surface.normal, base, count, 3, n);
        wt_rows(surface.position_dx, base, count, 3, dx);
        wt_rows(surface.position_dy, base, count, 3, dy);
    }
    const float o[3] = {(float)proj.origin.c[0], (float)proj.origin.c[1], (float)proj.origin.c[2]};
    wt_f4 value[WT_L], slope[WT_L];
    wt_lane_colours out;  // read_layer's: += w · sample per projection where triplanar, the one read's sample where not
    for (int l = 0; l < WT_L; ++l) value[l] = slope[l] = 0.0f;
    for (int k = 0; k < (triplanar ? 3 : 1); ++k) {
        wt_f4 f[WT_L], v[WT_L], d_u[WT_L], d_v[WT_L], d_lod[WT_L], d_spread[WT_L];
        const float* weight = at.data[9 + k];
        wt_footprint_slopes(tex, reads.smp, layer[k], at.data[k], at.data[3 + k], at.data[6 + k], at.data[12 + k],
                            at.data[15 + k], at.data[18 + k], weight, f, v, d_u, d_v, d_lod, d_spread);
        const int axis = params.projection == WT_PROJECT_WORLD_XZ ? 1 : k;
        const int c0 = axis == 0 ? 2 : 0, c1 = axis == 1 ? 2 : 1;  // projection.plane_coords
        for (int l = 0; l < count; ++l) {
            if (!(weight[l] > 0.0f)) continue;
            float uv_slope0 = p[0][l], uv_slope1 = p[1][l], lod_slope;  // splat_layers.layer_read_slopes
            if (params.projection == WT_PROJECT_UV) {
                lod_slope = wt_lod_scale_slope(width, height, dx[0][l], dx[1][l], dy[0][l], dy[1][l], t);
            } else {
                const float normal = params.projection == WT_PROJECT_WORLD_XZ ? 1.0f : n[axis][l];
                float s = 1.0f;  // projection.u_sign
                if (proj.mirror_fix != 0)
                    s = axis == 2 ? (normal < 0.0f ? -1.0f : 1.0f) : -(normal < 0.0f ? -1.0f : 1.0f);
                uv_slope0 = (p[c0][l] + o[c0]) * s;  // projection.slope_coords
                uv_slope1 = p[c1][l] + o[c1];
                lod_slope = wt_lod_scale_slope(width, height, dx[c0][l], dx[c1][l], dy[c0][l], dy[c1][l], t);
            }
            for (int c = 0; c < 4; ++c) out.data[l][c] = triplanar ? out.data[l][c] + weight[l] * f[l][c] : f[l][c];
            value[l] = value[l] + weight[l] * v[l];
            slope[l] = slope[l] +
                       weight[l] * (d_u[l] * uv_slope0 + d_v[l] * uv_slope1 + d_lod[l] * lod_slope + d_spread[l] / t);
        }
    }
    for (int l = 0; l < count; ++l) {
        if (!(weighted.c[l] > 0.0f)) continue;
        char* row = (char*)saved.data + (long long)(base + l) * saved.strides[0];
        const int at = wt_kept_column(params, keep - 1, false, j), slope_at = wt_kept_column(params, keep - 1, true, j);
        for (int c = 0; c < (keep == 1 ? 4 : 1); ++c) {
            *(float*)(row + (long long)(at + c) * saved.strides[1]) = value[l][c];
            *(float*)(row + (long long)(slope_at + c) * saved.strides[1]) = slope[l][c];
        }
    }
    return out;
}

// SplatPixels.saved, where it is not empty: row base + l (l < count), the lane's value of layer j of
// texture keep - 1 (wt_kept_column; a height layer's first channel): what the gradient lane's blend reads.
template <class Params, class Saved> WT_INLINE void wt_keep_layer(const Params& params, const Saved& saved, int keep,
                                                                  int j, int base, int count,
                                                                  const wt_lane_colours& value) {
    if (saved.shape[0] == 0) return;
    const int at = wt_kept_column(params, keep - 1, false, j);
    for (int l = 0; l < count; ++l) {
        char* row = (char*)saved.data + (long long)(base + l) * saved.strides[0];
        for (int c = 0; c < (keep == 1 ? 4 : 1); ++c)
            *(float*)(row + (long long)(at + c) * saved.strides[1]) = value.data[l][c];
    }
}

// wt_layer_values_slopes out of line: the kept forward of a fit that takes the tiling's gradient
// calls it, and the kept forward of every other gradient does not, whose body it burdened inlined.
template <class Tex, class Reads, class Floats, class UV, class Surface, class TriW, class Saved>
WT_OUTLINE wt_lane_colours wt_layer_values_slopes_outlined(const Tex& tex, const Reads& reads, int j,
                                                           const Floats& weighted, const UV& uv0, const UV& uv0_dx,
                                                           const UV& uv0_dy, const Surface& surface, int base,
                                                           int count, const TriW& tri_w, int keep, const Saved& saved) {
    return wt_layer_values_slopes(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, keep,
                                  saved);
}

// lanes.splat_layers.layer_values_lane: row l, layer j of tex read at lane pixel l over the footprints of
// wt_layer_reads_into's reads as read_layer reads them (per projection value += w · sample where
// triplanar, value = sample for the one read of the other projections; 0 where weighted[l] is not
// positive). Where keep (1 + the texture's place: colour layers 1, height layers 2) and saved is not
// empty, also stored in saved's row base + l (SplatPixels.saved, wt_kept_column); with Kept (the
// forward lane that keeps what the gradient lane reads), where saved has columns for the tiling's
// slopes too (wt_kept_slopes), wt_layer_values_slopes keeps them. Without Kept, the slopes' code is
// not compiled (a forward that keeps nothing: a render).
// twin: splat_layers._layer_reads:read_layer
template <bool Kept, class Tex, class Reads, class Floats, class UV, class Surface, class TriW, class Saved>
WT_INLINE wt_lane_colours wt_layer_values_lane(const Tex& tex, const Reads& reads, int j, const Floats& weighted,
                                               const UV& uv0, const UV& uv0_dx, const UV& uv0_dy,
                                               const Surface& surface, int base, int count, const TriW& tri_w, int keep,
                                               const Saved& saved) {
    if constexpr (Kept)
        if (keep && saved.shape[0] > 0 && wt_kept_slopes(reads.params, saved))  // the tiling's slopes too
            return wt_layer_values_slopes_outlined(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count,
                                                   tri_w, keep, saved);
    int layer[3][WT_L];
    wt_read_layers(reads.params, surface, j, base, count, layer);
    const int triplanar = reads.params.projection == WT_PROJECT_TRIPLANAR;  // value += w · sample, else value = sample
    const Tex* texs[3] = {&tex, &tex, &tex};
    const int* per_read[3] = {layer[0], layer[1], layer[2]};
    wt_lane_read_rows at;  // the reads' rows, all that is read
    wt_layer_reads_into(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, at);
    wt_lane_colours value;
    wt_accumulate_reads(texs, reads.smp, per_read, triplanar ? 3 : 1, triplanar, at, value);
    if (keep) wt_keep_layer(reads.params, saved, keep, j, base, count, value);
    return value;
}

// lanes.splat_layers.layer_values_stochastic_lane: wt_layer_values_lane with stochastic sampling (stoch, a
// linear blend: no histogram), as read_layer_stochastic reads a layer: per read k of wt_layer_reads_into
// with a positive weight w, value += w · sample_stochastic (from 0, for the one read of the UV and
// world-XZ projections too: its weight is 1), each read's sample_stochastic over its footprint
// (wt_stochastic_footprint). Kept in saved where keep, as wt_layer_values_lane keeps its value.
// twin: splat_layers._layer_reads:read_layer
template <class Tex, class Reads, class Stoch, class Floats, class UV, class Surface, class TriW, class Saved>
WT_INLINE wt_lane_colours wt_layer_values_stochastic_lane(const Tex& tex, const Reads& reads, const Stoch& stoch, int j,
                                                          const Floats& weighted, const UV& uv0, const UV& uv0_dx,
                                                          const UV& uv0_dy, const Surface& surface, int base, int count,
                                                          const TriW& tri_w, int keep, const Saved& saved) {
    wt_lane_read_rows at;  // the reads' rows, all that is read
    wt_layer_reads_into(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, at);
    int layer[3][WT_L];
    wt_read_layers(reads.params, surface, j, base, count, layer);
    wt_lane_colours value;
    for (int k = 0; k < (reads.params.projection == WT_PROJECT_TRIPLANAR ? 3 : 1); ++k) {
        wt_lane_colours sampled;
        wt_stochastic_footprint(tex, reads.smp, stoch, layer[k], at.data[k], at.data[3 + k], at.data[6 + k],
                                at.data[12 + k], at.data[15 + k], at.data[18 + k], at.data[9 + k], count, sampled);
        for (int l = 0; l < WT_L; ++l) {
            const float w = at.data[9 + k][l];
            if (!(w > 0.0f)) continue;
            for (int c = 0; c < 4; ++c) value.data[l][c] = value.data[l][c] + w * sampled.data[l][c];
        }
    }
    if (keep) wt_keep_layer(reads.params, saved, keep, j, base, count, value);
    return value;
}

// lanes.splat_layers.layer_blend_lane: colour plus layer j (wt_layer_values_lane) weighted by weighted,
// row by row: splat_blend.blend's sum without height blending, a layer at a time.
template <bool Kept, class Tex, class Reads, class Floats, class UV, class Surface, class TriW, class Saved>
WT_INLINE wt_lane_colours wt_layer_blend_lane(const Tex& tex, const Reads& reads, int j, const Floats& weighted,
                                              const UV& uv0, const UV& uv0_dx, const UV& uv0_dy, const Surface& surface,
                                              int base, int count, const TriW& tri_w, int keep, const Saved& saved,
                                              const wt_lane_colours& colour) {
    const bool keeping = keep && saved.shape[0] > 0;
    bool slopes = false;  // kept with the tiling's slopes (wt_layer_values_lane's own read)
    if constexpr (Kept) slopes = keeping && wt_kept_slopes(reads.params, saved);
    if (reads.params.projection != WT_PROJECT_TRIPLANAR && !slopes) {
        // One read a pixel (its weight 1, the layer's value its sample): the read adds weighted ·
        // sample into the colour itself, the same operations in the same order (the colour is
        // never -0, so a pixel not read, which the sum leaves as it is, is the same bits as colour
        // + 0 · 0). The layer's value never goes through a matrix of its own: 10% of a splat's
        // forward on the benchmark's sphere (8 layers, UV projection). Where kept, the read also
        // hands back each pixel's sample (wt_layer_values_lane's value, 0 where not read) to keep.
        int layer[3][WT_L];
        wt_read_layers(reads.params, surface, j, base, count, layer);
        wt_lane_read_rows at;  // read 0's rows, all that is read
        wt_layer_reads_into(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, at);
        __builtin_memcpy(at.data[9], weighted.c, sizeof(at.data[9]));  // read 0's weight (1 where read): the layer's
        wt_lane_colours out = colour;
        if (!keeping) {
            wt_accumulate_footprint(tex, reads.smp, layer[0], at.data[0], at.data[3], at.data[6], at.data[12],
                                    at.data[15], at.data[18], at.data[9], 1, out);
            return out;
        }
        wt_lane_colours value;
        wt_accumulate_footprint(tex, reads.smp, layer[0], at.data[0], at.data[3], at.data[6], at.data[12], at.data[15],
                                at.data[18], at.data[9], 1, out, &value);
        wt_keep_layer(reads.params, saved, keep, j, base, count, value);
        return out;
    }
    const wt_lane_colours value = wt_layer_values_lane<Kept>(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface,
                                                             base, count, tri_w, keep, saved);
    wt_lane_colours out = colour;
    for (int l = 0; l < WT_L; ++l)
        for (int c = 0; c < 4; ++c) out.data[l][c] = out.data[l][c] + weighted.c[l] * value.data[l][c];
    return out;
}

// wt_layer_reads_into compiled once, out of line, for the gradient lanes' adds (a layer's, or every
// layer's with face layers; plain or stochastic), which read only the reads a layer has.
// twin: splat_layers.layer_read
template <class Tex, class Reads, class UV, class Surface, class TriW>
WT_OUTLINE wt_lane_read_rows wt_layer_reads_outlined(const Tex& tex, const Reads& reads, int j, const float* weighted,
                                                     const UV& uv0, const UV& uv0_dx, const UV& uv0_dy,
                                                     const Surface& surface, int base, int count, const TriW& tri_w) {
    wt_lane_read_rows at;
    wt_layer_reads_into(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, at);
    return at;
}

// lanes.splat_layers.scatter_layer_lane: splat_layers.scatter_layer of the gradients g[l] of layer j's
// reads of tex (wt_layer_reads_into) into grad, pixel by pixel and read by read: w · g per projection
// where triplanar, g itself for the one read of the other projections (wt_scatter_lod: where a read
// has several taps, the anisotropic filter's, pixel by pixel, each read's taps a lane at a time).
// twin: splat_layers._layer_reads:scatter_layer
template <class Tex, class Grad, class Reads, class Floats, class UV, class Surface, class TriW>
WT_INLINE void wt_scatter_layer_lane(const Tex& tex, const Grad& grad, const Reads& reads, int j,
                                     const Floats& weighted, const UV& uv0, const UV& uv0_dx, const UV& uv0_dy,
                                     const Surface& surface, int base, int count, const TriW& tri_w,
                                     const wt_lane_colours& g) {
    int layer[WT_L];
    for (int l = 0; l < WT_L; ++l) layer[l] = j;
    const Tex* texs[3] = {&tex, &tex, &tex};
    const Grad* grads[3] = {&grad, &grad, &grad};
    const int triplanar =
        reads.params.projection == WT_PROJECT_TRIPLANAR;  // w · g per projection, else g for the one read
    const int nreads = triplanar ? 3 : 1;
    wt_scatter_lod(texs, grads, reads.smp, nreads, layer,
                   wt_layer_reads_outlined(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w),
                   triplanar, g);
}

// lanes.splat_layers.scatter_layers_lane8: wt_scatter_layer_lane of every colour layer j <
// num_layers of a splat kernel of up to 8 layers in turn, each weighted by w1s[l][j], adding the
// gradient of layer j's colour at lane pixel l, row 8 l + j of `back` (wt_blend_backward_lane8's):
// the lane body's loop over layers, whose gradient rows it built and passed, with the weights and
// the triplanar weights, by value into each layer's call.
// twin: splat_layers._layer_reads:scatter_layer
template <class Tex, class Grad, class Reads, class Weights, class Back, class UV, class Surface, class TriW>
WT_INLINE void wt_scatter_layers_lane8(const Tex& tex, const Grad& grad, const Reads& reads, const Weights& w1s,
                                       const Back& back, const UV& uv0, const UV& uv0_dx, const UV& uv0_dy,
                                       const Surface& surface, int base, int count, const TriW& tri_w) {
    const int num_layers = reads.params.num_layers < 8 ? reads.params.num_layers : 8;
    for (int j = 0; j < num_layers; ++j) {
        wp::vec_t<WT_L, float> weighted;
        wt_lane_colours g;
        for (int l = 0; l < WT_L; ++l) {
            weighted.c[l] = w1s.data[l][j];
            for (int c = 0; c < 4; ++c) g.data[l][c] = back.data[8 * l + j][c];
        }
        wt_scatter_layer_lane(tex, grad, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, g);
    }
}

// Every layer j < num_layers's reads of a lane for the face-layer adds, as read r = 3 j + k of
// wt_layer_reads_into's reads of layer j (weights w1s[l][j]), of the array layers wt_read_layers gives
// it, each adding layer j's gradient g[l · Cap + j] (wt_scatter_face_layers_lane's and
// wt_scatter_face_layers_stochastic_lane's shared set-up).
template <int Cap, class Tex, class Grad> struct wt_face_layer_reads {
    static constexpr int N = 3 * Cap;
    wt_lane_read_rows at[Cap];  // triplanar: every row written
    wt_lane_colours gj[Cap];
    int layer[N][WT_L];
    const Tex* texs[N];
    const Grad* grads[N];
    const wt_lane_colours* gr[N];
    wt_read_rows_n<N> rows;
    int nreads = 0;
    template <class Reads, class Weights, class UV, class Surface, class TriW, class G>
    __attribute__((always_inline)) wt_face_layer_reads(const Tex& tex, const Grad& grad, const Reads& reads,
                                                       const Weights& w1s, const UV& uv0, const UV& uv0_dx,
                                                       const UV& uv0_dy, const Surface& surface, int base, int count,
                                                       const TriW& tri_w, const G& g) {
        const int num_layers = reads.params.num_layers < Cap ? reads.params.num_layers : Cap;
        for (int j = 0; j < num_layers; ++j) {
            float weighted[WT_L];
            for (int l = 0; l < WT_L; ++l) weighted[l] = w1s.data[l][j];
            at[j] = wt_layer_reads_outlined(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w);
            wt_read_layers(reads.params, surface, j, base, count, &layer[3 * j]);
            for (int l = 0; l < WT_L; ++l)
                for (int c = 0; c < 4; ++c) gj[j].data[l][c] = g.data[l * Cap + j][c];
            for (int k = 0; k < 3; ++k) {
                const int r = 3 * j + k;
                texs[r] = &tex, grads[r] = &grad, gr[r] = &gj[j];
                wt_put_rows(rows, r, at[j], k);
            }
        }
        nreads = 3 * num_layers;
    }
};

// lanes.splat_layers.scatter_face_layers_lane: wt_scatter_layer_lane of every layer j < num_layers at
// once, where face layers let layers share array layers (wt_read_layers; projection triplanar,
// plain sampling): layer j's reads weighted by w1s[l][j] (wt_layer_reads_into) add w · g[l · Cap + j]
// pixel by pixel, layer by layer, read by read, the one-pixel body's order, so that two layers'
// reads of one array layer at two pixels add in pixel order as they do there (layer by layer, they
// would not). The reads of every layer go through one wt_scatter_footprint_rows of up to 3 · Cap
// reads, whose taps add through wt_tap_batch in the order they come (a read of one tap is its
// footprint of one): no other copy of the adds for the compiler to build.
// twin: splat_layers._layer_reads:scatter_layer
template <int Cap, class Tex, class Grad, class Reads, class Weights, class UV, class Surface, class TriW, class G>
WT_INLINE void wt_scatter_face_layers_lane(const Tex& tex, const Grad& grad, const Reads& reads, const Weights& w1s,
                                           const UV& uv0, const UV& uv0_dx, const UV& uv0_dy, const Surface& surface,
                                           int base, int count, const TriW& tri_w, const G& g) {
    const wt_face_layer_reads<Cap, Tex, Grad> f(tex, grad, reads, w1s, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w,
                                                g);
    wt_scatter_footprint_rows<3 * Cap>(f.texs, f.grads, reads.smp, f.nreads, f.layer[0], f.rows.u, f.rows.v, f.rows.lod,
                                       f.rows.du, f.rows.dv, f.rows.taps, f.rows.w, 1, f.gr, 1, WT_L);
}

// lanes.splat_layers.scatter_face_layers_stochastic_lane: wt_scatter_face_layers_lane with
// stochastic sampling (stoch, a linear blend): every layer's reads at once, pixel by pixel, layer
// by layer, read by read, each adding w · g[l · Cap + j] through its stochastic taps over its
// footprint (wt_scatter_stochastic_rows, every filter's), as the one-pixel body adds them.
// twin: splat_layers._layer_reads:scatter_layer
template <int Cap, class Tex, class Grad, class Reads, class Stoch, class Weights, class UV, class Surface, class TriW,
          class G>
WT_INLINE void wt_scatter_face_layers_stochastic_lane(const Tex& tex, const Grad& grad, const Reads& reads,
                                                      const Stoch& stoch, const Weights& w1s, const UV& uv0,
                                                      const UV& uv0_dx, const UV& uv0_dy, const Surface& surface,
                                                      int base, int count, const TriW& tri_w, const G& g) {
    const wt_face_layer_reads<Cap, Tex, Grad> f(tex, grad, reads, w1s, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w,
                                                g);
    wt_scatter_stochastic_rows(f.texs, f.grads, reads.smp, stoch, f.nreads, f.layer[0], f.rows, 1, f.gr, 1, WT_L);
}

// lanes.splat_layers.scatter_layer_stochastic_lane: splat_layers.scatter_layer_stochastic of the gradients
// g[l] of layer j's reads of tex (wt_layer_values_stochastic_lane's): each read k with a positive
// weight w adds w · g (for the one read of the UV and world-XZ projections too: w is 1) through its
// stochastic taps into grad, pixel by pixel in read and tap order (wt_scatter_projection_taps_lanes;
// with the anisotropic filter, wt_scatter_stochastic_rows: every footprint tap's taps in order).
// twin: splat_layers._layer_reads:scatter_layer
template <class Tex, class Grad, class Reads, class Stoch, class Floats, class UV, class Surface, class TriW>
WT_INLINE void wt_scatter_layer_stochastic_lane(const Tex& tex, const Grad& grad, const Reads& reads,
                                                const Stoch& stoch, int j, const Floats& weighted, const UV& uv0,
                                                const UV& uv0_dx, const UV& uv0_dy, const Surface& surface, int base,
                                                int count, const TriW& tri_w, const wt_lane_colours& g) {
    const wt_lane_read_rows at =
        wt_layer_reads_outlined(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w);
    const int nreads = reads.params.projection == WT_PROJECT_TRIPLANAR ? 3 : 1;
    struct {
        int c[WT_L];
    } layers;
    for (int l = 0; l < WT_L; ++l) layers.c[l] = j;
    if (reads.smp.filter == WT_ANISOTROPIC) {  // every footprint tap's stochastic taps, in order
        const Tex* texs[3] = {&tex, &tex, &tex};
        const Grad* grads[3] = {&grad, &grad, &grad};
        const wt_lane_colours* gr[1] = {&g};
        wt_scatter_stochastic_rows(texs, grads, reads.smp, stoch, nreads, layers.c, wt_rows_of(at), 1, gr, 0);
        return;
    }
    wt_lane_taps taps[3];  // a read not made: no weight, nothing added
    wt_lane_colours share[3];
    for (int k = 0; k < nreads; ++k) {
        taps[k] = wt_projection_taps_lane(stoch, at, k, count);
        for (int l = 0; l < WT_L; ++l)
            for (int c = 0; c < 4; ++c) share[k].data[l][c] = at.data[9 + k][l] * g.data[l][c];
    }
    wt_scatter_projection_taps_lanes(tex, tex, tex, grad, grad, grad, reads.smp, layers, taps[0], taps[1], taps[2],
                                     share[0], share[1], share[2]);
}
