"""A population: agents of one learner configuration trained together in one process.

Why: every question the platform answers is paid for in agent runs, and one run per
process repeats torch (about 590 MB resident) and the work of choosing each agent's
action alone. Here N agents step side by side: each agent's environment steps in turn,
their actions are chosen on one batched forward pass over their stacked weights, and
their updates are computed together (`learner.stacked`), or one agent at a time where
that is faster (a CPU's caches), or on several threads (`workers`).

Each agent is a `Trainer` of its own (seed, environment, advisor, strategy, callbacks,
replay memory, exploration, optimizer state), driven through the same code as alone:
`Trainer._act` chooses, asks for advice, steps and remembers; `Trainer._end_step` records
and tells the callbacks. So an agent's records are the same StepRecords and
EpisodeRecords, and its checkpoints are `Trainer`'s files (a population agent's
checkpoint resumes in a plain `Trainer`, a plain `Trainer`'s in a population).

The same science: advisors are asked one agent at a time, as alone (an agent advisor's
greedy action is its own batch-of-one forward pass, which batching cannot flip), and the
stacked computation uses each agent's own convolution and dense kernels on the same
shapes as alone, so for the same seed, device and torch threads an agent's records in a
population equal its records alone in every column, Q-values and losses included
(tests/learner/test_population.py, bfloat16 and float32). With `conv="grouped"` the
values are the same function in another float order (Q-values within 1e-2 relative in
bfloat16); actions through pretraining and advice, which do not depend on them, stay
the same, and learning differs only by floating-point order.

An agent that finishes (its episodes run, or a callback stopped it) leaves the
population; the others go on.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NotRequired, TypedDict

import gymnasium as gym
import numpy as np
import torch

from learner.config import PER_AGENT_FIELDS, DQNConfig, shared_config
from learner.records import EpisodeRecord, StepRecord
from learner.stacked import ConvMode, StackedAgents
from learner.strategies import AdvisingStrategy, AnyAdvisor
from learner.trainer import Trainer

Layout = Literal["auto", "stacked", "stacked-actions", "loop"]
LAYOUTS = ("auto", "stacked", "stacked-actions", "loop")


@dataclass
class Member:
    """One agent of a population: what a `Trainer` takes besides the shared config.
    Environments may differ (reward scheme, realism, sort rule); the image and action
    spaces may not."""

    env: gym.Env
    seed: int = 0
    advisor: AnyAdvisor | None = None
    strategy: AdvisingStrategy | str | None = None
    callbacks: Iterable[Any] = field(default_factory=tuple)


class PopulationNumerics(TypedDict):
    """How a population computes, as stored (JSON) with each agent's checkpoint and in its
    session's provenance (`Population.numerics`)."""

    population_size: int
    layout: str
    conv: str
    """`per-agent` (the loop layout) or the stacked layout's convolution."""
    conv_dtype: str
    device: str
    torch_threads: int
    workers: int
    torch: str
    """torch's version."""
    population_index: NotRequired[int]
    """Which agent (a checkpoint's)."""
    seed: NotRequired[int]
    """That agent's seed."""


