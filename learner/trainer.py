"""The training loop: the paper's Algorithms 1 and 2, one environment step at a time.

Pretraining (Algorithm 1) takes `pretraining_steps` actions to fill the memory: random,
except that an advising strategy may take some (early advising takes the last
`advice_budget` of them). Training (Algorithm 2) runs `episodes` episodes of
epsilon-greedy action with one update on a sampled batch after every action; strategies
other than early advising may replace an action by the advisor's. Under evaluative
feedback (an `evaluator` in the advisor's place) the learner's own action is always taken,
and on the strategy's steps the evaluator's judgement shapes the reward it remembers (with
`feedback_method="rating_model"`, a model of the judgements shapes the steps not judged too).

`step()` does one environment step and returns its record, so a server can interleave
its own work (pause, stop, progress) between steps; `run()` steps until done.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np
import torch

from learner.agent import DQNAgent
from learner.checkpoint import read_checkpoint, write_checkpoint
from learner.config import DQNConfig
from learner.device import configure_threads, resolve_device
from learner.evaluators import AnyEvaluator, judge
from learner.exploration import EpsilonSchedule
from learner.procedure import Schedule, ScheduledAdvising
from learner.rating_model import RatingModel
from learner.records import EpisodeRecord, StepRecord, stage_of
from learner.replay import ReplayMemory
from learner.seeding import run_streams
from learner.staged import EpisodeInProgress, StagedRun, StepTaken
from learner.strategies import AdviceMoment, AdvisingStrategy, AnyAdvisor, make_strategy

MAX_ACTIONS = 32
"""The most actions a task may have (a person picks one from buttons)."""
RUNTIME_FIELDS = ("device", "torch_threads", "precision", "conv_kernel", "episodes")
"""Config fields a resumed run may change: where it computes, and how long it goes on."""


class Trainer(StagedRun):
    """Trains one learner on one environment; see the module docstring.

    `callbacks` are objects with `on_step(StepRecord)` and/or `on_episode(EpisodeRecord)`;
    a callback returning False stops the trainer after the current step.
    """

    def __init__(
        self,
        env: gym.Env,
        config: DQNConfig | None = None,
        advisor: AnyAdvisor | None = None,
        strategy: AdvisingStrategy | str | None = None,
        seed: int = 0,
        callbacks: Iterable[Any] = (),
        schedule: Schedule | None = None,
        evaluator: AnyEvaluator | None = None,
        feedback_weight: float = 1.0,
        feedback_method: str = "shaping",
        rating_model_steps: int | None = None,
    ) -> None:
        """`schedule`: the procedure control's (`learner.procedure`): advice (from `advisor`,
        a random one) exactly at the recorded advised steps, fits exactly after the recorded
        pretraining steps, and the recorded epsilon at every recorded step. `evaluator`:
        evaluative feedback instead of advice (`learner.evaluators`): on the strategy's
        steps the action taken is judged, and the memory keeps the environment's reward
        plus `feedback_weight` times the judgement. `feedback_method` `rating_model`: the
        judgements also train a `RatingModel` H, and every step not judged after one (for
        `rating_model_steps` after the latest, or to the end) remembers the environment's
        reward plus `feedback_weight` times H of its observation and action."""
        self.config = config = config or DQNConfig()
        self.env = env
        _check_spaces(env)
        self.device = resolve_device(config.device)
        self.threads = configure_threads(config.torch_threads)
        if isinstance(strategy, str):
            strategy = make_strategy(strategy, config.advice_budget)
        self.schedule = schedule
        if schedule is not None:
            strategy = ScheduledAdvising(schedule)
        if advisor is not None and evaluator is not None:
            raise ValueError("a run is advised or evaluated, not both; pass advisor= or evaluator=")
        if evaluator is not None and strategy is not None and not strategy.judges:
            raise ValueError(
                f"the {strategy.name} strategy cannot give an evaluator its steps (it decides "
                "by the advisor's action); use early, alternating or importance"
            )
        giver = advisor if advisor is not None else evaluator
        if giver is not None and strategy is None:
            strategy = make_strategy("early", config.advice_budget)
        if strategy is not None:
            if giver is None:
                raise ValueError(f"the {strategy.name} strategy needs an advisor; pass advisor=")
            strategy.check(config.pretraining_steps, giver)
        self.advisor = advisor
        self.evaluator = evaluator
        self.feedback_weight = float(feedback_weight)
        if feedback_method not in ("shaping", "rating_model"):
            raise ValueError(f"feedback_method is shaping or rating_model, got {feedback_method!r}")
        self.last_judgement: tuple[int, float | None] | None = None
        """The last step judged (its global step) and its judgement (None: no answer)."""
        self.strategy = strategy
        self.callbacks = list(callbacks)
        self.seed = seed
        init, env_seeds, actions, memory = run_streams(seed)
        assert env.observation_space.shape is not None, "checked by _check_spaces"
        shape = tuple(int(n) for n in env.observation_space.shape)
        self.n_actions = int(cast(gym.spaces.Discrete, env.action_space).n)
        """How many actions the task has (the network's outputs)."""
        self.rating_model = (
            RatingModel(self.n_actions, shape, rating_model_steps)
            if evaluator is not None and feedback_method == "rating_model"
            else None
        )
        """The model of the judgements that shapes the steps not judged, if the method's."""
        self.agent = DQNAgent(
            config,
            self.device,
            self.n_actions,
            shape,
            int(init.generate_state(1)[0]),
        )
        self.memory = ReplayMemory(
            config.memory_size, self.agent.frame_shape, self.device, dtype=self.agent.frame_dtype
        )
        self.epsilon = EpsilonSchedule(
            config.epsilon_start, config.epsilon_decay, config.epsilon_min
        )
        self._env_rng = np.random.default_rng(env_seeds)
        self._action_rng = np.random.default_rng(actions)
        self._memory_rng = np.random.default_rng(memory)
        self.global_step = 0
        """Environment steps taken so far."""
        self.episodes_done = {"pretrain": 0, "train": 0}
        self.episode_record: EpisodeRecord | None = None
        """The record of the episode the last step ended, else None."""
        self._episode: EpisodeInProgress | None = None
        self._stopped = False

    def step(self) -> StepRecord:
        """Take one environment step (resetting first if no episode is in progress)."""
        step = self._act(self.agent.q_values(self._begin_step()))
        loss = None
        if step.updates:
            batch = self.memory.sample(self.config.batch_size, self._memory_rng)
            loss = self.agent.update(batch, self._memory_rng)
        return self._end_step(step, loss)

    def _act(self, q_values: np.ndarray) -> StepTaken:
        """Choose (and maybe get advised) an action on the learner's `q_values` of the
        current image, take it and remember the transition; the update, if `updates`, is
        the caller's (`step`, or a population updating its agents together)."""
        episode = self._episode
        assert episode is not None
        config = self.config
        global_step = self.global_step + 1
        pretraining = episode.stage == "pretrain"
        greedy = int(np.argmax(q_values))
        if self.schedule is not None:
            recorded = self.schedule.epsilon_at(global_step)
            if recorded is not None:
                self.epsilon.value = recorded
        rng_state = self._action_rng.bit_generator.state
        if pretraining:
            source = "random"
            intended = int(self._action_rng.integers(self.n_actions))
        else:
            explore = bool(self._action_rng.random() < self.epsilon.value)
            random_action = int(self._action_rng.integers(self.n_actions))
            source = "exploration" if explore else "greedy"
            intended = random_action if explore else greedy
        advised, judged = None, False
        if self.strategy is not None and (self.advisor, self.evaluator) != (None, None):
            moment = AdviceMoment(
                episode.obs, episode.info, episode.stage, global_step,
                config.pretraining_steps, intended, greedy,
            )  # fmt: skip
            try:
                if self.evaluator is not None:
                    judged = self.strategy.in_window(moment, self.evaluator)
                else:
                    advised = self.strategy.advise(moment, self.advisor, self.n_actions)  # type: ignore[arg-type]
            except BaseException:
                self._action_rng.bit_generator.state = rng_state  # the step never happened
                raise
        action = intended if advised is None else advised
        if advised is not None:
            source = "advisor"  # advice is a source, not a stage

        obs, reward, terminated, truncated, info = self.env.step(action)
        reward, terminated = float(reward), bool(terminated)
        remembered = reward
        if judged:
            assert self.evaluator is not None
            judgement = judge(self.evaluator, moment)  # after the step: it judges what was done
            self.last_judgement = (global_step, judgement)
            if judgement is not None:
                remembered = reward + self.feedback_weight * judgement
                if self.rating_model is not None:
                    self.rating_model.learn(episode.obs, action, judgement, global_step)
        elif self.rating_model is not None and self.rating_model.shapes(global_step):
            rating = self.rating_model.predict(episode.obs, action)
            remembered = reward + self.feedback_weight * rating
        self.global_step = global_step
        episode.actions.append(action)
        truncated = bool(truncated) or len(episode.actions) >= config.max_episode_steps
        if pretraining and global_step == config.pretraining_steps:
            truncated = truncated or not terminated  # pretraining ends: cut its last episode
        self.memory.add(
            self.agent.encode(episode.obs), action, remembered,
            self.agent.encode(obs), terminated, truncated,
        )  # fmt: skip
        updates = self._updates_now(
            pretraining, advised is not None or judged, terminated or truncated, global_step
        )
        return StepTaken(
            episode.stage, source, action, greedy, q_values, advised, obs, reward, terminated,
            truncated, info, self.epsilon.value, updates,
        )  # fmt: skip

    def _after_update(self) -> None:
        self.epsilon.step()

    def _updates_now(self, pretraining: bool, advised: bool, final: bool, global_step: int) -> bool:
        """Whether this step is followed by an update: every training step (Algorithm 2),
        with the authors' options also advised pretraining steps once the memory holds a
        batch, and not an episode's final step; in pretraining, a schedule's fits."""
        config = self.config
        if pretraining and self.schedule is not None:
            return global_step in self.schedule.fitted and len(self.memory) >= config.batch_size
        if final and not config.update_on_final_step:
            return False
        if pretraining:
            return advised and config.update_during_advice and len(self.memory) >= config.batch_size
        return True

    def save_checkpoint(
        self, path: str | Path, metadata: dict[str, Any] | None = None, memory: bool = True
    ) -> None:
        """Everything needed to continue exactly as if never stopped; `metadata` (plain
        JSON-like values) is stored alongside for the caller, e.g. how to rebuild the
        advisor. `memory=False` leaves out the replay memory (most of the file at paper
        scale): the checkpoint still advises and can be inspected, but cannot resume."""
        episode = self._episode
        write_checkpoint(
            path,
            {
                "metadata": metadata or {},
                "config": self.config.to_dict(),
                "seed": self.seed,
                "agent": self.agent.state_dict(),
                "image_shape": list(self.agent.network.observation_shape),
                "memory": self.memory.state_dict() if memory else None,
                "epsilon": self.epsilon.value,
                "global_step": self.global_step,
                "episodes_done": dict(self.episodes_done),
                "rngs": {
                    "env": self._env_rng.bit_generator.state,
                    "action": self._action_rng.bit_generator.state,
                    "memory": self._memory_rng.bit_generator.state,
                },
                "episode": None if episode is None else _episode_state(episode),
                "strategy": self.strategy.state_dict() if self.strategy else None,
                "advisor": _advisor_state(self.advisor),
                "evaluator": _advisor_state(self.evaluator),
                "rating_model": _advisor_state(self.rating_model),
            },
        )

    def load_checkpoint(self, path: str | Path) -> None:
        """Continue from a checkpoint of a run with the same config (except the
        `RUNTIME_FIELDS`), strategy and advisor kind. A partial episode is rebuilt by
        resetting the environment with its seed and replaying its actions."""
        state = read_checkpoint(path)
        if state["memory"] is None:
            raise ValueError(
                f"{path} was saved without its replay memory (a finished run's final "
                "checkpoint): it can advise, not resume; keep_replay_memory keeps it"
            )
        saved = DQNConfig.from_dict(state["config"]).to_dict()
        mine = self.config.to_dict()
        differ = [k for k in mine if k not in RUNTIME_FIELDS and saved[k] != mine[k]]
        if differ:
            changes = ", ".join(f"{k}: {saved[k]!r} (checkpoint) vs {mine[k]!r}" for k in differ)
            raise ValueError(f"the checkpoint was made with another config: {changes}")
        if (state["strategy"] is None) != (self.strategy is None):
            raise ValueError(
                "the checkpoint was made "
                + ("without" if state["strategy"] is None else "with")
                + " an advising strategy; create the Trainer the same way"
            )
        if self.strategy is not None:
            self.strategy.load_state_dict(state["strategy"])
        if state["advisor"] is not None and hasattr(self.advisor, "load_state_dict"):
            self.advisor.load_state_dict(state["advisor"])  # type: ignore[union-attr]
        if state.get("evaluator") is not None and hasattr(self.evaluator, "load_state_dict"):
            self.evaluator.load_state_dict(state["evaluator"])  # type: ignore[union-attr]
        saved_model = state.get("rating_model")
        if (saved_model is None) != (self.rating_model is None):
            raise ValueError(
                "the checkpoint was made "
                + ("without" if saved_model is None else "with")
                + " a rating model (feedback_method rating_model); create the Trainer the same way"
            )
        if self.rating_model is not None and saved_model is not None:
            self.rating_model.load_state_dict(saved_model)
        self.seed = int(state["seed"])
        self.agent.load_state_dict(state["agent"])
        self.memory.load_state_dict(state["memory"])
        self.epsilon.value = float(state["epsilon"])
        self.global_step = int(state["global_step"])
        self.episodes_done = {stage_of(k): int(v) for k, v in state["episodes_done"].items()}
        self._env_rng.bit_generator.state = state["rngs"]["env"]
        self._action_rng.bit_generator.state = state["rngs"]["action"]
        self._memory_rng.bit_generator.state = state["rngs"]["memory"]
        in_progress = state["episode"]
        self._episode = None if in_progress is None else replay_episode(self.env, in_progress)
        self.episode_record = None
        self._stopped = False


def replay_episode(env: gym.Env, saved: dict[str, Any]) -> EpisodeInProgress:
    """The checkpointed episode in progress, rebuilt by resetting `env` with its seed and
    replaying its actions (any learner whose checkpoint keeps `_episode_state`)."""
    obs, info = env.reset(seed=int(saved["reset_seed"]))
    actions = [int(a) for a in saved["actions"]]
    ended = False
    for action in actions:
        if ended:
            break
        obs, _, terminated, truncated, info = env.step(action)
        ended = terminated or truncated
    if ended or not np.array_equal(obs, saved["obs"].numpy()):
        raise RuntimeError(
            "replaying the checkpoint's episode from its reset seed and actions did not "
            "give the saved image: the environment is not deterministic, or not the one "
            "(or not configured as the one) the checkpoint was made with"
        )
    return EpisodeInProgress(
        stage=stage_of(saved["stage"]),
        number=int(saved["number"]),
        reset_seed=int(saved["reset_seed"]),
        obs=obs,
        info=info,
        first_global_step=int(saved["first_global_step"]),
        actions=actions,
        collected_reward=float(saved["collected_reward"]),
        advised_steps=int(saved["advised_steps"]),
        loss_sum=float(saved["loss_sum"]),
        loss_count=int(saved["loss_count"]),
    )


def _episode_state(episode: EpisodeInProgress) -> dict[str, Any]:
    return {
        "stage": episode.stage,
        "number": episode.number,
        "reset_seed": episode.reset_seed,
        "actions": list(episode.actions),
        "obs": torch.from_numpy(np.array(episode.obs)),
        "first_global_step": episode.first_global_step,
        "collected_reward": episode.collected_reward,
        "advised_steps": episode.advised_steps,
        "loss_sum": episode.loss_sum,
        "loss_count": episode.loss_count,
    }


def _advisor_state(
    advisor: AnyAdvisor | AnyEvaluator | RatingModel | None,
) -> dict[str, Any] | None:
    state_dict = getattr(advisor, "state_dict", None)
    return state_dict() if callable(state_dict) else None


def _check_spaces(env: gym.Env) -> None:
    """Images (H, W, 3) of uint8 for the paper's network, or float vectors (n,) for the
    dense one; discrete actions."""
    obs_space, action_space = env.observation_space, env.action_space
    box = isinstance(obs_space, gym.spaces.Box)
    shape = obs_space.shape or ()
    vector = box and len(shape) == 1 and np.issubdtype(obs_space.dtype, np.floating)
    image = box and obs_space.dtype == np.uint8 and len(shape) == 3 and shape[2] == 3
    if not (vector or image):
        raise ValueError(
            "the learner needs uint8 RGB image observations (H, W, 3) or float vectors (n,), "
            f"got {obs_space}"
        )
    if not (isinstance(action_space, gym.spaces.Discrete) and 2 <= action_space.n <= MAX_ACTIONS):
        raise ValueError(
            f"the learner needs Discrete(n) actions, n from 2 to {MAX_ACTIONS}, got {action_space}"
        )
    height, width = shape[:2] if image else (16, 16)
    if height % 8 or width % 8 or height < 16 or width < 16:
        raise ValueError(
            "the learner needs images whose sides are multiples of 8, at least 16, "
            f"got {height}x{width}"
        )
