/* The paper's second and third layers, each a "same" convolution, its ReLU and 2x2
 * max-pool, forward and backward (the weight's, the bias's and the input's gradients),
 * for 64x64 frames:
 *   second: 4 -> 8 channels, 4x4 filters on 32x32 (pads 1 before, 2 after);
 *   third:  8 -> 16 channels, 2x2 filters on 16x16 (pads 0 before, 1 after).
 *
 * One source, built once per instruction set with explicit flags (the Makefile): with
 * -DCONV_BF16 and AVX-512 the activations and gradients it reads and writes are bfloat16
 * bits and the weights are rounded to bfloat16 first, as the bfloat16 convolutions round
 * them; without, float32 (AVX2). Products of bfloat16 values are exact in float32, so
 * the float32 FMA here gives what bfloat16 dot products give, up to the order of the
 * float32 sums. Every sum is float32; each image's weight-gradient sums are added to the
 * batch's apart (short sums: the float32 error stays near the gradient's own).
 *
 * Vectorised over output channels (8 and 16 lanes, GCC vector extensions the flags map to
 * ymm or zmm registers), each image's input zero padded in float32 once, in L1.
 * Layouts (what the neighbouring layers read and write without a copy):
 *   second's input: the first kernel's output (B, 16, 16, 2, 2, 4), space-to-depth;
 *   second's output, third's input: channels-last (B, 16, 16, 8);
 *   third's output: (B, 16, 8, 8), the dense layer's (C, H, W) order.
 * `code` keeps, per output, the window position the max-pool took (0-3, row-major; the
 * first maximal one, as max_pool2d) or 255 where the ReLU is off; the max-pool compares
 * the convolution's outputs with their bias, as the plain network's pool does. */
#include <stdint.h>
#include <string.h>

#include "conv23.h"

typedef float v8 __attribute__((vector_size(32)));
typedef int32_t i8 __attribute__((vector_size(32)));
typedef float v16 __attribute__((vector_size(64)));
typedef int32_t i16 __attribute__((vector_size(64)));

#ifdef CONV_BF16
typedef uint16_t value_t;
#define SUFFIX(name) name##_bf16
static inline float load(value_t v) {
    uint32_t u = (uint32_t)v << 16;
    float f;
    memcpy(&f, &u, 4);
    return f;
}
static inline value_t store(float f) { /* round to nearest even, as torch's .bfloat16() */
    uint32_t u;
    memcpy(&u, &f, 4);
    if ((u & 0x7fffffffu) > 0x7f800000u) return (value_t)((u >> 16) | 0x40);
    u += 0x7fffu + ((u >> 16) & 1u);
    return (value_t)(u >> 16);
}
static inline float weight_value(float w) { return load(store(w)); }
#else
typedef float value_t;
#define SUFFIX(name) name##_fp32
static inline float load(value_t v) { return v; }
static inline value_t store(float f) { return f; }
static inline float weight_value(float w) { return w; }
#endif

static inline float sum8(v8 v) {
    return ((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7]));
}

static inline float sum16(v16 v) {
    v8 lo = {v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]};
    v8 hi = {v[8], v[9], v[10], v[11], v[12], v[13], v[14], v[15]};
    return sum8(lo + hi);
}

/* ---- the second layer ---- */

/* p[y + 1][x + 1][c]: one image's input, zero padded (1 before, 2 after) */
static void plane2(const value_t *in, float p[35][35][4]) {
    memset(p, 0, sizeof(float) * 35 * 35 * 4);
    for (int by = 0; by < 16; by++)
        for (int bx = 0; bx < 16; bx++)
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 4; c++)
                    p[2 * by + (r >> 1) + 1][2 * bx + (r & 1) + 1][c] =
                        load(in[((by * 16 + bx) * 4 + r) * 4 + c]);
}

/* w[ky][kx][c] over output channels, from torch's (8, 4, 4, 4) */
static void weights2(const float *weight, v8 w[4][4][4]) {
    for (int o = 0; o < 8; o++)
        for (int c = 0; c < 4; c++)
            for (int ky = 0; ky < 4; ky++)
                for (int kx = 0; kx < 4; kx++)
                    w[ky][kx][c][o] = weight_value(weight[((o * 4 + c) * 4 + ky) * 4 + kx]);
}

