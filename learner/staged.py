"""The stage-and-episode loop both trainers offer their callers (the worker, the batch, the
CLI), and its bookkeeping: an episode begins with a seeded reset, each step is recorded and
told to the callbacks, an episode ends with its record. `learner.trainer.Trainer` and
`learner.sb3_dqn.SB3DQNTrainer` differ in how they choose an action and learn, not here."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from learner.records import EpisodeRecord, Stage, StepRecord, observation_hash
from learner.seeding import draw_reset_seed
from sim.rewards import step_outcome

if TYPE_CHECKING:
    import gymnasium as gym

    from learner.strategies import AdvisingStrategy


@dataclass
class EpisodeInProgress:
    """The episode in progress, with what it takes to rebuild it: its reset seed and
    actions (the environment is replayed from them on resume)."""

    stage: str
    number: int
    reset_seed: int
    obs: np.ndarray
    info: dict[str, Any]
    first_global_step: int
    actions: list[int] = field(default_factory=list)
    collected_reward: float = 0.0
    advised_steps: int = 0
    loss_sum: float = 0.0
    loss_count: int = 0


class StepTaken(NamedTuple):
    """A step taken, before its update: what `StagedRun._end_step` records."""

    stage: str
    source: str
    action: int
    greedy: int
    q_values: np.ndarray
    advised: int | None
    obs: np.ndarray
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    epsilon: float
    """Epsilon as the action was chosen (before this step's update decays it)."""
    updates: bool
    """Whether an update follows this step."""


class StagedRun:
    """The stage-and-episode loop a trainer offers its callers, shared by
    `learner.trainer.Trainer` and `learner.sb3_dqn.SB3DQNTrainer`: they set `config`, `env`,
    `callbacks`, `global_step`, `episodes_done`, `episode_record`, `_episode`, `_env_rng`
    `_stopped` and `epsilon`, and define `step()` (which ends in `_end_step`)."""

    config: Any
    env: gym.Env[Any, Any]
    callbacks: Sequence[Any]
    global_step: int
    episodes_done: dict[str, int]
    episode_record: EpisodeRecord | None
    _episode: EpisodeInProgress | None
    _env_rng: np.random.Generator
    _stopped: bool
    strategy: AdvisingStrategy | None = None
    epsilon: Any
    """Exploration: its `value` is epsilon after the last update (the episode record's).
    Read as a value, not asked of the subclass, so the loop never calls back into it."""

    def step(self) -> StepRecord:
        raise NotImplementedError

    def _after_update(self) -> None:
        """What an update is followed by, before its step is recorded (e.g. a decay)."""

    @property
    def stage(self) -> Stage:
        """`pretrain` or `train`: the stage of the next step."""
        return "pretrain" if self.global_step < self.config.pretraining_steps else "train"

    @property
    def done(self) -> bool:
        return self._stopped or self.episodes_done["train"] >= self.config.episodes

    @property
    def observation(self) -> Any:
        """The image the learner sees now; None between episodes."""
        return None if self._episode is None else self._episode.obs

    def stop(self) -> None:
        """Make `done` true; `run` returns after the current step."""
        self._stopped = True

    def run(self) -> list[EpisodeRecord]:
        """Step until done; returns the training episodes finished in this call."""
        finished = []
        while not self.done:
            self.step()
            if self.episode_record is not None and self.episode_record.stage == "train":
                finished.append(self.episode_record)
        return finished

    def _begin_step(self) -> np.ndarray:
        """The image the next action is chosen on (resetting first if needed)."""
        if self.done:
            raise RuntimeError("the trainer is done (all episodes run, or stopped)")
        if self._episode is None:
            self._begin_episode()
        assert self._episode is not None
        return self._episode.obs

    def _begin_episode(self) -> None:
        stage = self.stage
        reset_seed = draw_reset_seed(self._env_rng)
        obs, info = self.env.reset(seed=reset_seed)
        number = self.episodes_done[stage] + 1
        self._episode = EpisodeInProgress(
            stage, number, reset_seed, obs, info, self.global_step + 1
        )

    def _end_step(self, step: StepTaken, loss: float | None) -> StepRecord:
        """Account for the update's `loss` (None: no update), record the step, end the
        episode if it ended, and tell the callbacks."""
        episode = self._episode
        assert episode is not None
        if loss is not None:
            self._after_update()
            episode.loss_sum += loss
            episode.loss_count += 1
        episode.collected_reward += step.reward
        episode.advised_steps += step.advised is not None
        q_values = step.q_values
        record = StepRecord(
            global_step=self.global_step,
            stage=step.stage,  # type: ignore[arg-type]
            episode=episode.number,
            episode_step=len(episode.actions),
            action=step.action,
            action_source=step.source,  # type: ignore[arg-type]
            greedy_action=step.greedy,
            **_q_columns(q_values),
            advised_action=step.advised,
            advice_remaining=self.strategy.remaining if self.strategy else 0,
            reward=step.reward,
            terminated=step.terminated,
            truncated=step.truncated,
            observation_hash=observation_hash(episode.obs),
            outcome=step_outcome(episode.info, step.info),  # type: ignore[arg-type]
            epsilon=step.epsilon,
            loss=loss,
        )
        self.episode_record = None
        if step.terminated or step.truncated:
            self.episode_record = self._finish_episode(step.info, step.terminated, step.truncated)
        else:
            episode.obs, episode.info = step.obs, step.info
        self._notify("on_step", record)
        if self.episode_record is not None:
            self._notify("on_episode", self.episode_record)
        return record

    def _finish_episode(
        self, info: dict[str, Any], terminated: bool, truncated: bool
    ) -> EpisodeRecord:
        episode = self._episode
        assert episode is not None
        self._episode = None
        self.episodes_done[episode.stage] += 1
        misplaced = int(info.get("misplaced", 0))
        return EpisodeRecord(
            stage=episode.stage,  # type: ignore[arg-type]
            episode=episode.number,
            collected_reward=episode.collected_reward,
            steps=len(episode.actions),
            placed_correct=int(info.get("placed_correct", 0)),
            misplaced=misplaced,
            lost=int(info.get("lost", 0)),
            # Gymnasium's `is_success` where the task states it (the sorting robot's equals
            # this fallback: it ends an episode only by finishing it or by a misplacement)
            success=bool(info.get("is_success", terminated and misplaced == 0)),
            terminated=terminated,
            truncated=truncated,
            advised_steps=episode.advised_steps,
            epsilon=float(self.epsilon.value),
            mean_loss=episode.loss_sum / episode.loss_count if episode.loss_count else None,
            first_global_step=episode.first_global_step,
            last_global_step=self.global_step,
            reset_seed=episode.reset_seed,
        )

    def _notify(self, method: str, record: StepRecord | EpisodeRecord) -> None:
        for callback in self.callbacks:
            handler = getattr(callback, method, None)
            if handler is not None and handler(record) is False:
                self._stopped = True


def _q_columns(q_values: np.ndarray) -> dict[str, Any]:
    """A step's Q-values as its record's columns: the four named ones for four actions,
    else a JSON list."""
    if len(q_values) == 4:
        named = dict(zip(Q_NAMES, map(float, q_values), strict=True))
        return {**named, "q_values": None}
    listed = json.dumps([float(q) for q in q_values])
    return {**dict.fromkeys(Q_NAMES), "q_values": listed}


Q_NAMES = ("q_grab", "q_move_right", "q_move_left", "q_drop")
