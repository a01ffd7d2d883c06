"""RMSprop and Adam written out, as `torch.optim` computes them.

Why not `torch.optim`: its first optimizer imports torch's compiler stack (dynamo, sympy:
about 800 modules, 67 MB resident and a second or two per process), which a batch of
training processes pays once each for nothing. The update rules are a few lines; the
tests check them against `torch.optim` step for step.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch


class RMSprop:
    """avg = alpha * avg + (1 - alpha) * grad^2;  param -= lr * grad / (sqrt(avg) + eps)."""

    def __init__(self, params: Iterable[torch.Tensor], lr: float, alpha: float, eps: float):
        self.params = list(params)
        self.lr, self.alpha, self.eps = lr, alpha, eps
        self.square_avg = [torch.zeros_like(p) for p in self.params]

    def zero_grad(self) -> None:
        for param in self.params:
            param.grad = None

    @torch.no_grad()
    def step(self) -> None:
        for param, avg in zip(self.params, self.square_avg, strict=True):
            if param.grad is None:
                continue
            grad = param.grad
            avg.mul_(self.alpha).addcmul_(grad, grad, value=1 - self.alpha)
            param.addcdiv_(grad, avg.sqrt().add_(self.eps), value=-self.lr)

    def state_dict(self) -> dict[str, Any]:
        return {"square_avg": [t.clone() for t in self.square_avg]}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for avg, saved in zip(self.square_avg, state["square_avg"], strict=True):
            avg.copy_(saved)


class Adam:
    """Adam with bias correction (Kingma and Ba), as `torch.optim.Adam` without options."""

    def __init__(
        self,
        params: Iterable[torch.Tensor],
        lr: float,
        eps: float,
        betas: tuple[float, float] = (0.9, 0.999),
    ):
        self.params = list(params)
        self.lr, self.eps, self.betas = lr, eps, betas
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        self.steps = 0

    def zero_grad(self) -> None:
        for param in self.params:
            param.grad = None

    @torch.no_grad()
    def step(self) -> None:
        self.steps += 1
        beta1, beta2 = self.betas
        step_size = self.lr / (1 - beta1**self.steps)
        root_correction = (1 - beta2**self.steps) ** 0.5
        for param, avg, avg_sq in zip(self.params, self.exp_avg, self.exp_avg_sq, strict=True):
            if param.grad is None:
                continue
            grad = param.grad
            avg.lerp_(grad, 1 - beta1)
            avg_sq.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
            denom = (avg_sq.sqrt() / root_correction).add_(self.eps)
            param.addcdiv_(avg, denom, value=-step_size)

    def state_dict(self) -> dict[str, Any]:
        return {
            "exp_avg": [t.clone() for t in self.exp_avg],
            "exp_avg_sq": [t.clone() for t in self.exp_avg_sq],
            "steps": self.steps,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for mine, saved in zip(
            self.exp_avg + self.exp_avg_sq, state["exp_avg"] + state["exp_avg_sq"], strict=True
        ):
            mine.copy_(saved)
        self.steps = int(state["steps"])
