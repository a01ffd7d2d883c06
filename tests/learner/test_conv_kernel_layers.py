"""The compiled second and third layers (`learner.conv_kernel.later_layer`) compute the
plain network's: outputs and the input's, weight's and bias's gradients within rtol 1e-5
and atol 1e-5 times the largest magnitude in float32, and rtol 1e-2 in bfloat16, on
random inputs, on the plain network's activations of rendered frames and on inputs whose
max-pool windows tie; and the fast forward with any set of compiled layers is the plain
network in float32."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from learner import conv_kernel
from learner.network import QNetwork, same_padding
from learner.phase_conv import PhaseConvForward
from tests.learner.test_conv_kernel import (
    PRECISIONS,
    assert_agree,
    kernel_or_skip,
    packed,
    random_frames,
    rendered_frames,
    tied_frames,
)

SHAPES = {2: (4, 32), 3: (8, 16)}
"""Input channels and size of each layer's input."""


def as_kernel_input(layer: int, x: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """The layer's input (B, C, H, W) laid out as the kernels pass it: layer 2's as the
    first kernel's space-to-depth output (B, 16, 16, 16), layer 3's channels-last."""
    b, c = x.shape[:2]
    if layer == 2:
        memory = x.view(b, c, 16, 2, 16, 2).permute(0, 2, 4, 3, 5, 1).reshape(b, 16, 16, 16)
        return memory.to(dtype).permute(0, 3, 1, 2)
    return x.to(dtype).contiguous(memory_format=torch.channels_last)


def from_kernel_input(layer: int, grad: torch.Tensor) -> torch.Tensor:
    """The input's gradient back in (B, C, H, W)."""
    if layer == 3:
        return grad
    b = grad.shape[0]
    blocks = grad.permute(0, 2, 3, 1).reshape(b, 16, 16, 2, 2, 4)
    return blocks.permute(0, 5, 1, 3, 2, 4).reshape(b, 4, 32, 32)


def plain_layer(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    before, after = same_padding(weight.shape[-1])
    y = F.conv2d(F.pad(x, (before, after, before, after)), weight, bias)
    return F.max_pool2d(F.relu(y), 2)


def compare(
    precision: str,
    layer: int,
    x: torch.Tensor,
    seed: int,
    parameters: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> None:
    """The kernel's output and gradients against the plain layer's. In bfloat16 the plain
    layer gets what bfloat16 keeps of its input, of the weights and of the output's
    gradient: the precision's own rounding, not the kernel's."""
    kernels = kernel_or_skip(precision)
    torch.manual_seed(seed)
    conv = QNetwork().convs[layer - 1]
    assert conv.bias is not None
    weight, bias = parameters or (conv.weight.detach(), conv.bias.detach())
    weight = weight.clone().requires_grad_()
    bias = bias.clone().requires_grad_()
    given = as_kernel_input(layer, x, kernels.dtype).detach().requires_grad_()
    out = conv_kernel.later_layer(kernels, layer, given, weight, bias)
    grad = torch.randn(out.shape)
    grads = torch.autograd.grad(out, (given, weight, bias), grad.to(out.dtype))
    input_grad, weight_grad, bias_grad = grads

    rtol = 1e-2 if precision == "bf16" else 1e-5
    rounded = [t.detach().to(kernels.dtype).float() for t in (x, weight, grad)]
    plain_x, plain_weight, plain_grad = rounded
    plain_x.requires_grad_()
    plain_weight.requires_grad_()
    plain_bias = bias.detach().clone().requires_grad_()
    expected = plain_layer(plain_x, plain_weight, plain_bias)
    expected_grads = torch.autograd.grad(expected, (plain_x, plain_weight, plain_bias), plain_grad)
    assert_agree(out.float(), expected, rtol)
    assert_agree(from_kernel_input(layer, input_grad).float(), expected_grads[0], rtol)
    assert_agree(weight_grad, expected_grads[1], rtol)
    assert_agree(bias_grad, expected_grads[2], rtol)


def random_input(layer: int, seed: int) -> torch.Tensor:
    channels, size = SHAPES[layer]
    generator = torch.Generator().manual_seed(seed)
    return torch.rand(6, channels, size, size, generator=generator)


def recorded_input(layer: int) -> torch.Tensor:
    """The plain network's activations of rendered frames, as this layer receives them."""
    torch.manual_seed(11)
    network = QNetwork()
    x = torch.from_numpy(rendered_frames(6)).permute(0, 3, 1, 2).float() / 255.0
    with torch.no_grad():
        for conv in network.convs[: layer - 1]:
            x = plain_layer(x, conv.weight, conv.bias)
    return x


def tied_input(layer: int) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
    """Inputs constant per channel (every interior output of a window is the same sum:
    four-way ties), one with a constant patch in random values, and integer weights and
    inputs scaled by powers of two (sums exact in float32 and bfloat16, so ties stay
    ties); biases that leave some outputs on either side of the ReLU."""
    channels, size = SHAPES[layer]
    rng = np.random.default_rng(13 + layer)
    flat = np.broadcast_to(rng.integers(0, 8, (2, channels, 1, 1)), (2, channels, size, size))
    mixed = rng.integers(0, 8, (1, channels, size, size))
    mixed[:, :, 4:12, 4:12] = 3
    x = torch.from_numpy(np.concatenate([flat, mixed]) / 8.0).float()
    out_channels = 2 * channels
    kernel = 4 if layer == 2 else 2
    weight = rng.integers(-8, 9, (out_channels, channels, kernel, kernel)) / 16.0
    bias = rng.integers(-4, 5, out_channels) / 4.0
    return x, (torch.from_numpy(weight).float(), torch.from_numpy(bias).float())


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("layer", [2, 3])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_kernel_is_the_plain_layer_on_random_inputs(
    precision: str, layer: int, seed: int
) -> None:
    compare(precision, layer, random_input(layer, seed) - 0.3, seed)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("layer", [2, 3])
def test_the_kernel_is_the_plain_layer_on_recorded_activations(precision: str, layer: int) -> None:
    compare(precision, layer, recorded_input(layer), 3)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("layer", [2, 3])
def test_the_kernel_pools_ties_as_max_pool2d(precision: str, layer: int) -> None:
    """Tied windows: the gradient goes to the first maximal position in row-major order,
    as `max_pool2d`'s; a tie broken otherwise moves whole gradient entries."""
    x, parameters = tied_input(layer)
    compare(precision, layer, x, 4, parameters)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("layer", [2, 3])
def test_the_kernel_without_gradients_gives_the_same_output(precision: str, layer: int) -> None:
    kernels = kernel_or_skip(precision)
    conv = QNetwork().convs[layer - 1]
    assert conv.bias is not None
    x = as_kernel_input(layer, random_input(layer, 5), kernels.dtype)
    with torch.no_grad():
        quick = conv_kernel.later_layer(kernels, layer, x, conv.weight, conv.bias)
    out = conv_kernel.later_layer(kernels, layer, x, conv.weight, conv.bias)
    assert torch.equal(quick, out.detach())


@pytest.mark.parametrize("layers", [(1,), (1, 2), (1, 3), (1, 2, 3)])
def test_the_network_with_any_compiled_layers_is_the_plain_network_in_float32(
    layers: tuple[int, ...],
) -> None:
    """The fast forward with the compiled layers `layers` and PyTorch's for the rest:
    Q-values and every parameter's gradient as the plain network's."""
    kernels = dataclasses.replace(kernel_or_skip("fp32"), layers=frozenset(layers))
    torch.manual_seed(8)
    network = QNetwork()
    images = np.concatenate([random_frames(4, 8), rendered_frames(3), tied_frames()])
    target = torch.randn(len(images), 4)
    plain = network(torch.from_numpy(images).permute(0, 3, 1, 2).float() / 255.0)
    (plain - target).square().mean().backward()
    plain_grads = [p.grad.clone() for p in network.parameters() if p.grad is not None]
    network.zero_grad()
    fast = PhaseConvForward(network, torch.float32, kernels)
    quick = fast(packed(images), fast.weights())
    (quick - target).square().mean().backward()
    assert_agree(quick, plain, 1e-5)
    for (name, param), expected in zip(network.named_parameters(), plain_grads, strict=True):
        assert param.grad is not None, name
        scale = float(expected.abs().max())
        torch.testing.assert_close(param.grad, expected, rtol=1e-5, atol=1e-5 * scale, msg=name)


def test_a_run_computes_every_layer_the_kernels_have() -> None:
    assert conv_kernel.LAYERS[0] == 1
    kernels = kernel_or_skip("fp32")
    assert kernels.layers == frozenset(conv_kernel.LAYERS)
    assert set(kernels.later) == {2, 3}
