"""Evaluators fitted to people: how often a study's people's ratings of the learner's moves
went against the task's correct action (Good for another action, Bad for the correct one),
by situation and by whether the move was right, how often they let a turn pass without an
answer, and how long they took; and `FittedEvaluator`, which rates like them.

The evaluative counterpart of `learner.fitted` (advice): a researcher tries an evaluative
study's design on evaluators as reliable, as silent and as slow as the people they will
recruit. A rating is right when it says what the task's correct action says of the move
(Good for it, Bad for any other). People judge a right move and a wrong one differently
(a trainer's positive bias, Thomaz and Breazeal 2008), so the hierarchy's root splits by
the move: within each, a situation's rate is pulled toward its group's rate, and that
toward the move's rate, by `prior_strength` pseudo-ratings, as the advice model pulls its
rates. A turn without an answer is drawn at the rate of one fitted
person (each simulated evaluator draws one session's share once, as a fitted advisor draws
when it leaves): some people let many turns pass, others none.

Torch-free and database-free: `study.services.fitting` reads a study's rows, replays the
rated episodes to recover each rating's situation and correct action, and calls
`fit_ratings`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from learner.evaluators import BAD, GOOD
from learner.fitted import (
    PRIOR_STRENGTH,
    QUANTILES,
    FittedModel,
    Moment,
    log_normal_time,
    read_model_json,
    situation,
    situation_key,
    vocabulary,
)
from learner.records import TRAINING
from tasks import GymInfo, Task, TaskError, TaskOptions, get_task

EVALUATIVE = "evaluative"
"""A rating model's `kind` (an advice model has none: `learner.fitted.FittedModel`)."""
RATINGS_VERSION = 1
MOVES = ("right", "wrong")
"""The rated move was the task's correct action, or another."""


@dataclass(frozen=True)
class RatingSeen:
    """One rating turn as the fit needs it: its situation, whether the move rated was the
    correct action, and the answer."""

    place: str
    group: str
    """The situation (`learner.fitted.situation`) of the state the move was made in."""
    right: bool
    """The move rated was the task's correct action in that state."""
    judgement: float | None
    """+1 Good, -1 Bad; None: no answer (the turn's time-out passed)."""
    decision_time_s: float | None = None


@dataclass(frozen=True)
class SessionRatings:
    """One session's rating turns, in order."""

    session_id: int
    ratings: Sequence[RatingSeen]

    @property
    def silent_share(self) -> float:
        """Its share of turns left without an answer."""
        return sum(r.judgement is None for r in self.ratings) / len(self.ratings)


@dataclass(frozen=True)
class RatingCount:
    """Answered ratings in a situation, and how many of them were wrong."""

    ratings: int = 0
    wrong: int = 0


class RatedMoment(Moment, Protocol):
    """What a fitted evaluator reads of a strategy's `AdviceMoment`: the state, the stage,
    and the move taken."""

    @property
    def intended_action(self) -> int: ...


def move_key(right: bool) -> str:
    return MOVES[0] if right else MOVES[1]


