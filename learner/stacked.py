"""Many agents' Q-networks computed together: the fast update over stacked weights.

A population (`learner.population`) keeps one `DQNAgent` per agent, with its own
parameters, optimizer state and checkpoints. Here their networks are evaluated in one
pass: agent a's frames are rows [a*M, (a+1)*M) of one batch, and the space-to-depth
rearrangement, the phase max-pool, the biases (stacked per agent) and the ReLUs run once
over all agents. The gradient of the sum of the agents' losses reaches each agent's own
parameters only, so `DQNAgent.apply_gradients` then clips and steps each agent alone
(global-norm clipping per agent).

The matrix products stay per agent: each agent has its own weights and its own images,
so agents cannot share a kernel call without cost. `conv="loop"` calls one convolution
per agent on its rows, the same oneDNN (or cuDNN) kernel on the same shapes as the agent
alone, and so do the dense layers and each agent's loss reduction; everything else is
elementwise or reduced per agent, so the values, losses and gradients are the agent's
own to the bit (checked in float32 and bfloat16 by tests/learner/test_population.py).
`conv="grouped"` makes one grouped convolution of all agents (agent a's channels are
group a), which needs a transposing copy in and out; measured on AVX-512 CPUs
(benchmarks/bench_population.py) it loses for the update's batches, and it is not
bit-identical to the agent alone (the same function, another summation order).

Pure PyTorch: any device, any dtype the agents' config picks (`learner.device`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from learner.agent import DQNAgent
from learner.config import shared_config
from learner.network import QNetwork
from learner.phase_conv import (
    PhaseConvForward,
    PhaseLayout,
    channels_last,
    phase_max_bias_relu,
    space_to_depth,
)
from learner.replay import ReplaySample

ConvMode = Literal["loop", "grouped"]


class StackedWeights(NamedTuple):
    """N agents' weights, as the fast forward takes them."""

    kernels: list[list[torch.Tensor]]
    """Per layer, each agent's space-to-depth kernel (compute dtype, channels-last)."""
    biases: list[torch.Tensor]
    """Per layer, (N, out) float32."""
    networks: list[QNetwork]
    """The agents' networks, whose dense layers (`QNetwork.output`) finish the pass."""

    def detach(self) -> StackedWeights:
        """The same weights cut from autograd (the dense layers: use `torch.no_grad`)."""
        return StackedWeights(
            [[k.detach() for k in layer] for layer in self.kernels],
            [b.detach() for b in self.biases],
            self.networks,
        )


def stack_weights(fasts: Sequence[PhaseConvForward]) -> StackedWeights:
    """The weights of the networks behind `fasts` (differentiable: the gradient reaches
    each network's own parameters)."""
    per_agent = [fast.weights() for fast in fasts]
    layers = range(len(per_agent[0]))
    kernels = [[weights[i][0] for weights in per_agent] for i in layers]
    biases = [torch.stack([weights[i][1] for weights in per_agent]) for i in layers]
    return StackedWeights(kernels, biases, [fast.network for fast in fasts])


def stacked_q(
    weights: StackedWeights,
    frames: torch.Tensor,
    layouts: Sequence[PhaseLayout],
    dtype: torch.dtype,
    conv: ConvMode = "loop",
) -> torch.Tensor:
    """Q-values (N, M, A) of N agents on their own packed uint8 frames (N, M, H/2, W/2, 4C)
    (`learner.phase_conv.pack_frame`): `PhaseConvForward`'s function and, with
    `conv="loop"`, its values to the bit."""
    n, m = frames.shape[:2]
    x = frames.flatten(0, 1)
    for i, layout in enumerate(layouts):
        s, pad = space_to_depth(x, i == 0, layout, dtype)
        kernels = weights.kernels[i]
        if n == 1:
            y = F.conv2d(s, kernels[0], padding=pad)
        elif conv == "grouped":
            y = _grouped_conv(s, kernels, n, pad)
        else:
            rows = [F.conv2d(s[a * m : (a + 1) * m], k, padding=pad) for a, k in enumerate(kernels)]
            y = torch.cat(rows)
        x = phase_max_bias_relu(channels_last(y), weights.biases[i])
    features = x.flatten(1).unflatten(0, (n, m))
    return torch.stack([net.output(f) for net, f in zip(weights.networks, features, strict=True)])


def _grouped_conv(
    s: torch.Tensor, kernels: list[torch.Tensor], n: int, padding: int
) -> torch.Tensor:
    """One grouped convolution of n agents' rows of `s` (n*M, C, h, w): agent a's channels
    form group a; returns (n*M, O, h', w') contiguous."""
    grouped = s.unflatten(0, (n, -1)).transpose(0, 1).flatten(1, 2)
    grouped = grouped.contiguous(memory_format=torch.channels_last)
    kernel = torch.cat(kernels).contiguous(memory_format=torch.channels_last)
    y = F.conv2d(grouped, kernel, padding=padding, groups=n)
    return y.unflatten(1, (n, -1)).transpose(0, 1).flatten(0, 1).contiguous()


