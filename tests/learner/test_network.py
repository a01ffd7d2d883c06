import numpy as np
import pytest
import torch
import torch.nn.functional as F

from learner.network import QNetwork
from learner.phase_conv import (
    PhaseConvForward,
    channels_last,
    pack_frame,
    phase_max_bias_relu,
    space_to_depth,
    unpack_frames,
)


def frames_with_flat_regions(count: int, seed: int = 0) -> np.ndarray:
    """Random images with flat patches: pooling windows with tied maxima, as in renders."""
    rng = np.random.default_rng(seed)
    images = rng.integers(0, 256, (count, 64, 64, 3), dtype=np.uint8)
    images[:, :24] = 200
    images[:, 40:, 10:50] = rng.integers(0, 256, 3, dtype=np.uint8)
    return images


def test_network_has_the_papers_layers_and_parameter_count() -> None:
    network = QNetwork()
    shapes = {name: tuple(p.shape) for name, p in network.named_parameters()}
    assert shapes == {
        "conv1.weight": (4, 3, 8, 8), "conv1.bias": (4,),
        "conv2.weight": (8, 4, 4, 4), "conv2.bias": (8,),
        "conv3.weight": (16, 8, 2, 2), "conv3.bias": (16,),
        "dense.weight": (256, 1024), "dense.bias": (256,),  # "same" padding: 16x8x8 in
        "out.weight": (4, 256), "out.bias": (4,),
    }  # fmt: skip
    assert sum(p.numel() for p in network.parameters()) == 265_248
    assert network(torch.rand(5, 3, 64, 64)).shape == (5, 4)


def test_softmax_head_outputs_a_distribution() -> None:
    out = QNetwork(head="softmax")(torch.rand(3, 3, 64, 64))
    assert torch.allclose(out.sum(1), torch.ones(3)) and (out >= 0).all()


def test_packing_a_frame_is_a_lossless_rearrangement() -> None:
    images = frames_with_flat_regions(3)
    packed = np.stack([pack_frame(image) for image in images])
    assert packed.shape == (3, 32, 32, 12) and packed.nbytes == images.nbytes
    assert np.array_equal(unpack_frames(torch.from_numpy(packed)).numpy(), images)


@pytest.mark.parametrize("head", ["linear", "softmax"])
def test_fast_forward_computes_the_same_function_and_gradient_in_float32(head: str) -> None:
    torch.manual_seed(0)
    network = QNetwork(head=head)
    images = frames_with_flat_regions(8)
    plain_input = torch.from_numpy(images).permute(0, 3, 1, 2).float() / 255
    packed = torch.from_numpy(np.stack([pack_frame(image) for image in images]))
    target = torch.randn(8, 4)

    plain = network(plain_input)
    (plain - target).square().mean().backward()
    plain_grads = [p.grad.clone() for p in network.parameters()]
    network.zero_grad()
    fast = PhaseConvForward(network, torch.float32)
    quick = fast(packed, fast.weights())
    (quick - target).square().mean().backward()

    assert torch.allclose(quick, plain, atol=1e-6)
    for (name, param), expected in zip(network.named_parameters(), plain_grads, strict=True):
        assert torch.allclose(param.grad, expected, rtol=1e-4, atol=1e-7), name


def test_fast_forward_in_bfloat16_stays_close() -> None:
    torch.manual_seed(1)
    network = QNetwork()
    images = frames_with_flat_regions(16, seed=1)
    plain = network(torch.from_numpy(images).permute(0, 3, 1, 2).float() / 255)
    fast = PhaseConvForward(network, torch.bfloat16)
    packed = torch.from_numpy(np.stack([pack_frame(image) for image in images]))
    with torch.no_grad():
        quick = fast(packed, fast.weights())
    assert quick.dtype == torch.float32
    assert (quick - plain).abs().max() < 0.02 * plain.abs().max() + 1e-3


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_a_layer_its_convolution_pads_computes_what_zeros_padded_before_do(
    dtype: torch.dtype,
) -> None:
    """The first two layers' "same" padding is symmetric after space-to-depth, so their
    convolutions pad (no zero-filled copy); the third pads after only, so it is padded
    before. Either way a layer computes the convolution of the zero-padded input."""
    torch.manual_seed(2)
    network = QNetwork()
    fast = PhaseConvForward(network, dtype)
    images = frames_with_flat_regions(4, seed=2)
    x = torch.from_numpy(np.stack([pack_frame(image) for image in images]))
    pads = []
    with torch.no_grad():
        for i, (layout, kernel) in enumerate(zip(fast.layouts, fast.kernels(), strict=True)):
            s, pad = space_to_depth(x, i == 0, layout, dtype)
            pads.append(pad)
            y = F.conv2d(s, kernel, padding=pad)
            zeros = F.pad(s, (pad,) * 4).contiguous(memory_format=torch.channels_last)
            expected = F.conv2d(zeros, kernel)
            tolerance = 1e-6 if dtype == torch.float32 else 1e-2
            assert torch.allclose(y.float(), expected.float(), rtol=tolerance, atol=tolerance)
            bias = network.convs[i].bias
            assert bias is not None
            x = phase_max_bias_relu(channels_last(y), bias)
    assert pads == [2, 1, 0]


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
@pytest.mark.parametrize("out_channels", [4, 8, 16])
@pytest.mark.parametrize("groups", [0, 2])
def test_the_phase_max_pool_is_max_pool2d_to_the_bit(
    dtype: torch.dtype, out_channels: int, groups: int
) -> None:
    """The max over the four output phases, plus bias and ReLU, computes what `max_pool2d`
    of the same pixels in their places does: outputs and the input's gradient equal to the
    bit, ties included (the gradient to the first maximum in row-major window order), in
    float32 (phases as views) and in bfloat16 (phases copied apart, by words where they
    fit), for one bias and for a population's bias per group of images."""
    torch.manual_seed(3)
    batch, side, o = 4, 6, out_channels
    # few distinct values: many windows with tied maxima
    y = (torch.randint(-3, 4, (batch, 4 * o, side, side)) / 4).to(dtype)
    y = y.contiguous(memory_format=torch.channels_last).requires_grad_()
    bias = torch.randn(groups, o) if groups else torch.randn(o)
    bias.requires_grad_()
    out = phase_max_bias_relu(y, bias)
    grad = torch.randn(out.shape).to(dtype)
    (out * grad).sum().backward()

    # the same pixels in their places: channel (py, px, c) at (i, j) is pixel (2i+py, 2j+px)
    y_ref = y.detach().clone().requires_grad_()
    places = y_ref.view(batch, 2, 2, o, side, side).permute(0, 3, 4, 1, 5, 2)
    pooled = F.max_pool2d(places.reshape(batch, o, 2 * side, 2 * side), 2)
    b = bias.detach().to(dtype)
    b = b.repeat_interleave(batch // groups, 0) if groups else b.expand(batch, o)
    expected = (pooled + b.view(batch, o, 1, 1)).relu()
    (expected * grad).sum().backward()

    assert torch.equal(out.detach(), expected.detach())
    assert torch.equal(y.grad, y_ref.grad)
    with torch.no_grad():  # the inference path (action selection, targets)
        assert torch.equal(phase_max_bias_relu(y, bias), expected)
