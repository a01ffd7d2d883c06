"""The place in line and the time estimate a queued session's thank-you page shows, from
the trainer slots' own bookkeeping (no worker processes: the seats are made by hand)."""

from __future__ import annotations

import time

import pytest

from runs.worker.messages import Progress, StatusChanged
from server.live.session import Changes, LiveSession
from server.live.trainers import Seat, TrainerSlots


def _seat(session_id: int, episode: int, episodes: int = 20) -> Seat:
    live = LiveSession(session_id, 1, [], Changes())
    live.receive(Progress("train", 0, episode, episodes, 0.1, 0.0, None, 1, 1))
    return Seat(live)


class Slots:
    """One trainer slot, and the seats of the sessions with a worker."""

    def __init__(self) -> None:
        self.seats: dict[int, Seat] = {}
        self.granted: list[list[int]] = []
        self.trainers = TrainerSlots(
            1, 0, lambda: self.seats, lambda g, _: self.granted.append([s.session_id for s in g])
        )

    def hold(self, *seats: Seat, queued: tuple[int, ...] = ()) -> None:
        self.seats = {s.session_id: s for s in seats}
        self.trainers._queue.extend(queued)


@pytest.fixture
def slots() -> Slots:
    return Slots()


def test_places_count_the_queued_sessions_in_order(slots: Slots) -> None:
    training, first, second = _seat(1, 0), _seat(2, 0), _seat(3, 0)
    training.training, training.training_since = True, time.monotonic()
    first.queued = second.queued = True
    slots.hold(training, first, second, queued=(2, 3))
    trainers = slots.trainers
    assert [trainers.place(i) for i in (1, 2, 3)] == [None, 1, 2]
    assert trainers.wait_s(2) is None, "nothing to estimate from before an episode ends"


def test_the_estimate_runs_the_sessions_ahead_through_the_free_slot(slots: Slots) -> None:
    training, first, second = _seat(1, 5), _seat(2, 0), _seat(3, 0)
    training.training = True
    training.training_since = time.monotonic() - 10.0  # 5 episodes in 10 s: 2 s each
    first.queued = second.queued = True
    slots.hold(training, first, second, queued=(2, 3))
    trainers = slots.trainers
    assert trainers.wait_s(2) == pytest.approx(15 * 2.0, abs=0.5)  # 15 episodes left
    assert trainers.wait_s(3) == pytest.approx(15 * 2.0 + 20 * 2.0, abs=0.5)
    trainers.slots = 2  # a second slot, free now: the next in line starts at once
    assert trainers.wait_s(2) == pytest.approx(0.0)
    assert trainers.wait_s(3) == pytest.approx(15 * 2.0, abs=0.5)


def _queued(session_id: int, key: str, size: int = 2, episodes: int = 20) -> Seat:
    seat = _seat(session_id, 0, episodes)
    seat.queued, seat.population_key, seat.population_size = True, key, size
    return seat


def test_sessions_that_train_together_share_a_place(slots: Slots) -> None:
    training = _seat(1, 0)
    training.training, training.training_since = True, time.monotonic()
    queued = [_queued(2, "a"), _queued(3, "b"), _queued(4, "a"), _queued(5, "a")]
    slots.hold(training, *queued, queued=(2, 3, 4, 5))
    trainers = slots.trainers
    # 2 and 4 share a learner configuration: the next slot takes both (a population of
    # at most 2); then 3, alone of its kind; then 5.
    assert [trainers.place(i) for i in (2, 3, 4, 5)] == [1, 2, 1, 3]
    for seat in queued:
        seat.population_size = 1
    assert [trainers.place(i) for i in (2, 3, 4, 5)] == [1, 2, 3, 4]


def test_the_estimate_counts_a_population_s_agent_episodes(slots: Slots) -> None:
    slot = object()
    training = [_seat(1, 5), _seat(2, 5)]
    for seat in training:  # a population of two: 5 episodes each in 10 s
        seat.training, seat.slot = True, slot
        seat.training_since = time.monotonic() - 10.0
    queued = [_queued(3, "a"), _queued(4, "a"), _queued(5, "a")]
    slots.hold(*training, *queued, queued=(3, 4, 5))
    trainers = slots.trainers
    # The slot frees once its 15 episodes left run (2 s each, side by side): 30 s. Its
    # speed is 1 s an agent-episode, so the next population (3 and 4, 20 episodes each)
    # holds the slot 20 x 2 x 1 s = 40 s before 5 starts.
    assert trainers.place(3) == trainers.place(4) == 1
    assert trainers.wait_s(3) == pytest.approx(30.0, abs=0.5)
    assert trainers.wait_s(4) == pytest.approx(30.0, abs=0.5)
    assert trainers.wait_s(5) == pytest.approx(70.0, abs=0.5)
    # one left its population: the slot frees with the other
    training[1].live.receive(StatusChanged("finished", ""))
    training[1].live.receive(Progress("train", 0, 20, 20, 0.1, 0.0, None, 1, 1))
    assert trainers.wait_s(3) == pytest.approx(30.0, abs=0.5)


