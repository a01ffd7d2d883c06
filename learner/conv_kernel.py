"""The paper's network's convolutions (with their ReLU and 2x2 max-pool) by compiled
kernels of our own, forward and backward: the first layer (8x8, 3 -> 4 channels), the
second (4x4, 4 -> 8) and the third (2x2, 8 -> 16), on 64x64 frames.

Why: the first layer is about 77 % of the network's FLOPs, and its 4 output channels leave
a library kernel's vector lanes mostly empty; ours vectorises over output pixels instead
(`learner/kernels/conv1_*.c`). The second and third (`learner/kernels/conv23.c`) are small
enough that PyTorch's layout copies, phase max-pool and element-wise passes cost more than
their FLOPs; ours compute each in one pass over an image held in L1, vectorised over
output channels. All are built by `make kernels`, one shared library per instruction set
and file, compiled with explicit flags, chosen by the CPU's flags in /proc/cpuinfo:
bfloat16 with AVX-512 BF16, float32 FMA with AVX2. Where none loads (another CPU, no
compiler, CUDA), the PyTorch update is used. Which variant a run takes is part of its
numerics (`config.conv_kernel`, pinned as precision and threads are), named with the
layers it computes (`avx2:1-3`; a bare `avx2`, the first alone): a run pinned to a layer
set computes that set wherever it resumes. A run left to choose takes `LAYERS`.

The first kernel takes the replay memory's packed uint8 frames (`pack_frame`) and gives
the layer's output as the second layer reads it: in the convolutions' dtype, in that
layer's space-to-depth layout (`space_to_depth`: (B, 16, 16, 16), channels (ry, rx, c),
channels-last), so no copy stands between the two layers. The second kernel reads that
layout and writes channels-last (B, 16, 16, 8), which the third reads; the third writes
(B, 16, 8, 8), the dense layer's order. `code` keeps, per output, the window position the
max-pool took (0-3, row-major; the first maximal one, as `max_pool2d` does) or 255 where
the ReLU is off: all the backward needs besides the layer's input.
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


LAYERS = machine.CONV_KERNEL_LAYERS


@dataclass(frozen=True)
class ConvKernels:
    """One variant's loaded kernels for one precision, and the layers (1-3) a network
    computes with them (the first always; the others where `layers` has them)."""

    variant: str
    precision: str
    dtype: torch.dtype
    forward_fn: Callable[..., None]
    backward_fn: Callable[..., None]
    later: dict[int, tuple[Callable[..., None], Callable[..., None]]]
    """Layer 2 and 3's forward and backward."""
    layers: frozenset[int] = frozenset(LAYERS)


def _open(variant: str, layers: frozenset[int] = frozenset(LAYERS)) -> ConvKernels:
    precision = VARIANTS[variant][1]
    library = ctypes.CDLL(str(BUILD / f"libconv1_{variant}.so"))
    forward_fn = getattr(library, f"conv1_forward_{precision}")
    backward_fn = getattr(library, f"conv1_backward_{precision}")
    forward_fn.restype = backward_fn.restype = None
    forward_fn.argtypes = [ctypes.c_void_p, ctypes.c_int64, *[ctypes.c_void_p] * 4]
    backward_fn.argtypes = [ctypes.c_void_p, ctypes.c_int64, *[ctypes.c_void_p] * 4]
    library23 = ctypes.CDLL(str(BUILD / f"libconv23_{variant}.so"))
    later = {}
    for layer in (2, 3):
        forward = getattr(library23, f"conv{layer}_forward_{precision}")
        backward = getattr(library23, f"conv{layer}_backward_{precision}")
        forward.restype = backward.restype = None
        forward.argtypes = [ctypes.c_void_p, ctypes.c_int64, *[ctypes.c_void_p] * 4]
        backward.argtypes = [ctypes.c_void_p, ctypes.c_int64, *[ctypes.c_void_p] * 6]
        later[layer] = (forward, backward)
    dtype = torch.bfloat16 if precision == "bf16" else torch.float32
    return ConvKernels(variant, precision, dtype, forward_fn, backward_fn, later, layers)


def load(precision: str, flags: frozenset[str] | set[str] | None = None) -> ConvKernels | None:
    """The kernel for `precision` ("bf16" or "fp32") on a CPU with `flags` (this one's by
    default), or None where no built variant runs there. The AVX2 library's float32
    functions also serve AVX-512 CPUs."""
    flags = machine.cpu_flags() if flags is None else flags
    for variant, (needs, variant_precision) in VARIANTS.items():
        built = all(
            (BUILD / f"{name}_{variant}.so").exists() for name in machine.CONV_KERNEL_LIBRARIES
        )
        if variant_precision == precision and needs <= flags and built:
            return _open(variant)
    return None


def for_run(conv_kernel: ConvKernel, dtype: torch.dtype) -> ConvKernels | None:
    """The kernels a run's `config.conv_kernel` names, for its convolution `dtype`: `none`,
    None (the PyTorch update); a variant with its layers (`avx2:1-3`, `avx2` the first
    alone), that variant's for those layers, which must run here; `auto` (a run not
    pinned), the variant the switch and this CPU decide (`learner.machine.conv_kernel_for`).
    A pinned run's kernels are part of its numerics (`RunSpec.pinned`), checked before it
    resumes (`RunSpec.numerics_problem`)."""
    precision = "bf16" if dtype == torch.bfloat16 else "fp32"
    name = machine.conv_kernel_for(precision) if conv_kernel == "auto" else conv_kernel
    if name == "none":
        return None
    variant, layers = machine.conv_kernel_parts(name)
    if not machine.conv_kernel_layers_computed(name):
        raise ValueError(
            f"conv_kernel {name} computes layers {sorted(layers)} with the kernels; this code "
            f"computes {' or '.join(str(sorted(s)) for s in machine.CONV_KERNEL_LAYER_SETS)}"
        )
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
    return _open(variant, layers)


