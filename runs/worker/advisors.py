"""Advisors as the worker sees them: the participant behind the channel, and machine
advisors whose advice is logged like a person's."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np

from learner.advisors import NO_ADVICE, Advisor, NoAdvice
from learner.strategies import AdviceMoment
from runs.worker.link import WorkerLink
from runs.worker.messages import AdviceRequest, AdviceResult
from study.services.advice import AdviceGiven
from study.services.observations import encode_png

log = logging.getLogger(__name__)


class HumanAdvisor:
    """`learner.Advisor` for a person: publishes a request and blocks until they answer.

    Advice already given (`given`, from the database) is replayed without asking, so a
    resumed session reaches the same point without troubling the participant again."""

    def __init__(
        self,
        link: WorkerLink,
        given: dict[int, int],
        start_index: int,
        advice_budget: int,
        idle_limit_s: float,
        moment: Callable[[], AdviceMoment],
        before_waiting: Callable[[], None] = lambda: None,
        until_participant_ready: Callable[[], None] = lambda: None,
    ) -> None:
        """`before_waiting()` runs before the request is sent (the worker flushes its
        records there, so every step before the wait is in the database);
        `until_participant_ready()` blocks until the participant consented and finished the
        induction. `moment()`: what the trainer is deciding on (the step, its greedy action)."""
        self._before_waiting = before_waiting
        self._until_ready = until_participant_ready
        self._link = link
        self._given = given
        self.count = start_index
        self._budget = advice_budget
        self._idle_limit_s = idle_limit_s
        self._moment = moment
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

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        index = self.count
        self._answered = None
        if index in self._given:
            action = self._given[index]
        else:
            moment = self._moment()
            request = AdviceRequest(
                advice_index=index,
                global_step=moment.global_step,
                greedy_action=moment.greedy_action,
                observation_png=encode_png(obs),
                info=dict(info),
                advice_budget=self._budget,
            )
            self._until_ready()
            # The request first: the flush of the steps before it then overlaps the
            # person's decision instead of delaying the turn (it ends before the answer
            # is read, so the steps are stored before the wait for it).
            self._link.send(request)
            self._before_waiting()
            action = self._link.wait_for_answer(index, self._idle_limit_s)
            self._given[index] = action
            self._answered = index
        self.count += 1
        return action


class RecordingAdvisor:
    """Wraps a machine advisor (agent, oracle, random, fitted) or a replayed stream: same
    advice, logged with the observation and the time it took, as the study's exports treat
    every advisor alike (`study.services.advice.AdviceGiven`, complete when built: the step
    and the learner's greedy action come from the trainer's `moment`). A simulated decision
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
        record: Callable[[AdviceGiven], None],
        moment: Callable[[], AdviceMoment],
    ) -> None:
        self._inner = inner
        self._session_id = session_id
        self._kind = kind
        self.count = start_index
        self._record = record
        self._moment = moment

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

    def advise(self, obs: np.ndarray, info: dict[str, Any]) -> int | NoAdvice:
        started = time.perf_counter()
        requested_at = datetime.now(UTC)
        answer = self._inner.advise(obs, info)
        action = None if answer is NO_ADVICE else int(answer)
        elapsed = time.perf_counter() - started
        moment = self._moment()
        self._record(
            AdviceGiven(
                session_id=self._session_id,
                advice_index=self.count,
                global_step=moment.global_step,
                advisor=self._kind,
                action=action,
                greedy_action=moment.greedy_action,
                observation_png=encode_png(obs),
                response_time_s=elapsed,
                decision_time_s=getattr(self._inner, "last_decision_time_s", None),
                requested_at=requested_at,
                answered_at=requested_at + timedelta(seconds=elapsed),
                same_observation=getattr(self._inner, "same_observation", None),
            )
        )
        self.count += 1
        return NO_ADVICE if action is None else action