@dataclass(frozen=True)
class FittedEvaluatorModel:
    """A study's evaluators, fitted (versioned JSON: `to_json`, `from_json`)."""

    turns: int
    """Rating turns it was fitted from, answered or not."""
    answered: int
    good: int
    """Answers that said Good (what an evaluator without the ground truth says as often)."""
    sessions: list[int]
    methods: list[str]
    by_move: dict[str, RatingCount]
    """By the move rated: `right` (the correct action) or `wrong`."""
    by_group: dict[str, RatingCount]
    """By move and the situation's group (`right/blue`)."""
    by_situation: dict[str, RatingCount]
    """By move, place and group (`right/center/blue`)."""
    silent_shares: list[float]
    """Each session's share of turns without an answer."""
    decision_time_median_s: float | None
    decision_time_sigma: float | None
    decision_time_quantiles: list[float]
    task: str
    places: list[str] = field(default_factory=list)
    groups: list[str] = field(default_factory=list)
    prior_strength: float = PRIOR_STRENGTH
    kind: str = EVALUATIVE
    version: int = RATINGS_VERSION

    # --- rates -------------------------------------------------------------------------
    def overall_rate(self) -> float:
        wrong = sum(c.wrong for c in self.by_move.values())
        return wrong / self.answered if self.answered else 0.0

    def move_rate(self, right: bool) -> float:
        count = self.by_move.get(move_key(right), RatingCount())
        return self._pulled(count, self.overall_rate())

    def group_rate(self, right: bool, group: str) -> float:
        count = self.by_group.get(f"{move_key(right)}/{group}", RatingCount())
        return self._pulled(count, self.move_rate(right))

    def error_rate(self, right: bool, place: str, group: str) -> float:
        """The chance that a rating of a move (right or not) in this situation is wrong."""
        key = f"{move_key(right)}/{situation_key(place, group)}"
        count = self.by_situation.get(key, RatingCount())
        return self._pulled(count, self.group_rate(right, group))

    def good_rate(self) -> float:
        return self.good / self.answered if self.answered else 0.5

    def silent_rate(self) -> float:
        return (self.turns - self.answered) / self.turns if self.turns else 0.0

    def _pulled(self, count: RatingCount, parent: float) -> float:
        k = self.prior_strength
        return (count.wrong + k * parent) / (count.ratings + k)

    def summary(self) -> dict[str, Any]:
        """What a researcher reads: rates by move and situation, silence, times."""
        groups = self.groups or sorted({k.split("/")[1] for k in self.by_group})
        places = self.places or sorted({k.split("/")[1] for k in self.by_situation})
        return {
            "kind": self.kind,
            "task": self.task,
            "ratings": self.turns,
            "answered": self.answered,
            "sessions": len(self.sessions),
            "error_rate": round(self.overall_rate(), 4),
            "error_rate_by_move": {m: round(self.move_rate(m == "right"), 4) for m in MOVES},
            "error_rate_by_situation": {
                f"{m}/{situation_key(p, g)}": round(self.error_rate(m == "right", p, g), 4)
                for m in MOVES
                for p in places
                for g in groups
            },
            "good_rate": round(self.good_rate(), 4),
            "no_answer_rate": round(self.silent_rate(), 4),
            "decision_time_median_s": self.decision_time_median_s,
            "decision_time_sigma": self.decision_time_sigma,
        }

    # --- JSON --------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: Any) -> FittedEvaluatorModel:
        """The model from its stored JSON; `ValueError` says what is wrong with it."""
        if not isinstance(data, Mapping) or data.get("kind") != EVALUATIVE:
            raise ValueError("a fitted evaluator is a JSON object of kind evaluative")
        if data.get("version") != RATINGS_VERSION:
            raise ValueError(f"fitted evaluators of version {RATINGS_VERSION} can be read")
        try:

            def counts(name: str) -> dict[str, RatingCount]:
                return {str(k): RatingCount(**v) for k, v in data[name].items()}

            median, sigma = data["decision_time_median_s"], data["decision_time_sigma"]
            model = cls(
                turns=int(data["turns"]),
                answered=int(data["answered"]),
                good=int(data["good"]),
                sessions=[int(s) for s in data["sessions"]],
                methods=[str(m) for m in data["methods"]],
                by_move=counts("by_move"),
                by_group=counts("by_group"),
                by_situation=counts("by_situation"),
                silent_shares=[float(s) for s in data["silent_shares"]],
                decision_time_median_s=None if median is None else float(median),
                decision_time_sigma=None if sigma is None else float(sigma),
                decision_time_quantiles=[float(q) for q in data["decision_time_quantiles"]],
                task=str(data["task"]),
                places=[str(p) for p in data["places"]],
                groups=[str(g) for g in data["groups"]],
                prior_strength=float(data.get("prior_strength", PRIOR_STRENGTH)),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            raise ValueError(f"not a fitted evaluator: {error!r}") from None
        if not 0 <= model.good <= model.answered <= model.turns or model.turns < 1:
            raise ValueError("a fitted evaluator's counts must be 0 <= good <= answered <= turns")
        if model.prior_strength <= 0:
            raise ValueError("a fitted evaluator's prior_strength must be above 0")
        if any(not 0.0 <= s <= 1.0 for s in model.silent_shares):
            raise ValueError("a fitted evaluator's silent_shares must lie in [0, 1]")
        return model


AnyFitted = FittedModel | FittedEvaluatorModel


def model_from_json(data: Any) -> AnyFitted:
    """A stored fitted model of either kind: an evaluator's (`kind` evaluative) or an
    advisor's."""
    if isinstance(data, Mapping) and data.get("kind") == EVALUATIVE:
        return FittedEvaluatorModel.from_json(data)
    return FittedModel.from_json(data)


def read_any_model(path: str | Path) -> AnyFitted:
    """A fitted model's JSON file (what `ideeprl fit` writes), of either kind."""
    return model_from_json(read_model_json(path))


def read_evaluator_model(path: str | Path) -> FittedEvaluatorModel:
    """A fitted evaluator's JSON file; `ValueError` for an advisor's."""
    model = read_any_model(path)
    if not isinstance(model, FittedEvaluatorModel):
        raise ValueError(
            f"the model at {path} was fitted to advice; evaluative feedback takes a model "
            "fitted to ratings (`ideeprl fit` of a study's evaluative sessions)"
        )
    return model


def fit_ratings(
    sessions: Sequence[SessionRatings],
    methods: Sequence[str] = ("human",),
    prior_strength: float = PRIOR_STRENGTH,
    task: Task | None = None,
) -> FittedEvaluatorModel:
    """Fit the evaluators of these sessions of `task` (the sorting robot when None);
    `ValueError` when they had no rating turns."""
    task = get_task("sorting") if task is None else task
    sessions = [s for s in sessions if s.ratings]
    seen = [r for s in sessions for r in s.ratings]
    if not seen:
        raise ValueError("the sessions had no rating turns to fit")
    answered = [r for r in seen if r.judgement is not None]
    tables: dict[str, dict[str, list[int]]] = {"move": {}, "group": {}, "situation": {}}
    for r in answered:
        wrong = int((r.judgement == GOOD) != r.right)
        move = move_key(r.right)
        keys = {
            "move": move,
            "group": f"{move}/{r.group}",
            "situation": f"{move}/{situation_key(r.place, r.group)}",
        }
        for table, key in keys.items():
            count = tables[table].setdefault(key, [0, 0])
            count[0] += 1
            count[1] += wrong
    times = np.array([r.decision_time_s for r in answered if r.decision_time_s])
    times = times[times > 0]
    logs = np.log(times) if len(times) else None
    places, groups = vocabulary(task)

    def counts(table: str) -> dict[str, RatingCount]:
        return {k: RatingCount(*v) for k, v in sorted(tables[table].items())}

    return FittedEvaluatorModel(
        turns=len(seen),
        answered=len(answered),
        good=sum(r.judgement == GOOD for r in answered),
        sessions=[s.session_id for s in sessions],
        methods=sorted(set(methods)),
        by_move=counts("move"),
        by_group=counts("group"),
        by_situation=counts("situation"),
        silent_shares=[s.silent_share for s in sessions],
        decision_time_median_s=float(np.exp(logs.mean())) if logs is not None else None,
        decision_time_sigma=float(logs.std()) if logs is not None else None,
        decision_time_quantiles=[float(q) for q in np.quantile(times, QUANTILES)]
        if len(times)
        else [],
        task=task.name,
        places=list(places),
        groups=list(groups),
        prior_strength=prior_strength,
    )


@dataclass
class FittedEvaluator:
    """Rates like a fitted study's people (`learner.evaluators.MomentEvaluator`): the move's
    verdict from the task's correct action (Good for it, Bad for another), wrong with the
    fitted rate of its move and situation; where nobody can say what is right (a page that
    shows no ground truth), Good as often as the people said Good. A turn passes without an
    answer at the rate of one fitted person, drawn once (`silent_rate`). Each answer has a
    decision time from the fitted log-normal (`last_decision_time_s`), slept only when
    `sleep` is set (a rehearsal through the page). `task` (the sorting robot, its
    `sort_rule`, when None) must be the model's."""

    model: FittedEvaluatorModel
    sort_rule: Any = "color"
    seed: int | None = None
    sleep: bool = False
    task: Task | None = None
    task_options: TaskOptions | None = None
    last_decision_time_s: float | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        if self.task is None:
            from sim.rules import SortRule

            self.task = get_task("sorting")
            self.task_options = {"sort_rule": SortRule.parse(self.sort_rule).to_spec()}
        if self.model.task != self.task.name:
            raise ValueError(
                f"the fitted evaluator is of task {self.model.task}, not of this run's task "
                f"{self.task.name}: fit one to a study of task {self.task.name}"
            )
        try:
            self._options = self.task.checked_options(self.task_options)
        except TaskError as error:
            raise ValueError(str(error)) from None
        self.rng = np.random.default_rng(self.seed)
        shares = self.model.silent_shares
        self.silent_rate = shares[int(self.rng.integers(len(shares)))] if shares else 0.0
        """This person's chance of letting a turn pass without an answer."""

    def judge(self, obs: np.ndarray, info: dict[str, Any], action: int) -> float | None:
        """A rating in the training stage (`judge_at` knows the moment's stage)."""
        return self.rate(info, TRAINING, action)

    def judge_at(self, moment: RatedMoment) -> float | None:
        return self.rate(moment.info, moment.stage, int(moment.intended_action))

    def rate(self, info: GymInfo | None, stage: str, action: int) -> float | None:
        """The rating of `action` taken in the state `info` describes (None: one the person
        cannot see the ground truth of), in the run's `stage`; None: no answer."""
        if self.rng.random() < self.silent_rate:
            self.last_decision_time_s = None
            return None
        assert self.task is not None, "set in __post_init__"
        correct = None if info is None else self.task.correct(info, self._options)
        if correct is None:
            good = self.rng.random() < self.model.good_rate()
        else:
            assert info is not None
            right = int(action) == int(correct)
            rate = self.model.error_rate(right, *situation(self.task, info, stage, correct))
            good = right != (self.rng.random() < rate)
        median, sigma = self.model.decision_time_median_s, self.model.decision_time_sigma
        self.last_decision_time_s = (
            log_normal_time(self.rng, median, sigma or 0.0) if median is not None else None
        )
        if self.sleep and self.last_decision_time_s:
            time.sleep(self.last_decision_time_s)
        return GOOD if good else BAD

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state, "silent_rate": self.silent_rate}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]
        self.silent_rate = float(state["silent_rate"])
