/* The second and third layers' kernels, one library per instruction set; see conv23.c.
 * Activations and gradients are bfloat16 bits (_bf16) or float32 (_fp32); weights, biases
 * and their gradients float32 in torch's layouts. */
#include <stdint.h>

void conv2_forward_bf16(const uint16_t *in, int64_t batch, const float *weight,
                        const float *bias, uint16_t *out, uint8_t *code);
void conv2_backward_bf16(const uint16_t *in, int64_t batch, const uint16_t *grad_out,
                         const uint8_t *code, const float *weight, float *grad_weight,
                         float *grad_bias, uint16_t *grad_in);
void conv3_forward_bf16(const uint16_t *in, int64_t batch, const float *weight,
                        const float *bias, uint16_t *out, uint8_t *code);
void conv3_backward_bf16(const uint16_t *in, int64_t batch, const uint16_t *grad_out,
                         const uint8_t *code, const float *weight, float *grad_weight,
                         float *grad_bias, uint16_t *grad_in);
void conv2_forward_fp32(const float *in, int64_t batch, const float *weight,
                        const float *bias, float *out, uint8_t *code);
void conv2_backward_fp32(const float *in, int64_t batch, const float *grad_out,
                         const uint8_t *code, const float *weight, float *grad_weight,
                         float *grad_bias, float *grad_in);
void conv3_forward_fp32(const float *in, int64_t batch, const float *weight,
                        const float *bias, float *out, uint8_t *code);
void conv3_backward_fp32(const float *in, int64_t batch, const float *grad_out,
                         const uint8_t *code, const float *weight, float *grad_weight,
                         float *grad_bias, float *grad_in);
