"""Advisors fitted to people: how often a study's advisors were right, by situation, what
they advised when wrong, how long they took, and how much of their budget they used; and
`FittedAdvisor`, which advises like them.

Simulated advisors let a researcher try a study's design (budget, strategy, sample size)
on advisors as reliable and as slow as the people they will recruit, before recruiting
them. The situation is what a person sees that changes how hard the choice is: the arm's
station and the colour of what it holds (nothing, red, blue). Nine situations stay
estimable from about 100 advice per person because each one's rate is pulled toward its
held colour's rate, and that toward the overall rate, by `prior_strength` pseudo-advice
(a situation with few advice gets its parent's rate; one with many, its own).

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
from typing import Any

import numpy as np

from learner.no_advice import NO_ADVICE

FITTED_VERSION = 1
"""Version of the stored model (`FittedModel.to_json`); `from_json` reads this one."""
N_ACTIONS = 4
STATIONS = ("center", "left", "right")
HELD = ("nothing", "red", "blue")
"""What the arm holds, as a situation knows it: nothing, or the held object's colour."""
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
"""The decision-time quantiles a model keeps beside its log-normal fit."""
PRIOR_STRENGTH = 10.0


def situation(info: Mapping[str, Any]) -> tuple[str, str]:
    """(station, held) of the environment's ground truth: `("center", "blue")`."""
    return str(info["station"]), str(info.get("held_color") or "") or "nothing"


def situation_key(station: str, held: str) -> str:
    return f"{station}/{held}"


