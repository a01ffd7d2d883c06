"""Advisors as the worker sees them: the participant behind the channel, and machine
advisors whose advice (or evaluative feedback) is logged like a person's."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from typing import Any, Protocol

from learner.advisors import NO_ADVICE, Advisor, NoAdvice
from learner.evaluators import AnyEvaluator, judge
from learner.records import observation_hash
from learner.strategies import AdviceMoment, ask
from runs.worker.link import WorkerLink
from runs.worker.messages import AdviceRequest, AdviceResult
from runs.worker.recorder import Reporter
from study.services.advice import AdviceGiven
from study.services.feedback import FeedbackGiven
from study.services.observations import encode_observation, encode_png
from tasks import NO_CORRECT_ACTION, CorrectActions

log = logging.getLogger(__name__)
Correct = Callable[[dict[str, Any]], CorrectActions]
"""The task's correct action in the state an `info` describes and every action as right
(`tasks.Task.correct_actions` with the run's options), stored beside each advice and rating
for its accuracy."""


def correct_at(correct: Correct | None, info: dict[str, Any]) -> CorrectActions:
    """What `correct` says of the state `info` describes; none known without it."""
    return NO_CORRECT_ACTION if correct is None else correct(info)


class HumanAdvisor:
    """The advisor for a person (`learner.strategies.MomentAdvisor`): publishes a request
    through the `link` to the page and blocks until they answer; the `reporter` shows the
    wait and has every step before it stored.

    Advice already given (`given`, from the database) is replayed without asking, so a
    resumed session reaches the same point without troubling the participant again."""

    def __init__(
        self,
        link: WorkerLink,
        reporter: Reporter,
        given: dict[int, int],
        start_index: int,
        advice_budget: int,
        idle_limit_s: float,
        frames: Callable[[], Any] | None = None,
        correct: Correct | None = None,
    ) -> None:
        self._link = link
        self._correct = correct
        self._frames = frames
        """A task without a live 3-D view: what people see now (an RGB image)."""
        self._reporter = reporter
        self._given = given
        self.count = start_index
        self._budget = advice_budget
        self._idle_limit_s = idle_limit_s
        self._answered: int | None = None

    def state_dict(self) -> dict[str, Any]:
        """Saved in the learner's checkpoint: how many advice were asked for."""
        return {"count": self.count}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.count = int(state["count"])

    @property
    def carrying_out(self) -> bool:
        """The step being taken is the one the participant just advised."""
        return self._answered is not None

    def after_step(self, action: int, reward: float, episode_over: bool) -> None:
        """Tell the participant what their last advice earned."""
        if self._answered is not None:
            self._link.send(AdviceResult(self._answered, action, reward, episode_over))
            self._answered = None

    def advise_at(self, moment: AdviceMoment) -> int:
        index = self.count
        self._answered = None
        if index in self._given:
            action = self._given[index]
        else:
            request = AdviceRequest(
                advice_index=index,
                global_step=moment.global_step,
                greedy_action=moment.greedy_action,
                observation_png=encode_observation(moment.obs, self._frames),
                info=dict(moment.info),
                advice_budget=self._budget,
                frame_png=encode_png(self._frames()) if self._frames is not None else None,
                correct=correct_at(self._correct, moment.info),
            )
            self._until_participant_ready()
            # The request first: the flush of the steps before it then overlaps the
            # person's decision instead of delaying the turn (it ends before the answer
            # is read, so the steps are stored before the wait for it).
            self._link.send(request)
            self._reporter.before_waiting()
            action = self._link.wait_for_answer(index, self._idle_limit_s)
            self._given[index] = action
            self._answered = index
        self.count += 1
        return action

    def _until_participant_ready(self) -> None:
        until_participant_ready(self._link, self._reporter, self._idle_limit_s)


def until_participant_ready(link: WorkerLink, reporter: Reporter, idle_limit_s: float) -> None:
    """Blocks until the participant consented and finished the induction (advice and
    ratings alike are asked only then)."""
    if link.participant_ready:
        return
    reporter.waiting_for_participant = True
    reporter.before_waiting()
    link.wait_for_participant(idle_limit_s)
    reporter.waiting_for_participant = False


class AdviceLog(Protocol):
    def add_advice(self, advice: AdviceGiven) -> None: ...


class RecordingAdvisor:
    """Wraps a machine advisor (agent, oracle, random, fitted) or a replayed stream: same
    advice, logged with the observation and the time it took, as the study's exports treat
    every advisor alike (`study.services.advice.AdviceGiven`, complete when built: the step
    and the learner's greedy action come from the moment it is asked at). A simulated decision
    time (an advisor's `last_decision_time_s`: fitted, or an oracle with times) is logged
    as `decision_time_s`, where a person's page puts theirs. A replayed advice also logs
    whether it met the image its advisor saw (`same_observation`); a request beyond the
    stream is logged without an action."""

    def __init__(
        self,
        inner: Advisor,
        session_id: int,
        kind: str,
        start_index: int,
        log: AdviceLog,
        correct: Correct | None = None,
        frames: Callable[[], Any] | None = None,
    ) -> None:
        self._inner = inner
        self._frames = frames
        """A vector task's rendered frame, stored with its advice's vector (or None)."""
        self._session_id = session_id
        self._kind = kind
        self.count = start_index
        self._log = log
        self._correct = correct

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)  # q_values, for importance advising

    def state_dict(self) -> dict[str, Any]:
        inner = getattr(self._inner, "state_dict", None)
        return {"count": self.count, "inner": inner() if callable(inner) else None}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.count = int(state["count"])
        load = getattr(self._inner, "load_state_dict", None)  # as state_dict found it
        if state["inner"] is not None and callable(load):
            load(state["inner"])

    def advise_at(self, moment: AdviceMoment) -> int | NoAdvice:
        started = time.perf_counter()
        requested_at = datetime.now(UTC)
        answer = ask(self._inner, moment)
        action = None if answer is NO_ADVICE else int(answer)
        elapsed = time.perf_counter() - started
        correct = correct_at(self._correct, moment.info)
        self._log.add_advice(
            AdviceGiven(
                session_id=self._session_id,
                advice_index=self.count,
                global_step=moment.global_step,
                advisor=self._kind,
                action=action,
                greedy_action=moment.greedy_action,
                observation_png=encode_observation(moment.obs, self._frames),
                response_time_s=elapsed,
                decision_time_s=getattr(self._inner, "last_decision_time_s", None),
                requested_at=requested_at,
                answered_at=requested_at + timedelta(seconds=elapsed),
                same_observation=getattr(self._inner, "same_observation", None),
                correct_action=correct.action,
                correct_actions=correct.stored,
            )
        )
        self.count += 1
        return NO_ADVICE if action is None else action


