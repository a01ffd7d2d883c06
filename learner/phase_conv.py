"""The Q-network's forward pass made fast: each convolution and its 2x2 max-pool at once.

Why: the network's convolutions have 3-16 channels, a shape that vectorised kernels
handle badly, and a 2x2 max-pool over small channel counts is slower still. Rearranging
each layer's input by space-to-depth (every 2x2 block of pixels becomes 4x the channels)
turns "conv k x k then pool 2x2" into one convolution with 4x the input and output
channels on a quarter of the pixels, followed by an element-wise max over the four
output phases (the four pixels a pool window covers). The kernel of that convolution is
the original kernel scattered into a larger, partly zero one: the parameters, and so the
network and its checkpoints, are exactly `QNetwork`'s, and the function is the same (up
to float rounding; in float32 the outputs agree to ~1e-8, gradients included).

The convolutions run in bfloat16 where the device supports it; the input's scaling by
1/255 is folded into the first kernel, so uint8 frames go straight in. The replay memory
keeps frames already rearranged (`pack_frame`), so the first layer's input is only their
conversion to the compute dtype; the first two layers' "same" padding is the same on both
sides after space-to-depth, so their convolutions pad (no zero-filled copy), and every
layer's output stays channels-last through the max-pool and its gradient.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from learner.conv_kernel import ConvKernels, first_layer, later_layer
from learner.network import QNetwork, same_padding


@dataclass(frozen=True)
class PhaseLayout:
    """How one "same" k x k convolution plus 2x2 max-pool maps onto space-to-depth."""

    kernel_index: torch.Tensor
    """(4*out, 4*in, ks, ks) indices into the flattened kernel; the last index is a zero."""
    pad_before: int
    """Zero pixels before the image in the original resolution (even)."""
    s2d_kernel: int
    """The kernel size `ks` of the space-to-depth convolution."""


def phase_layout(out_channels: int, in_channels: int, kernel: int) -> PhaseLayout:
    """Output phase (py, px) at pooled pixel i reads input phase (ry, rx) at i + d, d in
    [dmin, dmax], with original kernel tap k = 2 d + r - p + pad_before."""
    before, _ = same_padding(kernel)
    dmin, dmax = -before // 2, (kernel - before) // 2
    ks = dmax - dmin + 1
    p = np.arange(2)
    o, c, d = np.arange(out_channels), np.arange(in_channels), np.arange(ks)
    # axes: py, px, o, ry, rx, c, dy, dx
    py, px, oo, ry, rx, cc, dy, dx = np.ix_(p, p, o, p, p, c, d, d)
    ky = 2 * (dy + dmin) + ry - py + before
    kx = 2 * (dx + dmin) + rx - px + before
    valid = (ky >= 0) & (ky < kernel) & (kx >= 0) & (kx < kernel)
    flat = ((oo * in_channels + cc) * kernel + ky) * kernel + kx
    zero = out_channels * in_channels * kernel * kernel
    index = np.where(valid, flat, zero).reshape(4 * out_channels, 4 * in_channels, ks, ks)
    return PhaseLayout(torch.from_numpy(index.astype(np.int64)), -2 * dmin, ks)


def pack_frame(image: np.ndarray) -> np.ndarray:
    """(H, W, C) -> (H/2, W/2, 4C), channels (ry, rx, c): the layout the replay memory keeps,
    the same bytes once, so that the first layer reads long contiguous runs."""
    h, w, c = image.shape
    return np.ascontiguousarray(
        image.reshape(h // 2, 2, w // 2, 2, c)
        .transpose(0, 2, 1, 3, 4)
        .reshape(h // 2, w // 2, 4 * c)
    )


def unpack_frames(packed: torch.Tensor) -> torch.Tensor:
    """(B, H/2, W/2, 4C) -> (B, H, W, C), the inverse of `pack_frame` on a batch."""
    b, h2, w2, c4 = packed.shape
    c = c4 // 4
    return packed.view(b, h2, w2, 2, 2, c).permute(0, 1, 3, 2, 4, 5).reshape(b, 2 * h2, 2 * w2, c)


def space_to_depth(
    x: torch.Tensor, packed: bool, layout: PhaseLayout, dtype: torch.dtype
) -> tuple[torch.Tensor, int]:
    """The layer's input as its space-to-depth convolution reads it, (B, 4C, h, w) with
    channels (ry, rx, c) in channels-last memory, and the zero pixels the convolution adds
    on each side itself. `x` is packed frames (B, H/2, W/2, 4C) or activations (B, C, H, W).

    Where the layer's padding is the same on both sides (the paper's first two layers), the
    convolution pads: the input is only rearranged, one strided copy that also converts
    the dtype (packed frames are already in this layout: a conversion alone). Else (the
    third layer pads after only) it is padded here too: a zero fill and the copy."""
    a = layout.pad_before // 2
    after = layout.s2d_kernel - 1 - a
    if packed:
        b, h2, w2, c4 = x.shape
        c = c4 // 4
        if a == after:
            return x.permute(0, 3, 1, 2).to(dtype), a
        src = x.view(b, h2, w2, 2, 2, c)
    else:
        b, c, h, w = x.shape
        h2, w2 = h // 2, w // 2
        src = x.view(b, c, h2, 2, w2, 2).permute(0, 2, 4, 3, 5, 1)
    if a == after:
        out = torch.empty(b, h2, w2, 2, 2, c, dtype=dtype, device=x.device)
        out.copy_(src)
        return out.view(b, h2, w2, 4 * c).permute(0, 3, 1, 2), a
    sh, sw = h2 + a + after, w2 + a + after
    out = torch.zeros(b, sh, sw, 2, 2, c, dtype=dtype, device=x.device)
    out[:, a : a + h2, a : a + w2].copy_(src)
    return out.view(b, sh, sw, 4 * c).permute(0, 3, 1, 2), 0


class _PhaseMaxBiasRelu(torch.autograd.Function):
    """relu(max over the 4 phases + bias) on (B, 4*o, h, w) (bias: see `_add_bias`), in
    the memory format the convolution gave (channels-last: no transposing copy, forward
    or back).
    The gradient goes to the first maximal phase in row-major window order, as
    `max_pool2d`'s does; masks are built from signs of differences, which are exact and much
    faster on the CPU than `where`. The phases are views of `y` or, in bfloat16, a copy
    with each phase apart (`_phases`): the same values either way, to the bit."""

    @staticmethod
    def forward(ctx, y: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
        phases, ctx.apart = _phases(y)
        y0, y1, y2, y3 = phases.unbind(0)
        m01, m23 = torch.maximum(y0, y1), torch.maximum(y2, y3)
        out = _add_bias(torch.maximum(m01, m23), bias).relu_()
        ctx.save_for_backward(phases if ctx.apart else y, m01, m23, out)
        ctx.bias_groups = bias.shape[0] if bias.dim() == 2 else 0
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        saved, m01, m23, out = ctx.saved_tensors
        grad = torch.ops.aten.threshold_backward(grad, out, 0)
        if ctx.bias_groups:  # each group's sum as if alone: the same float order
            sums = [g.sum((0, 2, 3), dtype=torch.float32) for g in grad.chunk(ctx.bias_groups)]
            grad_bias = torch.stack(sums)
        else:
            grad_bias = grad.sum((0, 2, 3), dtype=torch.float32)
        if ctx.apart:
            phases, grad_phases = saved, torch.empty_like(saved)
        else:
            grad_y = torch.empty_like(saved)
            phases, grad_phases = _phase_views(saved), _phase_views(grad_y)
        y0, y1, y2, y3 = phases.unbind(0)
        grad_hi = grad * _greater(m23, m01)
        grad_lo = grad - grad_hi
        g0, g1, g2, g3 = grad_phases.unbind(0)
        torch.mul(grad_lo, _greater(y1, y0), out=g1)
        torch.sub(grad_lo, g1, out=g0)
        torch.mul(grad_hi, _greater(y3, y2), out=g3)
        torch.sub(grad_hi, g3, out=g2)
        return (_join_phases(grad_phases) if ctx.apart else grad_y), grad_bias


def _phase_views(y: torch.Tensor) -> torch.Tensor:
    """The four output phases of (B, 4*o, h, w) as views (4, B, o, h, w) of `y`."""
    return y.unflatten(1, (4, -1)).transpose(0, 1)


def _phases(y: torch.Tensor) -> tuple[torch.Tensor, bool]:
    """The four output phases of (B, 4*o, h, w) channels-last, as (4, B, o, h, w), and
    whether they were copied apart.

    In float32, views of `y` (no copy). In 2-byte types, a copy with each phase's values
    apart, (4, B, h, w, o) in memory: on strided views of `y` (o of every 4*o values) the
    CPU's bfloat16 kernels run several times slower than this one copy costs (measured on
    the Xeon with AMX: the first layer's max-pool forward and back 19.3 ms to 6.0, float32
    views 8.5). Where a phase's o values of a pixel fill one or two 8-byte words, they
    move as int64."""
    b, c, h, w = y.shape
    o = c // 4
    nhwc = y.permute(0, 2, 3, 1)
    if y.element_size() != 2 or not nhwc.is_contiguous():
        return _phase_views(y), False
    words = _phase_words(o, y.element_size())
    if words:
        flat = nhwc.reshape(-1).view(torch.int64).view(b * h * w, 4, words)
        apart = flat.transpose(0, 1).contiguous().view(y.dtype).view(4, b, h, w, o)
    else:
        apart = nhwc.reshape(b, h, w, 4, o).permute(3, 0, 1, 2, 4).contiguous()
    return apart.permute(0, 1, 4, 2, 3), True


def _join_phases(phases: torch.Tensor) -> torch.Tensor:
    """(B, 4*o, h, w) channels-last from phases copied apart by `_phases`: the copy back."""
    _, b, o, h, w = phases.shape
    apart = phases.permute(0, 1, 3, 4, 2)
    out = torch.empty((b, h, w, 4, o), dtype=phases.dtype, device=phases.device)
    words = _phase_words(o, phases.element_size())
    if words:
        flat = apart.reshape(-1).view(torch.int64).view(4, b * h * w, words)
        out.view(-1).view(torch.int64).view(b * h * w, 4, words).copy_(flat.transpose(0, 1))
    else:
        out.permute(3, 0, 1, 2, 4).copy_(apart)
    return out.view(b, h, w, 4 * o).permute(0, 3, 1, 2)


def _phase_words(o: int, itemsize: int) -> int:
    """How many 8-byte words hold one phase's o values of a pixel, where moving them as
    int64 is the faster copy (one or two words, measured); else 0."""
    size = o * itemsize
    return size // 8 if size % 8 == 0 and size // 8 <= 2 else 0


def _greater(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """1 where a > b else 0, in a's dtype."""
    return (a - b).sign_().relu_()


