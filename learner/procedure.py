"""The procedure control (SPEC section 5): an advised run's advising procedure without its
advice.

An advised arm differs from the unadvised one in more than the advice: it asks at some
steps, fits the network during advice (the `authors` preset: 98 extra fits), and so starts
training at a lower epsilon (0.952 instead of 1.0 in the replication). Only an arm that
goes through the same procedure with uninformed actions tells the advice's effect apart.
A `Schedule` is that procedure, read from the advised run's step records: the steps whose
action came from the advisor, the pretraining steps followed by an update, and epsilon as
each step's action was chosen. A judged run's procedure (evaluative feedback) is its judged
steps instead of advised ones: the judgements shape those steps' rewards and their fits.
A control run (method `procedure`) takes a random action (or, following a judged run, gets
an uninformed judgement, `RunSpec.make_evaluator`) at exactly those steps, fits exactly
after those pretraining steps, and follows that epsilon step by step (`Trainer` with
`schedule=`); beyond the recorded steps (its episodes end at other steps, so it may run
longer) it follows its own rules.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from learner.strategies import AdviceMoment, AdvisingStrategy

SCHEDULE_VERSION = 1


@dataclass(frozen=True)
class Schedule:
    """An advised run's procedure, by global step (from 1)."""

    advised: frozenset[int]
    """Steps whose action came from the advisor."""
    fitted: frozenset[int]
    """Pretraining steps followed by an update (the fits during advice)."""
    epsilon: tuple[float, ...]
    """Epsilon as the action of step i + 1 was chosen."""
    pretraining_steps: int
    source: str = ""
    """Which run it was read from (e.g. `session 12`)."""
    judged: frozenset[int] = frozenset()
    """Steps whose action was judged (evaluative feedback; an answer given)."""

    @property
    def asked(self) -> frozenset[int]:
        """The steps the control's advisor or evaluator is asked at."""
        return self.advised | self.judged

    @classmethod
    def from_steps(
        cls,
        steps: Iterable[tuple[int, str, str, float | None, float]],
        pretraining_steps: int,
        source: str = "",
        judged: Iterable[int] = (),
    ) -> Schedule:
        """From step records as `(global_step, stage, action_source, loss, epsilon)`, in
        step order from step 1, and the steps judged (a judged run's)."""
        advised, fitted, epsilon = set(), set(), []
        for expected, (global_step, stage, source_, loss, eps) in enumerate(steps, start=1):
            if global_step != expected:
                raise ValueError(
                    f"the steps of {source or 'the run'} are not complete: step {expected} "
                    "is missing"
                )
            if source_ == "advisor":
                advised.add(global_step)
            if stage == "pretrain" and loss is not None:
                fitted.add(global_step)
            epsilon.append(float(eps))
        return cls(
            frozenset(advised), frozenset(fitted), tuple(epsilon), pretraining_steps, source,
            frozenset(int(s) for s in judged),
        )  # fmt: skip

    def epsilon_at(self, global_step: int) -> float | None:
        """Epsilon of the recorded step, None beyond the record."""
        return self.epsilon[global_step - 1] if global_step <= len(self.epsilon) else None

    def to_json(self) -> dict[str, Any]:
        return {
            "version": SCHEDULE_VERSION,
            "source": self.source,
            "pretraining_steps": self.pretraining_steps,
            "advised": sorted(self.advised),
            "judged": sorted(self.judged),
            "fitted": sorted(self.fitted),
            "epsilon": list(self.epsilon),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Schedule:
        if data.get("version") != SCHEDULE_VERSION:
            raise ValueError(f"a schedule of version {SCHEDULE_VERSION} was expected")
        return cls(
            frozenset(int(s) for s in data["advised"]),
            frozenset(int(s) for s in data["fitted"]),
            tuple(float(e) for e in data["epsilon"]),
            int(data["pretraining_steps"]),
            str(data.get("source", "")),
            frozenset(int(s) for s in data.get("judged", ())),
        )

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(self.to_json()))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Schedule:
        try:
            return cls.from_json(json.loads(Path(path).read_text()))
        except FileNotFoundError:
            raise ValueError(f"no schedule at {path}") from None
        except (ValueError, KeyError, TypeError) as error:
            raise ValueError(f"{path} is not a schedule ({error})") from None


class ScheduledAdvising(AdvisingStrategy):
    """Asks exactly at the schedule's advised (or judged) steps (its budget: their number)."""

    name = "scheduled"

    def __init__(self, schedule: Schedule) -> None:
        super().__init__(len(schedule.asked))
        self.schedule = schedule

    def _asks(self, moment: AdviceMoment, advisor: Any) -> bool:
        return moment.global_step in self.schedule.asked

    def check(self, pretraining_steps: int, advisor: object) -> None:
        if pretraining_steps != self.schedule.pretraining_steps:
            raise ValueError(
                f"the schedule was recorded with {self.schedule.pretraining_steps} pretraining "
                f"steps; this run has {pretraining_steps}"
            )
