"""The trainer slots: where human sessions train once their advice is over.

People still advising must never share the cores with more trainers than there are cores,
so at most `slots` sessions (or populations) train at once and the others wait in a
queue. A slot that frees takes the session queued longest together with the queued
sessions that can train with it (one learner configuration, up to their population's
size), by the batch's rule (`runs.worker.population.next_group`).

What a caller needs: `request` a slot for a session's `Seat`, `release` it when the session
ends, `place` and `wait_s` for its page. What granting a slot does to the worker (train on,
or hand over to a population's worker) is the caller's `granted` callback, so the slots can
be placed elsewhere without the queue changing: on a Ray cluster (`server.live.cluster`)
they are the cluster's CPUs, and its sessions' seats hold them until their tasks end; a
machine session there, and a pool's practice, takes its seat at its start, without
queueing, so the sessions queued behind count the CPU it takes.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from learner.run import RunSpec
from runs.worker.population import default_population, next_group, population_key
from server.live.session import LiveSession
from study.db.models import LIVE_STATUSES, Status


@dataclass
class Seat:
    """One session's standing with the trainer slots."""

    live: LiveSession
    """What the session shows: its progress and status (read only)."""
    run: RunSpec | None = None
    """A human session's run: its population key is taken from it when it asks to train."""
    queued: bool = False
    """Waiting for a trainer slot after its advice."""
    training: bool = False
    """Holds a trainer slot."""
    training_since: float | None = None
    """`time.monotonic()` when it took its slot, and the episodes done then: how fast it
    trains, for the queue's time estimate."""
    episodes_at_slot: int = 0
    steps_at_slot: int = 0
    """The steps done when it took its slot: how fast a practice steps."""
    practice: bool = False
    """A pool's random practice on the Ray cluster: it leaves its slot at its first turn
    (`live.steps_before_first_turn`), before any training episode, so its wait is counted
    in the practice steps it has left."""
    population_key: Any = None
    """What it must share with other sessions to train with them in one population once its
    advice is over (`population_key`); None: it trains alone."""
    population_size: int = 1
    """How many sessions its population may hold at most."""
    slot: object | None = None
    """The trainer slot it shares with the rest of its population (None: a slot of its
    own, or none)."""

    @property
    def session_id(self) -> int:
        return self.live.session_id

    def take_slot(self, slot: object | None) -> None:
        self.queued = False
        self.training = True
        self.training_since = time.monotonic()
        self.episodes_at_slot = self.live.progress.episode if self.live.progress else 0
        self.steps_at_slot = self.live.progress.global_step if self.live.progress else 0
        self.slot = slot

    def episodes_left(self) -> int:
        """Training episodes the session has yet to run (none once it has ended)."""
        progress = self.live.progress
        if progress is None or self.live.status not in LIVE_STATUSES:
            return 0
        return max(0, progress.episodes - progress.episode)

    def practice_left_s(self, now: float) -> float | None:
        """Seconds a practice has left before its first turn, at the pace of its steps since
        it took its slot (`now`: `time.monotonic()`); None before it has taken one."""
        progress = self.live.progress
        if progress is None or self.training_since is None:
            return None
        left = max(0, self.live.steps_before_first_turn - progress.global_step)
        if not left or self.live.status not in LIVE_STATUSES:
            return 0.0
        done = progress.global_step - self.steps_at_slot
        return left * (now - self.training_since) / done if done > 0 else None


QUEUED = "queued"
"""The status shown for a running session that waits for a trainer slot (the database
keeps it `running`): to the researcher and to its participant alike."""


def shown_status(
    trainers: TrainerSlots | None, session_id: int, status: str
) -> tuple[str, int | None]:
    """A session's status as the researcher's API, the dashboard and the participant's
    pages show it, and its place in the trainer queue: a session whose advice is over and
    that waits for a trainer slot is `queued` (1: next to take a slot), not `running`,
    until it takes one; any other keeps its status."""
    # The seat is looked up whatever the status, so a request's path through the code does
    # not depend on how far the worker got.
    if trainers is None or not trainers.queued(session_id) or status != Status.running:
        return status, None
    return QUEUED, trainers.place(session_id)


def _left_s(
    seat: Seat, rate: float | None, typical: float | None, live: int, now: float
) -> float | None:
    """Seconds `seat` holds its slot yet: a practice's steps left at its pace, else its
    episodes left at its own `rate` (seconds an episode), or at the `typical` agent-episode's
    with `live` sessions side by side in its slot; None: nothing to estimate it from."""
    if seat.practice:
        return seat.practice_left_s(now)
    episodes = seat.episodes_left()
    if not episodes:
        return 0.0
    if rate is None and typical is not None:
        rate = typical * live
    return episodes * rate if rate is not None else None


Granted = Callable[[list[Seat], object | None], None]
"""Called with each group given a slot, and the slot (None: one session's own)."""