class StackedAgents:
    """Q-values and updates of agents of one config, computed together (module docstring).
    Each agent's `update` here does what its `DQNAgent.update` does alone."""

    def __init__(self, agents: Sequence[DQNAgent], conv: ConvMode = "loop") -> None:
        if not agents:
            raise ValueError("a population needs at least one agent")
        config = agents[0].config
        if any(shared_config(agent.config) != shared_config(config) for agent in agents):
            raise ValueError("agents computed together must share one config")
        if config.update != "fast":
            raise ValueError("stacked agents compute the fast update (config update='fast')")
        if conv not in ("loop", "grouped"):
            raise ValueError(f"conv must be 'loop' or 'grouped', got {conv!r}")
        self.agents = list(agents)
        self.config = config
        self.conv: ConvMode = conv
        self.dtype = agents[0].dtype
        self.device = agents[0].device
        self.layouts = agents[0].fast.layouts

    def _q(self, weights: StackedWeights, frames: torch.Tensor, conv: ConvMode | None = None):
        return stacked_q(weights, frames, self.layouts, self.dtype, conv or self.conv)

    def q_values(self, images: Sequence[np.ndarray], conv: ConvMode | None = None) -> np.ndarray:
        """(N, A) values of one uint8 image per agent: one batched forward pass."""
        frames = np.stack(
            [agent.encode(image) for agent, image in zip(self.agents, images, strict=True)]
        )
        batch = torch.from_numpy(frames).to(self.device).unsqueeze(1)
        with torch.inference_mode():
            weights = stack_weights([agent.fast for agent in self.agents]).detach()
            q = self._q(weights, batch, conv)
        return q[:, 0].float().cpu().numpy()

    def update(
        self, batches: Sequence[ReplaySample], rngs: Sequence[np.random.Generator]
    ) -> list[float]:
        """Fit each agent to its batch (`config.fit`); returns each agent's loss. `rngs`
        shuffle the Keras fit's minibatches, as `DQNAgent.update`'s `rng`."""
        if len(batches) != len(self.agents):
            raise ValueError(f"{len(batches)} batches for {len(self.agents)} agents")
        frames = torch.stack([batch.frames for batch in batches])
        actions = torch.stack([batch.actions for batch in batches])
        weights = stack_weights([agent.fast for agent in self.agents])
        targets = self._td_targets(batches, frames, weights.detach())
        b = actions.shape[1]
        if self.config.fit == "keras":
            return self._keras_fit(frames[:, :b], actions, targets, weights, rngs)
        q = self._q(weights, frames[:, :b])
        taken = q.gather(2, actions.unsqueeze(2)).squeeze(2)
        losses = torch.stack([self._loss(q, t) for q, t in zip(taken, targets, strict=True)])
        self._step(losses)
        return losses.tolist()

    def _loss(self, q: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """One agent's loss, reduced as `DQNAgent` reduces it (the same float order)."""
        if self.config.loss == "mse":
            return F.mse_loss(q, targets)
        return F.smooth_l1_loss(q, targets)

    def _step(self, losses: torch.Tensor) -> None:
        for agent in self.agents:
            agent.optimizer.zero_grad()
        losses.sum().backward()
        for agent in self.agents:
            agent.apply_gradients()

    def _td_targets(
        self, batches: Sequence[ReplaySample], frames: torch.Tensor, online: StackedWeights
    ) -> torch.Tensor:
        """(N, B) r + gamma max Q(s') per agent, as `DQNAgent._td_targets`."""
        config = self.config
        b = len(batches[0].actions)
        with torch.no_grad():
            next_frames = frames[:, b:]
            rewards = torch.stack([batch.rewards for batch in batches])
            terminated = torch.stack([batch.terminated for batch in batches])
            if not config.target_network:
                next_value = self._q(online, next_frames).max(2).values
            else:
                fasts = [agent._fast_target for agent in self.agents]
                target = stack_weights(fasts).detach()  # type: ignore[arg-type]
                target_q = self._q(target, next_frames)
                if config.double_dqn:
                    choice = self._q(online, next_frames).argmax(2, keepdim=True)
                    next_value = target_q.gather(2, choice).squeeze(2)
                else:
                    next_value = target_q.max(2).values
            return rewards + config.gamma * (1.0 - terminated) * next_value

    def _keras_fit(
        self,
        states: torch.Tensor,
        actions: torch.Tensor,
        td_targets: torch.Tensor,
        weights: StackedWeights,
        rngs: Sequence[np.random.Generator],
    ) -> list[float]:
        """`DQNAgent._keras_fit` for every agent: the targets of all outputs once, then a
        gradient step per shuffled minibatch, the agents' minibatches together."""
        n, b = actions.shape
        with torch.no_grad():
            targets = self._q(weights.detach(), states).float().clone()
            targets.scatter_(2, actions.unsqueeze(2), td_targets.float().unsqueeze(2))
        orders = torch.from_numpy(np.stack([rng.permutation(b) for rng in rngs]))
        orders = orders.to(states.device)
        agent_rows = torch.arange(n, device=states.device).unsqueeze(1)
        losses = []
        for start in range(0, b, self.config.keras_minibatch):
            part = orders[:, start : start + self.config.keras_minibatch]
            weights = stack_weights([agent.fast for agent in self.agents])
            q = self._q(weights, states[agent_rows, part])
            part_targets = targets[agent_rows, part]
            loss = torch.stack([self._loss(*pair) for pair in zip(q, part_targets, strict=True)])
            self._step(loss)
            losses.append(loss.detach())
        return torch.stack(losses).mean(0, dtype=torch.float64).tolist()
