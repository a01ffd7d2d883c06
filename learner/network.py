"""The paper's convolutional Q-network, written plainly; and the small dense Q-network a
task whose observations are vectors gets instead (`QNetwork.for_observation`).

Three convolutions (8x8/4, 4x4/8, 2x2/16 filters), each followed by ReLU and a 2x2
max-pool, then a dense layer of 256 and one output per action. As in the authors' Keras
code the convolutions pad "same" (so 16x8x8 features reach the dense layer); for even
kernels that pads one pixel more after than before, exactly like Keras and TensorFlow.

`forward` is the definition of the function. The fast update (`learner.phase_conv`)
computes the same function from the same parameters in another way.
"""

from __future__ import annotations

import itertools

import torch
import torch.nn.functional as F
from torch import nn

VECTOR_UNITS = (64, 64)
"""Hidden layers of the dense network for vector observations."""
CONV_LAYERS = ((4, 8), (8, 4), (16, 2))
"""(filters, kernel size) of the three convolutions."""
DENSE_UNITS = 256


def same_padding(kernel: int) -> tuple[int, int]:
    """Pixels padded (before, after) for a stride-1 "same" convolution, as Keras does."""
    total = kernel - 1
    return total // 2, total - total // 2


class QNetwork(nn.Module):
    """Maps a batch of images (B, 3, H, W) in [0, 1] to one value per action."""

    def __init__(
        self,
        n_actions: int = 4,
        image_shape: tuple[int, int, int] = (64, 64, 3),
        head: str = "linear",
        init: str = "torch",
    ) -> None:
        super().__init__()
        height, width, channels = image_shape
        if height % 8 or width % 8:
            raise ValueError(f"image height and width must be multiples of 8, got {image_shape}")
        if head not in ("linear", "softmax"):
            raise ValueError(f"head must be 'linear' or 'softmax', got {head!r}")
        self.image_shape = image_shape
        self.head = head
        convs = []
        in_channels = channels
        for filters, kernel in CONV_LAYERS:
            convs.append(nn.Conv2d(in_channels, filters, kernel))
            in_channels = filters
        self.conv1, self.conv2, self.conv3 = convs
        self.dense = nn.Linear(in_channels * (height // 8) * (width // 8), DENSE_UNITS)
        self.out = nn.Linear(DENSE_UNITS, n_actions)
        if init == "glorot":  # Keras' default: Glorot-uniform weights, zero biases
            layers: list[nn.Conv2d | nn.Linear] = [*convs, self.dense, self.out]
            for layer in layers:
                nn.init.xavier_uniform_(layer.weight)
                assert layer.bias is not None, "made with bias=True"
                nn.init.zeros_(layer.bias)
        elif init != "torch":
            raise ValueError(f"init must be 'torch' or 'glorot', got {init!r}")

    @classmethod
    def for_observation(
        cls, n_actions: int, shape: tuple[int, ...], head: str = "linear", init: str = "torch"
    ) -> QNetwork | DenseQNetwork:
        """The paper's network for images (H, W, C); the dense one for vectors (n,)."""
        if len(shape) == 1:
            return DenseQNetwork(n_actions, shape[0], head, init)
        height, width, channels = shape
        return cls(n_actions, (height, width, channels), head, init)

    @property
    def observation_shape(self) -> tuple[int, ...]:
        return self.image_shape

    @property
    def convs(self) -> tuple[nn.Conv2d, nn.Conv2d, nn.Conv2d]:
        return self.conv1, self.conv2, self.conv3

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        x = images
        for conv in self.convs:
            before, after = same_padding(conv.kernel_size[0])
            x = conv(F.pad(x, (before, after, before, after)))
            x = F.max_pool2d(F.relu(x), 2)
        return self.output(x.flatten(1))

    def output(self, features: torch.Tensor) -> torch.Tensor:
        """The dense layers on flattened (C, H, W) features, always in float32."""
        logits = self.out(F.relu(self.dense(features.float())))
        return torch.softmax(logits, dim=1) if self.head == "softmax" else logits


class DenseQNetwork(nn.Module):
    """Maps a batch of float vectors (B, n) to one value per action: two hidden layers of
    `VECTOR_UNITS` with ReLU (a Gymnasium Box of shape (n,), CartPole's four numbers)."""

    def __init__(
        self, n_actions: int, size: int, head: str = "linear", init: str = "torch"
    ) -> None:
        super().__init__()
        if size < 1:
            raise ValueError(f"a vector observation needs at least one number, got {size}")
        if head not in ("linear", "softmax"):
            raise ValueError(f"head must be 'linear' or 'softmax', got {head!r}")
        self.observation_shape = (size,)
        self.head = head
        sizes = (size, *VECTOR_UNITS)
        self.hidden = nn.ModuleList(nn.Linear(a, b) for a, b in itertools.pairwise(sizes))
        self.out = nn.Linear(sizes[-1], n_actions)
        if init == "glorot":
            for layer in (*self.hidden, self.out):
                assert isinstance(layer, nn.Linear)
                nn.init.xavier_uniform_(layer.weight)
                nn.init.zeros_(layer.bias)
        elif init != "torch":
            raise ValueError(f"init must be 'torch' or 'glorot', got {init!r}")

    def forward(self, vectors: torch.Tensor) -> torch.Tensor:
        x = vectors.float()
        for layer in self.hidden:
            x = F.relu(layer(x))
        logits = self.out(x)
        return torch.softmax(logits, dim=1) if self.head == "softmax" else logits