void SUFFIX(conv2_forward)(const value_t *in, int64_t batch, const float *weight,
                           const float *bias, value_t *out, uint8_t *code) {
    static __thread float p[35][35][4] __attribute__((aligned(64)));
    v8 w[4][4][4], bv;
    weights2(weight, w);
    for (int o = 0; o < 8; o++) bv[o] = bias[o];
    for (int64_t b = 0; b < batch; b++) {
        plane2(in + b * 4096, p);
        for (int py = 0; py < 16; py++) {
            v8 rows[2][32];
            for (int dy = 0; dy < 2; dy++)
                for (int x = 0; x < 32; x++) {
                    v8 acc = {0};
                    for (int ky = 0; ky < 4; ky++)
                        for (int kx = 0; kx < 4; kx++)
                            for (int c = 0; c < 4; c++)
                                acc += p[2 * py + dy + ky][x + kx][c] * w[ky][kx][c];
                    rows[dy][x] = acc + bv;
                }
            for (int px = 0; px < 16; px++) {
                v8 best = rows[0][2 * px];
                i8 where = {0};
                for (int i = 1; i < 4; i++) {
                    v8 cand = rows[i >> 1][2 * px + (i & 1)];
                    i8 gt = cand > best;
                    best = (v8)(((i8)cand & gt) | ((i8)best & ~gt));
                    where = (where & ~gt) | (gt & i);
                }
                i8 on = best > 0;
                int64_t at = ((b * 16 + py) * 16 + px) * 8;
                for (int o = 0; o < 8; o++) {
                    out[at + o] = store(on[o] ? best[o] : 0.0f);
                    if (code) code[at + o] = (uint8_t)(on[o] ? where[o] : 255);
                }
            }
        }
    }
}

void SUFFIX(conv2_backward)(const value_t *in, int64_t batch, const value_t *grad_out,
                            const uint8_t *code, const float *weight, float *grad_weight,
                            float *grad_bias, value_t *grad_in) {
    static __thread float p[35][35][4] __attribute__((aligned(64)));
    /* g[y + 2][x + 2]: the convolution's output gradient, zero padded (2 before, 1 after) */
    static __thread v8 g[35][35];
    v8 w[4][4][4], total[4][4][4], bsum = {0};
    weights2(weight, w);
    memset(total, 0, sizeof(total));
    for (int64_t b = 0; b < batch; b++) {
        plane2(in + b * 4096, p);
        memset(g, 0, sizeof(g));
        for (int py = 0; py < 16; py++)
            for (int px = 0; px < 16; px++) {
                int64_t at = ((b * 16 + py) * 16 + px) * 8;
                for (int o = 0; o < 8; o++) {
                    uint8_t k = code[at + o];
                    if (k == 255) continue;
                    g[2 * py + (k >> 1) + 2][2 * px + (k & 1) + 2][o] = load(grad_out[at + o]);
                }
            }
        v8 image_bsum = {0};
        for (int y = 0; y < 32; y++)
            for (int x = 0; x < 32; x++) image_bsum += g[y + 2][x + 2];
        bsum += image_bsum;
        for (int ky = 0; ky < 4; ky++)
            for (int kx = 0; kx < 4; kx++) {
                v8 a0 = {0}, a1 = {0}, a2 = {0}, a3 = {0};
                for (int y = 0; y < 32; y++)
                    for (int x = 0; x < 32; x++) {
                        v8 gv = g[y + 2][x + 2];
                        const float *q = p[y + ky][x + kx];
                        a0 += q[0] * gv;
                        a1 += q[1] * gv;
                        a2 += q[2] * gv;
                        a3 += q[3] * gv;
                    }
                total[ky][kx][0] += a0;
                total[ky][kx][1] += a1;
                total[ky][kx][2] += a2;
                total[ky][kx][3] += a3;
            }
        /* input pixel (y, x) reaches output (y + 1 - ky, x + 1 - kx) through tap (ky, kx) */
        value_t *gi = grad_in + b * 4096;
        for (int y = 0; y < 32; y++)
            for (int x = 0; x < 32; x++) {
                v8 a[4] = {{0}, {0}, {0}, {0}};
                for (int ky = 0; ky < 4; ky++)
                    for (int kx = 0; kx < 4; kx++) {
                        v8 gv = g[y + 3 - ky][x + 3 - kx];
                        for (int c = 0; c < 4; c++) a[c] += gv * w[ky][kx][c];
                    }
                value_t *to = gi + (((y >> 1) * 16 + (x >> 1)) * 4 + (y & 1) * 2 + (x & 1)) * 4;
                for (int c = 0; c < 4; c++) to[c] = store(sum8(a[c]));
            }
    }
    for (int o = 0; o < 8; o++) {
        grad_bias[o] = bsum[o];
        for (int c = 0; c < 4; c++)
            for (int ky = 0; ky < 4; ky++)
                for (int kx = 0; kx < 4; kx++)
                    grad_weight[((o * 4 + c) * 4 + ky) * 4 + kx] = total[ky][kx][c][o];
    }
}

/* ---- the third layer ---- */

/* p[y][x][c]: one image's input, zero padded (1 after) */
static void plane3(const value_t *in, float p[17][17][8]) {
    memset(p, 0, sizeof(float) * 17 * 17 * 8);
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 16; x++)
            for (int c = 0; c < 8; c++) p[y][x][c] = load(in[(y * 16 + x) * 8 + c]);
}

/* w[ky][kx][c] over output channels, from torch's (16, 8, 2, 2) */
static void weights3(const float *weight, v16 w[2][2][8]) {
    for (int o = 0; o < 16; o++)
        for (int c = 0; c < 8; c++)
            for (int ky = 0; ky < 2; ky++)
                for (int kx = 0; kx < 2; kx++)
                    w[ky][kx][c][o] = weight_value(weight[((o * 8 + c) * 2 + ky) * 2 + kx]);
}

