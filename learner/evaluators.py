"""Evaluative feedback: who judges the action the learner took.

The paper (its section 2) names two strategies of interactive feedback: corrective advice
(policy shaping: the trainer names the action to take, `learner.advisors`) and evaluative
feedback (reward shaping: the trainer judges the action the agent took, Ng et al. 1999,
Brys et al. 2014). Under evaluative feedback the learner always acts by itself; inside the
advising strategy's window (the same steps advice would take) an evaluator judges the
action taken, and the learner stores the environment's reward plus the scaled judgement
(`RunSpec.feedback_weight`; Knox and Stone's TAMER+RL reward shaping, R' = R + w * H).

A judgement is a signed number: +1 good, -1 bad, or None (no answer: the step keeps the
environment's reward).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from learner.advisors import NO_ADVICE, Advisor
from learner.strategies import AdviceMoment

GOOD, BAD = 1.0, -1.0


@runtime_checkable
class Evaluator(Protocol):
    """Anything that, shown what the learner saw and the action it took, judges it."""

    def judge(self, obs: np.ndarray, info: dict[str, Any], action: int) -> float | None:
        """The judgement of `action` taken on the uint8 image `obs`; `info` is the
        environment's ground truth before the action, which only simulated evaluators may
        look at. May block (a person)."""
        ...


@runtime_checkable
class MomentEvaluator(Protocol):
    """An evaluator shown the whole moment (the step, the learner's greedy choice), as the
    session worker's evaluators log it; `moment.intended_action` is the action taken."""

    def judge_at(self, moment: AdviceMoment) -> float | None: ...


AnyEvaluator = Evaluator | MomentEvaluator


def judge(evaluator: AnyEvaluator, moment: AdviceMoment) -> float | None:
    """The evaluator's judgement of the action taken at `moment` (its `intended_action`:
    under evaluative feedback the learner's own action is the one executed)."""
    if isinstance(evaluator, MomentEvaluator):
        return evaluator.judge_at(moment)
    return evaluator.judge(moment.obs, moment.info, moment.intended_action)


class AdvisorEvaluator:
    """Judges as an advisor would advise: good when the action taken is the one `advisor`
    names (a trained agent's greedy one) or, for the oracle, one as right as its correct
    action (the grid world's equally short moves), else bad; each
    judgement turned into its opposite with probability `error_rate` (an evaluator of
    known reliability, as the oracle advisor is one of advice). A simulated decision time
    of the advisor's (`last_decision_time_s`) is the judgement's."""

    def __init__(self, advisor: Advisor, error_rate: float = 0.0, seed: int | None = None) -> None:
        if not 0.0 <= error_rate <= 1.0:
            raise ValueError(f"error_rate must be between 0 and 1, got {error_rate}")
        self.advisor = advisor
        self.error_rate = float(error_rate)
        # its own stream, apart from the advisor's (seeded from the same run seed)
        self.rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[1])

    def __getattr__(self, name: str) -> Any:
        if name in ("q_values", "last_decision_time_s"):  # importance's window; times
            return getattr(self.advisor, name)
        raise AttributeError(name)

    def judge(self, obs: np.ndarray, info: dict[str, Any], action: int) -> float:
        named = self.advisor.advise(obs, info)
        assert named is not NO_ADVICE, "a machine advisor always names an action"
        rights = getattr(self.advisor, "right_actions", None)  # the oracle's: all as right
        right = int(action) in rights(info).actions if rights else int(named) == int(action)
        if self.rng.random() < self.error_rate:
            right = not right
        return GOOD if right else BAD

    def state_dict(self) -> dict[str, Any]:
        inner = getattr(self.advisor, "state_dict", None)
        return {
            "rng": self.rng.bit_generator.state,
            "advisor": inner() if callable(inner) else None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]
        load = getattr(self.advisor, "load_state_dict", None)
        if state["advisor"] is not None and callable(load):
            load(state["advisor"])


class RecordedEvaluator:
    """A recorded stream of ratings fed by order (`ideeprl replay`): the i-th judgement is
    the i-th recorded one (None where the recording has no answer), whatever the action
    and the state; past the stream's end, None. `observation_hashes[i]` is the hash of the
    image the i-th rating was given on: `same_observation` says whether the learner now
    shows the same one."""

    def __init__(
        self, judgements: Sequence[float | None], observation_hashes: Sequence[str | None]
    ) -> None:
        if len(judgements) != len(observation_hashes):
            raise ValueError("a recorded stream needs one observation hash per rating")
        self.judgements = [None if j is None else float(j) for j in judgements]
        self.observation_hashes = list(observation_hashes)
        self.count = 0
        """Requests so far, answered or not."""
        self.same_observation: bool | None = None
        """Whether the last rating met the image it was given on (None: past the stream)."""

    def judge(self, obs: np.ndarray, info: dict[str, Any], action: int) -> float | None:
        from learner.records import observation_hash

        index = self.count
        self.count += 1
        if index >= len(self.judgements):
            self.same_observation = None
            return None
        self.same_observation = observation_hash(obs) == self.observation_hashes[index]
        return self.judgements[index]

    def state_dict(self) -> dict[str, Any]:
        return {"count": self.count}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.count = int(state["count"])