class Population:
    """Trains `members` under one `config` together; see the module docstring.

    `layout` says what is computed together (`resolve_layout`): `stacked`, the agents'
    action values (one forward pass) and their updates, over their stacked weights;
    `stacked-actions`, the action values, while each agent's update is its own
    `DQNAgent.update` in turn (on a CPU the faster: one agent's working set stays in the
    caches, and the stacked update has nothing else to gain there, see
    benchmarks/bench_population.py); `loop`, nothing: each agent's own `DQNAgent` one
    after the other, as alone (the fallback, and the only way for `update="plain"`).
    `auto`: `stacked` on CUDA, `stacked-actions` on a CPU, `loop` for the plain update.

    `workers` > 1 computes the updates on that many threads, each taking every
    `workers`-th agent (stacked together in the `stacked` layout): agents are independent,
    so on a multi-core CPU this parallelises whole updates rather than each small operation
    (`config.torch_threads`); measured on 2 cores, 2 workers of 1 torch thread each beat 1
    worker of 2 threads. Each agent's ops run with the process's torch threads, so with
    `torch_threads=1` every agent computes what it computes alone, to the bit. Keep
    workers x torch threads within the free cores.
    `conv` is how the convolutions run in the stacked layout (`learner.stacked`):
    `loop` (one call per agent: each agent's values and gradients are its own alone, to
    the bit) or `grouped` (one grouped convolution: the same function, another order).

    Drive it with `step()` (one step of every agent still training) or `run()`; each
    agent's records go to its own callbacks. `trainers[i]` is agent i's `Trainer`: its
    `save_checkpoint`/`load_checkpoint` are the per-agent checkpoints (or use
    `save_checkpoint(i, path)`, which records the population's numerics with it).
    """

    def __init__(
        self,
        config: DQNConfig,
        members: Sequence[Member],
        layout: Layout = "auto",
        conv: ConvMode = "loop",
        workers: int = 1,
    ) -> None:
        if not members:
            raise ValueError("a population needs at least one member")
        trainers = [
            Trainer(m.env, config, m.advisor, m.strategy, m.seed, m.callbacks) for m in members
        ]
        self._setup(trainers, layout, conv, workers)

    @classmethod
    def of(
        cls,
        trainers: Sequence[Trainer],
        layout: Layout = "auto",
        conv: ConvMode = "loop",
        workers: int = 1,
    ) -> Population:
        """A population of trainers built elsewhere (a batch worker builds each agent's
        `Trainer` from its session, with its schedule and recording callbacks). Their
        configs may differ only in `PER_AGENT_FIELDS` (`shared_config`)."""
        if not trainers:
            raise ValueError("a population needs at least one member")
        population = cls.__new__(cls)
        population._setup(list(trainers), layout, conv, workers)
        return population

    def _setup(self, trainers: list[Trainer], layout: Layout, conv: ConvMode, workers: int) -> None:
        if conv not in ("loop", "grouped"):
            raise ValueError(f"conv must be 'loop' or 'grouped', got {conv!r}")
        shared = {shared_config(t.config) for t in trainers}
        if len(shared) > 1:
            raise ValueError(
                "a population's agents share one learner configuration (they may differ in "
                f"{', '.join(PER_AGENT_FIELDS)} only)"
            )
        self.trainers = trainers
        config = self.config = trainers[0].config
        self.layout = resolve_layout(layout, config, self.trainers[0].device)
        if trainers[0].agent.vector:  # the dense network: each agent computes on its own
            if layout not in ("auto", "loop"):
                raise ValueError("a vector task's agents run with layout='loop' (or 'auto')")
            self.layout = "loop"
        self.conv: ConvMode = conv
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers must be a whole number >= 1, got {workers!r}")
        self.workers = workers
        self._pool = ThreadPoolExecutor(workers, "population") if workers > 1 else None
        shapes = {t.env.observation_space.shape for t in self.trainers}
        if len(shapes) > 1:
            raise ValueError(f"the members' environments differ in image shape: {shapes}")

    @property
    def size(self) -> int:
        return len(self.trainers)

    @property
    def active(self) -> list[int]:
        """Indices of the agents still training."""
        return [i for i, trainer in enumerate(self.trainers) if not trainer.done]

    @property
    def done(self) -> bool:
        return not self.active

    def numerics(self, index: int | None = None) -> PopulationNumerics:
        """How this population computes (plain JSON, recorded with each agent's checkpoint):
        its size and layout, the convolutions' dtype, device and threads; with `index`,
        also which agent."""
        agent = self.trainers[0].agent
        numerics: PopulationNumerics = {
            "population_size": self.size,
            "layout": self.layout,
            "conv": "per-agent" if self.layout == "loop" else self.conv,
            "conv_dtype": str(agent.dtype).replace("torch.", ""),
            "device": str(agent.device),
            "torch_threads": self.trainers[0].threads,
            "workers": self.workers,
            "torch": str(torch.__version__),
        }
        if index is not None:
            numerics["population_index"] = index
            numerics["seed"] = self.trainers[index].seed
        return numerics

    def step(self) -> dict[int, StepRecord]:
        """One environment step of every agent still training; their records by index."""
        active = self.active
        if not active:
            raise RuntimeError("the population is done (every agent finished or stopped)")
        trainers = [self.trainers[i] for i in active]
        images = [trainer._begin_step() for trainer in trainers]
        q_values = self._q_values(trainers, images)
        steps = [trainer._act(q) for trainer, q in zip(trainers, q_values, strict=True)]
        updating = [k for k, step in enumerate(steps) if step.updates]
        losses = dict(zip(updating, self._update([trainers[k] for k in updating]), strict=True))
        return {
            i: trainer._end_step(step, losses.get(k))
            for k, (i, trainer, step) in enumerate(zip(active, trainers, steps, strict=True))
        }

    def run(self) -> dict[int, list[EpisodeRecord]]:
        """Step until every agent is done; each agent's training episodes finished here."""
        finished: dict[int, list[EpisodeRecord]] = {i: [] for i in self.active}
        while not self.done:
            for i in self.step():
                record = self.trainers[i].episode_record
                if record is not None and record.stage == "train":
                    finished[i].append(record)
        return finished

    def stop(self) -> None:
        """Stop every agent; `run` returns after the current step."""
        for trainer in self.trainers:
            trainer.stop()

    def _q_values(
        self, trainers: list[Trainer], images: list[np.ndarray]
    ) -> Sequence[np.ndarray] | np.ndarray:
        if self.layout == "loop":
            return [t.agent.q_values(image) for t, image in zip(trainers, images, strict=True)]
        return StackedAgents([t.agent for t in trainers], self.conv).q_values(images)

    def _update(self, trainers: list[Trainer]) -> list[float]:
        """Each trainer's update on a batch from its own memory, as `Trainer.step` does."""
        if not trainers:
            return []
        size = self.config.batch_size
        batches = [t.memory.sample(size, t._memory_rng) for t in trainers]
        rngs = [t._memory_rng for t in trainers]
        agents = [t.agent for t in trainers]
        groups = [list(range(w, len(agents), self.workers)) for w in range(self.workers)]
        groups = [group for group in groups if group]

        def update(group: list[int]) -> list[float]:
            mine = [agents[k] for k in group]
            if self.layout == "stacked":
                stacked = StackedAgents(mine, self.conv)
                return stacked.update([batches[k] for k in group], [rngs[k] for k in group])
            return [agents[k].update(batches[k], rngs[k]) for k in group]

        if self._pool is None or len(groups) == 1:
            results = [update(group) for group in groups]
        else:
            results = list(self._pool.map(update, groups))
        losses = [0.0] * len(agents)
        for group, result in zip(groups, results, strict=True):
            for k, loss in zip(group, result, strict=True):
                losses[k] = loss
        return losses

    def close(self) -> None:
        """End the worker threads (a population with `workers` > 1); idempotent."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def save_checkpoint(
        self,
        index: int,
        path: str | Path,
        metadata: dict[str, Any] | None = None,
        memory: bool = True,
    ) -> None:
        """Agent `index`'s checkpoint, in `Trainer`'s format (a plain `Trainer` resumes
        it), with the population's numerics under `metadata["population"]`."""
        metadata = {**(metadata or {}), "population": self.numerics(index)}
        self.trainers[index].save_checkpoint(path, metadata, memory)

    def load_checkpoint(self, index: int, path: str | Path) -> None:
        """Continue agent `index` from a checkpoint of a `Trainer` or a population's agent
        (same config except its runtime fields, strategy and advisor kind)."""
        self.trainers[index].load_checkpoint(path)


def resolve_layout(layout: str, config: DQNConfig, device: torch.device) -> Layout:
    """The layout `auto` stands for on `device` (see `Population`); checks the others."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    if config.update != "fast":
        if layout not in ("auto", "loop"):
            raise ValueError(
                f"the {layout} layout computes the fast update; config update='plain' runs "
                "with layout='loop' (or 'auto')"
            )
        return "loop"
    if layout == "auto":
        return "stacked" if device.type == "cuda" else "stacked-actions"
    return layout  # type: ignore[return-value]
