"""The worker's end of the duplex pipe: sends events, obeys commands, waits for advice.

Commands are read between learner steps (`poll`) and while a human advisor waits
(`wait_for_answer`); pause blocks in place, stop and a vanished web process unwind the
worker through the exceptions below.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from multiprocessing.connection import Connection

from runs.worker.messages import (
    AdviceAnswer,
    Command,
    RatingAnswer,
    StatusChanged,
    Tagged,
    WorkerMessage,
)


class WorkerExit(Exception):
    """Unwinds the learner from inside a step; `status` is what the session becomes."""

    status = "stopped"


class StopRequested(WorkerExit):
    status = "stopped"
    session_id: int | None = None
    """Which of a population's sessions is to stop (None: the worker's every session)."""


class SessionAbandoned(WorkerExit):
    status = "abandoned"


WAITED_FOR_PARTICIPANT = "the participant did not consent and start"
"""How an abandonment before the first advice begins its detail (the server resumes such
a session by itself when the participant comes back)."""


SHUTTING_DOWN = "the server shut down in order (a restart or an update)"
"""The detail of a session its server's shutdown interrupted (an update, a restart): the
server resumes such a human session by itself when it starts again, if it was interrupted
recently (`server.live.manager.RESUME_WITHIN_S`), so the participant goes on where they
were. A session paused when the server shut down has its own detail below: it is never
resumed by itself."""
SHUT_DOWN_WHILE_PAUSED = "the server shut down while the session was paused; resume it"
"""The detail of a session the researcher had paused: it waits for them, not the restart."""


class HandOver(WorkerExit):
    """A trainer slot is free for this session in a population (`Command("handover")`):
    the worker checkpoints and exits, the session still `running` under its token, and a
    population's worker (`runs.worker.population.population_main`) goes on from that
    checkpoint."""

    status = "running"


class ParentGone(WorkerExit):
    """The web process died or closed the pipe: nobody can advise or watch any more."""

    status = "interrupted"


class WorkerLink:
    def __init__(
        self,
        conn: Connection | TaggedChannel,
        on_pause: Callable[[bool, bool], None],
        on_watch: Callable[[], None],
        on_idle: Callable[[], None] = lambda: None,
        assigned: bool = True,
        on_session_watch: Callable[[int, bool], None] | None = None,
    ) -> None:
        """`on_pause(paused, at_step_boundary)` records the new status (and checkpoints);
        `on_watch()` sends the whole scene to a viewer that just arrived; `on_idle()` runs
        about once a second while the worker waits (paused, or for advice), so it can
        mark itself alive: a worker that stops beating is killed as hung.
        `on_session_watch(session_id, watched)`: a population's link passes a viewer's
        arrival or departure named for one of its sessions to that session."""
        self._conn = conn
        self.assigned = assigned
        """Someone's session: False while it waits in a pool, where no idle limit runs."""
        self._on_watch = on_watch
        self._parent = os.getppid()
        self._on_pause = on_pause
        self._on_idle = on_idle
        self._on_session_watch = on_session_watch
        self.watching = False
        self.paused = False
        self.participant_ready = False
        """The participant consented and finished the induction (`Command("ready")`)."""
        self.may_train = False
        """The server granted a trainer slot (`Command("train")`)."""

    def send(self, message: WorkerMessage) -> None:
        try:
            self._conn.send(message)
        except (BrokenPipeError, EOFError, OSError) as error:
            raise ParentGone("the web process closed the channel") from error

    def poll(self) -> None:
        """Handle every command waiting; blocks here while paused."""
        while self._ready(0):
            self._handle(self._recv())
        while self.paused:
            if self._ready(1.0):
                self._handle(self._recv())
            self._on_idle()

    def wait_for_participant(self, idle_limit_s: float) -> None:
        """Block, obeying commands and marking itself alive, until the participant may be
        asked for advice. A participant who has not come after `idle_limit_s` (pauses not
        counted: a visitor who opened the link and left) abandons the session, so nobody
        holds a worker; the server starts it again when the participant comes back."""
        waited = 0.0
        while not self.participant_ready or self.paused:
            started = time.monotonic()
            ready = self._ready(1.0)
            if not self.paused and self.assigned:
                waited += time.monotonic() - started
            self._on_idle()
            if ready:
                self._handle(self._recv(), waiting_for_advice=True)
            elif waited >= idle_limit_s and not self.participant_ready:
                raise SessionAbandoned(
                    f"{WAITED_FOR_PARTICIPANT} for {idle_limit_s:.0f} s (the idle limit); "
                    "it starts again when they come"
                )

    def wait_for_training_slot(self) -> None:
        """Block, obeying commands and marking itself alive, until the server lets this
        session train (its queue may take longer than the stale limit)."""
        while not self.may_train or self.paused:
            if self._ready(1.0):
                self._handle(self._recv())
            self._on_idle()

    def wait_for_answer(self, advice_index: int, idle_limit_s: float) -> int:
        """Block until the participant answers `advice_index`; no limit per action, but
        `idle_limit_s` without an answer (pauses not counted) abandons the session."""
        answer = self._wait_for(AdviceAnswer, advice_index, idle_limit_s)
        assert isinstance(answer, AdviceAnswer)
        return answer.action

    def wait_for_rating(self, advice_index: int, idle_limit_s: float) -> float | None:
        """Block until the web process answers the rating `advice_index`: the person's, or
        no answer once its time-out has passed (the web process keeps that clock, so a
        rating is either recorded and used, or refused)."""
        answer = self._wait_for(RatingAnswer, advice_index, idle_limit_s)
        assert isinstance(answer, RatingAnswer)
        return answer.judgement

    def _wait_for(
        self, kind: type[AdviceAnswer | RatingAnswer], advice_index: int, idle_limit_s: float
    ) -> AdviceAnswer | RatingAnswer:
        waited = 0.0
        while True:
            started = time.monotonic()
            ready = self._ready(1.0)
            if not self.paused:
                waited += time.monotonic() - started
            self._on_idle()
            if ready:
                message = self._recv()
                if isinstance(message, kind):
                    if message.advice_index == advice_index:
                        return message
                    continue
                self._handle(message, waiting_for_advice=True)
            elif waited >= idle_limit_s:
                raise SessionAbandoned(f"no advice for {idle_limit_s:.0f} s (the idle limit)")

    def _ready(self, timeout: float) -> bool:
        if os.getppid() != self._parent:
            raise ParentGone("the web process died")
        try:
            return self._conn.poll(timeout)
        except (BrokenPipeError, EOFError, OSError) as error:
            raise ParentGone("the web process closed the channel") from error

    def _recv(self) -> object:
        try:
            return self._conn.recv()
        except (BrokenPipeError, EOFError, OSError) as error:
            raise ParentGone("the web process closed the channel") from error

    def _handle(self, message: object, waiting_for_advice: bool = False) -> None:
        if isinstance(message, AdviceAnswer | RatingAnswer):
            return  # a late duplicate of an answer already used
        assert isinstance(message, Command), message
        if message.name == "ready":
            self.participant_ready = True
        elif message.name == "assigned":
            self.assigned = True
        elif message.name == "train":
            self.may_train = True
        elif message.name in ("watch", "unwatch") and (
            self._on_session_watch is not None and message.session_id is not None
        ):
            self._on_session_watch(message.session_id, message.name == "watch")
        elif message.name == "watch":
            self.watching = True
            self._on_watch()
        elif message.name == "unwatch":
            self.watching = False
        elif message.name in ("pause", "resume"):
            pausing = message.name == "pause"
            if pausing != self.paused:
                self.paused = pausing
                # A checkpoint needs a step boundary; while waiting for advice we are inside one.
                self._on_pause(pausing, not waiting_for_advice)
                self.send(StatusChanged("paused" if pausing else "running"))
        elif message.name == "handover":
            raise HandOver("handed over to a population")
        elif message.name == "stop":
            stop = StopRequested(message.reason or "stopped by the researcher")
            stop.session_id = message.session_id
            raise stop
        elif message.name == "shutdown":
            raise ParentGone(SHUT_DOWN_WHILE_PAUSED if self.paused else SHUTTING_DOWN)


class TaggedChannel:
    """One session's end of a population's shared channel (a `Connection` as far as its
    `WorkerLink` is concerned): what the session sends goes out `Tagged` with it; commands
    are read by the population's own link, never here."""

    def __init__(self, conn: Connection, session_id: int) -> None:
        self._conn = conn
        self.session_id = session_id

    def send(self, message: object) -> None:
        self._conn.send(Tagged(self.session_id, message))

    def poll(self, timeout: float = 0.0) -> bool:
        return False

    def recv(self) -> object:
        raise EOFError("a population's commands are read by its own link")