def test_a_freed_slot_goes_to_the_longest_queued_with_its_population(slots: Slots) -> None:
    training = _seat(1, 5)
    training.training, training.training_since = True, time.monotonic()
    slots.hold(training)
    trainers = slots.trainers
    for seat in (_seat(2, 0), _seat(3, 0), _seat(4, 0)):
        slots.seats[seat.session_id] = seat
        seat.population_key, seat.population_size = "a" if seat.session_id != 3 else "b", 2
        trainers.request(seat)
    assert slots.granted == [] and [trainers.place(i) for i in (2, 3, 4)] == [1, 2, 1]
    trainers.release(training)
    assert slots.granted == [[2, 4]], "the longest queued, with the one it trains with"
    assert slots.seats[2].slot is slots.seats[4].slot is not None
    assert trainers.place(3) == 1 and not trainers.queued(2)


def test_machine_sessions_on_a_cluster_hold_slots_the_queue_counts(slots: Slots) -> None:
    """A machine session on a Ray cluster takes its slot at its start, without queueing
    (`TrainingCluster.train`): a participant queued behind waits for it, and one started
    while every slot was taken waits for the first slot to free before it runs."""
    running, waiting = _seat(1, 5), _seat(2, 0)
    for seat in (running, waiting):  # machine sessions: no run, no queue
        seat.take_slot(None)
    running.training_since = time.monotonic() - 10.0  # 5 episodes in 10 s: 2 s each
    running.episodes_at_slot = 0
    slots.hold(running, waiting)
    trainers = slots.trainers
    person = _seat(3, 0)
    slots.seats[3] = person
    trainers.request(person)
    assert slots.granted == [], "both machine sessions hold the one slot"
    assert trainers.place(3) == 1
    # the slot frees after 15 x 2 s, then the waiting one runs its 20 episodes at 2 s each
    assert trainers.wait_s(3) == pytest.approx(30.0 + 40.0, abs=0.5)
    trainers.release(running)
    assert slots.granted == [], "the waiting machine session takes the slot that freed"
    trainers.release(waiting)
    assert slots.granted == [[3]]


def _practice(session_id: int, steps: int, first_turn: int) -> Seat:
    """A pool's practice on a Ray cluster, `steps` of its `first_turn` random steps done."""
    live = LiveSession(session_id, 1, [], Changes(), first_turn)
    live.receive(Progress("pretrain", steps, 0, 20, 1.0, 0.0, None, 0, 1))
    return Seat(live, practice=True)


def test_a_practice_on_a_cluster_holds_its_slot_until_its_first_turn(slots: Slots) -> None:
    """A pool's practice on a Ray cluster takes its slot at its start, without queueing
    (`TrainingCluster.train`), and frees it at its first turn: the participants queued
    behind wait for the practice steps it has left at its pace, not for the episodes of
    the run it practises for."""
    machine, practice = _seat(1, 5), _practice(2, 0, 40)
    for seat in (machine, practice):  # no run, no queue
        seat.take_slot(None)
    machine.training_since = time.monotonic() - 10.0  # 5 episodes in 10 s: 2 s each
    machine.episodes_at_slot = 0
    slots.hold(machine, practice)
    trainers = slots.trainers
    trainers.slots = 2
    first, second = _seat(3, 0), _seat(4, 0)
    for seat in (first, second):
        slots.seats[seat.session_id] = seat
        trainers.request(seat)
    assert slots.granted == [], "the practice holds the second slot"
    assert [trainers.place(3), trainers.place(4)] == [1, 2]
    assert trainers.wait_s(3) is None, "no practice step taken yet: nothing to estimate from"
    practice.live.receive(Progress("pretrain", 10, 0, 20, 1.0, 0.0, None, 0, 1))
    practice.training_since = time.monotonic() - 5.0  # 10 steps in 5 s: 0.5 s each
    # the practice's slot frees after its 30 steps left (15 s), the machine session's after
    # its 15 episodes left (30 s); the first queued then trains 20 episodes at 2 s each
    assert trainers.wait_s(3) == pytest.approx(30 * 0.5, abs=0.5)
    assert trainers.wait_s(4) == pytest.approx(15 * 2.0, abs=0.5)
    practice.live.receive(Progress("pretrain", 40, 0, 20, 1.0, 0.0, None, 0, 1))
    assert trainers.wait_s(3) == pytest.approx(0.0), "at its first turn: its slot frees"
    trainers.release(practice)  # its task ended; a worker here takes it back
    assert slots.granted == [[3]]
