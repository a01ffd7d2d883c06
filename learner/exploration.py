"""Epsilon-greedy exploration's schedule (Algorithm 2: epsilon <- epsilon * decay)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class EpsilonSchedule:
    """Epsilon starts at `start` and is multiplied by `decay` after every training update,
    never going below `floor`. Kept as a running product, as the algorithm states it."""

    start: float = 1.0
    decay: float = 0.9995
    floor: float = 0.01
    value: float = -1.0
    """The current epsilon; `start` unless given."""

    def __post_init__(self) -> None:
        if self.value < 0:
            self.value = self.start

    def step(self) -> float:
        """Decay once (after an update) and return the new value."""
        self.value = max(self.floor, self.value * self.decay)
        return self.value

    def updates_to_reach(self, epsilon: float) -> int:
        """How many updates until epsilon is at or below `epsilon` (for docs and tests)."""
        value, updates = self.start, 0
        while value > epsilon and value > self.floor:
            value, updates = max(self.floor, value * self.decay), updates + 1
        return updates
