/* The paper's first layer (8x8 "same" convolution, 3 -> 4 channels on 64x64, ReLU, 2x2
 * max-pool) with bfloat16 dot products (AVX-512 BF16), forward and the weight's and bias's
 * gradients, on packed uint8 frames (64x64x3 stored as 32x32x12, channels (ry, rx, c)).
 *
 * Pixel values 0..255 are exact in bfloat16 (integers up to 256 fit its 8 significant
 * bits), so the frames go in as integers and the scale 1/255 is applied once to each
 * float32 sum: the weights' rounding to bfloat16 (and, in the backward, the output
 * gradient's) is the only one before float32 accumulation.
 * Vectorised over output pixels: a lane of vdpbf16ps holds two horizontally adjacent
 * taps (forward) or two adjacent pixels (weight gradient). */
#include <immintrin.h>
#include <stdint.h>
#include <string.h>

#include "conv1.h"

#define W 80 /* padded row: 3 zeros, 64 pixels, 13 zeros (vector loads read past 71) */
#define R 71 /* padded rows: 3 zeros, 64 rows, 4 zeros */

/* plane[c][r][x]: the frame's channel c, zero padded, as bfloat16 bits. A packed row
 * (384 bytes) holds image rows 2 py and 2 py + 1; 16 pixels of one of them lie in 96
 * bytes, which one byte permutation (VBMI) sorts by channel, 16 bytes each. */
static void unpack(const uint8_t *frame, uint16_t plane[3][R + 1][W]) {
    memset(plane, 0, sizeof(uint16_t) * 3 * (R + 1) * W);
    uint8_t index[2][64];
    for (int ry = 0; ry < 2; ry++)
        for (int i = 0; i < 64; i++) {
            int c = i >> 4, j = i & 15;
            index[ry][i] = (uint8_t)(c < 3 ? 12 * (j >> 1) + 3 * (j & 1) + 6 * ry + c : 0);
        }
    const __m512i sort[2] = {_mm512_loadu_si512(index[0]), _mm512_loadu_si512(index[1])};
    for (int py = 0; py < 32; py++) {
        const uint8_t *row = frame + py * 384;
        for (int g = 0; g < 4; g++) {
            __m512i lo = _mm512_loadu_si512(row + 96 * g);
            /* the last group's window ends 32 bytes past the row: not read */
            __mmask64 inside = g == 3 ? 0xffffffffull : ~0ull;
            __m512i hi = _mm512_maskz_loadu_epi8(inside, row + 96 * g + 64);
            for (int ry = 0; ry < 2; ry++) {
                __m512i bytes = _mm512_permutex2var_epi8(lo, sort[ry], hi);
                for (int c = 0; c < 3; c++) {
                    __m128i v = _mm512_extracti32x4_epi32(bytes, 0);
                    if (c == 1) v = _mm512_extracti32x4_epi32(bytes, 1);
                    if (c == 2) v = _mm512_extracti32x4_epi32(bytes, 2);
                    __m512 f = _mm512_cvtepi32_ps(_mm512_cvtepu8_epi32(v));
                    _mm256_storeu_si256((__m256i *)&plane[c][2 * py + ry + 3][16 * g + 3],
                                        (__m256i)_mm512_cvtneps_pbh(f));
                }
            }
        }
    }
}

/* One pooled row py of the 4 channels into the next layer's space-to-depth layout:
 * (B, 16, 16, 2, 2, 4), element (b, py / 2, px / 2, py % 2, px % 2, oc). */
static void store_s2d(const uint16_t pooled[4][32], uint16_t *out, int64_t b, int py) {
    uint16_t *row = out + (b * 16 + (py >> 1)) * 256 + (py & 1) * 8;
    for (int px = 0; px < 32; px++)
        for (int oc = 0; oc < 4; oc++) row[(px >> 1) * 16 + (px & 1) * 4 + oc] = pooled[oc][px];
}

/* The output's gradient of image b, from the space-to-depth layout, as g[oc][py][px]. */
static void load_s2d(const uint16_t *grad, int64_t b, float g[4][32][32]) {
    const uint16_t *image = grad + b * 4096;
    for (int py = 0; py < 32; py++)
        for (int px = 0; px < 32; px++)
            for (int oc = 0; oc < 4; oc++) {
                uint32_t bits = (uint32_t)image[(py >> 1) * 256 + (px >> 1) * 16 + (py & 1) * 8 + (px & 1) * 4 + oc] << 16;
                memcpy(&g[oc][py][px], &bits, 4);
            }
}

static inline uint32_t bf16_bits(float f) {
    __m128 v = _mm_set_ss(f);
    __m128bh b = _mm_cvtneps_pbh(v);
    uint16_t h;
    memcpy(&h, &b, 2);
    return h;
}

