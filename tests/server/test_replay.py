"""`ideeprl replay`: a recorded session's advice fed by order to a new run. Unchanged, the
replay takes the original's steps; changed, each advice says whether it met the image its
advisor saw; past the stream, no advice, and the records say so. Real PyBullet, a real
database, the real worker; tiny scale."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select, update

from cli.main import main
from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Advice, Feedback, Step, StudySession
from study.schemas.sessions import SessionOptions
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database

SCALE = {"batch_size": 8, "memory_size": 500, "episodes": 1, "torch_threads": 1}


@dataclass
class Database:
    url: str
    data_dir: Path

    def factory(self) -> Any:
        return make_session_factory(make_engine(self.url))

    def session(self, method: str, seed: int = 3, **run: Any) -> int:
        """A finished session of the tests' study, run by the real worker."""
        config = {**SCALE, **run.pop("config", {})}
        spec = RunSpec.from_json({"method": method, "seed": seed, "config": config, **run})
        with self.factory()() as db:
            session = create_session(db, 1, spec, SessionOptions(label="source"))
            session_id = session.id
        assert run_session(session_id, self.url, WorkerOptions(data_dir=self.data_dir)) == (
            "finished"
        )
        return session_id

    def replay(self, session_id: int, *flags: str) -> tuple[int, dict[str, Any]]:
        """`ideeprl replay --json`: its exit code and its report."""
        where = ["--database-url", self.url, "--data-dir", str(self.data_dir)]
        return _run_json(["replay", "--session", str(session_id), *flags, *where, "--json"])

    def ratings(self, session_id: int) -> list[Feedback]:
        with self.factory()() as db:
            query = select(Feedback).where(Feedback.session_id == session_id)
            return list(db.scalars(query.order_by(Feedback.feedback_index)))

    def advice(self, session_id: int) -> list[Advice]:
        with self.factory()() as db:
            query = select(Advice).where(Advice.session_id == session_id)
            return list(db.scalars(query.order_by(Advice.advice_index)))


_captured: list[str] = []


def _run_json(argv: list[str]) -> tuple[int, dict[str, Any]]:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(argv)
    return code, json.loads(out.getvalue())


@pytest.fixture(scope="module")
def database(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Database]:
    tmp = tmp_path_factory.mktemp("replay")
    with fresh_database(tmp) as url:
        engine = make_engine(url)
        upgrade(engine)
        with make_session_factory(engine)() as db:
            create_study(db, "replays")
        engine.dispose()
        yield Database(url, tmp / "data")


EARLY = {"pretraining_steps": 40, "advice_budget": 10, "max_episode_steps": 30}


@pytest.fixture(scope="module")
def oracle_early(database: Database) -> int:
    """An oracle-advised session, early advising: 10 advice at steps 31..40."""
    return database.session("oracle", motion="fast", config=EARLY)


def test_an_unchanged_replay_takes_the_originals_steps(
    database: Database, oracle_early: int
) -> None:
    code, report = database.replay(oracle_early)
    assert code == 0, report
    assert report["unchanged"] and report["changed"] == []
    assert report["status"] == "finished"
    assert report["why_records_may_differ"] is None
    assert report["comparison"]["difference"] is None
    assert report["comparison"]["steps"] > 40  # pretraining and one training episode
    assert report["advice"] == {
        "replayed": 10, "same_observation": 10, "beyond_stream": 0, "first_different": None
    }  # fmt: skip
    with database.factory()() as db:
        replay = db.get(StudySession, report["session_id"])
        assert replay is not None
        assert replay.method == "replayed" and replay.replay_of == oracle_early
        hashes = db.scalars(select(Step.observation_hash).where(Step.session_id == replay.id))
        assert all(h is not None and len(h) == 16 for h in hashes)


