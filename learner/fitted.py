"""Advisors fitted to people: how often a study's advisors were right, by situation, what
they advised when wrong, how long they took, and how much of their budget they used; and
`FittedAdvisor`, which advises like them.

Simulated advisors let a researcher try a study's design (budget, strategy, sample size)
on advisors as reliable and as slow as the people they will recruit, before recruiting
them. The situation is what a person sees that changes how hard the choice is: a place
within a group, which the task declares (`tasks.Situations`: the sorting robot's arm's
station within the colour it holds), or else the run's stage within the correct action.
A handful of groups and situations stay estimable from about 100 advice per person because
each situation's rate is pulled toward its group's rate, and that toward the overall rate,
by `prior_strength` pseudo-advice (a situation with few advice gets its parent's rate; one
with many, its own).

Torch-free and database-free: `study.services.fitting` reads a study's rows, replays the
advised episodes to recover each advice's situation and correct action, and calls `fit`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from learner.no_advice import NO_ADVICE, NoAdvice
from learner.records import STAGES, TRAINING
from tasks import GymInfo, Task, TaskError, TaskOptions, get_task

FITTED_VERSION = 2
"""Version of the stored model (`FittedModel.to_json`); `from_json` reads it and version 1
(the sorting robot's, whose groups were `by_held`)."""
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
"""The decision-time quantiles a model keeps beside its log-normal fit."""
PRIOR_STRENGTH = 10.0


class Moment(Protocol):
    """What a fitted advisor reads of a strategy's `AdviceMoment`."""

    @property
    def info(self) -> dict[str, Any]: ...
    @property
    def stage(self) -> str: ...


def situation_key(place: str, group: str) -> str:
    return f"{place}/{group}"


def vocabulary(task: Task) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(places, groups) a task's situations take: its declared ones, else the stages and
    its actions' words."""
    if task.situations is not None:
        return task.situations.places, task.situations.groups
    return STAGES, task.action_words


def situation(task: Task, info: GymInfo, stage: str, correct: int) -> tuple[str, str]:
    """(place, group) of a state: the task's declared situation, else (the run's stage,
    the correct action's word): `("center", "blue")`, `("pretrain", "up")`."""
    if task.situations is not None:
        return task.situations.of(info)
    return stage, task.action_words[correct]


@dataclass(frozen=True)
class AdviceSeen:
    """One advice as the fit needs it: its situation, what was right, what was advised."""

    place: str
    group: str
    """The situation (`situation`): `center` within `blue`, or `pretrain` within `up`."""
    correct: int
    """The task's correct action in that state (`Task.correct`, the oracle's)."""
    advised: int
    decision_time_s: float | None = None
    """Seconds from the buttons becoming active to the answer; None when not measured."""


@dataclass(frozen=True)
class SessionAdvice:
    """One session's advice, in order, and the budget it had."""

    session_id: int
    advice: Sequence[AdviceSeen]
    budget: int
    given: int | None = None
    """Advice the session got, when some could not be placed in a situation (None: all)."""

    @property
    def budget_used(self) -> float:
        """Its share of the budget it used (1.0: all of it)."""
        given = len(self.advice) if self.given is None else self.given
        return min(1.0, given / self.budget) if self.budget else 1.0


@dataclass(frozen=True)
class Count:
    """Advice in a situation, and how many of them were wrong."""

    advice: int = 0
    wrong: int = 0


@dataclass(frozen=True)
class FittedModel:
    """A study's advisors, fitted (versioned JSON: `to_json`, `from_json`)."""

    advice: int
    """Advice it was fitted from."""
    sessions: list[int]
    """The sessions it was fitted from."""
    methods: list[str]
    """Their methods (human; oracle for a pilot standing in for people)."""
    overall: Count
    by_group: dict[str, Count]
    """By the situation's group (the sorting robot: what the arm held)."""
    by_situation: dict[str, Count]
    """By place within group (`situation_key`: `center/blue`, `pretrain/up`)."""
    wrong_actions: list[list[int]]
    """[correct][advised]: how often each wrong action was advised for each correct one
    (the task's action count a side)."""
    decision_time_median_s: float | None
    """The log-normal fit of the decision times: its median (None: no times recorded)."""
    decision_time_sigma: float | None
    """... and the standard deviation of their logarithm."""
    decision_time_quantiles: list[float]
    """The empirical decision times at `QUANTILES` (empty without times)."""
    budget_used: list[float]
    """Each session's share of its advice budget that it used (1.0: the whole budget)."""
    task: str = "sorting"
    """The task it was fitted in (a run of another task cannot use it)."""
    places: list[str] = field(default_factory=list)
    groups: list[str] = field(default_factory=list)
    """The places and groups the task's situations take (`vocabulary`; empty: those seen)."""
    correct_actions: list[int] = field(default_factory=list)
    """Advice by correct action (empty: not counted): with `wrong_actions`, what the people
    advised, which a simulated person who cannot see the situation advises."""
    prior_strength: float = PRIOR_STRENGTH
    """Pseudo-advice that pull a situation's rate toward its parent's."""
    version: int = FITTED_VERSION

    # --- rates -------------------------------------------------------------------------
    def overall_rate(self) -> float:
        return self.overall.wrong / self.overall.advice if self.overall.advice else 0.0

    def group_rate(self, group: str) -> float:
        return self._pulled(self.by_group.get(group, Count()), self.overall_rate())

    def error_rate(self, place: str, group: str) -> float:
        """The chance that advice in this situation is wrong."""
        count = self.by_situation.get(situation_key(place, group), Count())
        return self._pulled(count, self.group_rate(group))

    @property
    def n_actions(self) -> int:
        return len(self.wrong_actions)

    def advised_actions(self) -> np.ndarray:
        """The share of advice that named each action (uniform where not counted)."""
        counts = np.array(self.correct_actions, dtype=float)
        if len(counts) != self.n_actions or not counts.sum():
            return np.full(self.n_actions, 1.0 / self.n_actions)
        wrong = np.array(self.wrong_actions, dtype=float)
        advised = counts - wrong.sum(axis=1) + wrong.sum(axis=0)
        return np.clip(advised, 0.0, None) / counts.sum()

    def _pulled(self, count: Count, parent: float) -> float:
        k = self.prior_strength
        return (count.wrong + k * parent) / (count.advice + k)

    @property
    def stop_early_rate(self) -> float:
        """Share of sessions that stopped advising before their budget was used."""
        used = self.budget_used
        return sum(u < 1.0 for u in used) / len(used) if used else 0.0

    def summary(self) -> dict[str, Any]:
        """What a researcher reads: rates by situation, times, stopping."""
        groups = self.groups or sorted(self.by_group)
        keys = [(p, g) for p in self.places for g in groups] or [
            (k.partition("/")[0], k.partition("/")[2]) for k in sorted(self.by_situation)
        ]
        return {
            "task": self.task,
            "advice": self.advice,
            "sessions": len(self.sessions),
            "error_rate": round(self.overall_rate(), 4),
            "error_rate_by_group": {g: round(self.group_rate(g), 4) for g in groups},
            "error_rate_by_situation": {
                situation_key(p, g): round(self.error_rate(p, g), 4) for p, g in keys
            },
            "decision_time_median_s": self.decision_time_median_s,
            "decision_time_sigma": self.decision_time_sigma,
            "stop_early_rate": round(self.stop_early_rate, 4),
        }

    # --- JSON --------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: Any) -> FittedModel:
        """The model from its stored JSON; `ValueError` says what is wrong with it."""
        if not isinstance(data, Mapping):
            raise ValueError("a fitted model must be a JSON object")
        if data.get("kind") == "evaluative":
            raise ValueError(
                "the model was fitted to ratings (a fitted evaluator): it judges a run with "
                "evaluative feedback, and advises none"
            )
        if data.get("version") not in (1, FITTED_VERSION):
            raise ValueError(f"fitted models of versions 1 to {FITTED_VERSION} can be read")
        if data["version"] == 1:  # the sorting robot's, its groups what the arm held
            places, groups = vocabulary(get_task("sorting"))
            data = {**data, "by_group": data.get("by_held", {}), "task": "sorting",
                    "places": list(places), "groups": list(groups)}  # fmt: skip
        try:
            model = cls(
                advice=int(data["advice"]),
                sessions=[int(s) for s in data["sessions"]],
                methods=[str(m) for m in data["methods"]],
                overall=Count(**data["overall"]),
                by_group={str(k): Count(**v) for k, v in data["by_group"].items()},
                by_situation={str(k): Count(**v) for k, v in data["by_situation"].items()},
                wrong_actions=[[int(n) for n in row] for row in data["wrong_actions"]],
                decision_time_median_s=_optional(data["decision_time_median_s"]),
                decision_time_sigma=_optional(data["decision_time_sigma"]),
                decision_time_quantiles=[float(q) for q in data["decision_time_quantiles"]],
                budget_used=[float(u) for u in data["budget_used"]],
                task=str(data["task"]),
                places=[str(p) for p in data["places"]],
                groups=[str(g) for g in data["groups"]],
                correct_actions=[int(n) for n in data.get("correct_actions", [])],
                prior_strength=float(data.get("prior_strength", PRIOR_STRENGTH)),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            raise ValueError(f"not a fitted model: {error!r}") from None
        n = model.n_actions
        if n < 2 or any(len(row) != n for row in model.wrong_actions):
            raise ValueError("a fitted model's wrong_actions must be square, 2x2 or more")
        if model.correct_actions and len(model.correct_actions) != n:
            raise ValueError(f"a fitted model's correct_actions must have {n} counts")
        if model.prior_strength <= 0:
            raise ValueError("a fitted model's prior_strength must be above 0")
        return model


def _optional(value: Any) -> float | None:
    return None if value is None else float(value)


def read_model_json(path: str | Path) -> Any:
    """A fitted model's JSON file (what `ideeprl fit` writes), of either kind, as JSON;
    `ValueError` saying what is wrong where it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ValueError(
            f"no fitted model at {path}: `ideeprl fit --study ID` fits one and says where"
        ) from None
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"cannot read the fitted model at {path}: {error}") from None


def read_model(path: str | Path) -> FittedModel:
    """A fitted model's JSON file (what `ideeprl fit` writes)."""
    return FittedModel.from_json(read_model_json(path))


def fit(
    sessions: Sequence[SessionAdvice],
    methods: Sequence[str] = ("human",),
    prior_strength: float = PRIOR_STRENGTH,
    task: Task | None = None,
) -> FittedModel:
    """Fit the advisors of these sessions of `task` (the sorting robot when None);
    `ValueError` when they gave no advice, or advice outside the task's actions."""
    task = get_task("sorting") if task is None else task
    n = task.n_actions
    seen = [a for s in sessions for a in s.advice]
    if not seen:
        raise ValueError("the sessions gave no advice to fit")
    if any(not (0 <= a.correct < n and 0 <= a.advised < n) for a in seen):
        raise ValueError(f"advice to fit must name actions 0..{n - 1} of task {task.name}")
    by_situation: dict[str, list[int]] = {}
    by_group: dict[str, list[int]] = {}
    wrong_actions = [[0] * n for _ in range(n)]
    correct_actions = [0] * n
    for a in seen:
        wrong = int(a.advised != a.correct)
        for key, table in ((situation_key(a.place, a.group), by_situation), (a.group, by_group)):
            count = table.setdefault(key, [0, 0])
            count[0] += 1
            count[1] += wrong
        correct_actions[a.correct] += 1
        if wrong:
            wrong_actions[a.correct][a.advised] += 1
    times = np.array(
        [a.decision_time_s for a in seen if a.decision_time_s and a.decision_time_s > 0]
    )
    logs = np.log(times) if len(times) else None
    places, groups = vocabulary(task)
    return FittedModel(
        advice=len(seen),
        sessions=[s.session_id for s in sessions],
        methods=sorted(set(methods)),
        overall=Count(len(seen), sum(a.advised != a.correct for a in seen)),
        by_group={k: Count(*v) for k, v in sorted(by_group.items())},
        by_situation={k: Count(*v) for k, v in sorted(by_situation.items())},
        wrong_actions=wrong_actions,
        decision_time_median_s=float(np.exp(logs.mean())) if logs is not None else None,
        decision_time_sigma=float(logs.std()) if logs is not None else None,
        decision_time_quantiles=[float(q) for q in np.quantile(times, QUANTILES)]
        if len(times)
        else [],
        budget_used=[s.budget_used for s in sessions],
        task=task.name,
        places=list(places),
        groups=list(groups),
        correct_actions=correct_actions,
        prior_strength=prior_strength,
    )


def log_normal_time(rng: np.random.Generator, median_s: float, sigma: float) -> float:
    """A decision time drawn from a log-normal with this median."""
    return float(median_s * math.exp(sigma * rng.standard_normal()))


@dataclass
class FittedAdvisor:
    """Advises like a fitted study's people: the task's correct action from the ground
    truth (like `OracleAdvisor`), wrong with its situation's fitted rate (then an action
    drawn by the fitted confusions, uniform where none were seen); where nobody can say
    what is right (a page that shows no ground truth), an action drawn as the people
    advised. Each advice has a decision time drawn from the fitted log-normal
    (`last_decision_time_s`, which the server logs as the advice's `decision_time_s`). It
    sleeps that long only when `sleep` is set (a rehearsal through the participant's page),
    never in batch or worker runs. Given the run's `budget`, it leaves early as the fitted
    people did (`stop_after`, drawn once): past that many advice it answers `NO_ADVICE`
    (asked, counted, none given). `task` (the sorting robot, its `sort_rule`, when None)
    must be the model's."""

    model: FittedModel
    sort_rule: Any = "color"
    seed: int | None = None
    sleep: bool = False
    budget: int | None = None
    task: Task | None = None
    task_options: TaskOptions | None = None
    last_decision_time_s: float | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        if self.task is None:  # the sorting task, its rule given alone
            from sim.rules import SortRule

            self.task = get_task("sorting")
            self.task_options = {"sort_rule": SortRule.parse(self.sort_rule).to_spec()}
        if self.model.task != self.task.name:
            raise ValueError(
                f"the fitted model is of task {self.model.task}, not of this run's task "
                f"{self.task.name}: fit one to a study of task {self.task.name}"
            )
        if self.model.n_actions != self.task.n_actions:
            raise ValueError(
                f"the fitted model has {self.model.n_actions} actions; task {self.task.name} "
                f"has {self.task.n_actions}"
            )
        try:
            self._options = self.task.checked_options(self.task_options)
        except TaskError as error:
            raise ValueError(str(error)) from None
        self.rng = np.random.default_rng(self.seed)
        self.leaves_after = None if self.budget is None else self.stop_after(self.budget)
        """Advice given before this person leaves (None: the whole budget)."""
        self.given = 0

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int | NoAdvice:
        """Advice in the training stage (`advise_in` names another)."""
        return self.advise_in(info, TRAINING)

    def advise_at(self, moment: Moment) -> int | NoAdvice:
        return self.advise_in(moment.info, moment.stage)

    def advise_in(self, info: GymInfo | None, stage: str) -> int | NoAdvice:
        """Advice in the state `info` describes (None: one the person cannot see the ground
        truth of), in the run's `stage`."""
        if self.leaves_after is not None and self.given >= self.leaves_after:
            self.last_decision_time_s = None
            return NO_ADVICE
        assert self.task is not None, "set in __post_init__"
        self.given += 1
        correct = None if info is None else self.task.correct(info, self._options)
        if correct is None:
            shares = self.model.advised_actions()
            action = int(self.rng.choice(self.model.n_actions, p=shares / shares.sum()))
        else:
            assert info is not None
            rate = self.model.error_rate(*situation(self.task, info, stage, correct))
            action = self._wrong(correct) if self.rng.random() < rate else correct
        median, sigma = self.model.decision_time_median_s, self.model.decision_time_sigma
        self.last_decision_time_s = (
            log_normal_time(self.rng, median, sigma or 0.0) if median is not None else None
        )
        if self.sleep and self.last_decision_time_s:
            time.sleep(self.last_decision_time_s)
        return action

    def _wrong(self, correct: int) -> int:
        weights = np.array(self.model.wrong_actions[correct], dtype=float) + 1.0
        weights[correct] = 0.0
        return int(self.rng.choice(self.model.n_actions, p=weights / weights.sum()))

    def stop_after(self, budget: int) -> int | None:
        """How many advice this simulated person gives before leaving, drawn from the
        fitted sessions' budget use; None: the whole budget."""
        used = self.model.budget_used
        if not used:
            return None
        share = used[int(self.rng.integers(len(used)))]
        return None if share >= 1.0 else int(share * budget)

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state, "given": self.given,
                "leaves_after": self.leaves_after}  # fmt: skip

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]
        self.given = int(state.get("given", 0))
        self.leaves_after = state.get("leaves_after", self.leaves_after)
