"""An independent baseline: Stable-Baselines3's DQN, stepped like the paper's learner.

A study shows how the paper's learner compares with a standard one only if both meet the
same scenes under the same stages and are recorded the same way. So this trainer has the
`Trainer`'s contract (`step()`, `done`, `stage`, the same `StepRecord`s and
`EpisodeRecord`s to its callbacks, checkpoints that resume exactly), its stages
(`pretraining_steps` random actions, the last pretraining episode cut, then `episodes`
training episodes), and its episode reset seeds; the learner itself is SB3's: its
`CnnPolicy` (NatureCNN) on a task's images, its `MlpPolicy` on a task's float vectors (as
the paper's learner takes its dense network for them), its replay buffer, linear
exploration schedule, target network, Huber loss and Adam, and its own `train()` and
`_on_step()`. Only SB3's rollout loop is spelled out here (one environment, no VecEnv), as
`OffPolicyAlgorithm.collect_rollouts` and `learn` do it, so that every step can be
recorded and the run paused between steps.

The paper's hyperparameters become SB3's where SB3 has the same knob
(`learner.sb3_spec.sb3_hyperparameters`, torch-free); the session stores them, and the
report's audit shows them.
Stable-Baselines3 is an optional extra (`pip install 'ideeprl[sb3]'`), imported only when
a trainer is made.
"""

from __future__ import annotations

import importlib.util
import random
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from learner.config import DQNConfig
from learner.records import EpisodeRecord, StepRecord, stage_of
from learner.sb3_spec import VECTOR_POLICY, sb3_hyperparameters
from learner.seeding import run_streams
from learner.staged import EpisodeInProgress, StagedRun, StepTaken

FORMAT = "ideeprl-sb3-dqn-checkpoint"
VERSION = 1
MISSING = (
    "the sb3-dqn baseline needs Stable-Baselines3: pip install 'ideeprl[sb3]' "
    "(or pip install stable-baselines3 --no-deps, keeping this torch)"
)

RUNTIME_FIELDS = ("device", "torch_threads", "episodes")


def available() -> bool:
    """Whether Stable-Baselines3 can be imported here (without importing it)."""
    return importlib.util.find_spec("stable_baselines3") is not None


class _Exploration:
    """SB3's exploration rate, read as the staged loop reads a trainer's epsilon."""

    def __init__(self, model: Any) -> None:
        self.model = model

    @property
    def value(self) -> float:
        return float(self.model.exploration_rate)