@pytest.mark.slow
def test_an_agent_advised_session_replays_unchanged(database: Database) -> None:
    """Advice from a trained agent's checkpoint: the replay needs only the stream (the
    checkpoint is not the replay's), and takes the original's steps."""
    advisor = database.session("autonomous", seed=4, motion="fast", config=EARLY)
    with database.factory()() as db:
        checkpoint = db.get(StudySession, advisor).checkpoint_path  # type: ignore[union-attr]
    original = database.session(
        "agent", seed=6, motion="fast", advisor_checkpoint=checkpoint, config=EARLY
    )
    code, report = database.replay(original)
    assert code == 0, report
    assert report["unchanged"] and report["comparison"]["difference"] is None
    assert report["advice"]["replayed"] == report["advice"]["same_observation"] == 10


def test_under_another_preset_early_advice_meets_the_same_states(
    database: Database, oracle_early: int
) -> None:
    code, report = database.replay(oracle_early, "--preset", "authors")
    assert code == 0, report
    assert not report["unchanged"] and "preset" in report["changed"]
    assert "comparison" not in report  # a changed run is not compared step by step
    assert report["advice"]["replayed"] == 10
    assert report["advice"]["same_observation"] == 10  # pretraining's states ignore the net
    original = database.advice(oracle_early)
    replayed = database.advice(report["session_id"])
    assert [a.action for a in replayed] == [a.action for a in original]
    assert [a.global_step for a in replayed] == list(range(31, 41))
    assert all(a.same_observation is True and a.advisor == "replayed" for a in replayed)


def test_a_stream_shorter_than_the_budget_gives_no_advice_beyond_it(
    database: Database, oracle_early: int
) -> None:
    code, report = database.replay(oracle_early, "--advice-budget", "15")
    assert code == 0, report
    assert report["advice"]["replayed"] == 10 and report["advice"]["beyond_stream"] == 5
    rows = database.advice(report["session_id"])
    assert [a.global_step for a in rows] == list(range(26, 41))  # early: the last 15 steps
    assert [a.action for a in rows[10:]] == [None] * 5
    assert [a.same_observation for a in rows[10:]] == [None] * 5
    assert [a.action for a in rows[:10]] == [a.action for a in database.advice(oracle_early)]
    with database.factory()() as db:
        query = select(Step).where(Step.session_id == report["session_id"], Step.global_step > 25)
        steps = list(db.scalars(query.order_by(Step.global_step)))[:15]
    assert [s.action_source for s in steps] == ["advisor"] * 10 + ["random"] * 5
    assert [s.advised_action is None for s in steps] == [False] * 10 + [True] * 5
    # every request is counted against the budget, answered or not: it ends spent
    assert [s.advice_remaining for s in steps] == list(range(14, -1, -1))


def test_an_alternating_replay_is_marked_different_from_where_it_diverges(
    database: Database,
) -> None:
    """Cutting episodes at 8 steps instead of 40 (pretraining is 8 steps, so it is the
    same): the replay follows the original through training step 8, then starts a new
    episode; advice 0-3 (training steps 1, 3, 5, 7) meet the original's images, advice 4-9
    (steps 9..19) do not."""
    alternating = {
        "pretraining_steps": 8, "advice_budget": 10, "max_episode_steps": 40, "episodes": 3
    }  # fmt: skip
    original = database.session(
        "oracle", seed=5, motion="fast", strategy="alternating", config=alternating
    )
    with database.factory()() as db:
        first = db.scalars(
            select(Step.terminated).where(
                Step.session_id == original, Step.stage == "train", Step.global_step <= 8 + 20
            )
        ).all()
    assert len(first) == 20 and not any(first), "the original's first episode must run 20 steps"
    code, report = database.replay(original, "--max-episode-steps", "8")
    assert code == 0, report
    rows = database.advice(report["session_id"])
    assert [a.global_step - 8 for a in rows] == list(range(1, 20, 2))
    assert [a.same_observation for a in rows] == [True] * 4 + [False] * 6
    assert report["advice"] == {
        "replayed": 10, "same_observation": 4, "beyond_stream": 0, "first_different": 8 + 9
    }  # fmt: skip


