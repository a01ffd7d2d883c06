"""A model of the trainer's rating, H(s, a), that shapes the steps nobody rated.

Evaluative feedback's second learner method (`RunSpec.feedback_method` `rating_model`):
as in TAMER+RL's reward shaping (Knox and Stone 2010) and Deep TAMER (Warnell et al.
2018), the ratings received so far train a regressor of the rating, and every later step
the evaluator was not asked about is remembered with the environment's reward plus
`w * H(s, a)`, so a rating counts beyond the step it was given on.

H is linear in fixed features of the observation, one weight vector per action (TAMER's
linear model; Deep TAMER's features come from an encoder trained before and kept fixed,
these from average pooling): an image pooled to an 8 x 8 grid of mean colours in [0, 1],
a vector observation as it is, each with a constant 1. Fixed features keep the model a
function of the ratings alone (the learner's own features change under every update), and
cheap: a ridge regression over all the ratings of an action, refit when one arrives.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

GRID = 8
"""An image's side in pooled cells (the learner takes sides that are multiples of 8)."""
RIDGE = 1.0
"""The ridge penalty: an action rated n times the same on one observation is predicted
n|f|^2 / (1 + n|f|^2) of that rating, and an action never rated 0 (no shaping)."""


def features(obs: np.ndarray) -> np.ndarray:
    """The observation's features: an image's 8 x 8 grid of mean colours in [0, 1], or a
    vector observation's values, then a constant 1."""
    if obs.ndim == 3:
        height, width, channels = obs.shape
        cells = obs.reshape(GRID, height // GRID, GRID, width // GRID, channels)
        pooled = cells.mean(axis=(1, 3), dtype=np.float64).ravel() / 255.0
    else:
        pooled = np.asarray(obs, dtype=np.float64).ravel()
    return np.append(pooled, 1.0)


class RatingModel:
    """H(s, a) trained on the ratings received so far; `steps`: how many steps after the
    latest rating it shapes (None: to the end of the run)."""

    def __init__(
        self, n_actions: int, observation_shape: tuple[int, ...], steps: int | None = None
    ) -> None:
        size = features(np.zeros(observation_shape)).size
        self.steps = steps
        self.gram = np.stack([RIDGE * np.eye(size) for _ in range(n_actions)])
        """Per action: the ridge penalty plus the sum of f f^T over its ratings."""
        self.targets = np.zeros((n_actions, size))
        """Per action: the sum of f times the rating over its ratings."""
        self.ratings = 0
        self.last_rated_step: int | None = None
        self._weights = np.zeros((n_actions, size))

    def learn(self, obs: np.ndarray, action: int, rating: float, global_step: int) -> None:
        """Fit H to one more rating of `action` taken on `obs`."""
        f = features(obs)
        self.gram[action] += np.outer(f, f)
        self.targets[action] += rating * f
        self._weights[action] = np.linalg.solve(self.gram[action], self.targets[action])
        self.ratings += 1
        self.last_rated_step = global_step

    def predict(self, obs: np.ndarray, action: int) -> float:
        """H(obs, action), within the ratings' range [-1, 1]."""
        return float(np.clip(self._weights[action] @ features(obs), -1.0, 1.0))

    def shapes(self, global_step: int) -> bool:
        """Whether the step `global_step` is shaped: a rating was received, and (with
        `steps`) at most `steps` steps ago."""
        if self.last_rated_step is None:
            return False
        return self.steps is None or global_step - self.last_rated_step <= self.steps

    def state_dict(self) -> dict[str, Any]:
        return {
            "gram": torch.from_numpy(self.gram.copy()),
            "targets": torch.from_numpy(self.targets.copy()),
            "weights": torch.from_numpy(self._weights.copy()),
            "ratings": self.ratings,
            "last_rated_step": self.last_rated_step,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.gram = state["gram"].numpy().copy()
        self.targets = state["targets"].numpy().copy()
        self._weights = state["weights"].numpy().copy()
        self.ratings = int(state["ratings"])
        last = state["last_rated_step"]
        self.last_rated_step = None if last is None else int(last)
