"""When to ask the advisor: teaching on a budget.

The paper uses early advising (its advisor's 100 actions close the pretraining stage).
The others come from the teaching-on-a-budget literature it cites (Torrey and Taylor,
2013) and act during training. Every strategy counts the advice it gives and never
exceeds its budget; an advised action is executed (policy shaping).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from learner.advisors import NO_ADVICE, Advisor, NoAdvice

STRATEGY_NAMES = ("early", "alternating", "importance", "mistake_correcting")


def early_budget_problem(budget: int, pretraining_steps: int) -> str | None:
    """Why early advising cannot give `budget` advice in `pretraining_steps` steps, or None.
    Its advice closes the pretraining stage, so there must be room for all of it (the one
    place this rule is written: the trainer, `RunSpec.validate` and so the server and the
    batch ask it)."""
    if budget <= pretraining_steps:
        return None
    return (
        f"early advising gives its {budget} advice at the end of pretraining, which has only "
        f"{pretraining_steps} steps (its budget cannot exceed pretraining_steps); lower the "
        "advice budget or raise pretraining_steps"
    )


@dataclass(frozen=True)
class AdviceMoment:
    """What a strategy may look at when deciding to ask for advice."""

    obs: np.ndarray
    """The image the learner sees."""
    info: dict[str, Any]
    """The environment's ground truth (for simulated advisors)."""
    stage: str
    """`pretraining` or `training`."""
    global_step: int
    """The step about to be taken, from 1."""
    pretraining_steps: int
    """Length of the pretraining stage."""
    intended_action: int
    """The action the learner would take without advice (random in pretraining,
    epsilon-greedy in training)."""
    greedy_action: int
    """The learner's greedy action."""

    @property
    def training_step(self) -> int:
        """The step's number within the training stage, from 1 (<= 0 in pretraining)."""
        return self.global_step - self.pretraining_steps


@runtime_checkable
class MomentAdvisor(Protocol):
    """An advisor shown the whole moment, not only the image: the step and the learner's
    own choice, which the session worker's advisors log beside the advice."""

    def advise_at(self, moment: AdviceMoment) -> int | NoAdvice: ...


AnyAdvisor = Advisor | MomentAdvisor


def ask(advisor: AnyAdvisor, moment: AdviceMoment) -> int | NoAdvice:
    """The advisor's answer at this moment: shown the moment where it takes one, else the
    image and the ground truth."""
    if isinstance(advisor, MomentAdvisor):
        return advisor.advise_at(moment)
    return advisor.advise(moment.obs, moment.info)


