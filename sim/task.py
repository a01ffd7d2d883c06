"""The sorting task's bookkeeping and reward (the paper's Eq. "reward", SPEC 1).

Knows objects by name and (shape, color) only, never PyBullet: the env reports what the
arm did in a step (`StepEvents`), the task says what it earned.
"""

from dataclasses import dataclass, field
from typing import Any

from sim.rewards import RewardScheme, step_penalty
from sim.rules import Side, SortRule

REWARD_COMPLETE = 1.0
"""The placement that completes the task: center empty, every placement correct."""
REWARD_CORRECT = 0.4
"""Any other correct placement."""
REWARD_WRONG = -1.0
"""An incorrect placement; it ends the episode."""


@dataclass(frozen=True)
class StepEvents:
    """What happened to the objects during one step."""

    grabbed: str | None = None
    """The object picked from the center table."""
    placed: tuple[str, Side] | None = None
    """The object put down and the side table it went to."""
    lost: tuple[str, ...] = ()
    """Objects that left the center table other than by being grabbed."""


@dataclass
class SortingTask:
    """Which objects are where, and the reward for each step."""

    rule: SortRule
    """Where each object belongs."""
    kinds: dict[str, tuple[str, str]]
    """(shape, color) of each object, by name, in a fixed order."""
    reward_scheme: RewardScheme = "paper"
    """What a step without a placement costs (`sim.rewards.step_penalty`)."""
    remaining: list[str] = field(default_factory=list)
    """Objects still on the center table, in `kinds` order."""
    held: str | None = None
    """The object in the suction cup."""
    placed_correct: int = 0
    """Objects put on the side table they belong on."""
    misplaced: int = 0
    """Objects put on the wrong side table (at most one: it ends the episode)."""
    lost: int = 0
    """Objects that left the center table other than by the cup (knocked off)."""
    episode_step: int = 0
    """Steps taken in this episode."""
    succeeded: bool = False
    """The center table is empty, nothing is held and nothing was misplaced."""

    def reset(self) -> None:
        self.remaining = list(self.kinds)
        self.held = None
        self.placed_correct = self.misplaced = self.lost = self.episode_step = 0
        self.succeeded = False

    def update(self, events: StepEvents) -> tuple[float, bool]:
        """Book one step's events; returns (reward, terminated)."""
        self.episode_step += 1
        if events.grabbed is not None:
            assert self.held is None and events.grabbed in self.remaining
            self.remaining.remove(events.grabbed)
            self.held = events.grabbed
        for name in events.lost:
            assert name in self.remaining
            self.remaining.remove(name)
            self.lost += 1
        reward = step_penalty(self.reward_scheme, self.episode_step)
        if events.placed is not None:
            name, side = events.placed
            assert name == self.held
            self.held = None
            if self.rule.side(*self.kinds[name]) != side:
                self.misplaced += 1
                return REWARD_WRONG, True
            self.placed_correct += 1
            reward = REWARD_COMPLETE if self._complete() else REWARD_CORRECT
        self.succeeded = self._complete()
        return reward, self.succeeded

    def _complete(self) -> bool:
        return not self.remaining and self.held is None and self.misplaced == 0

    def _kind(self, name: str) -> dict[str, str]:
        shape, color = self.kinds[name]
        return {"shape": shape, "color": color}

    def info(self) -> dict[str, Any]:
        """The ground truth the env reports in `info` (fresh objects, safe to keep)."""
        return {
            "held": None if self.held is None else self._kind(self.held),
            "remaining": [self._kind(name) for name in self.remaining],
            "placed_correct": self.placed_correct,
            "misplaced": self.misplaced,
            "lost": self.lost,
            "episode_step": self.episode_step,
            "is_success": self.succeeded,
        }
