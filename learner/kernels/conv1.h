/* The first layer's kernels, one pair per instruction set; see conv1_bf16.c. */
#include <stdint.h>

void conv1_forward_bf16(const uint8_t *frames, int64_t batch, const float *weight,
                        const float *bias, float *out, uint8_t *code);
void conv1_backward_bf16(const uint8_t *frames, int64_t batch, const float *grad_out,
                         const uint8_t *code, float *grad_weight, float *grad_bias);
void conv1_forward_fp32(const uint8_t *frames, int64_t batch, const float *weight,
                        const float *bias, float *out, uint8_t *code);
void conv1_backward_fp32(const uint8_t *frames, int64_t batch, const float *grad_out,
                         const uint8_t *code, float *grad_weight, float *grad_bias);