void conv1_forward_bf16(const uint8_t *frames, int64_t batch, const float *weight,
                        const float *bias, uint16_t *out, uint8_t *code) {
    /* w2[oc][c][ky][kxp]: the pair of taps (2 kxp, 2 kxp + 1) as one 32-bit lane */
    uint32_t w2[4][3][8][4];
    for (int oc = 0; oc < 4; oc++)
        for (int c = 0; c < 3; c++)
            for (int ky = 0; ky < 8; ky++)
                for (int p = 0; p < 4; p++) {
                    const float *t = weight + ((oc * 3 + c) * 8 + ky) * 8 + 2 * p;
                    w2[oc][c][ky][p] = bf16_bits(t[0]) | (bf16_bits(t[1]) << 16);
                }
    static __thread uint16_t plane[3][R + 1][W] __attribute__((aligned(64)));
    static __thread uint32_t pairs[3][R][W] __attribute__((aligned(64)));
    float rows[2][4][64] __attribute__((aligned(64)));
    uint16_t pooled[4][32] __attribute__((aligned(64)));
    const __m512i even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
    const __m512i odd = _mm512_add_epi32(even, _mm512_set1_epi32(1));
    const __m512 scale = _mm512_set1_ps(1.0f / 255.0f);
    for (int64_t b = 0; b < batch; b++) {
        unpack(frames + b * 64 * 64 * 3, plane);
        for (int c = 0; c < 3; c++)
            for (int r = 0; r < R; r++)
                for (int x = 0; x < W; x += 16) {
                    __m512i lo = _mm512_cvtepu16_epi32(_mm256_loadu_si256((const __m256i *)&plane[c][r][x]));
                    __m512i hi = _mm512_cvtepu16_epi32(_mm256_loadu_si256((const __m256i *)&plane[c][r][x + 1]));
                    _mm512_storeu_si512(&pairs[c][r][x], _mm512_or_si512(lo, _mm512_slli_epi32(hi, 16)));
                }
        for (int y = 0; y < 64; y++) {
            __m512 acc[4][4];
            for (int oc = 0; oc < 4; oc++)
                for (int v = 0; v < 4; v++) acc[oc][v] = _mm512_setzero_ps();
            for (int c = 0; c < 3; c++)
                for (int ky = 0; ky < 8; ky++) {
                    const uint32_t *row = pairs[c][y + ky];
                    for (int p = 0; p < 4; p++) {
                        __m512i in[4];
                        for (int v = 0; v < 4; v++) in[v] = _mm512_loadu_si512(row + 16 * v + 2 * p);
                        for (int oc = 0; oc < 4; oc++) {
                            __m512bh wv = (__m512bh)_mm512_set1_epi32((int)w2[oc][c][ky][p]);
                            for (int v = 0; v < 4; v++)
                                acc[oc][v] = _mm512_dpbf16_ps(acc[oc][v], (__m512bh)in[v], wv);
                        }
                    }
                }
            for (int oc = 0; oc < 4; oc++)
                for (int v = 0; v < 4; v++) _mm512_store_ps(&rows[y & 1][oc][16 * v], acc[oc][v]);
            if (!(y & 1)) continue;
            int py = y >> 1;
            for (int oc = 0; oc < 4; oc++) {
                __m512 bv = _mm512_set1_ps(bias[oc]);
                for (int h = 0; h < 2; h++) {
                    __m512 a0 = _mm512_load_ps(&rows[0][oc][32 * h]), b0 = _mm512_load_ps(&rows[0][oc][32 * h + 16]);
                    __m512 a1 = _mm512_load_ps(&rows[1][oc][32 * h]), b1 = _mm512_load_ps(&rows[1][oc][32 * h + 16]);
                    __m512 m = _mm512_permutex2var_ps(a0, even, b0);
                    __m512i k = _mm512_setzero_si512();
                    __m512 t = _mm512_permutex2var_ps(a0, odd, b0);
                    __mmask16 g = _mm512_cmp_ps_mask(t, m, _CMP_GT_OQ);
                    m = _mm512_mask_blend_ps(g, m, t);
                    k = _mm512_mask_blend_epi32(g, k, _mm512_set1_epi32(1));
                    t = _mm512_permutex2var_ps(a1, even, b1);
                    g = _mm512_cmp_ps_mask(t, m, _CMP_GT_OQ);
                    m = _mm512_mask_blend_ps(g, m, t);
                    k = _mm512_mask_blend_epi32(g, k, _mm512_set1_epi32(2));
                    t = _mm512_permutex2var_ps(a1, odd, b1);
                    g = _mm512_cmp_ps_mask(t, m, _CMP_GT_OQ);
                    m = _mm512_mask_blend_ps(g, m, t);
                    k = _mm512_mask_blend_epi32(g, k, _mm512_set1_epi32(3));
                    __m512 v = _mm512_fmadd_ps(m, scale, bv);
                    __mmask16 on = _mm512_cmp_ps_mask(v, _mm512_setzero_ps(), _CMP_GT_OQ);
                    int64_t o = ((b * 4 + oc) * 32 + py) * 32 + 16 * h;
                    __m256bh rounded = _mm512_cvtneps_pbh(_mm512_maskz_mov_ps(on, v));
                    _mm256_store_si256((__m256i *)&pooled[oc][16 * h], (__m256i)rounded);
                    if (code) {
                        k = _mm512_mask_blend_epi32(on, _mm512_set1_epi32(255), k);
                        _mm_storeu_si128((__m128i *)(code + o), _mm512_cvtepi32_epi8(k));
                    }
                }
            }
            store_s2d(pooled, out, b, py);
        }
    }
}