class FeedbackLog(Protocol):
    def add_feedback(self, feedback: FeedbackGiven) -> None: ...


class RecordingEvaluator:
    """Wraps a machine evaluator (`learner.evaluators`): the same judgements, each logged
    with the action judged, what it added to the remembered reward (`weight` times the
    judgement: the run's feedback_weight), the task's correct action at the judged step
    (`correct`, from the moment's info: the step before it was taken) and the time it
    took, as `RecordingAdvisor` logs advice. `count` is the judgements given (the worker's
    advice count)."""

    def __init__(
        self,
        inner: AnyEvaluator,
        session_id: int,
        kind: str,
        start_index: int,
        weight: float,
        log: FeedbackLog,
        correct: Correct | None = None,
    ) -> None:
        self._inner = inner
        self._session_id = session_id
        self._kind = kind
        self.count = start_index
        self._weight = weight
        self._log = log
        self._correct = correct

    def __getattr__(self, name: str) -> Any:
        if name == "q_values":  # for importance's window
            return getattr(self._inner, name)
        raise AttributeError(name)

    def state_dict(self) -> dict[str, Any]:
        inner = getattr(self._inner, "state_dict", None)
        return {"count": self.count, "inner": inner() if callable(inner) else None}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.count = int(state["count"])
        load = getattr(self._inner, "load_state_dict", None)
        if state["inner"] is not None and callable(load):
            load(state["inner"])

    def judge_at(self, moment: AdviceMoment) -> float | None:
        started = time.perf_counter()
        requested_at = datetime.now(UTC)
        judgement = judge(self._inner, moment)
        elapsed = time.perf_counter() - started
        correct = correct_at(self._correct, moment.info)
        self._log.add_feedback(
            FeedbackGiven(
                session_id=self._session_id,
                feedback_index=self.count,
                global_step=moment.global_step,
                evaluator=self._kind,
                action=moment.intended_action,
                judgement=judgement,
                shaping=0.0 if judgement is None else self._weight * judgement,
                greedy_action=moment.greedy_action,
                observation_hash=observation_hash(moment.obs),
                response_time_s=elapsed,
                decision_time_s=getattr(self._inner, "last_decision_time_s", None),
                requested_at=requested_at,
                answered_at=requested_at + timedelta(seconds=elapsed),
                correct_action=correct.action,
                correct_actions=correct.stored,
            )
        )
        self.count += 1
        return judgement