class SB3DQNTrainer(StagedRun):
    """Trains SB3's DQN on one environment with the `Trainer`'s contract; see the module
    docstring. `hyperparameters`: the `sb3_*` fields (default `sb3_hyperparameters(config)`);
    the config gives the stages (`pretraining_steps`, `episodes`, `max_episode_steps`) and
    where to compute (`device`, `torch_threads`)."""

    def __init__(
        self,
        env: Any,
        config: DQNConfig | None = None,
        seed: int = 0,
        callbacks: Iterable[Any] = (),
        hyperparameters: dict[str, Any] | None = None,
    ) -> None:
        try:
            from stable_baselines3 import DQN
            from stable_baselines3.common.logger import Logger
        except ImportError:
            raise RuntimeError(MISSING) from None
        from learner.device import configure_threads, resolve_device
        from learner.trainer import _check_spaces

        self.config = config = config or DQNConfig()
        self.env = env
        _check_spaces(env)
        self.vector = len(env.observation_space.shape or ()) == 1
        self.hyperparameters = h = dict(hyperparameters or sb3_hyperparameters(config))
        if self.vector:
            h["sb3_policy"] = VECTOR_POLICY
        self.device = resolve_device(config.device)
        self.threads = configure_threads(config.torch_threads)
        self.callbacks = list(callbacks)
        self.seed = seed
        _, env_seeds, _, _ = run_streams(seed)
        self._env_rng = np.random.default_rng(env_seeds)  # the Trainer's reset seeds
        model = DQN(
            h["sb3_policy"],
            None,  # type: ignore[arg-type]  # SB3 takes no env here (its annotation says otherwise)
            learning_rate=h["sb3_learning_rate"],
            buffer_size=h["sb3_buffer_size"],
            learning_starts=h["sb3_learning_starts"],
            batch_size=h["sb3_batch_size"],
            tau=h["sb3_tau"],
            gamma=h["sb3_gamma"],
            train_freq=h["sb3_train_freq"],
            gradient_steps=h["sb3_gradient_steps"],
            target_update_interval=h["sb3_target_update_interval"],
            exploration_fraction=1.0,
            exploration_initial_eps=h["sb3_exploration_initial_eps"],
            exploration_final_eps=h["sb3_exploration_final_eps"],
            max_grad_norm=h["sb3_max_grad_norm"],
            device=self.device,
            seed=seed,
            _init_setup_model=False,
        )
        # SB3 builds its networks from the spaces; the env is stepped here, not by SB3.
        model.observation_space = _sb3_space(env.observation_space)
        model.action_space = spaces.Discrete(int(env.action_space.n))  # the task's actions
        model.n_envs = 1
        model._setup_model()
        model.set_logger(Logger(None, []))  # no outputs, and no folder made in /tmp
        model.exploration_rate = h["sb3_exploration_initial_eps"]
        self.model = model
        self.epsilon = _Exploration(model)
        self.global_step = 0
        self.episodes_done = {"pretrain": 0, "train": 0}
        self.episode_record: EpisodeRecord | None = None
        self._episode: EpisodeInProgress | None = None
        self._stopped = False

    def _progress_remaining(self) -> float:
        """SB3's progress, counted in training steps: its linear schedule then reaches the
        final epsilon after `sb3_exploration_steps` of them, as the paper's decay does."""
        steps = self.hyperparameters["sb3_exploration_steps"]
        trained = max(0, self.model.num_timesteps - self.model.learning_starts)
        return 1.0 - trained / steps if steps else 0.0

    def step(self) -> StepRecord:
        """One environment step: SB3's action choice, transition storage, `_on_step` and
        `train`, in `collect_rollouts`' and `learn`'s order."""
        import torch

        self._begin_step()
        episode = self._episode
        assert episode is not None
        model = self.model
        pretraining = episode.stage == "pretrain"
        model.policy.set_training_mode(False)
        obs = self._sb3_obs(episode.obs)
        with torch.no_grad():
            tensor, _ = model.policy.obs_to_tensor(obs)
            q_values = model.q_net(tensor)[0].cpu().numpy()
        greedy = int(np.argmax(q_values))
        epsilon = float(model.exploration_rate)
        if model.num_timesteps < model.learning_starts:  # SB3's `_sample_action`
            stage, source = "pretrain", "random"
            action = int(model.action_space.sample())
        elif np.random.rand() < model.exploration_rate:  # `DQN.predict`, spelled out
            stage, source = "train", "exploration"
            action = int(model.action_space.sample())
        else:
            stage, source = "train", "greedy"
            action = greedy

        next_obs, reward, terminated, truncated, info = self.env.step(action)
        reward, terminated = float(reward), bool(terminated)
        self.global_step += 1
        episode.actions.append(action)
        truncated = bool(truncated) or len(episode.actions) >= self.config.max_episode_steps
        if pretraining and self.global_step == self.config.pretraining_steps:
            truncated = truncated or not terminated  # pretraining ends: cut its last episode
        model.num_timesteps += 1
        assert model.replay_buffer is not None, "made by _setup_model"
        model.replay_buffer.add(
            obs,
            self._sb3_obs(next_obs),
            np.array([[action]]),
            np.array([reward], dtype=np.float32),
            np.array([terminated or truncated]),
            [{"TimeLimit.truncated": truncated and not terminated}],
        )
        model._current_progress_remaining = self._progress_remaining()
        model._on_step()
        loss = None
        if model.num_timesteps > model.learning_starts:
            model.train(gradient_steps=model.gradient_steps, batch_size=model.batch_size)
            loss = float(model.logger.name_to_value["train/loss"])
        taken = StepTaken(
            stage, source, action, greedy, q_values, None, next_obs, reward, terminated,
            truncated, info, epsilon, loss is not None,
        )  # fmt: skip
        return self._end_step(taken, loss)

    def _sb3_obs(self, obs: np.ndarray) -> np.ndarray:
        """An observation as SB3's policy takes it: a batch of one, images channels first."""
        if self.vector:
            return np.asarray(obs, np.float32)[None]
        return _channels_first(obs)

    # --- checkpoints -----------------------------------------------------------------------
    def save_checkpoint(
        self, path: str | Path, metadata: dict[str, Any] | None = None, memory: bool = True
    ) -> None:
        """Everything needed to continue exactly: SB3's networks, optimizer, counters and
        replay buffer, and every random generator SB3 draws from (numpy's and torch's
        global ones, the action space's). `memory=False` leaves the buffer out."""
        import torch

        from learner.checkpoint import write_checkpoint
        from learner.trainer import _episode_state

        model = self.model
        numpy_state = np.random.get_state(legacy=False)
        numpy_state["state"]["key"] = numpy_state["state"]["key"].tolist()
        write_checkpoint(
            path,
            {
                "format": FORMAT,
                "version": VERSION,
                "metadata": metadata or {},
                "config": self.config.to_dict(),
                "hyperparameters": dict(self.hyperparameters),
                "seed": self.seed,
                "policy": model.policy.state_dict(),
                "optimizer": model.policy.optimizer.state_dict(),
                "buffer": _buffer_state(model.replay_buffer) if memory else None,
                "counters": {
                    "num_timesteps": model.num_timesteps,
                    "n_calls": model._n_calls,
                    "n_updates": model._n_updates,
                    "exploration_rate": float(model.exploration_rate),
                },
                "global_step": self.global_step,
                "episodes_done": dict(self.episodes_done),
                "rngs": {
                    "env": self._env_rng.bit_generator.state,
                    "numpy": numpy_state,
                    "python": random.getstate(),
                    "torch": torch.get_rng_state(),
                    "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
                    "action_space": model.action_space.np_random.bit_generator.state,
                },
                "episode": None if self._episode is None else _episode_state(self._episode),
            },
        )

    def load_checkpoint(self, path: str | Path) -> None:
        """Continue from a checkpoint of a run with the same config and hyperparameters (the
        config's runtime fields aside); the episode in progress is replayed."""
        import torch

        from learner.trainer import replay_episode

        state = torch.load(Path(path), map_location="cpu", weights_only=True)
        if not isinstance(state, dict) or state.get("format") != FORMAT:
            raise ValueError(f"{path} is not an sb3-dqn checkpoint")
        if state["buffer"] is None:
            raise ValueError(
                f"{path} was saved without its replay buffer (a finished run's final "
                "checkpoint): it cannot resume; keep_replay_memory keeps it"
            )
        saved, mine = state["config"], self.config.to_dict()
        differ = [k for k in mine if k not in RUNTIME_FIELDS and saved.get(k) != mine[k]]
        if differ or state["hyperparameters"] != self.hyperparameters:
            raise ValueError(
                "the checkpoint was made with another config: "
                + (", ".join(differ) or "the sb3_* hyperparameters")
            )
        model = self.model
        model.policy.load_state_dict(state["policy"])
        model.policy.optimizer.load_state_dict(state["optimizer"])
        _load_buffer(model.replay_buffer, state["buffer"])
        counters = state["counters"]
        model.num_timesteps = int(counters["num_timesteps"])
        model._n_calls = int(counters["n_calls"])
        model._n_updates = int(counters["n_updates"])
        model.exploration_rate = float(counters["exploration_rate"])
        model._current_progress_remaining = self._progress_remaining()
        self.seed = int(state["seed"])
        self.global_step = int(state["global_step"])
        self.episodes_done = {stage_of(k): int(v) for k, v in state["episodes_done"].items()}
        rngs = state["rngs"]
        self._env_rng.bit_generator.state = rngs["env"]
        numpy_state = dict(rngs["numpy"])
        numpy_state["state"] = {
            **numpy_state["state"],
            "key": np.array(numpy_state["state"]["key"], dtype=np.uint32),
        }
        np.random.set_state(numpy_state)
        random.setstate(_tuples(rngs["python"]))
        torch.set_rng_state(rngs["torch"])
        if rngs["cuda"] and torch.cuda.is_available():
            torch.cuda.set_rng_state_all(rngs["cuda"])
        model.action_space.np_random.bit_generator.state = rngs["action_space"]
        self._episode = (
            None if state["episode"] is None else replay_episode(self.env, state["episode"])
        )
        self.episode_record = None
        self._stopped = False


