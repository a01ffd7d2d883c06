/* The paper's first layer (see conv1_bf16.c) in float32 with AVX2 FMA: the same layouts
 * and the same function, 8 output pixels a vector; frames go in as integers (exact) and
 * the scale 1/255 is applied once to each sum. */
#include <immintrin.h>
#include <stdint.h>
#include <string.h>

#include "conv1.h"

#define W 80 /* padded row: 3 zeros, 64 pixels, 13 zeros (vector loads read past 71) */
#define R 71 /* padded rows: 3 zeros, 64 rows, 4 zeros */

/* plane[c][r][x]: the frame's channel c, zero padded, as float32. */
static void unpack(const uint8_t *frame, float plane[3][R][W]) {
    memset(plane, 0, sizeof(float) * 3 * R * W);
    for (int y = 0; y < 64; y++) {
        const uint8_t *src = frame + (y >> 1) * 32 * 12 + (y & 1) * 6;
        for (int x = 0; x < 64; x++) {
            const uint8_t *p = src + (x >> 1) * 12 + (x & 1) * 3;
            plane[0][y + 3][x + 3] = p[0];
            plane[1][y + 3][x + 3] = p[1];
            plane[2][y + 3][x + 3] = p[2];
        }
    }
}

/* max over the 2x2 windows of rows[2][64] at pooled pixels 4 q .. 4 q + 3 (one __m128 of
 * each parity), the first maximal position in row-major order */
static inline void pool4(const float rows[2][64], int q, __m128 *m, __m128i *k) {
    __m256 r0 = _mm256_loadu_ps(&rows[0][8 * q]), r1 = _mm256_loadu_ps(&rows[1][8 * q]);
    __m256 e0 = _mm256_permutevar8x32_ps(r0, _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7));
    __m256 e1 = _mm256_permutevar8x32_ps(r1, _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7));
    __m128 cand[4] = {_mm256_castps256_ps128(e0), _mm256_extractf128_ps(e0, 1),
                      _mm256_castps256_ps128(e1), _mm256_extractf128_ps(e1, 1)};
    __m128 best = cand[0];
    __m128i where = _mm_setzero_si128();
    for (int i = 1; i < 4; i++) {
        __m128 gt = _mm_cmpgt_ps(cand[i], best);
        best = _mm_blendv_ps(best, cand[i], gt);
        where = _mm_blendv_epi8(where, _mm_set1_epi32(i), _mm_castps_si128(gt));
    }
    *m = best;
    *k = where;
}

/* One pooled row py of the 4 channels into the next layer's space-to-depth layout:
 * (B, 16, 16, 2, 2, 4), element (b, py / 2, px / 2, py % 2, px % 2, oc). */
static void store_s2d(const float pooled[4][32], float *out, int64_t b, int py) {
    float *row = out + (b * 16 + (py >> 1)) * 256 + (py & 1) * 8;
    for (int px = 0; px < 32; px++)
        for (int oc = 0; oc < 4; oc++) row[(px >> 1) * 16 + (px & 1) * 4 + oc] = pooled[oc][px];
}

void conv1_forward_fp32(const uint8_t *frames, int64_t batch, const float *weight,
                        const float *bias, float *out, uint8_t *code) {
    static __thread float plane[3][R][W] __attribute__((aligned(64)));
    float rows[2][4][64] __attribute__((aligned(64)));
    float pooled[4][32] __attribute__((aligned(64)));
    const __m128 scale = _mm_set1_ps(1.0f / 255.0f);
    for (int64_t b = 0; b < batch; b++) {
        unpack(frames + b * 64 * 64 * 3, plane);
        for (int y = 0; y < 64; y++) {
            for (int x0 = 0; x0 < 64; x0 += 16) {
                __m256 acc[4][2];
                for (int oc = 0; oc < 4; oc++) acc[oc][0] = acc[oc][1] = _mm256_setzero_ps();
                for (int c = 0; c < 3; c++)
                    for (int ky = 0; ky < 8; ky++) {
                        const float *row = plane[c][y + ky] + x0;
                        const float *w = weight + c * 64 + ky * 8;
                        for (int kx = 0; kx < 8; kx++) {
                            __m256 in0 = _mm256_loadu_ps(row + kx), in1 = _mm256_loadu_ps(row + kx + 8);
                            for (int oc = 0; oc < 4; oc++) {
                                __m256 wv = _mm256_broadcast_ss(w + oc * 192 + kx);
                                acc[oc][0] = _mm256_fmadd_ps(in0, wv, acc[oc][0]);
                                acc[oc][1] = _mm256_fmadd_ps(in1, wv, acc[oc][1]);
                            }
                        }
                    }
                for (int oc = 0; oc < 4; oc++) {
                    _mm256_store_ps(&rows[y & 1][oc][x0], acc[oc][0]);
                    _mm256_store_ps(&rows[y & 1][oc][x0 + 8], acc[oc][1]);
                }
            }
            if (!(y & 1)) continue;
            int py = y >> 1;
            for (int oc = 0; oc < 4; oc++) {
                float both[2][64];
                memcpy(both[0], rows[0][oc], sizeof(both[0]));
                memcpy(both[1], rows[1][oc], sizeof(both[1]));
                __m128 bv = _mm_set1_ps(bias[oc]);
                for (int q = 0; q < 8; q++) {
                    __m128 m;
                    __m128i k;
                    pool4(both, q, &m, &k);
                    __m128 v = _mm_add_ps(_mm_mul_ps(m, scale), bv);
                    __m128 on = _mm_cmpgt_ps(v, _mm_setzero_ps());
                    int64_t o = ((b * 4 + oc) * 32 + py) * 32 + 4 * q;
                    _mm_store_ps(&pooled[oc][4 * q], _mm_and_ps(v, on));
                    if (code) {
                        k = _mm_blendv_epi8(_mm_set1_epi32(255), k, _mm_castps_si128(on));
                        __m128i bytes = _mm_shuffle_epi8(k, _mm_setr_epi8(0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1));
                        int32_t packed = _mm_cvtsi128_si32(bytes);
                        memcpy(code + o, &packed, 4);
                    }
                }
            }
            store_s2d(pooled, out, b, py);
        }
    }
}