@pytest.mark.slow
def test_on_another_cpu_a_difference_is_explained_and_on_the_same_one_a_fault(
    database: Database,
) -> None:
    """The original's records and provenance are faked in the database: a step that no
    longer matches is a fault when the original was computed here, and explained (exit 0)
    when its provenance names another CPU kind."""
    original = database.session("oracle", seed=8, motion="fast", config=EARLY)
    with database.factory()() as db:
        db.execute(
            update(Step)
            .where(Step.session_id == original, Step.global_step == 35)
            .values(observation_hash="0" * 16)
        )
        db.commit()
    code, report = database.replay(original)
    assert code == 1 and report["fault"]
    assert report["comparison"]["difference"]["global_step"] == 35
    assert report["comparison"]["difference"]["column"] == "observation_hash"
    with database.factory()() as db:
        session = db.get(StudySession, original)
        assert session is not None
        session.provenance = [{**session.provenance[0], "cpu": "Some Other CPU @ 1.0GHz"}]
        db.commit()
    code, report = database.replay(original)
    assert code == 0 and not report["fault"]
    assert "CPU Some Other CPU @ 1.0GHz" in report["why_records_may_differ"]
    assert report["comparison"]["difference"]["global_step"] == 35


def test_steps_recorded_without_observation_hashes_compare_on_the_other_columns() -> None:
    from study.services.replays import DECIDING, compare

    step = {column: 1 for column in DECIDING}
    old = {**step, "observation_hash": None}
    assert compare([old], [{**step, "observation_hash": "ab" * 8}]).equal
    changed = compare([old], [{**step, "action": 2, "observation_hash": "ab" * 8}])
    assert changed.difference == {
        "global_step": 1, "column": "action", "original": 1, "replay": 2
    }  # fmt: skip


@pytest.fixture(scope="module")
def oracle_rated(database: Database) -> int:
    """A session of evaluative feedback: an oracle that errs a third of the time rates the
    learner's own actions at steps 31..40 (so its ratings cannot be had again from the
    task's correct action)."""
    return database.session(
        "oracle", motion="fast", feedback="evaluative", error_rate=0.3, config=EARLY
    )


def test_an_unchanged_replay_of_ratings_takes_the_originals_steps(
    database: Database, oracle_rated: int
) -> None:
    code, report = database.replay(oracle_rated)
    assert code == 0, report
    assert report["unchanged"] and report["status"] == "finished"
    assert report["recorded_ratings"] == 10 and "advice" not in report
    assert report["comparison"]["difference"] is None and report["comparison"]["steps"] > 40
    assert report["ratings"] == {
        "replayed": 10, "same_observation": 10, "beyond_stream": 0, "first_different": None
    }  # fmt: skip
    original, replayed = database.ratings(oracle_rated), database.ratings(report["session_id"])
    assert {f.evaluator for f in replayed} == {"replayed"}
    mine = [(f.global_step, f.action, f.judgement, f.shaping) for f in original]
    assert [(f.global_step, f.action, f.judgement, f.shaping) for f in replayed] == mine
    assert {f.judgement for f in original} == {1.0, -1.0}
    assert database.advice(report["session_id"]) == []


def test_ratings_replay_by_order_into_another_learner_and_none_beyond_the_stream(
    database: Database, oracle_rated: int
) -> None:
    """Another seed (another scene, other random actions) and a larger budget: the i-th
    recorded rating judges the i-th action the new learner is asked about, whatever it is;
    the five requests past the stream get no answer."""
    code, report = database.replay(oracle_rated, "--seed", "11", "--advice-budget", "15")
    assert code == 0, report
    assert not report["unchanged"] and report["status"] == "finished"
    assert report["ratings"]["replayed"] == 10 and report["ratings"]["beyond_stream"] == 5
    original, replayed = database.ratings(oracle_rated), database.ratings(report["session_id"])
    assert [f.global_step for f in replayed] == list(range(26, 41))  # early: the last 15
    assert [f.judgement for f in replayed[:10]] == [f.judgement for f in original]
    assert [f.judgement for f in replayed[10:]] == [None] * 5
    assert [f.shaping for f in replayed[10:]] == [0.0] * 5
    different = [
        i
        for i, (mine, theirs) in enumerate(zip(original, replayed, strict=False))
        if mine.observation_hash != theirs.observation_hash
    ]
    assert different and report["ratings"]["same_observation"] == 10 - len(different)
    assert report["ratings"]["first_different"] == replayed[different[0]].global_step