def _pointer(t: torch.Tensor | None) -> int | None:
    return None if t is None else t.data_ptr()


def first_layer_forward(
    kernel: ConvKernels,
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
    kernel: ConvKernels, frames: torch.Tensor, grad_out: torch.Tensor, code: torch.Tensor
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
        kernel: ConvKernels,
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
    kernel: ConvKernels, frames: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor
) -> torch.Tensor:
    """The first layer's output in the second layer's space-to-depth layout,
    differentiable in weight and bias."""
    if torch.is_grad_enabled() and (weight.requires_grad or bias.requires_grad):
        return _FirstLayer.apply(frames, weight, bias, kernel)
    return first_layer_forward(kernel, frames, weight, bias, with_code=False)[0]


# ---- the second and third layers ----

LATER_SHAPES = {
    2: {"input": (16, 16, 16), "weight": (8, 4, 4, 4), "output": (16, 16, 8), "code": (16, 16, 8)},
    3: {"input": (16, 16, 8), "weight": (16, 8, 2, 2), "output": (16, 8, 8), "code": (8, 8, 16)},
}
"""Per image, in memory order: layer 2 reads the first kernel's space-to-depth output and
writes channels-last; layer 3 reads channels-last and writes (C, H, W)."""


def later_forward(
    kernels: ConvKernels,
    layer: int,
    memory: torch.Tensor,
    weight: torch.Tensor,
    bias: torch.Tensor,
    with_code: bool,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Layer 2 or 3's output from its input in memory order (`LATER_SHAPES`), in memory
    order too, and the max-pool's codes where `with_code`."""
    shapes = LATER_SHAPES[layer]
    assert memory.shape[1:] == shapes["input"] and memory.dtype == kernels.dtype, memory.shape
    assert weight.shape == shapes["weight"], weight.shape
    memory = memory.contiguous()
    weight = weight.detach().float().contiguous()
    bias = bias.detach().float().contiguous()
    batch = memory.shape[0]
    out = torch.empty(batch, *shapes["output"], dtype=kernels.dtype)
    code = torch.empty(batch, *shapes["code"], dtype=torch.uint8) if with_code else None
    kernels.later[layer][0](
        memory.data_ptr(), batch, weight.data_ptr(), bias.data_ptr(), out.data_ptr(), _pointer(code)
    )
    return out, code


def later_backward(
    kernels: ConvKernels,
    layer: int,
    memory: torch.Tensor,
    grad_out: torch.Tensor,
    code: torch.Tensor,
    weight: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The input's gradient (memory order, the kernels' dtype), the weight's and the
    bias's (float32), from the output's gradient in memory order."""
    grad_out = grad_out.to(kernels.dtype).contiguous()
    weight = weight.detach().float().contiguous()
    grad_weight = torch.empty(weight.shape)
    grad_bias = torch.empty(weight.shape[0])
    grad_in = torch.empty(memory.shape, dtype=kernels.dtype)
    kernels.later[layer][1](
        memory.data_ptr(),
        memory.shape[0],
        grad_out.data_ptr(),
        code.data_ptr(),
        weight.data_ptr(),
        grad_weight.data_ptr(),
        grad_bias.data_ptr(),
        grad_in.data_ptr(),
    )
    return grad_in, grad_weight, grad_bias


def _to_memory(layer: int, x: torch.Tensor) -> torch.Tensor:
    """Layer 2 or 3's input tensor as the kernel reads it: (B, 16, 16, 16) space-to-depth
    and (B, 8, 16, 16) channels-last are permuted views of it (no copy where laid out so)."""
    return x.permute(0, 2, 3, 1).contiguous()


def _from_memory(layer: int, out: torch.Tensor) -> torch.Tensor:
    """Layer 2 or 3's output as the network's tensor: (B, 8, 16, 16) channels-last, or
    (B, 16, 8, 8) as it is."""
    return out.permute(0, 3, 1, 2) if layer == 2 else out


class _LaterLayer(torch.autograd.Function):
    @staticmethod
    def forward(
        ctx: Any,
        x: torch.Tensor,
        weight: torch.Tensor,
        bias: torch.Tensor,
        kernels: ConvKernels,
        layer: int,
    ) -> torch.Tensor:
        memory = _to_memory(layer, x)
        out, code = later_forward(kernels, layer, memory, weight, bias, with_code=True)
        ctx.save_for_backward(memory, code, weight)
        ctx.kernels, ctx.layer = kernels, layer
        return _from_memory(layer, out)

    @staticmethod
    def backward(
        ctx: Any, grad: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, None, None]:
        memory, code, weight = ctx.saved_tensors
        grad_memory = _to_memory(ctx.layer, grad) if ctx.layer == 2 else grad
        grad_in, grad_weight, grad_bias = later_backward(
            ctx.kernels, ctx.layer, memory, grad_memory, code, weight
        )
        return grad_in.permute(0, 3, 1, 2), grad_weight, grad_bias, None, None


def later_layer(
    kernels: ConvKernels, layer: int, x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor
) -> torch.Tensor:
    """Layer 2's output (B, 8, 16, 16) from the first kernel's (B, 16, 16, 16), or layer
    3's (B, 16, 8, 8) from layer 2's, differentiable in the input, weight and bias."""
    needs_grad = x.requires_grad or weight.requires_grad or bias.requires_grad
    if torch.is_grad_enabled() and needs_grad:
        return _LaterLayer.apply(x, weight, bias, kernels, layer)
    memory = _to_memory(layer, x.to(kernels.dtype))
    out = later_forward(kernels, layer, memory, weight, bias, with_code=False)[0]
    return _from_memory(layer, out)
