"""Each advice is stored with the task's correct action at its step, a person's (through
the request the web process stores) and a machine advisor's alike: what the report's
accuracy reads."""

from __future__ import annotations

from typing import Any

import numpy as np

from learner.strategies import AdviceMoment
from runs.worker.advisors import HumanAdvisor, RecordingAdvisor
from runs.worker.messages import AdviceRequest
from study.services.advice import AdviceGiven
from tasks import CorrectActions, get_task

STATES = [
    ({"held": "", "station": "center"}, 0),  # nothing held: grab
    ({"held": "cube/blue", "station": "center"}, 1),  # blue goes right: move right
    ({"held": "disk/red", "station": "center"}, 2),  # red goes left: move left
    ({"held": "cube/red", "station": "left"}, 3),  # at its side: drop
]
"""States of the sorting robot under the colour rule (blue right, red left), with the
correct action worked out by hand (0 grab, 1 move right, 2 move left, 3 drop)."""


def _correct(info: dict[str, Any]) -> CorrectActions:
    return get_task("sorting").correct_actions(info, {"sort_rule": "color"})


def _moment(info: dict[str, Any], step: int) -> AdviceMoment:
    return AdviceMoment(
        obs=np.zeros((64, 64, 3), np.uint8), info=info, stage="pretrain", global_step=step,
        pretraining_steps=100, intended_action=0, greedy_action=0,
    )  # fmt: skip


class _Link:
    """The web process as the advisor sees it: the participant always moves right."""

    participant_ready = True

    def __init__(self) -> None:
        self.sent: list[Any] = []

    def send(self, message: Any) -> None:
        self.sent.append(message)

    def wait_for_answer(self, advice_index: int, idle_limit_s: float) -> int:
        return 1


class _Log:
    """Where a machine advisor logs its advice: kept here, in order."""

    def __init__(self) -> None:
        self.logged: list[AdviceGiven] = []

    def add_advice(self, advice: AdviceGiven) -> None:
        self.logged.append(advice)


class _Reporter:
    def before_waiting(self) -> None:
        pass


def test_a_persons_advice_request_carries_the_correct_action() -> None:
    link = _Link()
    reporter: Any = _Reporter()
    advisor = HumanAdvisor(link, reporter, {}, 0, 10, 60.0, correct=_correct)  # type: ignore[arg-type]
    answers = [advisor.advise_at(_moment(info, i + 1)) for i, (info, _) in enumerate(STATES)]
    requests = [m for m in link.sent if isinstance(m, AdviceRequest)]
    assert answers == [1, 1, 1, 1]
    assert [r.correct for r in requests] == [CorrectActions(a, (a,)) for _, a in STATES]
    # one of the four answers was right: the report's accuracy for this person is 1/4


def test_a_machine_advisors_advice_is_logged_with_the_correct_action() -> None:
    class Left:
        def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
            return 2

    log = _Log()
    logged = log.logged

    advisor = RecordingAdvisor(Left(), 1, "oracle", 0, log, _correct)  # type: ignore[arg-type]
    for i, (info, _) in enumerate(STATES):
        advisor.advise_at(_moment(info, i + 1))
    assert [a.correct_action for a in logged] == [right for _, right in STATES]
    assert [a.correct_actions for a in logged] == [[right] for _, right in STATES]
    assert [a.action for a in logged] == [2, 2, 2, 2]


def test_without_a_correct_action_none_is_stored() -> None:
    log = _Log()
    logged = log.logged

    class Zero:
        def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
            return 0

    advisor = RecordingAdvisor(Zero(), 1, "random", 0, log)  # type: ignore[arg-type]
    advisor.advise_at(_moment(STATES[0][0], 1))
    assert logged[0].correct_action is None and logged[0].correct_actions is None


def test_the_grid_worlds_equally_short_moves_are_stored_beside_its_advice() -> None:
    """Above and left of the goal, right and down both bring the agent nearer: the advice
    is stored with both (its accuracy counts either), the oracle's own move first."""
    task = get_task("gridworld")
    env = task.env({}, 250, False)
    log = _Log()
    logged = log.logged

    class Down:
        def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
            return 2

    advisor = RecordingAdvisor(
        Down(), 1, "human", 0, log, lambda info: task.correct_actions(info, {})
    )  # type: ignore[arg-type]
    infos = [env.reset(seed=seed)[1] for seed in range(8)]
    for i, info in enumerate(infos):
        advisor.advise_at(_moment(info, i + 1))
    both = [a for a, info in zip(logged, infos, strict=True) if info["correct_actions"] == [1, 2]]
    assert both and all(a.correct_action == 1 and a.correct_actions == [1, 2] for a in both)
    assert [a.correct_actions for a in logged] == [info["correct_actions"] for info in infos]