def test_ratings_replay_from_an_export_and_only_into_a_run_that_asks_for_ratings(
    database: Database, oracle_rated: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from study.services.export import export_study

    with database.factory()() as db:
        export_study(db, 1, tmp_path / "export")
    code, report = database.replay(
        oracle_rated, "--export", str(tmp_path / "export"), "--study", "rated export"
    )
    assert code == 0, report
    assert report["comparison"]["difference"] is None
    assert report["ratings"]["same_observation"] == 10
    judged = [f.judgement for f in database.ratings(report["session_id"])]
    assert judged == [f.judgement for f in database.ratings(oracle_rated)]
    where = ["--database-url", database.url, "--data-dir", str(database.data_dir), "--no-run"]
    assert main(["replay", "--session", str(oracle_rated), "--feedback", "advice", *where]) == 2
    assert "recorded ratings" in capsys.readouterr().err


def test_a_missing_source_is_named_and_nothing_is_created(
    database: Database, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    where = ["--database-url", database.url, "--data-dir", str(database.data_dir)]
    with database.factory()() as db:
        before = len(db.scalars(select(StudySession.id)).all())
    assert main(["replay", "--session", "424242", *where]) == 1
    assert "no session with id 424242" in capsys.readouterr().err
    missing = ["--export", str(tmp_path / "nothing"), "--study", "x"]
    assert main(["replay", "--session", "1", *missing, *where]) == 1
    assert "no study export at" in capsys.readouterr().err
    assert main(["replay", "--session", "1", "--export", str(tmp_path), *where]) == 2
    assert "--export needs --study" in capsys.readouterr().err
    with database.factory()() as db:
        assert len(db.scalars(select(StudySession.id)).all()) == before


def test_strategies_that_weigh_values_and_a_replay_without_a_stream_are_refused(
    database: Database, oracle_early: int
) -> None:
    code = main(
        ["replay", "--session", str(oracle_early), "--strategy", "importance",
         "--database-url", database.url, "--data-dir", str(database.data_dir), "--no-run"]
    )  # fmt: skip
    assert code == 2
    with database.factory()() as db:
        from study.services.errors import Invalid

        spec = RunSpec.from_json({"method": "replayed", "config": SCALE})
        with pytest.raises(Invalid, match="ideeprl replay"):
            create_session(db, 1, spec)


def test_deleting_the_source_deletes_its_replays_and_the_export_says_which_derives(
    database: Database, tmp_path: Path
) -> None:
    """A replay into another study: that study's export names its source
    (`replay_of`); deleting the source session (as deleting a participant does) deletes
    the replay's rows and files, and a replay of the replay, wherever they are."""
    import csv

    from study.services.export import export_study
    from study.services.storage import delete_session, session_dir

    original = database.session("oracle", seed=9, motion="fast", config=EARLY)
    code, first = database.replay(original, "--study", "reuse", "--preset", "authors")
    assert code == 0, first
    code, second = database.replay(first["session_id"], "--no-run")
    assert code == 0, second
    replays = [first["session_id"], second["session_id"]]
    assert session_dir(database.data_dir, replays[0]).is_dir()
    with database.factory()() as db:
        export_study(db, first["study_id"], tmp_path / "export")
    with open(tmp_path / "export" / "sessions.csv", newline="") as file:
        rows = {int(r["session_id"]): r for r in csv.DictReader(file)}
    assert rows[replays[0]]["replay_of"] == str(original)
    assert rows[replays[1]]["replay_of"] == str(replays[0])
    assert json.loads(rows[replays[0]]["replay_source"])["session"] == original
    with database.factory()() as db:
        delete_session(db, database.data_dir, original, live_here=False)
    with database.factory()() as db:
        assert db.scalars(select(StudySession).where(StudySession.id.in_(replays))).all() == []
        for table in (Step, Advice):
            left = db.scalars(select(table.id).where(table.session_id.in_(replays))).all()
            assert left == [], table
    assert not session_dir(database.data_dir, replays[0]).exists()


def test_a_session_of_an_export_replays_unchanged(
    database: Database, oracle_early: int, tmp_path: Path
) -> None:
    import shutil

    from study.services.export import export_study

    with database.factory()() as db:
        export_study(db, 1, tmp_path / "export")
    archive = shutil.make_archive(str(tmp_path / "export"), "zip", tmp_path / "export")
    code, report = database.replay(oracle_early, "--export", archive, "--study", "from a zip")
    assert code == 0, report
    assert report["source"]["export"] == archive
    assert report["comparison"]["difference"] is None and report["comparison"]["steps"] > 40
    assert report["advice"]["same_observation"] == 10
    with database.factory()() as db:
        replay = db.get(StudySession, report["session_id"])
        assert replay is not None and replay.replay_of is None  # not this database's session


@pytest.mark.slow
def test_a_persons_session_replays_unchanged_in_physics_and_goes_with_them(
    server: Any, api: Any
) -> None:
    """A human session (physics motion) driven through the participant API, replayed
    unchanged: every deciding column equal. Deleting the person's session through the API
    (how a person's data is deleted) deletes the replay, which has no participant."""
    from tests.server.participant import SimulatedParticipant
    from tests.server.scale import session_body, wait_for_status

    study = api.post("/api/studies", json={"name": "people to replay"}).json()
    body = session_body("human", advice_budget=5, motion="physics", episodes=1)
    body["run"]["config"].update(pretraining_steps=20, max_episode_steps=15)
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    participant = SimulatedParticipant(server.url, created["participant_token"])
    participant.begin()
    for index in range(5):
        state = participant.next_request()
        assert state["advice_index"] == index, state
        assert participant.advise(index, (3 * index) % 4, wait=10).status_code == 200
    wait_for_status(api, created["id"], {"finished"})
    participant.close()

    where = ["--database-url", server.database_url, "--data-dir", str(server.data_dir)]
    code, report = _run_json(["replay", "--session", str(created["id"]), *where, "--json"])
    assert code == 0, report
    assert report["comparison"]["difference"] is None and report["comparison"]["steps"] > 20
    assert report["advice"]["replayed"] == 5 and report["advice"]["same_observation"] == 5
    replay = api.get(f"/api/sessions/{report['session_id']}").json()
    assert replay["run"]["motion"] == "physics" and replay["participant"] is None
    longer = ["--advice-budget", "7", "--motion", "fast", "--episodes", "1"]
    code, report = _run_json(["replay", "--session", str(created["id"]), *longer, *where, "--json"])
    assert code == 0 and report["advice"]["beyond_stream"] == 2, report
    advice = api.get(f"/api/sessions/{report['session_id']}/advice")
    assert advice.status_code == 200, advice.text
    assert [a["action"] is None for a in advice.json()] == [False] * 5 + [True] * 2
    assert [a["advisor"] for a in advice.json()] == ["replayed"] * 7

    refused = api.post(f"/api/studies/{study['id']}/sessions", json=session_body("replayed"))
    assert refused.status_code == 422 and "ideeprl replay" in refused.text

    assert api.delete(f"/api/sessions/{created['id']}").status_code in (200, 204)
    assert api.get(f"/api/sessions/{report['session_id']}").status_code == 404


def test_a_replay_shows_its_source_through_the_api(server: Any, api: Any) -> None:
    """`replay_of` is the session a replay derives from (what deleting it takes along):
    the session says so, as the export's `sessions` table does."""
    from study.services import replays
    from tests.server.scale import session_body

    study = api.post("/api/studies", json={"name": "a replay's source"}).json()["id"]
    body = session_body("oracle", advice_budget=10)
    created = api.post(f"/api/studies/{study}/sessions", json=body)
    assert created.status_code == 201, created.text
    source = created.json()["id"]
    engine = make_engine(server.database_url)
    with make_session_factory(engine)() as db:
        stream = replays.stream_of_session(db, source)
        replay = replays.create_replay(db, study, stream, replays.replay_run(stream.run, {})).id
    engine.dispose()
    assert api.get(f"/api/sessions/{replay}").json()["replay_of"] == source
    assert api.get(f"/api/sessions/{source}").json()["replay_of"] is None
    listed = {s["id"]: s["replay_of"] for s in api.get(f"/api/studies/{study}/sessions").json()}
    assert listed == {source: None, replay: source}