void conv1_backward_bf16(const uint8_t *frames, int64_t batch, const uint16_t *grad_out,
                         const uint8_t *code, float *grad_weight, float *grad_bias) {
    static __thread uint16_t plane[3][R + 1][W] __attribute__((aligned(64)));
    /* gy[oc][y][x]: the gradient of the convolution's output, bfloat16, pairs of pixels */
    static __thread uint32_t gy[4][64][32] __attribute__((aligned(64)));
    /* acc[c][ky][half][oc][k]: per-lane sums of kx = 4 half + k */
    static __thread __m512 acc[3][8][2][4][4];
    memset(acc, 0, sizeof(acc));
    __m512 bsum[4];
    for (int oc = 0; oc < 4; oc++) bsum[oc] = _mm512_setzero_ps();
    const __m512i none = _mm512_set1_epi32(255);
    static __thread float image_grad[4][32][32] __attribute__((aligned(64)));
    for (int64_t b = 0; b < batch; b++) {
        unpack(frames + b * 64 * 64 * 3, plane);
        load_s2d(grad_out, b, image_grad);
        for (int oc = 0; oc < 4; oc++)
            for (int py = 0; py < 32; py++)
                for (int h = 0; h < 2; h++) {
                    int64_t o = ((b * 4 + oc) * 32 + py) * 32 + 16 * h;
                    __m512 g = _mm512_load_ps(&image_grad[oc][py][16 * h]);
                    __m512i k = _mm512_cvtepu8_epi32(_mm_loadu_si128((const __m128i *)(code + o)));
                    __mmask16 on = _mm512_cmpneq_epi32_mask(k, none);
                    bsum[oc] = _mm512_mask_add_ps(bsum[oc], on, bsum[oc], g);
                    __m512i gb = _mm512_cvtepu16_epi32((__m256i)_mm512_cvtneps_pbh(g));
                    for (int dy = 0; dy < 2; dy++) {
                        __mmask16 left = _mm512_cmpeq_epi32_mask(k, _mm512_set1_epi32(2 * dy));
                        __mmask16 right = _mm512_cmpeq_epi32_mask(k, _mm512_set1_epi32(2 * dy + 1));
                        __m512i pair = _mm512_or_si512(_mm512_maskz_mov_epi32(left, gb),
                                                       _mm512_maskz_mov_epi32(right, _mm512_slli_epi32(gb, 16)));
                        _mm512_store_si512(&gy[oc][2 * py + dy][16 * h], pair);
                    }
                }
        for (int c = 0; c < 3; c++)
            for (int ky = 0; ky < 8; ky++)
                for (int half = 0; half < 2; half++) {
                    __m512 a[4][4];
                    for (int oc = 0; oc < 4; oc++)
                        for (int k = 0; k < 4; k++) a[oc][k] = acc[c][ky][half][oc][k];
                    for (int y = 0; y < 64; y++) {
                        const uint16_t *row = plane[c][y + ky] + 4 * half;
                        for (int v = 0; v < 2; v++) {
                            __m512i in[4];
                            for (int k = 0; k < 4; k++) in[k] = _mm512_loadu_si512(row + 32 * v + k);
                            for (int oc = 0; oc < 4; oc++) {
                                __m512bh gv = (__m512bh)_mm512_load_si512(&gy[oc][y][16 * v]);
                                for (int k = 0; k < 4; k++)
                                    a[oc][k] = _mm512_dpbf16_ps(a[oc][k], (__m512bh)in[k], gv);
                            }
                        }
                    }
                    for (int oc = 0; oc < 4; oc++)
                        for (int k = 0; k < 4; k++) acc[c][ky][half][oc][k] = a[oc][k];
                }
    }
    for (int oc = 0; oc < 4; oc++) {
        grad_bias[oc] = _mm512_reduce_add_ps(bsum[oc]);
        for (int c = 0; c < 3; c++)
            for (int ky = 0; ky < 8; ky++)
                for (int kx = 0; kx < 8; kx++)
                    grad_weight[((oc * 3 + c) * 8 + ky) * 8 + kx] =
                        _mm512_reduce_add_ps(acc[c][ky][kx >> 2][oc][kx & 3]) / 255.0f;
    }
}
