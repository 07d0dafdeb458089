/* What this machine allows 8-bit texels against float32 ones at random UVs (issue 48's speed bar),
   outside warptex: plain C loops over 2^20 random UVs in [0, 8)² of a 2048² RGBA texture, wrap
   addressing, 2 threads, each loop's fastest of 9 interleaved rounds.

     gcc -O3 -march=native -fopenmp benchmarks/formats_yardstick.c -o /tmp/formats_yardstick -lm
     OMP_NUM_THREADS=2 /tmp/formats_yardstick      # 4 KB pages, as warptex's arrays get
     OMP_NUM_THREADS=2 /tmp/formats_yardstick 1    # 2 MB pages (madvise(MADV_HUGEPAGE))

   - bilinear: the whole lookup, float32 texels against 8-bit ones decoded as code · (1/255) (the two
     agree to float rounding: "max diff");
   - loads only: the four texels' loads of each sample and a sum, nothing else: the pace the memory
     allows each format, whatever the arithmetic.
   Whether 16 MB of 8-bit texels are read from cache depends on the cache this process gets:
   `bench_samplers.py --limit` reports it (docs/performance.md, "The cache a run gets"). */
#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#define W 2048
static inline int wrap(int i) { return i & (W - 1); }

static void *texels(size_t bytes, int huge) {
    size_t rounded = (bytes + (2u << 20) - 1) & ~((size_t)(2u << 20) - 1);
    void *p = aligned_alloc(2u << 20, rounded);
    madvise(p, rounded, huge ? MADV_HUGEPAGE : MADV_NOHUGEPAGE); /* before the first touch */
    memset(p, 0, rounded);
    return p;
}

#define TAPS(u_, v_)                                                                        \
    float u = (u_) - floorf(u_), v = (v_) - floorf(v_);                                     \
    float x = u * W - 0.5f, y = (1 - v) * W - 0.5f, x0 = floorf(x), y0 = floorf(y);         \
    float fx = x - x0, fy = y - y0;                                                         \
    int i0 = wrap((int)x0), i1 = wrap((int)x0 + 1), j0 = wrap((int)y0), j1 = wrap((int)y0 + 1)

static void bilinear_f32(const float *tex, const float *uv, float *out, int n) {
#pragma omp parallel for schedule(static)
    for (int s = 0; s < n; ++s) {
        TAPS(uv[2 * s], uv[2 * s + 1]);
        const float *a = tex + 4 * (j0 * W + i0), *b = tex + 4 * (j0 * W + i1);
        const float *c = tex + 4 * (j1 * W + i0), *d = tex + 4 * (j1 * W + i1);
        for (int k = 0; k < 4; ++k) {
            float top = a[k] * (1 - fx) + b[k] * fx, bottom = c[k] * (1 - fx) + d[k] * fx;
            out[4 * s + k] = top * (1 - fy) + bottom * fy;
        }
    }
}

static void bilinear_u8(const uint32_t *tex, const float *uv, float *out, int n) {
    const float r = 1.0f / 255.0f;
#pragma omp parallel for schedule(static)
    for (int s = 0; s < n; ++s) {
        TAPS(uv[2 * s], uv[2 * s + 1]);
        uint32_t a = tex[j0 * W + i0], b = tex[j0 * W + i1], c = tex[j1 * W + i0], d = tex[j1 * W + i1];
        for (int k = 0; k < 4; ++k) {
            float A = ((a >> (8 * k)) & 255) * r, B = ((b >> (8 * k)) & 255) * r;
            float C = ((c >> (8 * k)) & 255) * r, D = ((d >> (8 * k)) & 255) * r;
            float top = A * (1 - fx) + B * fx, bottom = C * (1 - fx) + D * fx;
            out[4 * s + k] = top * (1 - fy) + bottom * fy;
        }
    }
}

static float loads_f32(const float *tex, const float *uv, int n) {
    float acc = 0;
#pragma omp parallel for reduction(+ : acc) schedule(static)
    for (int s = 0; s < n; ++s) {
        TAPS(uv[2 * s], uv[2 * s + 1]);
        (void)fx, (void)fy;
        acc += tex[4 * (j0 * W + i0)] + tex[4 * (j0 * W + i1)] + tex[4 * (j1 * W + i0)] + tex[4 * (j1 * W + i1)];
    }
    return acc;
}

static float loads_u8(const uint32_t *tex, const float *uv, int n) {
    uint32_t acc = 0;
#pragma omp parallel for reduction(+ : acc) schedule(static)
    for (int s = 0; s < n; ++s) {
        TAPS(uv[2 * s], uv[2 * s + 1]);
        (void)fx, (void)fy;
        acc += tex[j0 * W + i0] + tex[j0 * W + i1] + tex[j1 * W + i0] + tex[j1 * W + i1];
    }
    return (float)acc;
}

int main(int argc, char **argv) {
    const int huge = argc > 1 && atoi(argv[1]), n = 1 << 20;
    float *tf = texels((size_t)W * W * 16, huge);
    uint32_t *tu = texels((size_t)W * W * 4, huge);
    srand(1);
    for (size_t i = 0; i < (size_t)W * W; ++i) {
        uint32_t code = (uint32_t)rand();
        tu[i] = code;
        for (int k = 0; k < 4; ++k) tf[4 * i + k] = ((code >> (8 * k)) & 255) / 255.0f;
    }
    float *uv = malloc(sizeof(float) * 2 * n), *o1 = calloc(4 * (size_t)n, 4), *o2 = calloc(4 * (size_t)n, 4);
    for (int i = 0; i < 2 * n; ++i) uv[i] = 8.0f * rand() / (float)RAND_MAX;
    double best[4] = {1e9, 1e9, 1e9, 1e9};
    volatile float sink = 0;
    for (int round = 0; round < 9; ++round) {
        double t = omp_get_wtime();
        bilinear_f32(tf, uv, o1, n);
        best[0] = fmin(best[0], omp_get_wtime() - t), t = omp_get_wtime();
        bilinear_u8(tu, uv, o2, n);
        best[1] = fmin(best[1], omp_get_wtime() - t), t = omp_get_wtime();
        sink += loads_f32(tf, uv, n);
        best[2] = fmin(best[2], omp_get_wtime() - t), t = omp_get_wtime();
        sink += loads_u8(tu, uv, n);
        best[3] = fmin(best[3], omp_get_wtime() - t);
    }
    double diff = 0;
    for (size_t i = 0; i < 4 * (size_t)n; ++i) diff = fmax(diff, fabs(o1[i] - o2[i]));
    printf("%s pages, %d threads: bilinear float32 %.2f ms, 8-bit %.2f ms (float32 time / 8-bit time %.2f); "
           "loads only float32 %.2f ms, 8-bit %.2f ms (%.2f); max diff %.1e\n",
           huge ? "2 MB" : "4 KB", omp_get_max_threads(), best[0] * 1e3, best[1] * 1e3, best[0] / best[1], best[2] * 1e3,
           best[3] * 1e3, best[2] / best[3], diff);
    return 0;
}