@dataclass(frozen=True)
class AdviceSeen:
    """One advice as the fit needs it: where the arm was, what was right, what was advised."""

    station: str
    held: str
    """nothing, red or blue."""
    correct: int
    """The oracle's action in that state (`sim.oracle_action`)."""
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
    by_held: dict[str, Count]
    """By what the arm held (`HELD`)."""
    by_situation: dict[str, Count]
    """By station and what the arm held (`situation_key`: `center/blue`)."""
    wrong_actions: list[list[int]]
    """[correct][advised]: how often each wrong action was advised for each correct one."""
    decision_time_median_s: float | None
    """The log-normal fit of the decision times: its median (None: no times recorded)."""
    decision_time_sigma: float | None
    """... and the standard deviation of their logarithm."""
    decision_time_quantiles: list[float]
    """The empirical decision times at `QUANTILES` (empty without times)."""
    budget_used: list[float]
    """Each session's share of its advice budget that it used (1.0: the whole budget)."""
    prior_strength: float = PRIOR_STRENGTH
    """Pseudo-advice that pull a situation's rate toward its parent's."""
    version: int = FITTED_VERSION

    # --- rates -------------------------------------------------------------------------
    def overall_rate(self) -> float:
        return self.overall.wrong / self.overall.advice if self.overall.advice else 0.0

    def held_rate(self, held: str) -> float:
        return self._pulled(self.by_held.get(held, Count()), self.overall_rate())

    def error_rate(self, station: str, held: str) -> float:
        """The chance that advice in this situation is wrong."""
        count = self.by_situation.get(situation_key(station, held), Count())
        return self._pulled(count, self.held_rate(held))

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
        return {
            "advice": self.advice,
            "sessions": len(self.sessions),
            "error_rate": round(self.overall_rate(), 4),
            "error_rate_by_held": {h: round(self.held_rate(h), 4) for h in HELD},
            "error_rate_by_situation": {
                situation_key(s, h): round(self.error_rate(s, h), 4) for s in STATIONS for h in HELD
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
        if data.get("version") != FITTED_VERSION:
            raise ValueError(f"fitted models of version {FITTED_VERSION} can be read")
        try:
            model = cls(
                advice=int(data["advice"]),
                sessions=[int(s) for s in data["sessions"]],
                methods=[str(m) for m in data["methods"]],
                overall=Count(**data["overall"]),
                by_held={str(k): Count(**v) for k, v in data["by_held"].items()},
                by_situation={str(k): Count(**v) for k, v in data["by_situation"].items()},
                wrong_actions=[[int(n) for n in row] for row in data["wrong_actions"]],
                decision_time_median_s=_optional(data["decision_time_median_s"]),
                decision_time_sigma=_optional(data["decision_time_sigma"]),
                decision_time_quantiles=[float(q) for q in data["decision_time_quantiles"]],
                budget_used=[float(u) for u in data["budget_used"]],
                prior_strength=float(data.get("prior_strength", PRIOR_STRENGTH)),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            raise ValueError(f"not a fitted model: {error!r}") from None
        if len(model.wrong_actions) != N_ACTIONS or any(
            len(row) != N_ACTIONS for row in model.wrong_actions
        ):
            raise ValueError(f"a fitted model's wrong_actions must be {N_ACTIONS}x{N_ACTIONS}")
        if model.prior_strength <= 0:
            raise ValueError("a fitted model's prior_strength must be above 0")
        return model


def _optional(value: Any) -> float | None:
    return None if value is None else float(value)


def read_model(path: str | Path) -> FittedModel:
    """A fitted model's JSON file (what `ideeprl fit` writes)."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ValueError(
            f"no fitted model at {path}: `ideeprl fit --study ID` fits one and says where"
        ) from None
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"cannot read the fitted model at {path}: {error}") from None
    return FittedModel.from_json(data)


def fit(
    sessions: Sequence[SessionAdvice],
    methods: Sequence[str] = ("human",),
    prior_strength: float = PRIOR_STRENGTH,
) -> FittedModel:
    """Fit the advisors of these sessions; `ValueError` when they gave no advice."""
    seen = [a for s in sessions for a in s.advice]
    if not seen:
        raise ValueError("the sessions gave no advice to fit")
    by_situation: dict[str, list[int]] = {}
    by_held: dict[str, list[int]] = {}
    wrong_actions = [[0] * N_ACTIONS for _ in range(N_ACTIONS)]
    for a in seen:
        wrong = int(a.advised != a.correct)
        for key, table in ((situation_key(a.station, a.held), by_situation), (a.held, by_held)):
            count = table.setdefault(key, [0, 0])
            count[0] += 1
            count[1] += wrong
        if wrong:
            wrong_actions[a.correct][a.advised] += 1
    times = np.array(
        [a.decision_time_s for a in seen if a.decision_time_s and a.decision_time_s > 0]
    )
    logs = np.log(times) if len(times) else None
    return FittedModel(
        advice=len(seen),
        sessions=[s.session_id for s in sessions],
        methods=sorted(set(methods)),
        overall=Count(len(seen), sum(a.advised != a.correct for a in seen)),
        by_held={k: Count(*v) for k, v in sorted(by_held.items())},
        by_situation={k: Count(*v) for k, v in sorted(by_situation.items())},
        wrong_actions=wrong_actions,
        decision_time_median_s=float(np.exp(logs.mean())) if logs is not None else None,
        decision_time_sigma=float(logs.std()) if logs is not None else None,
        decision_time_quantiles=[float(q) for q in np.quantile(times, QUANTILES)]
        if len(times)
        else [],
        budget_used=[s.budget_used for s in sessions],
        prior_strength=prior_strength,
    )


def log_normal_time(rng: np.random.Generator, median_s: float, sigma: float) -> float:
    """A decision time drawn from a log-normal with this median."""
    return float(median_s * math.exp(sigma * rng.standard_normal()))


@dataclass
class FittedAdvisor:
    """Advises like a fitted study's people: the correct action from the ground truth
    (like `OracleAdvisor`), wrong with its situation's fitted rate (then an action drawn
    by the fitted confusions, uniform where none were seen), each advice with a decision
    time drawn from the fitted log-normal (`last_decision_time_s`, which the server logs
    as the advice's `decision_time_s`). It sleeps that long only when `sleep` is set (a
    rehearsal through the participant's page), never in batch or worker runs. Given the
    run's `budget`, it leaves early as the fitted people did (`stop_after`, drawn once):
    past that many advice it answers `NO_ADVICE` (asked, counted, none given)."""

    model: FittedModel
    sort_rule: Any = "color"
    seed: int | None = None
    sleep: bool = False
    budget: int | None = None
    last_decision_time_s: float | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        import sim

        self._rule = sim.SortRule.parse(self.sort_rule)
        self._oracle_action = sim.oracle_action
        self.rng = np.random.default_rng(self.seed)
        self.leaves_after = None if self.budget is None else self.stop_after(self.budget)
        """Advice given before this person leaves (None: the whole budget)."""
        self.given = 0

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> Any:
        if self.leaves_after is not None and self.given >= self.leaves_after:
            self.last_decision_time_s = None
            return NO_ADVICE
        self.given += 1
        correct = int(self._oracle_action(info, self._rule))
        rate = self.model.error_rate(*situation(info))
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
        return int(self.rng.choice(N_ACTIONS, p=weights / weights.sum()))

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