class AdvisingStrategy:
    """Base: asks the advisor and keeps the budget; subclasses say when to ask (`_asks`)."""

    name: ClassVar[str] = ""
    needs_values: ClassVar[bool] = False
    """Whether the advisor must offer `q_values` (importance)."""
    judges: ClassVar[bool] = True
    """Whether its window is decided without the advisor's action, so that an evaluator can
    judge in it (evaluative feedback: `in_window`)."""
    corrects_only: ClassVar[bool] = False
    """Whether an advice the learner would have followed anyway (the advisor's action is
    the learner's intended one) is dropped, uncounted (mistake correcting)."""

    def __init__(self, budget: int = 100) -> None:
        if isinstance(budget, bool) or not isinstance(budget, int) or budget < 0:
            raise ValueError(f"budget must be a whole number >= 0, got {budget!r}")
        self.budget = budget
        self.used = 0

    @property
    def remaining(self) -> int:
        return self.budget - self.used

    def advise(self, moment: AdviceMoment, advisor: AnyAdvisor, n_actions: int = 4) -> int | None:
        """The advised action to execute, or None; counts the advice against the budget.
        Where the strategy asks (`_asks`), the advisor is shown the moment if it takes one
        (a `MomentAdvisor`), else the image and the ground truth. An advisor that answers
        `NO_ADVICE` (a replayed stream that ran out) was asked all the same: the request is
        counted, and the learner acts on its own."""
        if self.remaining <= 0 or not self._asks(moment, advisor):
            return None
        if isinstance(advisor, MomentAdvisor):
            action = advisor.advise_at(moment)
        else:
            action = advisor.advise(moment.obs, moment.info)
        if self.corrects_only and action == moment.intended_action:
            return None
        if action is NO_ADVICE:
            self.used += 1
            return None
        if isinstance(action, bool) or not isinstance(action, int | np.integer):
            raise ValueError(
                f"advisor returned {action!r}; an action is an int in 0..{n_actions - 1}"
            )
        if not 0 <= action < n_actions:
            raise ValueError(
                f"advisor returned action {action}; valid actions are 0..{n_actions - 1}"
            )
        self.used += 1
        return int(action)

    def in_window(self, moment: AdviceMoment, evaluator: Any) -> bool:
        """Whether this step is one the strategy gives its advisor, counted against the
        budget: evaluative feedback's window (`learner.evaluators`), decided by the very
        rule that gives advice its steps (`_asks`), so both kinds of feedback get the same
        ones. The strategy is shown `evaluator` (its values, for importance) in the
        advisor's place; an evaluator with `window_opens` (a person's) is told the step is
        in it."""
        if self.remaining <= 0 or not self._asks(moment, evaluator):
            return False
        opens = getattr(evaluator, "window_opens", None)
        if opens is not None:
            opens(moment)
        self.used += 1
        return True

    def _asks(self, moment: AdviceMoment, advisor: Any) -> bool:
        """Whether the advisor is asked at this moment (the budget aside): each strategy's
        rule. `advisor` is the advisor, or the evaluator in its place (`in_window`)."""
        raise NotImplementedError

    def first_advice_step(self, pretraining_steps: int) -> int:
        """The earliest global step it may advise at (from 1): the training stage's first
        step, unless a strategy advises in pretraining."""
        return pretraining_steps + 1

    def check(self, pretraining_steps: int, advisor: object) -> None:
        """Raise a `ValueError` if this strategy cannot work with this run."""
        if self.needs_values and not callable(getattr(advisor, "q_values", None)):
            raise ValueError(
                f"the {self.name} strategy needs an advisor with q_values (the agent advisor); "
                f"{type(advisor).__name__} has none"
            )

    def options(self) -> dict[str, Any]:
        """Constructor arguments besides the budget (for checkpoints and logs)."""
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {"name": self.name, "budget": self.budget, "used": self.used, **self.options()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        mine = self.state_dict()
        for key in mine:
            if key != "used" and state.get(key) != mine[key]:
                raise ValueError(
                    f"checkpoint strategy has {key}={state.get(key)!r}, this one {mine[key]!r}"
                )
        self.used = int(state["used"])

    def __repr__(self) -> str:
        options = "".join(f", {k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}(budget={self.budget}{options}, used={self.used})"


class EarlyAdvising(AdvisingStrategy):
    """The paper's: the advisor takes the last `budget` steps of pretraining, consecutively
    (global steps 901..1000 with the defaults)."""

    name = "early"

    def _asks(self, moment: AdviceMoment, advisor: Any) -> bool:
        first = self.first_advice_step(moment.pretraining_steps)
        return moment.stage == "pretrain" and moment.global_step >= first

    def first_advice_step(self, pretraining_steps: int) -> int:
        return max(1, pretraining_steps - self.budget + 1)

    def check(self, pretraining_steps: int, advisor: object) -> None:
        super().check(pretraining_steps, advisor)
        problem = early_budget_problem(self.budget, pretraining_steps)
        if problem:
            raise ValueError(problem)


class AlternatingAdvising(AdvisingStrategy):
    """From the first training step, advice on every `interval`-th step (advised, own,
    advised, own, ... with 2) until the budget is spent."""

    name = "alternating"

    def __init__(self, budget: int = 100, interval: int = 2) -> None:
        super().__init__(budget)
        if isinstance(interval, bool) or not isinstance(interval, int) or interval < 1:
            raise ValueError(f"interval must be a whole number >= 1, got {interval!r}")
        self.interval = interval

    def _asks(self, moment: AdviceMoment, advisor: Any) -> bool:
        return moment.stage == "train" and (moment.training_step - 1) % self.interval == 0

    def options(self) -> dict[str, Any]:
        return {"interval": self.interval}


class ImportanceAdvising(AdvisingStrategy):
    """During training, advice in states the advisor finds important: the spread of its
    Q-values (max - min) is at least `threshold`."""

    name = "importance"
    needs_values = True

    def __init__(self, budget: int = 100, threshold: float = 0.1) -> None:
        super().__init__(budget)
        if isinstance(threshold, bool) or not isinstance(threshold, int | float) or threshold < 0:
            raise ValueError(f"threshold must be a number >= 0, got {threshold!r}")
        self.threshold = float(threshold)

    def _asks(self, moment: AdviceMoment, advisor: Any) -> bool:
        if moment.stage != "train":
            return False
        values = np.asarray(advisor.q_values(moment.obs))
        return float(values.max() - values.min()) >= self.threshold

    def options(self) -> dict[str, Any]:
        return {"threshold": self.threshold}


class MistakeCorrecting(ImportanceAdvising):
    """Importance advising that spends advice only where the learner's intended action
    differs from the advisor's; where they agree the learner acts on its own."""

    name = "mistake_correcting"
    judges = False
    corrects_only = True


_STRATEGIES: dict[str, type[AdvisingStrategy]] = {
    cls.name: cls
    for cls in (EarlyAdvising, AlternatingAdvising, ImportanceAdvising, MistakeCorrecting)
}


def make_strategy(name: str, budget: int = 100, **options: Any) -> AdvisingStrategy:
    """`early`, `alternating` (interval=2), `importance` (threshold=0.1) or
    `mistake_correcting` (threshold=0.1), each with an advice budget."""
    if name not in _STRATEGIES:
        raise ValueError(
            f"unknown strategy {name!r}; valid strategies: {', '.join(STRATEGY_NAMES)}"
        )
    try:
        return _STRATEGIES[name](budget, **options)
    except TypeError as error:
        raise ValueError(f"bad options for the {name} strategy: {error}") from error
