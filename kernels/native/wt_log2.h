// log2 of a float on the CPU, the same bits whether a kernel computes it for one pixel or the CPU
// lanes for 16 at once: glibc's log2f is a call per value, which no vector code can match bit for
// bit. Its algorithm, with a table of our own and no fused multiply-adds: x = 2^k z, z in [0.699,
// 1.398) (the offset keeps z's bits exact), z's subinterval i of 16 (its centre c, or 1 where z can
// be 1), log2 x = k + log2 c + log2(1 + r), r = z / c - 1, |r| < 0.024, the last by its series to
// r^5 in float64 (error under 4e-11): within one ulp of log2(x), the nearest float for 99.97% of
// [0.5, 2) and 99.998% of all floats (glibc's log2f: 99.0% and 99.98%; tests/test_sampling.py),
// exact at powers of two. For positive normal floats, which every LOD's argument is; NaN for any
// other. Branch-free, so a loop over lanes vectorises; no contraction, so a vector and a scalar
// copy agree. Its throughput in a kernel equals log2f's, its latency is higher.
#pragma once
#include "wt_config.h"

// twin: footprint.lod_log2
WT_INLINE float wt_log2(float x) {
    // Subinterval i holds the z whose bits are 0x3f330000 + (i << 19) .. + ((i + 1) << 19); c its
    // centre (1 for i = 9, which holds 1), invc = 1 / c and logc = -log2(invc), both rounded to
    // float64.
    static const double invc[16] = {
        1.3989071038251366, 1.3403141361256545, 1.2864321608040201, 1.2367149758454106, 1.1906976744186046,
        1.147982062780269,  1.1082251082251082, 1.0711297071129706, 1.0364372469635628, 1.0,
        0.9481481481481482, 0.8951048951048951, 0.847682119205298,  0.8050314465408805, 0.7664670658682635,
        0.7314285714285714};
    static const double logc[16] = {
        -0.4843001617159575,  -0.4225711719642514,  -0.3633753794563512,  -0.3065130425006747,  -0.2518071504105397,
        -0.19910010007969525, -0.14825095858394247, -0.09913319201925132, -0.05163276841532236, 0.0,
        0.07681559705083084,  0.1598713367783894,   0.2384047393250789,   0.3128829552843553,   0.38370429247405213,
        0.4512111118323288};
    unsigned int iy;
    __builtin_memcpy(&iy, &x, 4);
    const unsigned int tmp = iy - 0x3f330000u;
    const int i = (int)((tmp >> 19) & 15u);
    const unsigned int iz = iy - (tmp & 0xff800000u);
    const int k = (int)tmp >> 23;
    float z;
    __builtin_memcpy(&z, &iz, 4);
    const double r = (double)z * invc[i] - 1.0;
    const double r2 = r * r;
    // log2(1 + r) = r (c1 + c2 r) + r^3 (c3 + c4 r) + r^5 c5, c_n = (-1)^(n+1) / (n ln 2)
    const double c1 = 1.4426950408889634, c2 = -0.7213475204444817, c3 = 0.48089834696298783;
    const double c4 = -0.36067376022224085, c5 = 0.28853900817779266;
    const double p = (r * (c1 + c2 * r) + (r2 * r) * (c3 + c4 * r)) + (r2 * r2 * r) * c5;
    const float result = (float)((logc[i] + (double)k) + p);
    return iy - 0x00800000u < 0x7f000000u ? result : __builtin_nanf("");  // a positive normal float, or NaN
}