def phase_max_bias_relu(y: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    if torch.is_grad_enabled() and (y.requires_grad or bias.requires_grad):
        return _PhaseMaxBiasRelu.apply(y, bias)
    y0, y1, y2, y3 = _phases(y)[0].unbind(0)
    m = torch.maximum(torch.maximum(y0, y1), torch.maximum(y2, y3))
    return _add_bias(m, bias).relu_()


def _add_bias(m: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """m += bias in place: a bias (o,) for every image, or (G, o), one per group of
    consecutive images (the agents of a population, `learner.stacked`).

    `m` is channels-last, so its channels are the innermost o values of each pixel: the
    bias is added as one row of a pixel row's w*o values (the bias repeated w times),
    which the CPU's kernels vectorise, where adding it per channel runs in loops of o
    (several times slower in bfloat16). The same sums, element by element."""
    groups = bias.shape[0] if bias.dim() == 2 else 1
    b, o, h, w = m.shape
    per_group = bias.to(m.dtype).view(groups, 1, o)
    pixels = m.permute(0, 2, 3, 1)
    if pixels.is_contiguous():
        row = per_group.repeat(1, w, 1).view(groups, 1, w * o)
        pixels.view(groups, (b // groups) * h, w * o).add_(row)
    else:
        m.unflatten(0, (groups, -1)).add_(per_group.view(groups, 1, o, 1, 1))
    return m


class _CachedKernel(torch.autograd.Function):
    """A space-to-depth kernel built earlier (`PhaseConvForward`'s cache) made differentiable
    in its weight: the backward is, op for op, the one autograd derives for the kernel's
    construction (cast back, the 1/255 scale, the scatter of `flat[index]`, the slice of
    `cat`), so the weight's gradient is the same to the bit as if the kernel were rebuilt."""

    @staticmethod
    def forward(
        ctx,
        weight: torch.Tensor,
        kernel: torch.Tensor,
        index: torch.Tensor,
        scale: float | None,
    ) -> torch.Tensor:
        ctx.save_for_backward(index)
        ctx.weight_shape, ctx.weight_dtype, ctx.scale = weight.shape, weight.dtype, scale
        return kernel.detach()

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor | None, None, None, None]:
        (index,) = ctx.saved_tensors
        grad = grad.to(ctx.weight_dtype)
        if ctx.scale is not None:
            grad = grad * ctx.scale
        numel = ctx.weight_shape.numel()
        flat = grad.new_zeros(numel + 1).index_put_((index,), grad, accumulate=True)
        return flat[:numel].view(ctx.weight_shape), None, None, None


class PhaseConvForward:
    """The fast forward of one `QNetwork`: `weights()` once per update, then `__call__`
    on packed uint8 frames as many times as needed with those weights.

    The space-to-depth kernels depend only on the convolutions' weights, which change only
    at an optimizer step, a `load_state_dict` or a target-network sync; each of those writes
    the parameters in place, which bumps their version counters. So the kernels are built
    once per version of the weights and reused by every forward pass until then: action
    selection, the target network's values, and the update's own forward (through
    `_CachedKernel`, whose gradient is the rebuilt kernel's to the bit).
    """

    def __init__(
        self,
        network: QNetwork,
        dtype: torch.dtype,
        conv_kernels: ConvKernels | None = None,
    ) -> None:
        self.network = network
        self.dtype = dtype
        device = network.out.weight.device
        fits = (
            conv_kernels is not None
            and device.type == "cpu"
            and network.image_shape == (64, 64, 3)
            and network.conv1.weight.shape == (4, 3, 8, 8)
            and conv_kernels.dtype == dtype
        )
        self.conv_kernels = conv_kernels if fits else None
        """The compiled convolutions (`learner.conv_kernel`) where given and they fit this
        network, device and precision: the first layer and those of `layers`; else all
        layers run in PyTorch."""
        self.layouts = []
        for conv in network.convs:
            out_channels, in_channels, kernel, _ = conv.weight.shape
            layout = phase_layout(out_channels, in_channels, kernel)
            index = layout.kernel_index.to(device)
            self.layouts.append(PhaseLayout(index, layout.pad_before, layout.s2d_kernel))
        self._kernels: list[torch.Tensor] = []
        self._built_for: tuple[tuple[int, int], ...] | None = None
        self.builds = 0
        """Times the kernels were built: how a test sees that a stale cache is rebuilt."""

    def _weights_version(self) -> tuple[tuple[int, int], ...]:
        """Identifies the convolutions' weights' current values: their storage and version
        counter (bumped by every in-place write, including under `no_grad`)."""
        return tuple((conv.weight.data_ptr(), conv.weight._version) for conv in self.network.convs)

    def kernels(self) -> list[torch.Tensor]:
        """Space-to-depth kernels (compute dtype, channels-last), cut from autograd; built
        only when the weights changed since the last call."""
        version = self._weights_version()
        if version != self._built_for:
            # normal tensors even when built under inference mode (action selection): the
            # update's forward saves them for its backward
            with torch.inference_mode(False), torch.no_grad():
                self._kernels = [
                    self._build(conv.weight, i) for i, conv in enumerate(self.network.convs)
                ]
            self._built_for = version
            self.builds += 1
        return self._kernels

    def _build(self, weight: torch.Tensor, layer: int) -> torch.Tensor:
        flat = torch.cat((weight.reshape(-1), weight.new_zeros(1)))
        kernel = flat[self.layouts[layer].kernel_index]
        if layer == 0:
            kernel = kernel * (1.0 / 255.0)
        return kernel.to(self.dtype).contiguous(memory_format=torch.channels_last)

    def weights(self) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Space-to-depth kernels (compute dtype) and float32 biases; differentiable in the
        parameters where autograd records (the kernels themselves come from the cache)."""
        kernels = self.kernels()
        result = []
        for i, (conv, kernel) in enumerate(zip(self.network.convs, kernels, strict=True)):
            if torch.is_grad_enabled() and conv.weight.requires_grad:
                scale = 1.0 / 255.0 if i == 0 else None
                index = self.layouts[i].kernel_index
                kernel = _CachedKernel.apply(conv.weight, kernel, index, scale)
            assert conv.bias is not None, "the network's convolutions have biases"
            result.append((kernel, conv.bias))
        return result

    def __call__(
        self, frames: torch.Tensor, weights: list[tuple[torch.Tensor, torch.Tensor]]
    ) -> torch.Tensor:
        """Q-values of packed uint8 frames (B, H/2, W/2, 4C), see `pack_frame`."""
        x = frames
        compiled = self.conv_kernels
        for i, (layout, (kernel, bias)) in enumerate(zip(self.layouts, weights, strict=True)):
            conv = self.network.convs[i]
            assert conv.bias is not None, "the network's convolutions have biases"
            if compiled is not None and i == 0:
                x = first_layer(compiled, frames, conv.weight, conv.bias)
                continue
            if compiled is not None and i + 1 in compiled.layers:
                x = later_layer(compiled, i + 1, x, conv.weight, conv.bias)
                continue
            if compiled is not None and i == 1:  # the first kernel gave this layer's input
                s, padding = x, layout.pad_before // 2
            else:
                s, padding = space_to_depth(x, i == 0, layout, self.dtype)
            x = phase_max_bias_relu(channels_last(F.conv2d(s, kernel, padding=padding)), bias)
        return self.network.output(x.flatten(1))


def channels_last(y: torch.Tensor) -> torch.Tensor:
    """A layer's convolution output as the phase max-pool takes it, alone or in a
    population (one memory format: the same float order in its gradients)."""
    return y.contiguous(memory_format=torch.channels_last)
