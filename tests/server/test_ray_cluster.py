"""Sessions trained on a Ray cluster of two 1-CPU nodes (`server.live.cluster`) with
PostgreSQL and a shared folder: their records are those of training on this machine with
the same seeds, and a session whose node is killed mid-run finishes on the other node
from its last checkpoint, with the records of an uninterrupted run. The trainer slots
(and so the queue's place and wait) are the cluster's CPUs, as its nodes come and go, and
the machine sessions it trains hold theirs, so a participant queued behind them waits."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from sqlalchemy.orm import Session, sessionmaker

from learner.run import RunSpec
from runs.worker.cluster import TRAINS_ON, Handed
from runs.worker.link import SHUTTING_DOWN
from runs.worker.worker import WorkerOptions, run_session
from server.live.cluster import SHUT_DOWN, TrainingCluster, cluster_refusal
from server.live.hub import Hub
from server.live.session import Changes, LiveSession
from server.live.trainers import Seat, TrainerSlots
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Status, StudySession
from study.services.sessions import claim, create_session
from study.services.studies import create_study
from tests.server.cluster import ON_POSTGRES
from tests.server.live import fresh_database
from tests.server.scale import records, session_body

ray = pytest.importorskip("ray")
pytestmark = ON_POSTGRES


CONTROLLED_EPISODES = 60
"""Episodes of the session paused, resumed and stopped: more than it trains in the seconds
the test takes, so the stop finds it running (the final checkpoint of a run that ended
would also be a checkpoint after the pause's)."""


def session(factory: sessionmaker[Session], study_id: int, seed: int, episodes: int) -> int:
    body = session_body("oracle", advice_budget=10, seed=seed, episodes=episodes)
    with factory() as db:
        return create_session(db, study_id, RunSpec.from_json(body["run"])).id


def handed(factory: sessionmaker[Session], session_id: int) -> Handed:
    """The session claimed here, as the web process holds one it hands over."""
    with factory() as db:
        return Handed(session_id, claim(db, session_id, resume=False))


def until(
    factory: sessionmaker[Session],
    session_id: int,
    done: Callable[[StudySession], bool],
    timeout_s: float = 240,
) -> StudySession:
    """The session's row once `done` holds for it."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = row(factory, session_id)
        if done(found):
            return found
        time.sleep(0.2)
    raise AssertionError(f"session {session_id}: {found.status} {found.status_detail}")


def until_true(done: Callable[[], bool], what: str, timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, what
        time.sleep(0.2)


def hold(seconds: float) -> None:
    """A task that holds its node's CPU."""
    time.sleep(seconds)


def row(factory: sessionmaker[Session], session_id: int) -> StudySession:
    with factory() as db:
        found = db.get(StudySession, session_id)
        assert found is not None
        return found


@pytest.fixture
def database(tmp_path: Path) -> Iterator[tuple[str, sessionmaker[Session]]]:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        yield url, make_session_factory(engine)
        engine.dispose()


def test_a_cluster_refuses_sqlite_and_a_missing_storage_root(tmp_path: Path) -> None:
    refusal = cluster_refusal(f"sqlite:///{tmp_path / 'x.sqlite3'}", tmp_path)
    assert refusal is not None and "PostgreSQL" in refusal
    refusal = cluster_refusal("postgresql+psycopg://h/db", tmp_path / "absent")
    assert refusal is not None and "does not exist" in refusal
    assert cluster_refusal("postgresql+psycopg://h/db", tmp_path) is None


def test_sessions_train_on_two_nodes_as_here_and_survive_a_node_killed(
    database: tuple[str, sessionmaker[Session]], tmp_path: Path
) -> None:
    from ray.cluster_utils import Cluster
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    url, factory = database
    shared = tmp_path / "shared"  # the folder every node sees
    options = WorkerOptions(data_dir=shared, checkpoint_every_episodes=1, heartbeat_s=1)
    with factory() as db:
        study_id = create_study(db, "on a cluster").id
    here = {seed: session(factory, study_id, seed, 3) for seed in (11, 12)}
    here[13] = session(factory, study_id, 13, 6)
    there = {seed: session(factory, study_id, seed, 3) for seed in (11, 12)}
    there[13] = session(factory, study_id, 13, 6)
    for session_id in here.values():
        assert run_session(session_id, url, options) == Status.finished

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    worker = cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    trainer = TrainingCluster(cluster.address, factory, url, options, Hub())
    loop = asyncio.new_event_loop()  # the web process's, where the trainer slots live
    threading.Thread(target=loop.run_forever, daemon=True).start()
    person = Seat(LiveSession(999, 10, [], Changes()))  # a participant queued for training
    queued: dict[int, Seat] = {}
    granted: list[list[int]] = []
    slots = TrainerSlots(
        7,
        1,
        lambda: {**trainer.seats(), **queued},
        lambda seats, slot: granted.append([s.session_id for s in seats]),
    )

    async def bind() -> None:
        trainer.bind(lambda session_id: None, slots.release, slots.set_slots)

    async def queue() -> None:
        queued[person.session_id] = person
        slots.request(person)

    try:
        asyncio.run_coroutine_threadsafe(bind(), loop).result(10)
        trainer.open()
        assert trainer.capacity() == 2
        until_true(lambda: slots.slots == 2, "the queue counts the cluster's two CPUs")
        for seed in (11, 12):  # machine sessions, one CPU each: one on each node
            seat = Seat(LiveSession(there[seed], 10, [], Changes()))
            trainer.train(handed(factory, there[seed]), seat, row(factory, there[seed]).spec)
        assert set(trainer.seats()) == {there[11], there[12]}
        asyncio.run_coroutine_threadsafe(queue(), loop).result(10)
        assert granted == [] and slots.place(person.session_id) == 1, "they hold both slots"
        assert trainer.wait(300), "trained within 5 minutes"
        until_true(lambda: granted == [[person.session_id]], "their slots free as they end")
        assert trainer.seats() == {}
        nodes = {row(factory, there[seed]).worker_host for seed in (11, 12)}
        assert len(nodes) == 2, f"trained on both nodes: {nodes}"
        for seed in (11, 12):
            assert row(factory, there[seed]).status == Status.finished
            assert records(factory, there[seed]) == records(factory, here[seed])

        controlled = session(factory, study_id, 14, CONTROLLED_EPISODES)
        trainer.submit([handed(factory, controlled)])
        until(factory, controlled, lambda s: s.checkpoint_episodes >= 1)
        assert trainer.control(controlled, Status.paused)
        time.sleep(2)  # read within a second, checkpointed at the next step boundary
        paused = row(factory, controlled)
        time.sleep(3)  # paused: no step taken, its heartbeat goes on
        still = row(factory, controlled)
        assert still.status == Status.paused
        assert still.progress["global_step"] == paused.progress["global_step"]
        assert still.checkpoint_step == paused.checkpoint_step
        assert still.heartbeat_at is not None and paused.heartbeat_at is not None
        assert still.heartbeat_at > paused.heartbeat_at
        assert trainer.control(controlled, Status.running)
        until(factory, controlled, lambda s: s.checkpoint_step > paused.checkpoint_step)
        assert trainer.control(controlled, Status.stopped, "stopped by the researcher")
        assert trainer.wait(120)
        stopped = row(factory, controlled)
        assert (stopped.status, stopped.status_detail) == (
            Status.stopped,
            "stopped by the researcher",
        )
        assert stopped.checkpoint_episodes < CONTROLLED_EPISODES, "stopped before its end"

        head = ray.get_runtime_context().get_node_id()
        sleep = ray.remote(num_cpus=1)(hold)
        holds_head = sleep.options(
            scheduling_strategy=NodeAffinitySchedulingStrategy(head, soft=False)
        ).remote(600)
        trainer.submit([handed(factory, there[13])])  # to the other node
        killed = until(
            factory,
            there[13],
            lambda s: s.checkpoint_episodes >= 1 and TRAINS_ON in s.status_detail,
        )
        assert killed.status == Status.running and killed.checkpoint_episodes < 6
        cluster.remove_node(worker)  # mid-run, after a checkpoint
        ray.cancel(holds_head, force=True)  # the head's CPU frees for it
        assert trainer.wait(300), "finished elsewhere within 5 minutes"
        until_true(lambda: slots.slots == 1, "the queue counts the one node left")
        done = row(factory, there[13])
        assert done.status == Status.finished, done.status_detail
        assert done.worker_host != killed.worker_host, "finished on the other node"
        resumed = [entry["from_step"] for entry in done.provenance]
        assert resumed[0] == 0 and resumed[-1] > 0, "resumed from its last checkpoint"
        assert records(factory, there[13]) == records(factory, here[13])

        cut = session(factory, study_id, 15, 6)
        trainer.submit([handed(factory, cut)])
        until(factory, cut, lambda s: s.checkpoint_episodes >= 1)
        trainer.close()  # the server shuts down in order
        time.sleep(2)
        left = row(factory, cut)
        assert (left.status, left.status_detail) == (Status.interrupted, SHUT_DOWN)
        assert left.status_detail.startswith(SHUTTING_DOWN), "resumed by the next start"
    finally:
        trainer.close()
        cluster.shutdown()
        loop.call_soon_threadsafe(loop.stop)