void SUFFIX(conv3_forward)(const value_t *in, int64_t batch, const float *weight,
                           const float *bias, value_t *out, uint8_t *code) {
    static __thread float p[17][17][8] __attribute__((aligned(64)));
    v16 w[2][2][8], bv;
    weights3(weight, w);
    for (int o = 0; o < 16; o++) bv[o] = bias[o];
    for (int64_t b = 0; b < batch; b++) {
        plane3(in + b * 2048, p);
        for (int py = 0; py < 8; py++) {
            v16 rows[2][16];
            for (int dy = 0; dy < 2; dy++)
                for (int x = 0; x < 16; x++) {
                    v16 acc = {0};
                    for (int ky = 0; ky < 2; ky++)
                        for (int kx = 0; kx < 2; kx++)
                            for (int c = 0; c < 8; c++)
                                acc += p[2 * py + dy + ky][x + kx][c] * w[ky][kx][c];
                    rows[dy][x] = acc + bv;
                }
            for (int px = 0; px < 8; px++) {
                v16 best = rows[0][2 * px];
                i16 where = {0};
                for (int i = 1; i < 4; i++) {
                    v16 cand = rows[i >> 1][2 * px + (i & 1)];
                    i16 gt = cand > best;
                    best = (v16)(((i16)cand & gt) | ((i16)best & ~gt));
                    where = (where & ~gt) | (gt & i);
                }
                i16 on = best > 0;
                int64_t at = ((b * 8 + py) * 8 + px) * 16;
                for (int o = 0; o < 16; o++) {
                    out[((b * 16 + o) * 8 + py) * 8 + px] = store(on[o] ? best[o] : 0.0f);
                    if (code) code[at + o] = (uint8_t)(on[o] ? where[o] : 255);
                }
            }
        }
    }
}

void SUFFIX(conv3_backward)(const value_t *in, int64_t batch, const value_t *grad_out,
                            const uint8_t *code, const float *weight, float *grad_weight,
                            float *grad_bias, value_t *grad_in) {
    static __thread float p[17][17][8] __attribute__((aligned(64)));
    /* g[y + 1][x + 1]: the convolution's output gradient, zero padded (1 before) */
    static __thread v16 g[17][17];
    v16 w[2][2][8], total[2][2][8], bsum = {0};
    weights3(weight, w);
    memset(total, 0, sizeof(total));
    for (int64_t b = 0; b < batch; b++) {
        plane3(in + b * 2048, p);
        memset(g, 0, sizeof(g));
        for (int py = 0; py < 8; py++)
            for (int px = 0; px < 8; px++) {
                int64_t at = ((b * 8 + py) * 8 + px) * 16;
                for (int o = 0; o < 16; o++) {
                    uint8_t k = code[at + o];
                    if (k == 255) continue;
                    g[2 * py + (k >> 1) + 1][2 * px + (k & 1) + 1][o] =
                        load(grad_out[((b * 16 + o) * 8 + py) * 8 + px]);
                }
            }
        v16 image_bsum = {0};
        for (int y = 0; y < 16; y++)
            for (int x = 0; x < 16; x++) image_bsum += g[y + 1][x + 1];
        bsum += image_bsum;
        for (int ky = 0; ky < 2; ky++)
            for (int kx = 0; kx < 2; kx++) {
                v16 a[8] = {{0}};
                for (int y = 0; y < 16; y++)
                    for (int x = 0; x < 16; x++) {
                        v16 gv = g[y + 1][x + 1];
                        const float *q = p[y + ky][x + kx];
                        for (int c = 0; c < 8; c++) a[c] += q[c] * gv;
                    }
                for (int c = 0; c < 8; c++) total[ky][kx][c] += a[c];
            }
        /* input pixel (y, x) reaches output (y - ky, x - kx) through tap (ky, kx) */
        value_t *gi = grad_in + b * 2048;
        for (int y = 0; y < 16; y++)
            for (int x = 0; x < 16; x++) {
                v16 a[8] = {{0}};
                for (int ky = 0; ky < 2; ky++)
                    for (int kx = 0; kx < 2; kx++) {
                        v16 gv = g[y + 1 - ky][x + 1 - kx];
                        for (int c = 0; c < 8; c++) a[c] += gv * w[ky][kx][c];
                    }
                for (int c = 0; c < 8; c++) gi[(y * 16 + x) * 8 + c] = store(sum16(a[c]));
            }
    }
    for (int o = 0; o < 16; o++) {
        grad_bias[o] = bsum[o];
        for (int c = 0; c < 8; c++)
            for (int ky = 0; ky < 2; ky++)
                for (int kx = 0; kx < 2; kx++)
                    grad_weight[((o * 8 + c) * 2 + ky) * 2 + kx] = total[ky][kx][c][o];
    }
}
