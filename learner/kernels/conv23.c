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
#define VL 16  /* lanes of a vector: a zmm */
#define OCB 8  /* output channels a forward pass holds (x NV accumulators) */
#define OCBW 4 /* output channels a weight-gradient pass holds (x 4 taps) */
#define ICB 4  /* input channels an input-gradient pass holds (x NV) */
#else
#define VL 8 /* a ymm: 16 registers, so fewer channels a pass */
#define OCB 2
#define OCBW 2
#define ICB 2
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

/* ---- the second layer ----
 * Vectorised over a row's 32 output pixels (VL lanes a vector, NV vectors a row): its 4
 * input channels would fill few lanes, and its 8 output channels too few for the input
 * gradient. Planes are channel-major, zero padded, rows of PW floats. */

#define PW 40 /* padded row: the pixels at 1 .. 32 (input) or 2 .. 33 (gradient) */

typedef float vl __attribute__((vector_size(VL * 4)));
typedef int32_t il __attribute__((vector_size(VL * 4)));
#define NV (32 / VL)

static inline vl loadu(const float *p) {
    vl v;
    memcpy(&v, p, sizeof(v));
    return v;
}

/* p[c][y + 1][x + 1]: one image's input; the padding (1 before, 2 after) is zeroed
 * once a call, by the caller, and never written */
static void plane2(const value_t *in, float p[4][35][PW]) {
    for (int by = 0; by < 16; by++)
        for (int bx = 0; bx < 16; bx++)
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 4; c++)
                    p[c][2 * by + (r >> 1) + 1][2 * bx + (r & 1) + 1] =
                        load(in[((by * 16 + bx) * 4 + r) * 4 + c]);
}

/* torch's (8, 4, 4, 4), rounded as the precision rounds it */
static void weights2(const float *weight, float w[8][4][4][4]) {
    for (int i = 0; i < 512; i++) (&w[0][0][0][0])[i] = weight_value(weight[i]);
}

/* the max-pool of two conv rows (32 pixels, one channel) into 16 outputs: value, code */
static void pool_rows(const float r0[32], const float r1[32], float best[16], int where[16]) {
    for (int px = 0; px < 16; px++) {
        float cand[4] = {r0[2 * px], r0[2 * px + 1], r1[2 * px], r1[2 * px + 1]};
        float m = cand[0];
        int k = 0;
        for (int i = 1; i < 4; i++)
            if (cand[i] > m) m = cand[i], k = i;
        best[px] = m;
        where[px] = k;
    }
}

void SUFFIX(conv2_forward)(const value_t *in, int64_t batch, const float *weight,
                           const float *bias, value_t *out, uint8_t *code) {
    static __thread float p[4][35][PW] __attribute__((aligned(64)));
    float w[8][4][4][4];
    float rows[2][8][32] __attribute__((aligned(64)));
    weights2(weight, w);
    memset(p, 0, sizeof(float) * 4 * 35 * PW);
    for (int64_t b = 0; b < batch; b++) {
        plane2(in + b * 4096, p);
        for (int y = 0; y < 32; y++) {
            for (int o0 = 0; o0 < 8; o0 += OCB) {
                vl acc[OCB][NV];
                for (int o = 0; o < OCB; o++)
                    for (int v = 0; v < NV; v++) acc[o][v] = (vl){0} + bias[o0 + o];
                for (int c = 0; c < 4; c++)
                    for (int ky = 0; ky < 4; ky++)
                        for (int kx = 0; kx < 4; kx++) {
                            vl x[NV];
                            for (int v = 0; v < NV; v++) x[v] = loadu(&p[c][y + ky][VL * v + kx]);
                            for (int o = 0; o < OCB; o++) {
                                float wv = w[o0 + o][c][ky][kx];
                                for (int v = 0; v < NV; v++) acc[o][v] += x[v] * wv;
                            }
                        }
                for (int o = 0; o < OCB; o++)
                    for (int v = 0; v < NV; v++) memcpy(&rows[y & 1][o0 + o][VL * v], &acc[o][v], sizeof(vl));
            }
            if (!(y & 1)) continue;
            int py = y >> 1;
            for (int o = 0; o < 8; o++) {
                float best[16];
                int where[16];
                pool_rows(rows[0][o], rows[1][o], best, where);
                for (int px = 0; px < 16; px++) {
                    int64_t at = ((b * 16 + py) * 16 + px) * 8 + o;
                    int on = best[px] > 0;
                    out[at] = store(on ? best[px] : 0.0f);
                    if (code) code[at] = (uint8_t)(on ? where[px] : 255);
                }
            }
        }
    }
}

