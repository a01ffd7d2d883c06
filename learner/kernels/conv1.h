/* The first layer's kernels, one pair per instruction set; see conv1_bf16.c. The output
 * (and its gradient) is the second layer's input in its space-to-depth layout,
 * (B, 16, 16, 2, 2, 4) in the convolutions' dtype (bfloat16 bits or float32). */
#include <stdint.h>

void conv1_forward_bf16(const uint8_t *frames, int64_t batch, const float *weight,
                        const float *bias, uint16_t *out, uint8_t *code);
void conv1_backward_bf16(const uint8_t *frames, int64_t batch, const uint16_t *grad_out,
                         const uint8_t *code, float *grad_weight, float *grad_bias);
void conv1_forward_fp32(const uint8_t *frames, int64_t batch, const float *weight,
                        const float *bias, float *out, uint8_t *code);
void conv1_backward_fp32(const uint8_t *frames, int64_t batch, const float *grad_out,
                         const uint8_t *code, float *grad_weight, float *grad_bias);
