"""The first layer of the paper's network (8x8 convolution, 3 -> 4 channels, ReLU, 2x2
max-pool) by a compiled kernel of our own, forward and the parameters' gradients.

Why: this layer is about 77 % of the network's FLOPs, and its 4 output channels leave a
library kernel's vector lanes mostly empty; ours vectorises over output pixels instead
(`learner/kernels/conv1_*.c`, built by `make kernels`). One shared library per
instruction set, compiled with explicit flags, is chosen by the CPU's flags in
/proc/cpuinfo: bfloat16 dot products with AVX-512 BF16, float32 FMA with AVX2. Where
neither loads (another CPU, no compiler, CUDA), the PyTorch update is used. Which variant
a run takes is part of its numerics (`config.conv_kernel`, pinned as precision and threads
are).

The kernel takes the replay memory's packed uint8 frames (`pack_frame`) and gives the
layer's output as the second layer reads it: in the convolutions' dtype, in that layer's
space-to-depth layout (`space_to_depth`: (B, 16, 16, 16), channels (ry, rx, c),
channels-last), so no copy stands between the two layers. `code` keeps, per output, the
window position the max-pool took (0-3, row-major; the first maximal one, as
`max_pool2d` does) or 255 where the ReLU is off: all the backward needs besides the
frames.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch

from learner import machine
from learner.config import ConvKernel

SWITCH = machine.CONV_KERNEL_SWITCH
BUILD = machine.CONV_KERNEL_BUILD
VARIANTS = machine.CONV_KERNEL_VARIANTS


@dataclass(frozen=True)
class FirstLayerKernel:
    """One loaded library's forward and backward for one precision."""

    variant: str
    precision: str
    dtype: torch.dtype
    forward_fn: Callable[..., None]
    backward_fn: Callable[..., None]


def _open(variant: ConvKernel) -> FirstLayerKernel:
    precision = VARIANTS[variant][1]
    library = ctypes.CDLL(str(BUILD / f"libconv1_{variant}.so"))
    forward_fn = getattr(library, f"conv1_forward_{precision}")
    backward_fn = getattr(library, f"conv1_backward_{precision}")
    forward_fn.restype = backward_fn.restype = None
    forward_fn.argtypes = [ctypes.c_void_p, ctypes.c_int64, *[ctypes.c_void_p] * 4]
    backward_fn.argtypes = [ctypes.c_void_p, ctypes.c_int64, *[ctypes.c_void_p] * 4]
    dtype = torch.bfloat16 if precision == "bf16" else torch.float32
    return FirstLayerKernel(variant, precision, dtype, forward_fn, backward_fn)


def load(precision: str, flags: frozenset[str] | set[str] | None = None) -> FirstLayerKernel | None:
    """The kernel for `precision` ("bf16" or "fp32") on a CPU with `flags` (this one's by
    default), or None where no built variant runs there. The AVX2 library's float32
    functions also serve AVX-512 CPUs."""
    flags = machine.cpu_flags() if flags is None else flags
    for variant, (needs, variant_precision) in VARIANTS.items():
        built = (BUILD / f"libconv1_{variant}.so").exists()
        if variant_precision == precision and needs <= flags and built:
            return _open(variant)
    return None


def for_run(conv_kernel: ConvKernel, dtype: torch.dtype) -> FirstLayerKernel | None:
    """The kernel a run's `config.conv_kernel` names, for its convolution `dtype`: `none`,
    None (the PyTorch update); a variant, that variant's, which must run here; `auto` (a
    run not pinned), the variant the switch and this CPU decide
    (`learner.machine.conv_kernel_for`). A pinned run's kernel is part of its numerics
    (`RunSpec.pinned`), checked before it resumes (`RunSpec.numerics_problem`)."""
    precision = "bf16" if dtype == torch.bfloat16 else "fp32"
    variant = machine.conv_kernel_for(precision) if conv_kernel == "auto" else conv_kernel
    if variant == "none":
        return None
    if VARIANTS[variant][1] != precision:
        raise ValueError(
            f"conv_kernel {variant} computes {VARIANTS[variant][1]} convolutions, and the "
            f"run's are {precision}: pin the precision it computes, or conv_kernel none"
        )
    if not machine.conv_kernel_runs(variant):
        raise ValueError(
            f"conv_kernel {variant} does not run here ({machine.cpu_kind()}): this CPU lacks "
            "its instructions, or `make kernels` has not built it"
        )
    return _open(variant)


