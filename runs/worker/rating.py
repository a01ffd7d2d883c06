"""A person's evaluative feedback, as the worker sees it: the learner's action, taken, is
shown on the advice page and rated good or bad, or not at all within the run's time-out.

The web process writes each rating to the `feedback` table, complete, before it answers
the worker (`server.live.rating`), and keeps the time-out's clock: a rating either reaches
the learner and the database, or is refused. The worker only waits for the answer.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from learner.strategies import AdviceMoment
from runs.worker.advisors import Correct, correct_at, until_participant_ready
from runs.worker.link import SessionAbandoned, WorkerLink
from runs.worker.messages import AdviceRequest
from runs.worker.recorder import Reporter
from study.services.feedback import rated_turns
from study.services.observations import encode_observation, encode_png


def given_ratings(factory: sessionmaker[Session], session_id: int) -> dict[int, float | None]:
    """The person's ratings stored so far (None: no answer), replayed on resume."""
    with factory() as db:
        return {f.feedback_index: f.judgement for f in rated_turns(db, session_id)}


class HumanEvaluator:
    """The evaluator for a person (`learner.evaluators.MomentEvaluator`): after the learner's
    step in the strategy's window, publishes what it did through the `link` and blocks until
    the web process answers (the rating, or None after the time-out).

    Ratings already given (`given`, from the database) are replayed without asking, so a
    resumed session reaches the same point without troubling the participant again. Turns
    that lapse one after another for the idle limit (their time-outs summed) mean the person
    has gone: the session is abandoned, as an advice session is after the idle limit without
    advice, and an online visit ends timed out."""

    def __init__(
        self,
        link: WorkerLink,
        reporter: Reporter,
        given: dict[int, float | None],
        start_index: int,
        advice_budget: int,
        idle_limit_s: float,
        time_out_s: float,
        frames: Callable[[], Any] | None = None,
        correct: Correct | None = None,
    ) -> None:
        self._link = link
        self._reporter = reporter
        self._given = given
        self.count = start_index
        self._budget = advice_budget
        self._idle_limit_s = idle_limit_s
        self._time_out_s = time_out_s
        self._frames = frames
        """A task without a live 3-D view: what people see now (after the rated move)."""
        self._correct = correct
        """The task's correct action at a step, sent with the request for the web process
        to store beside the rating (never shown to the participant)."""
        self.carrying_out = False
        """The step being taken is to be rated: the 3-D view replays it as motion."""
        self._reward: float | None = None
        """The reward of the step just taken, shown with it."""
        self._silent_s = 0.0
        """The time-outs of the turns that lapsed since the person's last rating."""

    def state_dict(self) -> dict[str, Any]:
        """Saved in the learner's checkpoint: how many ratings were asked for."""
        return {"count": self.count}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.count = int(state["count"])

    def window_opens(self, moment: AdviceMoment) -> None:
        """The strategy gave this step to the evaluator: the step about to be taken is
        the one to show."""
        self.carrying_out = True

    def after_step(self, action: int, reward: float, episode_over: bool) -> None:
        self.carrying_out = False
        self._reward = reward

    def judge_at(self, moment: AdviceMoment) -> float | None:
        index = self.count
        if index in self._given:
            judgement = self._given[index]
        else:
            request = AdviceRequest(
                advice_index=index,
                global_step=moment.global_step,
                greedy_action=moment.greedy_action,
                observation_png=encode_observation(moment.obs, self._frames),
                info=dict(moment.info),
                advice_budget=self._budget,
                frame_png=encode_png(self._frames()) if self._frames is not None else None,
                rated_action=moment.intended_action,
                rated_reward=self._reward,
                rating_time_out_s=self._time_out_s,
                correct=correct_at(self._correct, moment.info),
            )
            until_participant_ready(self._link, self._reporter, self._idle_limit_s)
            self._link.send(request)
            self._reporter.before_waiting()
            # the web process answers by the time-out; the idle limit only guards a lost one
            judgement = self._link.wait_for_rating(
                index, max(self._idle_limit_s, self._time_out_s + 60.0)
            )
            self._given[index] = judgement
            self._silent_s = self._silent_s + self._time_out_s if judgement is None else 0.0
            if self._silent_s >= self._idle_limit_s:
                raise SessionAbandoned(
                    f"no rating for {self._silent_s:.0f} s of turns (the idle limit, "
                    f"{self._idle_limit_s:.0f} s)"
                )
        self.count += 1
        return judgement
