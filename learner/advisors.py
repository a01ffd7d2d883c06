"""Who gives advice: the protocol, and the advisors the learner ships.

The server plugs in its own `human` advisor (a person in a browser) by implementing the
same protocol: `advise` may block as long as the person takes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from learner.config import DQNConfig
from learner.fitted import FittedAdvisor, log_normal_time, read_model
from learner.no_advice import NO_ADVICE as NO_ADVICE
from learner.no_advice import NoAdvice as NoAdvice
from sim.rules import SortRule
from tasks import CorrectActions, Task, TaskOptions, get_task

ADVISOR_KINDS = ("agent", "fitted", "oracle", "random")


@runtime_checkable
class Advisor(Protocol):
    """Anything that, shown what the learner sees, names an action (0..3), or `NO_ADVICE`
    when it has none to give (a recorded stream that ran out)."""

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int | NoAdvice:
        """The advised action for the uint8 image `obs`; `info` is the environment's
        ground truth, which only simulated advisors may look at. May block."""
        ...


@runtime_checkable
class ValueAdvisor(Advisor, Protocol):
    """An advisor with its own value estimate, which importance advising needs."""

    def q_values(self, obs: np.ndarray) -> np.ndarray: ...


class RandomAdvisor:
    """Advises uniformly at random: the baseline for advice that carries no knowledge."""

    def __init__(self, seed: int | None = None, n_actions: int = 4) -> None:
        self.n_actions = n_actions
        self.rng = np.random.default_rng(seed)

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        return int(self.rng.integers(self.n_actions))

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]


class OracleAdvisor:
    """The correct action from the simulator's ground truth, wrong with probability
    `error_rate` (then one of the other actions at random): a stand-in for a person of
    known reliability. With `decision_time_median_s`, each advice also gets a simulated
    decision time (log-normal, `decision_time_sigma`; `last_decision_time_s`, logged as
    the advice's `decision_time_s`), so an oracle pilot can stand in for people when an
    advisor is fitted. The times come from their own random stream: the advice is the same
    with or without them."""

    def __init__(
        self,
        sort_rule: Any = "color",
        error_rate: float = 0.0,
        seed: int | None = None,
        n_actions: int | None = None,
        decision_time_median_s: float | None = None,
        decision_time_sigma: float = 0.5,
        task: Task | None = None,
        task_options: TaskOptions | None = None,
    ) -> None:

        if not 0.0 <= error_rate <= 1.0:
            raise ValueError(f"error_rate must be between 0 and 1, got {error_rate}")
        if decision_time_median_s is not None and not decision_time_median_s > 0:
            raise ValueError("decision_time_median_s must be above 0")
        if not decision_time_sigma >= 0:
            raise ValueError("decision_time_sigma must be at least 0")
        if task is None:  # the sorting task, its rule given alone
            task = get_task("sorting")
            task_options = {"sort_rule": SortRule.parse(sort_rule).to_spec()}
        self.task = task
        self.task_options = task.checked_options(task_options)
        self.error_rate = float(error_rate)
        self.n_actions = task.n_actions if n_actions is None else n_actions
        self.rng = np.random.default_rng(seed)
        self.decision_time_median_s = decision_time_median_s
        self.decision_time_sigma = float(decision_time_sigma)
        self.time_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
        self.last_decision_time_s: float | None = None

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        right = self.right_actions(info)
        correct = right.action
        assert correct is not None  # right_actions refuses a state without one
        wrong = self.rng.random() < self.error_rate
        # a mistake is an action that is not right (where another move is as right, as the
        # grid world's equally short ones are, naming it would be no mistake)
        others = [a for a in range(self.n_actions) if a not in right.actions]
        other = int(self.rng.integers(max(len(others), 1)))
        if self.decision_time_median_s is not None:
            self.last_decision_time_s = log_normal_time(
                self.time_rng, self.decision_time_median_s, self.decision_time_sigma
            )
        if not wrong or not others:
            return correct
        return others[other]

    def right_actions(self, info: dict[str, Any]) -> CorrectActions:
        """The correct action in the state `info` describes, and every action as right."""
        right = self.task.correct_actions(info, self.task_options)
        if right.action is None:
            raise ValueError(
                f"the oracle was asked where task {self.task.name} names no correct action"
            )
        return right

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state, "time_rng": self.time_rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]
        if "time_rng" in state:  # checkpoints from before simulated times lack it
            self.time_rng.bit_generator.state = state["time_rng"]


class AgentAdvisor:
    """A previously trained learner acting greedily on the same image (agent-IDeepRL)."""

    def __init__(self, checkpoint: str | Path, device: str = "auto") -> None:
        from learner.agent import DQNAgent
        from learner.checkpoint import read_checkpoint
        from learner.device import resolve_device

        state = read_checkpoint(checkpoint)
        config = DQNConfig.from_dict({**state["config"], "device": device})
        network = state["agent"]["network"]
        # the task's action count and image size, as the checkpoint's learner had them
        # (a vector task's: its length; checkpoints without them: 4, 64x64x3)
        n_actions = int(network["out.weight"].shape[0])
        image_shape = tuple(int(n) for n in state.get("image_shape", (64, 64, 3)))
        self.agent = DQNAgent(config, resolve_device(device), n_actions, image_shape)
        self.agent.network.load_state_dict(network)
        self.checkpoint = str(checkpoint)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        return self.agent.q_values(obs)

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        return int(np.argmax(self.q_values(obs)))


class RecordedAdvisor:
    """A recorded advice stream fed by order (SPEC section 5, "Replay"): the i-th call gets
    the i-th recorded action, whatever the state; past the stream's end, `NO_ADVICE`.
    `observation_hashes[i]` is the hash of the image the advisor saw for advice i
    (`learner.records.observation_hash`): `same_observation` says whether the learner now
    shows the advisor the same one."""

    def __init__(self, actions: Sequence[int], observation_hashes: Sequence[str | None]) -> None:
        if len(actions) != len(observation_hashes):
            raise ValueError("a recorded stream needs one observation hash per action")
        self.actions = [int(a) for a in actions]
        self.observation_hashes = list(observation_hashes)
        self.count = 0
        """Requests so far, answered or not."""
        self.same_observation: bool | None = None
        """Whether the last advice met the image its advisor saw (None: no advice given)."""

    @property
    def exhausted(self) -> bool:
        return self.count >= len(self.actions)

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int | NoAdvice:
        from learner.records import observation_hash

        index = self.count
        self.count += 1
        if index >= len(self.actions):
            self.same_observation = None
            return NO_ADVICE
        self.same_observation = observation_hash(obs) == self.observation_hashes[index]
        return self.actions[index]

    def state_dict(self) -> dict[str, Any]:
        return {"count": self.count}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.count = int(state["count"])


def make_advisor(kind: str, **options: Any) -> Advisor:
    """`agent` (checkpoint=PATH, device=...), `fitted` (model=PATH, task=..., task_options=...
    or sort_rule=..., seed=...), `oracle` (sort_rule=..., error_rate=..., seed=...,
    decision_time_median_s=..., decision_time_sigma=...) or `random` (seed=...)."""
    factories: dict[str, Callable[..., Advisor]] = {
        "agent": AgentAdvisor,
        "fitted": _fitted,
        "oracle": OracleAdvisor,
        "random": RandomAdvisor,
    }
    if kind not in factories:
        raise ValueError(
            f"unknown advisor {kind!r}; valid advisors: {', '.join(ADVISOR_KINDS)} "
            "(the server provides 'human')"
        )
    if kind == "fitted" and "model" not in options:
        raise ValueError("the fitted advisor needs model=PATH of a fitted model (ideeprl fit)")
    if kind == "agent" and "checkpoint" not in options:
        raise ValueError("the agent advisor needs checkpoint=PATH of a trained learner")
    try:
        return factories[kind](**options)
    except TypeError as error:
        raise ValueError(f"bad options for the {kind} advisor: {error}") from error


def _fitted(model: str | Path, **options: Any) -> FittedAdvisor:
    return FittedAdvisor(read_model(model), **options)
