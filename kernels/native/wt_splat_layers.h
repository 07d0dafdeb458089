// Splat layers for a lane of pixels: what each lane pixel reads of a layer (splat_layers.layer_read
// restated: its UV, footprint and weight of each read, 16 pixels at a time), the layer's texels read
// over those footprints, and their gradients added into the layer's texels.
#pragma once
#include "wt_config.h"
#include "wt_core.h"
#include "wt_footprint.h"
#include "wt_projection.h"
#include "wt_scatter.h"

// What each lane pixel l (pixel base + l of the launch) with weighted[l] > 0 reads of layer j of tex
// (no face layers): splat_layers.layer_read's UV, footprint and weight of each read k at the pixel's
// point (its UV0 and their derivatives, or its surface; tri_w: its triplanar weights), as a
// lane_reads matrix (all 0 for the other pixels), 16 pixels at a time.
// twin: splat_layers.layer_read
template <class Tex, class Reads, class UV, class Surface, class TriW>
WT_INLINE wt_lane_reads wt_layer_reads(const Tex& tex, const Reads& reads, int j, const float* weighted, const UV& uv0,
                                       const UV& uv0_dx, const UV& uv0_dy, const Surface& surface, int base, int count,
                                       const TriW& tri_w) {
    const auto& params = reads.params;
    const float t = wt_float(params.tiling, wp::min(j, params.tiling.shape[0] - 1));  // layer_tiling
    wt_vf w;
    __builtin_memcpy(&w, weighted, sizeof(w));
    const wt_vi read = w > 0.0f;
    const wt_vf zero = 0.0f, one = 1.0f;
    wt_lane_reads out;
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
    return out;
}

// lanes.splat.layer_values_lane: row l, layer j of tex read at lane pixel l over the footprints of
// wt_layer_reads' reads as read_layer reads them (per projection value += w · sample where
// triplanar, value = sample for the one read of the other projections; 0 where weighted[l] is not
// positive). Where keep and saved is not empty, also stored in saved's row base + l, columns 4 j ..
// 4 j + 3 (SplatPixels.saved).
// twin: splat_layers._layer_reads:read_layer
template <class Tex, class Reads, class Floats, class UV, class Surface, class TriW, class Saved>
WT_INLINE wt_lane_colours wt_layer_values_lane(const Tex& tex, const Reads& reads, int j, const Floats& weighted,
                                               const UV& uv0, const UV& uv0_dx, const UV& uv0_dy,
                                               const Surface& surface, int base, int count, const TriW& tri_w, int keep,
                                               const Saved& saved) {
    int layer[WT_L];
    for (int l = 0; l < WT_L; ++l) layer[l] = j;
    const Tex* texs[3] = {&tex, &tex, &tex};
    const int triplanar = reads.params.projection == WT_PROJECT_TRIPLANAR;  // value += w · sample, else value = sample
    wt_lane_colours value;
    wt_accumulate_reads(texs, reads.smp, layer, triplanar ? 3 : 1, triplanar,
                        wt_layer_reads(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w),
                        value);
    if (keep && saved.shape[0] > 0) {  // SplatPixels.saved: row base + l, the layer's 4 floats
        for (int l = 0; l < count; ++l) {
            float* row = (float*)((char*)saved.data + (long long)(base + l) * saved.strides[0]);
            for (int c = 0; c < 4; ++c)
                *(float*)((char*)row + (long long)(4 * j + c) * saved.strides[1]) = value.data[l][c];
        }
    }
    return value;
}

// lanes.splat.layer_blend_lane: colour plus layer j (wt_layer_values_lane) weighted by weighted,
// row by row: splat_blend.blend's sum without height blending, a layer at a time.
template <class Tex, class Reads, class Floats, class UV, class Surface, class TriW, class Saved>
WT_INLINE wt_lane_colours wt_layer_blend_lane(const Tex& tex, const Reads& reads, int j, const Floats& weighted,
                                              const UV& uv0, const UV& uv0_dx, const UV& uv0_dy, const Surface& surface,
                                              int base, int count, const TriW& tri_w, int keep, const Saved& saved,
                                              const wt_lane_colours& colour) {
    const wt_lane_colours value =
        wt_layer_values_lane(tex, reads, j, weighted, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w, keep, saved);
    wt_lane_colours out = colour;
    for (int l = 0; l < WT_L; ++l)
        for (int c = 0; c < 4; ++c) out.data[l][c] = out.data[l][c] + weighted.c[l] * value.data[l][c];
    return out;
}

// lanes.splat.scatter_layer_lane: splat_layers.scatter_layer of the gradients g[l] of layer j's
// reads of tex (wt_layer_reads) into grad, pixel by pixel and read by read: w · g per projection
// where triplanar, g itself for the one read of the other projections.
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
    wt_scatter_lod(texs, grads, reads.smp, triplanar ? 3 : 1, layer,
                   wt_layer_reads(tex, reads, j, weighted.c, uv0, uv0_dx, uv0_dy, surface, base, count, tri_w),
                   triplanar, g);
}