def _pointer(t: torch.Tensor | None) -> int | None:
    return None if t is None else t.data_ptr()


def first_layer_forward(
    kernel: FirstLayerKernel,
    frames: torch.Tensor,
    weight: torch.Tensor,
    bias: torch.Tensor,
    with_code: bool,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The layer's output in the second layer's space-to-depth layout (see the module's
    docstring) from packed uint8 frames (B, 32, 32, 12), and the max-pool's codes where
    `with_code`."""
    assert frames.dtype == torch.uint8 and frames.shape[1:] == (32, 32, 12), frames.shape
    assert weight.shape == (4, 3, 8, 8) and bias.shape == (4,)
    frames = frames.contiguous()
    weight = weight.detach().float().contiguous()
    bias = bias.detach().float().contiguous()
    batch = frames.shape[0]
    out = torch.empty(batch, 16, 16, 16, dtype=kernel.dtype)
    code = torch.empty(batch, 4, 32, 32, dtype=torch.uint8) if with_code else None
    kernel.forward_fn(
        frames.data_ptr(), batch, weight.data_ptr(), bias.data_ptr(), out.data_ptr(), _pointer(code)
    )
    return out.permute(0, 3, 1, 2), code


def as_pooled(s2d: torch.Tensor) -> torch.Tensor:
    """The layer's output (B, 4, 32, 32) from its space-to-depth layout (B, 16, 16, 16)."""
    b = s2d.shape[0]
    blocks = s2d.permute(0, 2, 3, 1).reshape(b, 16, 16, 2, 2, 4)
    return blocks.permute(0, 5, 1, 3, 2, 4).reshape(b, 4, 32, 32)


def first_layer_backward(
    kernel: FirstLayerKernel, frames: torch.Tensor, grad_out: torch.Tensor, code: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The weight's (4, 3, 8, 8) and bias's (4,) gradients, float32, from the output's
    gradient in the output's shape (B, 16, 16, 16)."""
    frames = frames.contiguous()
    grad_out = grad_out.to(kernel.dtype).permute(0, 2, 3, 1).contiguous()
    grad_weight = torch.empty(4, 3, 8, 8)
    grad_bias = torch.empty(4)
    kernel.backward_fn(
        frames.data_ptr(),
        frames.shape[0],
        grad_out.data_ptr(),
        code.data_ptr(),
        grad_weight.data_ptr(),
        grad_bias.data_ptr(),
    )
    return grad_weight, grad_bias


class _FirstLayer(torch.autograd.Function):
    @staticmethod
    def forward(
        ctx: Any,
        frames: torch.Tensor,
        weight: torch.Tensor,
        bias: torch.Tensor,
        kernel: FirstLayerKernel,
    ) -> torch.Tensor:
        out, code = first_layer_forward(kernel, frames, weight, bias, with_code=True)
        ctx.save_for_backward(frames, code)
        ctx.kernel = kernel
        return out

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[None, torch.Tensor, torch.Tensor, None]:
        frames, code = ctx.saved_tensors
        grad_weight, grad_bias = first_layer_backward(ctx.kernel, frames, grad, code)
        return None, grad_weight, grad_bias, None


def first_layer(
    kernel: FirstLayerKernel, frames: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor
) -> torch.Tensor:
    """The first layer's output in the second layer's space-to-depth layout,
    differentiable in weight and bias."""
    if torch.is_grad_enabled() and (weight.requires_grad or bias.requires_grad):
        return _FirstLayer.apply(frames, weight, bias, kernel)
    return first_layer_forward(kernel, frames, weight, bias, with_code=False)[0]
