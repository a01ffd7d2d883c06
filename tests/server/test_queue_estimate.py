"""The place in line and the time estimate a queued session's thank-you page shows, from
the manager's own bookkeeping (no worker processes: the handles are made by hand)."""

from __future__ import annotations

import time

import pytest

from runs.worker.messages import Progress, StatusChanged
from runs.worker.worker import WorkerOptions
from server.live.changes import Changes
from server.live.hub import Hub
from server.live.manager import SessionManager, WorkerHandle
from server.live.session import LiveSession


def _handle(session_id: int, episode: int, episodes: int = 20) -> WorkerHandle:
    live = LiveSession(session_id, 1, [], Changes())
    live.receive(Progress("train", 0, episode, episodes, 0.1, 0.0, None, 1, 1))
    return WorkerHandle(session_id, f"token-{session_id}", None, None, live)  # type: ignore[arg-type]


@pytest.fixture
def manager() -> SessionManager:
    return SessionManager(None, "", Hub(), WorkerOptions(), 60.0, max_trainers=1)  # type: ignore[arg-type]


def test_places_count_the_queued_sessions_in_order(manager: SessionManager) -> None:
    training, first, second = _handle(1, 0), _handle(2, 0), _handle(3, 0)
    training.training, training.training_since = True, time.monotonic()
    first.queued = second.queued = True
    manager.handles = {h.session_id: h for h in (training, first, second)}
    manager._train_queue.extend([2, 3])
    assert [manager.queue_place(i) for i in (1, 2, 3)] == [None, 1, 2]
    assert manager.queue_wait_s(2) is None, "nothing to estimate from before an episode ends"


def test_the_estimate_runs_the_sessions_ahead_through_the_free_slot(
    manager: SessionManager,
) -> None:
    training, first, second = _handle(1, 5), _handle(2, 0), _handle(3, 0)
    training.training = True
    training.training_since = time.monotonic() - 10.0  # 5 episodes in 10 s: 2 s each
    first.queued = second.queued = True
    manager.handles = {h.session_id: h for h in (training, first, second)}
    manager._train_queue.extend([2, 3])
    assert manager.queue_wait_s(2) == pytest.approx(15 * 2.0, abs=0.5)  # 15 episodes left
    assert manager.queue_wait_s(3) == pytest.approx(15 * 2.0 + 20 * 2.0, abs=0.5)
    manager.max_trainers = 2  # a second slot, free now: the next in line starts at once
    assert manager.queue_wait_s(2) == pytest.approx(0.0)
    assert manager.queue_wait_s(3) == pytest.approx(15 * 2.0, abs=0.5)


def _queued(session_id: int, key: str, size: int = 2, episodes: int = 20) -> WorkerHandle:
    handle = _handle(session_id, 0, episodes)
    handle.queued, handle.population_key, handle.population_size = True, key, size
    return handle


def test_sessions_that_train_together_share_a_place(manager: SessionManager) -> None:
    training = _handle(1, 0)
    training.training, training.training_since = True, time.monotonic()
    queued = [_queued(2, "a"), _queued(3, "b"), _queued(4, "a"), _queued(5, "a")]
    manager.handles = {h.session_id: h for h in (training, *queued)}
    manager._train_queue.extend([2, 3, 4, 5])
    # 2 and 4 share a learner configuration: the next slot takes both (a population of
    # at most 2); then 3, alone of its kind; then 5.
    assert [manager.queue_place(i) for i in (2, 3, 4, 5)] == [1, 2, 1, 3]
    for handle in queued:
        handle.population_size = 1
    assert [manager.queue_place(i) for i in (2, 3, 4, 5)] == [1, 2, 3, 4]


def test_the_estimate_counts_a_population_s_agent_episodes(manager: SessionManager) -> None:
    slot = object()
    training = [_handle(1, 5), _handle(2, 5)]
    for handle in training:  # a population of two: 5 episodes each in 10 s
        handle.training, handle.slot = True, slot
        handle.training_since = time.monotonic() - 10.0
    queued = [_queued(3, "a"), _queued(4, "a"), _queued(5, "a")]
    manager.handles = {h.session_id: h for h in (*training, *queued)}
    manager._train_queue.extend([3, 4, 5])
    # The slot frees once its 15 episodes left run (2 s each, side by side): 30 s. Its
    # speed is 1 s an agent-episode, so the next population (3 and 4, 20 episodes each)
    # holds the slot 20 x 2 x 1 s = 40 s before 5 starts.
    assert manager.queue_place(3) == manager.queue_place(4) == 1
    assert manager.queue_wait_s(3) == pytest.approx(30.0, abs=0.5)
    assert manager.queue_wait_s(4) == pytest.approx(30.0, abs=0.5)
    assert manager.queue_wait_s(5) == pytest.approx(70.0, abs=0.5)
    # one left its population: the slot frees with the other
    training[1].live.receive(StatusChanged("finished", ""))
    training[1].live.receive(Progress("train", 0, 20, 20, 0.1, 0.0, None, 1, 1))
    assert manager.queue_wait_s(3) == pytest.approx(30.0, abs=0.5)