void conv1_backward_fp32(const uint8_t *frames, int64_t batch, const float *grad_out,
                         const uint8_t *code, float *grad_weight, float *grad_bias) {
    static __thread float plane[3][R][W] __attribute__((aligned(64)));
    /* gy[oc][y][x]: the gradient of the convolution's output */
    static __thread float gy[4][64][64] __attribute__((aligned(64)));
    /* acc[c][ky][oc][kx]: per-lane sums */
    static __thread __m256 acc[3][8][4][8];
    memset(acc, 0, sizeof(acc));
    float bsum[4] = {0, 0, 0, 0};
    for (int64_t b = 0; b < batch; b++) {
        unpack(frames + b * 64 * 64 * 3, plane);
        memset(gy, 0, sizeof(gy));
        const float *image = grad_out + b * 4096;
        for (int oc = 0; oc < 4; oc++) {
            const uint8_t *k = code + (b * 4 + oc) * 1024;
            for (int i = 0; i < 1024; i++) {
                if (k[i] == 255) continue;
                int py = i >> 5, px = i & 31;
                float g = image[(py >> 1) * 256 + (px >> 1) * 16 + (py & 1) * 8 + (px & 1) * 4 + oc];
                bsum[oc] += g;
                gy[oc][2 * py + (k[i] >> 1)][2 * px + (k[i] & 1)] = g;
            }
        }
        for (int c = 0; c < 3; c++)
            for (int ky = 0; ky < 8; ky++)
                for (int half = 0; half < 2; half++) {
                    __m256 a[4][4];
                    for (int oc = 0; oc < 4; oc++)
                        for (int j = 0; j < 4; j++) a[oc][j] = acc[c][ky][oc][4 * half + j];
                    for (int y = 0; y < 64; y++) {
                        const float *row = plane[c][y + ky] + 4 * half;
                        for (int x0 = 0; x0 < 64; x0 += 8) {
                            __m256 in[4];
                            for (int j = 0; j < 4; j++) in[j] = _mm256_loadu_ps(row + x0 + j);
                            for (int oc = 0; oc < 4; oc++) {
                                __m256 gv = _mm256_load_ps(&gy[oc][y][x0]);
                                for (int j = 0; j < 4; j++) a[oc][j] = _mm256_fmadd_ps(in[j], gv, a[oc][j]);
                            }
                        }
                    }
                    for (int oc = 0; oc < 4; oc++)
                        for (int j = 0; j < 4; j++) acc[c][ky][oc][4 * half + j] = a[oc][j];
                }
    }
    for (int oc = 0; oc < 4; oc++) {
        grad_bias[oc] = bsum[oc];
        for (int c = 0; c < 3; c++)
            for (int ky = 0; ky < 8; ky++)
                for (int kx = 0; kx < 8; kx++) {
                    float lanes[8];
                    _mm256_storeu_ps(lanes, acc[c][ky][oc][kx]);
                    float s = ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) +
                              ((lanes[4] + lanes[5]) + (lanes[6] + lanes[7]));
                    grad_weight[((oc * 3 + c) * 8 + ky) * 8 + kx] = s / 255.0f;
                }
    }
}
