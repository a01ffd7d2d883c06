"""Checkpoint paths kept relative to the storage root a Ray cluster's nodes share
(`study.db.models.stored_path`, `located`): a session trained with the root at one path resumes
from its checkpoint with the same folder mounted at another, with the records of an
uninterrupted run; a path stored absolute still reads. A root apart from the data folder
holds the checkpoints that `session:ID` advisors read (their path kept relative to it too)
and that deletion removes."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest
from sqlalchemy import update
from sqlalchemy.orm import Session

from learner.run import RunSpec
from runs.worker.cluster import STORAGE_ROOT_VARIABLE, DatabaseChannel, Handed, node_storage_root
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Advice, Status, StudySession, located, stored_path
from study.services import storage
from study.services.errors import Conflict, Invalid
from study.services.sessions import claim, create_session, set_status
from study.services.studies import create_study
from study.settings import Settings
from tests.server.live import fresh_database
from tests.server.scale import records, session_body

pytestmark = pytest.mark.slow


def test_a_path_is_kept_relative_to_the_root_it_lies_in(tmp_path: Path) -> None:
    root = tmp_path / "shared"
    inside = root / "checkpoints" / "session-3" / "final.pt"
    assert stored_path(inside, root) == "checkpoints/session-3/final.pt"
    assert stored_path(inside, None) == str(inside), "one machine's training keeps it absolute"
    elsewhere = tmp_path / "other" / "final.pt"
    assert stored_path(elsewhere, root) == str(elsewhere)
    moved = tmp_path / "mounted" / "here"
    assert located("checkpoints/session-3/final.pt", moved) == moved / inside.relative_to(root)
    assert located(str(inside), moved) == inside, "an absolute path reads as it is"
    assert located(None, moved) is None and located("", moved) is None


def test_a_session_resumes_with_its_storage_root_mounted_elsewhere(tmp_path: Path) -> None:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        factory = make_session_factory(engine)
        body = session_body("oracle", advice_budget=10, seed=5, episodes=4)
        with factory() as db:
            study_id = create_study(db, "storage root").id
            ids = [create_session(db, study_id, RunSpec.from_json(body["run"])).id for _ in "ab"]
        whole, cut = ids
        options = WorkerOptions(data_dir=tmp_path / "whole", checkpoint_every_episodes=1)
        assert run_session(whole, url, options) == Status.finished

        first = tmp_path / "node-a" / "shared"  # the root as the first node mounts it
        shared = WorkerOptions(
            data_dir=first, shared_storage=True, checkpoint_every_episodes=1, heartbeat_s=1
        )
        with factory() as db:
            token = claim(db, cut, resume=False)

        def stop_after_a_checkpoint() -> None:  # the researcher's stop, through the row
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline:
                with factory() as db:
                    found = db.get(StudySession, cut)
                    if found is not None and found.checkpoint_episodes >= 1:
                        set_status(db, cut, Status.stopped, "stopped", token=token)
                        return
                time.sleep(0.1)

        stopper = threading.Thread(target=stop_after_a_checkpoint)
        stopper.start()
        channel = DatabaseChannel(factory, [Handed(cut, token)], population=False)
        status = run_session(cut, url, shared, worker_token=token, conn=channel)  # type: ignore[arg-type]
        stopper.join()
        assert status == Status.stopped
        with factory() as db:
            stopped = db.get(StudySession, cut)
            assert stopped is not None and stopped.checkpoint_path
            assert stopped.checkpoint_episodes < 4, "stopped before its end"
            kept = stopped.checkpoint_path
        assert kept.startswith(f"checkpoints/session-{cut}/"), kept
        assert (first / kept).is_file()

        second = tmp_path / "node-b" / "mnt"  # the same folder, mounted elsewhere
        second.parent.mkdir()
        first.rename(second)
        moved = WorkerOptions(data_dir=second, shared_storage=True, checkpoint_every_episodes=1)
        assert run_session(cut, url, moved) == Status.finished
        with factory() as db:
            done = db.get(StudySession, cut)
            assert done is not None and done.checkpoint_path is not None
            resumed = [entry["from_step"] for entry in done.provenance]
            assert resumed[0] == 0 and resumed[-1] > 0, "resumed from its checkpoint"
            assert not Path(done.checkpoint_path).is_absolute()
            assert (second / done.checkpoint_path).is_file()
        assert records(factory, cut) == records(factory, whole)

        # a database from one machine's training keeps absolute paths: they still read
        with factory() as db:
            db.execute(
                update(StudySession)
                .where(StudySession.id == cut)
                .values(checkpoint_path=str(second / kept))
            )
            db.commit()
            found = db.get(StudySession, cut)
            assert found is not None
            assert located(found.checkpoint_path, tmp_path / "elsewhere") == second / kept
        engine.dispose()


def test_a_node_reads_the_storage_root_where_it_mounts_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    web = tmp_path / "srv" / "shared"  # where the web server mounts it
    monkeypatch.delenv(STORAGE_ROOT_VARIABLE, raising=False)
    assert node_storage_root(web) == web
    monkeypatch.setenv(STORAGE_ROOT_VARIABLE, str(tmp_path / "mnt"))  # `ray start`'s here
    assert node_storage_root(web) == tmp_path / "mnt"


def test_the_checkpoint_root_is_the_storage_root_only_with_a_cluster(tmp_path: Path) -> None:
    data, root = tmp_path / "data", tmp_path / "shared"
    alone = Settings(data_dir=data, storage_root=root)
    assert (alone.checkpoint_root, alone.shared_root) == (data, None)
    clustered = Settings(data_dir=data, storage_root=root, ray_address="10.0.0.1:6379")
    assert clustered.checkpoint_root == clustered.shared_root == root
    assert Settings(data_dir=data, ray_address="auto").checkpoint_root == data.absolute()


def _trained_advisor(
    url: str, factory: Callable[[], Session], root: Path, study: str
) -> tuple[int, int, WorkerOptions]:
    """A new study with an autonomous run trained to its end, its checkpoints under the
    storage `root`: the study, the run, and the options its worker had."""
    shared = WorkerOptions(data_dir=root, shared_storage=True)
    with factory() as db:
        study_id = create_study(db, study).id
        body = session_body("autonomous", episodes=2)
        advisor = create_session(db, study_id, RunSpec.from_json(body["run"])).id
    assert run_session(advisor, url, shared) == Status.finished
    return study_id, advisor, shared


def test_advisors_and_deletion_find_checkpoints_under_a_root_apart(tmp_path: Path) -> None:
    data, root = tmp_path / "data", tmp_path / "shared"  # the web server's, the nodes'
    data.mkdir()
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        factory = make_session_factory(engine)
        study_id, advisor, shared = _trained_advisor(url, factory, root, "apart")

        def agent() -> int:
            body = session_body(
                "agent", advice_budget=10, episodes=2, advisor_checkpoint=f"session:{advisor}"
            )
            with factory() as db:
                spec = RunSpec.from_json(body["run"])
                return create_session(db, study_id, spec, data_dir=data, shared_root=root).id

        advised, waiting = agent(), agent()
        with factory() as db:
            stored = db.get(StudySession, advised)
            assert stored is not None
            kept = stored.run["advisor_checkpoint"]
        assert kept == f"checkpoints/session-{advisor}/final.pt", "relative, as its own row's"
        mounted = tmp_path / "node" / "mnt"  # a node mounts the root elsewhere
        mounted.parent.mkdir()
        root.rename(mounted)
        assert run_session(advised, url, replace(shared, data_dir=mounted)) == Status.finished
        mounted.rename(root)
        with factory() as db:
            given = db.query(Advice).filter_by(session_id=advised).count()
            assert given == 10, "advised by the checkpoint under the root"
            disk = storage.study_disk(db, data, study_id, root)
            assert disk.session_bytes[advisor] > 0 and disk.session_bytes[advised] > 0
            with pytest.raises(Conflict, match="advises"):  # `waiting` has not run yet
                storage.delete_session(db, data, advisor, False, root)
            db.rollback()
            older = db.get(StudySession, waiting)  # an older database's absolute path
            assert older is not None
            older.run = {**older.run, "advisor_checkpoint": str(root / kept)}
            db.commit()
            with pytest.raises(Conflict, match="advises"):
                storage.delete_session(db, data, advisor, False, root)
            db.rollback()
            storage.delete_session(db, data, waiting, False, root)
            storage.delete_session(db, data, advised, False, root)
            storage.delete_session(db, data, advisor, False, root)
        for session_id in (advisor, advised):
            assert not storage.session_dir(root, session_id).exists(), "deleted under the root"
        assert not (data / "checkpoints").exists(), "nothing was ever in the data folder"
        engine.dispose()


def test_an_advisors_file_lies_under_the_storage_root_and_is_kept_relative(tmp_path: Path) -> None:
    """With a cluster, an advisor named by its file must lie where every node reads it (the
    storage root, not the web server's data folder), and is kept relative to the root, so a
    node that mounts the root elsewhere finds it."""
    data, root = tmp_path / "data", tmp_path / "shared"
    data.mkdir()
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        factory = make_session_factory(engine)
        study_id, advisor, shared = _trained_advisor(url, factory, root, "a file apart")
        trained = root / f"checkpoints/session-{advisor}/final.pt"
        in_data = data / "advisors" / "final.pt"
        in_root = root / "advisors" / "final.pt"
        for copy in (in_data, in_root):
            copy.parent.mkdir(parents=True)
            copy.write_bytes(trained.read_bytes())

        def agent(path: Path) -> int:
            body = session_body("agent", advice_budget=10, episodes=2, advisor_checkpoint=str(path))
            with factory() as db:
                spec = RunSpec.from_json(body["run"])
                return create_session(db, study_id, spec, data_dir=data, shared_root=root).id

        with pytest.raises(Invalid, match="under the storage root the cluster's nodes share"):
            agent(in_data)
        advised = agent(in_root)
        with factory() as db:
            stored = db.get(StudySession, advised)
            assert stored is not None
            assert stored.run["advisor_checkpoint"] == "advisors/final.pt"
        mounted = tmp_path / "node" / "mnt"  # a node mounts the root elsewhere
        mounted.parent.mkdir()
        root.rename(mounted)
        assert run_session(advised, url, replace(shared, data_dir=mounted)) == Status.finished
        with factory() as db:
            assert db.query(Advice).filter_by(session_id=advised).count() == 10
        engine.dispose()