def _sb3_space(space: Any) -> Any:
    """The task's observation space as SB3's policy sees it: a vector's as it is (float32),
    an (H, W, 3) image's channels first."""
    if len(space.shape) == 1:
        return spaces.Box(space.low, space.high, space.shape, np.float32)
    height, width, channels = space.shape
    return spaces.Box(0, 255, (channels, height, width), np.uint8)


def _channels_first(image: np.ndarray) -> np.ndarray:
    """An (H, W, 3) frame as SB3's image policies take it: a batch of one (1, 3, H, W)."""
    return np.ascontiguousarray(np.asarray(image).transpose(2, 0, 1))[None]


_BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def _buffer_state(buffer: Any) -> dict[str, Any]:
    """The filled part of SB3's replay buffer, as tensors (the checkpoint loads weights-only)."""
    import torch

    size = buffer.buffer_size if buffer.full else buffer.pos
    return {
        "pos": int(buffer.pos),
        "full": bool(buffer.full),
        **{name: torch.from_numpy(getattr(buffer, name)[:size].copy()) for name in _BUFFER_ARRAYS},
    }


def _load_buffer(buffer: Any, state: dict[str, Any]) -> None:
    for name in _BUFFER_ARRAYS:
        values = state[name].numpy()
        getattr(buffer, name)[: len(values)] = values
    buffer.pos, buffer.full = int(state["pos"]), bool(state["full"])


def _tuples(value: Any) -> Any:
    """`random.getstate()` back from a checkpoint, which may give its tuples as lists."""
    if isinstance(value, list | tuple):
        return tuple(_tuples(v) for v in value)
    return value