void SUFFIX(conv2_backward)(const value_t *in, int64_t batch, const value_t *grad_out,
                            const uint8_t *code, const float *weight, float *grad_weight,
                            float *grad_bias, value_t *grad_in) {
    static __thread float p[4][35][PW] __attribute__((aligned(64)));
    /* g[o][y + 2][x + 2]: the convolution's output gradient, zero padded (2 before, 1 after) */
    static __thread float g[8][35][PW] __attribute__((aligned(64)));
    static __thread vl total[8][4][4][4];
    float w[8][4][4][4];
    vl bsum[8];
    weights2(weight, w);
    memset(total, 0, sizeof(total));
    memset(g, 0, sizeof(g));
    memset(p, 0, sizeof(float) * 4 * 35 * PW);
    memset(bsum, 0, sizeof(bsum));
    for (int64_t b = 0; b < batch; b++) {
        plane2(in + b * 4096, p);
        for (int o = 0; o < 8; o++)
            for (int py = 0; py < 16; py++) {
                const uint8_t *k = code + (b * 16 + py) * 128 + o;
                const value_t *from = grad_out + (b * 16 + py) * 128 + o;
                float *r0 = &g[o][2 * py + 2][2], *r1 = &g[o][2 * py + 3][2];
                for (int px = 0; px < 16; px++) {
                    float gv = load(from[8 * px]);
                    int kk = k[8 * px];
                    r0[2 * px] = kk == 0 ? gv : 0.0f;
                    r0[2 * px + 1] = kk == 1 ? gv : 0.0f;
                    r1[2 * px] = kk == 2 ? gv : 0.0f;
                    r1[2 * px + 1] = kk == 3 ? gv : 0.0f;
                }
            }
        for (int o = 0; o < 8; o++) {
            vl s = {0};
            for (int y = 0; y < 32; y++)
                for (int v = 0; v < NV; v++) s += loadu(&g[o][y + 2][VL * v + 2]);
            bsum[o] += s;
        }
        /* the weight's: sum over pixels of input (shifted by the tap) times gradient */
        for (int c = 0; c < 4; c++)
            for (int ky = 0; ky < 4; ky++)
                for (int o0 = 0; o0 < 8; o0 += OCBW) {
                    vl acc[OCBW][4];
                    memset(acc, 0, sizeof(acc));
                    for (int y = 0; y < 32; y++)
                        for (int v = 0; v < NV; v++) {
                            vl x[4], gv[OCBW];
                            for (int kx = 0; kx < 4; kx++) x[kx] = loadu(&p[c][y + ky][VL * v + kx]);
                            for (int o = 0; o < OCBW; o++) gv[o] = loadu(&g[o0 + o][y + 2][VL * v + 2]);
                            for (int o = 0; o < OCBW; o++)
                                for (int kx = 0; kx < 4; kx++) acc[o][kx] += x[kx] * gv[o];
                        }
                    for (int o = 0; o < OCBW; o++)
                        for (int kx = 0; kx < 4; kx++) total[o0 + o][c][ky][kx] += acc[o][kx];
                }
        /* the input's: input pixel (y, x) reaches output (y + 1 - ky, x + 1 - kx) */
        value_t *gi = grad_in + b * 4096;
        for (int y = 0; y < 32; y++)
            for (int c0 = 0; c0 < 4; c0 += ICB) {
                vl acc[ICB][NV];
                memset(acc, 0, sizeof(acc));
                for (int o = 0; o < 8; o++)
                    for (int ky = 0; ky < 4; ky++)
                        for (int kx = 0; kx < 4; kx++) {
                            vl gv[NV];
                            for (int v = 0; v < NV; v++) gv[v] = loadu(&g[o][y + 3 - ky][VL * v + 3 - kx]);
                            for (int c = 0; c < ICB; c++) {
                                float wv = w[o][c0 + c][ky][kx];
                                for (int v = 0; v < NV; v++) acc[c][v] += gv[v] * wv;
                            }
                        }
                float row[ICB][32];
                memcpy(row, acc, sizeof(row));
                for (int x = 0; x < 32; x++) {
                    value_t *to = gi + (((y >> 1) * 16 + (x >> 1)) * 4 + (y & 1) * 2 + (x & 1)) * 4;
                    for (int c = 0; c < ICB; c++) to[c0 + c] = store(row[c][x]);
                }
            }
    }
    for (int o = 0; o < 8; o++) {
        float s = 0;
        for (int i = 0; i < VL; i++) s += bsum[o][i];
        grad_bias[o] = s;
        for (int c = 0; c < 4; c++)
            for (int ky = 0; ky < 4; ky++)
                for (int kx = 0; kx < 4; kx++) {
                    float t = 0;
                    for (int i = 0; i < VL; i++) t += total[o][c][ky][kx][i];
                    grad_weight[((o * 4 + c) * 4 + ky) * 4 + kx] = t;
                }
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
