"""The deep Q-learning agent: its network(s), optimizer, greedy values and the update.

Separate from the training loop (`learner.trainer`), which decides when to act, ask for
advice and update; this file decides how.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from learner import conv_kernel
from learner.config import DQNConfig
from learner.device import conv_dtype
from learner.network import DenseQNetwork, QNetwork
from learner.optim import Adam, RMSprop
from learner.phase_conv import PhaseConvForward, pack_frame
from learner.replay import ReplaySample


class DQNAgent:
    """Q-values of images and one gradient step on a replay batch, per `DQNConfig`."""

    def __init__(
        self,
        config: DQNConfig,
        device: torch.device,
        n_actions: int = 4,
        image_shape: tuple[int, ...] = (64, 64, 3),
        init_seed: int = 0,
    ) -> None:
        self.config = config
        self.device = device
        self.n_actions = n_actions
        self.vector = len(image_shape) == 1
        """Vector observations (n,): the dense network, computed plainly whatever `update`."""
        self.mode = "plain" if self.vector else config.update
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(init_seed)
            self.network = QNetwork.for_observation(
                n_actions, image_shape, config.head, config.init
            )
        self.network.to(device)
        self.target = copy.deepcopy(self.network) if config.target_network else None
        self.updates = 0
        """Gradient steps taken so far."""
        params = self.network.parameters()
        if config.optimizer == "rmsprop":
            self.optimizer: RMSprop | Adam = RMSprop(
                params, config.learning_rate, config.rmsprop_alpha, config.optimizer_eps
            )
        else:
            self.optimizer = Adam(params, config.learning_rate, config.optimizer_eps)
        self.dtype = conv_dtype(config.precision, device)
        self._fast, self._fast_target = None, None
        if isinstance(self.network, QNetwork):
            kernel = conv_kernel.for_run(config.conv_kernel, self.dtype)
            self._fast = PhaseConvForward(self.network, self.dtype, kernel)
            if kernel is not None and self._fast.conv_kernels is None:
                raise ValueError(
                    f"conv_kernel {kernel.variant} computes the convolutions of the paper's "
                    "network on 64x64 RGB images on the CPU only: use conv_kernel none"
                )
            if isinstance(self.target, QNetwork):
                self._fast_target = PhaseConvForward(self.target, self.dtype, kernel)

    @property
    def fast(self) -> PhaseConvForward:
        """The fast update's form of the paper's network (none for the dense one)."""
        assert self._fast is not None, "a vector task's dense network has no fast form"
        return self._fast

    @property
    def frame_shape(self) -> tuple[int, ...]:
        """Shape of a frame as the replay memory stores it (see `encode`)."""
        shape = self.network.observation_shape
        if self.mode != "fast":
            return shape
        h, w, c = shape
        return (h // 2, w // 2, 4 * c)

    @property
    def frame_dtype(self) -> torch.dtype:
        """How the replay memory stores a frame: image bytes, or a vector's float32s."""
        return torch.float32 if self.vector else torch.uint8

    def encode(self, image: np.ndarray) -> np.ndarray:
        """An observation as the replay memory stores it: packed for the fast update."""
        shape = self.network.observation_shape
        if self.vector:
            if image.shape != shape or not np.issubdtype(image.dtype, np.floating):
                raise ValueError(
                    f"observations must be float vectors of shape {shape}, "
                    f"got {image.dtype} {image.shape}"
                )
            return image.astype(np.float32, copy=False)
        if image.shape != shape or image.dtype != np.uint8:
            raise ValueError(
                f"observations must be uint8 images of shape {shape}, "
                f"got {image.dtype} {image.shape}"
            )
        return pack_frame(image) if self.mode == "fast" else image

    def q_values(self, image: np.ndarray) -> np.ndarray:
        """The network's values for one uint8 image (H, W, C), as the update computes them."""
        frames = torch.from_numpy(self.encode(image)).to(self.device).unsqueeze(0)
        with torch.inference_mode():
            q = self._forward(self.network, self._fast, frames, grad=False)
        return q[0].float().cpu().numpy()

    def update(self, batch: ReplaySample, rng: np.random.Generator | None = None) -> float:
        """Fit the batch (`config.fit`): one gradient step on its TD error, or the authors'
        Keras fit (`rng` shuffles its minibatches); returns the loss. The batch's frames
        are stored as `encode` makes them."""
        if self.config.fit == "keras":
            return self._keras_fit(batch, rng or np.random.default_rng(self.updates))
        config = self.config
        n = len(batch.actions)
        weights = self._fast.weights() if self._fast and self.mode == "fast" else None
        targets = self._td_targets(batch, weights)
        q = self._forward(self.network, self._fast, batch.frames[:n], True, weights)
        taken = q.gather(1, batch.actions.unsqueeze(1)).squeeze(1)
        if config.loss == "mse":
            loss = F.mse_loss(taken, targets)
        else:
            loss = F.smooth_l1_loss(taken, targets)
        self._step(loss)
        return float(loss.detach())

    def _keras_fit(self, batch: ReplaySample, rng: np.random.Generator) -> float:
        """`model.fit(states, targets, epochs=1)` on the batch, as the authors' Keras code:
        every output gets a target (the untaken ones their own prediction), the loss is the
        mean squared error over all outputs, one gradient step per shuffled minibatch.
        Returns the mean of the minibatches' losses (what Keras reports)."""
        config = self.config
        n = len(batch.actions)
        frames = batch.frames[:n]
        with torch.no_grad():
            weights = self._fast.weights() if self._fast and self.mode == "fast" else None
            targets = self._forward(self.network, self._fast, frames, False, weights).float()
            targets = targets.clone()
            rows = torch.arange(n, device=targets.device)
            targets[rows, batch.actions] = self._td_targets(batch, weights).float()
        order = torch.from_numpy(rng.permutation(n)).to(frames.device)
        losses = []
        for start in range(0, n, config.keras_minibatch):
            part = order[start : start + config.keras_minibatch]
            q = self._forward(self.network, self._fast, frames[part], True)
            loss = (
                F.mse_loss(q, targets[part])
                if config.loss == "mse"
                else F.smooth_l1_loss(q, targets[part])
            )
            self._step(loss)
            losses.append(float(loss.detach()))
        return float(np.mean(losses))

    def _td_targets(
        self, batch: ReplaySample, weights: list[tuple[torch.Tensor, torch.Tensor]] | None
    ) -> torch.Tensor:
        """r + gamma max Q(s') (or the target network's / Double DQN's value) unless
        terminated."""
        config = self.config
        with torch.no_grad():
            next_frames = batch.next_states
            if self.target is None:
                detached = [(k.detach(), b.detach()) for k, b in weights] if weights else None
                next_q = self._forward(self.network, self._fast, next_frames, False, detached)
                next_value = next_q.max(1).values
            else:
                target_q = self._forward(self.target, self._fast_target, next_frames, False)
                if config.double_dqn:
                    detached = [(k.detach(), b.detach()) for k, b in weights] if weights else None
                    online = self._forward(self.network, self._fast, next_frames, False, detached)
                    choice = online.argmax(1, keepdim=True)
                    next_value = target_q.gather(1, choice).squeeze(1)
                else:
                    next_value = target_q.max(1).values
            return batch.rewards + config.gamma * (1.0 - batch.terminated) * next_value

    def _step(self, loss: torch.Tensor) -> None:
        """One optimizer step on `loss` (one of `updates`)."""
        self.optimizer.zero_grad()
        loss.backward()
        self.apply_gradients()

    def apply_gradients(self) -> None:
        """Clip the gradients in the parameters' `.grad` (per config) and take the optimizer
        step: one of `updates`. Apart from `_step` so that a population, which computes its
        agents' gradients together, steps each agent on its own."""
        config = self.config
        if config.grad_clip_norm is not None:
            torch.nn.utils.clip_grad_norm_(self.network.parameters(), config.grad_clip_norm)
        self.optimizer.step()
        self.updates += 1
        if self.target is not None and self.updates % config.target_update_interval == 0:
            self.target.load_state_dict(self.network.state_dict())

    def _forward(
        self,
        network: QNetwork | DenseQNetwork,
        fast: PhaseConvForward | None,
        frames: torch.Tensor,
        grad: bool,
        weights: list[tuple[torch.Tensor, torch.Tensor]] | None = None,
    ) -> torch.Tensor:
        if self.vector:
            return network(frames.float())
        if self.mode == "plain":
            return network(frames.permute(0, 3, 1, 2).contiguous().float().div(255.0))
        assert fast is not None
        if weights is None:
            weights = fast.weights()
            if not grad:
                weights = [(k.detach(), b.detach()) for k, b in weights]
        return fast(frames, weights)

    def state_dict(self) -> dict[str, Any]:
        return {
            "network": self.network.state_dict(),
            "target": self.target.state_dict() if self.target is not None else None,
            "optimizer": self.optimizer.state_dict(),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.network.load_state_dict(state["network"])
        if self.target is not None:
            self.target.load_state_dict(state["target"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.updates = int(state["updates"])