class TrainerSlots:
    def __init__(
        self,
        slots: int,
        population: int,
        seats: Callable[[], Mapping[int, Seat]],
        granted: Granted,
    ) -> None:
        """`slots`: how many train at once; `population`: sessions trained together in one
        slot at most (0: `default_population`, 1: each alone); `seats`: the current seat of
        each session with a worker here."""
        self.slots = slots
        self.population = population
        self._seats = seats
        self._granted = granted
        self._queue: deque[int] = deque()

    def request(self, seat: Seat) -> None:
        """The session's advice is over: queue it for a slot, and grant what is free."""
        if seat.run is not None:
            seat.population_key = population_key(seat.run, advice_over=True)
            seat.population_size = self.population or default_population(
                seat.run, workers=self.slots
            )
        seat.queued = True
        self._queue.append(seat.session_id)
        self.grant()

    def release(self, seat: Seat) -> None:
        """The session's worker is gone: its place in the queue or its slot frees."""
        if seat.training or seat.queued:
            seat.training = seat.queued = False
            self.grant()

    def vacate(self, seat: Seat) -> None:
        """The session left its slot to join its population's worker (granted then)."""
        seat.training = False

    def joined(self, old: Seat, live: LiveSession, size: int) -> Seat:
        """The session's seat in its population's worker: the slot it was granted, its
        training speed measured from now."""
        seat = Seat(live, population_key=old.population_key, population_size=size)
        seat.take_slot(old.slot)
        return seat

    def set_slots(self, slots: int) -> None:
        """Change how many human sessions may train at once (0: none); freed slots go to
        the queue at once. Sessions already training keep theirs."""
        assert slots >= 0
        self.slots = slots
        self.grant()

    def grant(self) -> None:
        """Hand free trainer slots to the sessions queued longest, each with the queued
        sessions that can train with it in one population (`next_group`, as the batch)."""
        while True:
            free = self.slots - self._busy()
            waiting = self._waiting()
            self._queue = deque(s.session_id for s in waiting)
            if free <= 0 or not waiting:
                return
            group = self._next_group(waiting, free)
            taken = {s.session_id for s in group}
            self._queue = deque(sid for sid in self._queue if sid not in taken)
            slot = object() if len(group) > 1 else None
            for seat in group:
                seat.take_slot(slot)
            self._granted(group, slot)

    def queued(self, session_id: int) -> bool:
        seat = self._seats().get(session_id)
        return seat is not None and seat.queued

    def place(self, session_id: int) -> int | None:
        """1 for the queued sessions that take the next trainer slot to free (several
        together, as a population), 2 for those after, ...; None when the session is not
        queued."""
        if not self.queued(session_id):
            return None
        for place, group in enumerate(self._plan(), 1):
            if any(s.session_id == session_id for s in group):
                return place
        return None

    def wait_s(self, session_id: int) -> float | None:
        """Seconds until a queued session gets a slot, estimated from how fast the sessions
        in the slots train now. Speed is counted per agent-episode: a slot whose n sessions
        (a population, or one alone) each take r seconds an episode runs one agent-episode
        every r / n seconds. A slot frees when its slowest session has run its remaining
        episodes; each group ahead in the queue (`_plan`) then holds the earliest free slot
        while its m sessions run theirs, m side by side at the typical speed. A practice
        (`Seat.practice`) frees its slot once its practice steps left are run, at its pace so
        far. None while something it needs is not measured yet: a slot's session that has
        not finished an episode there (and no other has), a practice that has taken no step,
        or the typical speed for the groups ahead."""
        place = self.place(session_id)
        if place is None or self.slots <= 0:
            return None
        now = time.monotonic()
        slots: dict[int, list[Seat]] = {}
        for s in self._seats().values():
            if s.training and s.live.progress is not None:
                slots.setdefault(id(s.slot or s), []).append(s)
        rates: dict[int, float] = {}  # seconds an episode, each session in its slot
        costs: list[float] = []  # seconds an agent-episode, per measured session
        for members in slots.values():
            live = max(1, sum(1 for s in members if s.episodes_left()))
            for s in members:
                assert s.live.progress is not None
                done = s.live.progress.episode - s.episodes_at_slot
                if s.training_since is not None and done > 0:
                    rates[s.session_id] = (now - s.training_since) / done
                    costs.append(rates[s.session_id] / live)
        typical = sum(costs) / len(costs) if costs else None
        frees = [0.0] * max(0, self.slots - len(slots))
        for members in slots.values():
            live = max(1, sum(1 for s in members if s.episodes_left()))
            left = [_left_s(s, rates.get(s.session_id), typical, live, now) for s in members]
            if None in left:
                return None
            frees.append(max(x for x in left if x is not None))
        frees.sort()
        while len(frees) > self.slots:  # more train than there are slots (a cluster's
            # machine sessions and practices start without a queue): the extra wait for the
            # first to free
            extra = frees.pop()
            frees[0] += extra
            frees.sort()
        for group in self._plan()[: place - 1]:
            if typical is None:
                return None
            longest = max(s.episodes_left() for s in group)
            frees[0] += longest * typical * len(group)
            frees.sort()
        return frees[0]

    def _waiting(self) -> list[Seat]:
        """The queued sessions, longest queued first."""
        seats = self._seats()
        found = (seats.get(sid) for sid in dict.fromkeys(self._queue))
        return [s for s in found if s is not None and s.queued]

    @staticmethod
    def _next_group(waiting: list[Seat], free: int) -> list[Seat]:
        """`next_group` of the queued sessions; a paused one takes a slot alone (granted
        like any other, it resumes where it waits)."""
        keys = [s.population_key if s.live.status == Status.running else None for s in waiting]
        return next_group(waiting, keys, waiting[0].population_size, free)

    def _busy(self) -> int:
        """Trainer slots taken: a session training alone, or a population."""
        return len({id(s.slot or s) for s in self._seats().values() if s.training})

    def _plan(self) -> list[list[Seat]]:
        """The queued sessions in the groups they will take trainer slots in, in order: as
        `grant` takes them when a slot frees (`next_group` with one free slot)."""
        waiting, plan = self._waiting(), []
        while waiting:
            group = self._next_group(waiting, 1)
            plan.append(group)
            taken = {s.session_id for s in group}
            waiting = [s for s in waiting if s.session_id not in taken]
        return plan
