import gzip
import json
import math
import shutil
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import MetaData, Table, func, inspect, select, text
from sqlalchemy.orm import Session

from analysis.human import participants
from learner.config import DQNConfig
from learner.run import RunSpec
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import alembic_config, upgrade
from study.db.models import Advice, Base, Feedback, Step, StudySession
from study.services.advice import AdviceGiven, write_advice
from study.services.episodes import load_visits
from study.services.feedback import FeedbackGiven, write_feedback
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database


def test_migrations_build_exactly_the_schema_of_the_models(tmp_path: Path) -> None:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        upgrade(engine)  # a second start-up finds nothing to do
        with engine.connect() as connection:
            diff = compare_metadata(MigrationContext.configure(connection), Base.metadata)
            tables = set(inspect(connection).get_table_names())
        engine.dispose()
    assert diff == [], f"models and migrations differ; add a migration: {diff}"
    assert {"studies", "sessions", "steps", "episodes", "advice", "alembic_version"} <= tables


def test_sqlite_runs_in_wal_mode_with_a_busy_timeout(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite3'}")
    with engine.connect() as connection:
        assert connection.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert connection.exec_driver_sql("PRAGMA busy_timeout").scalar() >= 10_000
        assert connection.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    engine.dispose()


REPLICATION_DB = Path(__file__).parents[2] / "docs/results/replication/state/ideeprl.sqlite3.gz"
OLD_SESSION = {  # a session row as revision 0006 stored it
    "study_id": 1, "label": "old", "status": "finished", "status_detail": "", "progress": {},
    "checkpoint_step": 0, "checkpoint_episodes": 0, "checkpoint_advice": 0,
    "created_at": datetime(2026, 11, 1, tzinfo=UTC), "max_episode_steps": 40,
}  # fmt: skip


OLD_STEP = {  # a step row of revision 0006 (its `phase` is 0008's `stage`)
    "session_id": 2, "episode": 1, "episode_step": 1, "action": 0, "greedy_action": 0,
    "q_grab": 0.0, "q_move_right": 0.0, "q_move_left": 0.0, "q_drop": 0.0,
    "advised_action": None, "advice_remaining": 0, "reward": 0.0, "terminated": False,
    "truncated": False, "epsilon": 1.0, "loss": None, "wall_time": 0.0,
}  # fmt: skip


def _config(**changes: object) -> dict[str, object]:
    return {**DQNConfig.preset("paper", pretraining_steps=60, batch_size=16).to_dict(), **changes}


def test_migration_0007_stores_each_session_as_one_run_document(tmp_path: Path) -> None:
    """Rows of 0006 (advice budget, episodes and limits twice, options NULL, sb3 settings in
    the config) become version-1 run documents that `RunSpec` reads; nothing else changes."""
    rows = [
        dict(method="autonomous", seed=3, config=_config(advice_budget=0), sort_rule="color",
             strategy=None, strategy_options=None, advice_budget=0, advisor_checkpoint=None,
             oracle_error_rate=None, motion="fast", scenario={}, episodes=300),
        dict(method="oracle", seed=4, config=_config(advice_budget=30), sort_rule="shape",
             strategy="alternating", strategy_options=None, advice_budget=30,
             advisor_checkpoint=None, oracle_error_rate=0.25, motion="physics",
             scenario={"reward_scheme": "authors-interactive"}, episodes=300),
        dict(method="sb3-dqn", seed=5, config={**_config(advice_budget=0), "sb3_gamma": 0.9},
             sort_rule={"cube/red": "left", "cube/blue": "right", "cylinder/red": "left",
                        "cylinder/blue": "right", "disk/red": "left", "disk/blue": "right"},
             strategy=None, strategy_options=None, advice_budget=0, advisor_checkpoint=None,
             oracle_error_rate=None, motion="fast", scenario={}, episodes=300),
        dict(method="agent", seed=6, config=_config(fit="keras", head="softmax"),
             sort_rule="color", strategy="early", strategy_options={}, advice_budget=100,
             advisor_checkpoint="/data/advisor.pt", oracle_error_rate=None, motion="fast",
             scenario={"reward_scheme": "paper", "grasp_failure_rate": 0.05,
                       "knock_off_rate": 0.05}, episodes=300),
    ]  # fmt: skip
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        command.upgrade(alembic_config(engine), "0006")
        with engine.begin() as c:
            c.execute(text("INSERT INTO studies (name, description, texts, created_at) "
                           "VALUES ('s', '', '{}', CURRENT_TIMESTAMP)"))  # fmt: skip
            sessions = Table("sessions", MetaData(), autoload_with=c)
            for row in rows:
                c.execute(sessions.insert().values(**OLD_SESSION, **row))
            steps = Table("steps", MetaData(), autoload_with=c)
            for step, (phase, source) in enumerate(
                [("pretrain", "random"), ("advice", "advisor"), ("train", "greedy")], 1
            ):
                c.execute(steps.insert().values(**OLD_STEP, global_step=step, phase=phase,
                                                action_source=source))  # fmt: skip
        upgrade(engine)
        with engine.connect() as c:
            stages = c.execute(text("SELECT stage, action_source FROM steps ORDER BY global_step"))
            assert [tuple(r) for r in stages] == [
                ("pretrain", "random"),
                ("pretrain", "advisor"),
                ("train", "greedy"),
            ]  # fmt: skip  (0008: advice is a source, not a stage)
        with make_session_factory(engine)() as db:
            stored = list(db.scalars(select(StudySession).order_by(StudySession.id)))
            specs = [s.spec for s in stored]
        engine.dispose()
    assert [s.method for s in stored] == ["autonomous", "oracle", "sb3-dqn", "agent"]
    assert [s.seed for s in specs] == [3, 4, 5, 6] and [s.id for s in stored] == [1, 2, 3, 4]
    autonomous, oracle, sb3, agent = specs
    assert (
        autonomous.advice_budget == 0 and autonomous.config.max_episode_steps == 250
    )  # config wins
    assert oracle.strategy == "alternating" and oracle.strategy_options.interval == 2
    assert oracle.error_rate == 0.25 and oracle.motion == "physics" and oracle.sort_rule == "shape"
    assert oracle.scenario.reward_scheme == "authors-interactive"
    assert oracle.config.advice_budget == 30 and oracle.preset == "paper"
    assert "sb3_gamma" not in stored[2].run["config"] and sb3.sb3["sb3_gamma"] == 0.9
    assert sb3.sort_rule == rows[2]["sort_rule"]
    assert agent.preset == "authors" and agent.advisor_checkpoint == "/data/advisor.pt"
    assert agent.scenario.knock_off_rate == 0.05 and agent.strategy_options.given() == {}
    assert all(s.validate() == s.normalized() for s in specs[:3])


def test_the_committed_replication_database_migrates(tmp_path: Path) -> None:
    copy = tmp_path / "replication.sqlite3"
    with gzip.open(REPLICATION_DB) as packed, copy.open("wb") as out:
        shutil.copyfileobj(packed, out)
    engine = make_engine(f"sqlite:///{copy}")
    with engine.connect() as c:
        before = c.execute(text("SELECT id, method, seed, config, scenario, advice_budget "
                                "FROM sessions ORDER BY id")).all()  # fmt: skip
        steps = c.execute(text("SELECT count(*) FROM steps")).scalar()
    upgrade(engine)
    with make_session_factory(engine)() as db:
        after = list(db.scalars(select(StudySession).order_by(StudySession.id)))
        assert db.scalar(select(func.count()).select_from(Step)) == steps
        for old, new in zip(before, after, strict=True):
            spec = new.spec
            config = json.loads(old.config)
            assert (new.id, spec.method, spec.seed) == (old.id, old.method, old.seed)
            assert spec.config.learning_rate == config["learning_rate"]
            assert spec.config.head == config["head"] and spec.config.fit == config["fit"]
            assert spec.advice_budget == old.advice_budget
            assert spec.scenario.to_dict() == json.loads(old.scenario)
    engine.dispose()
    assert len(after) == 35


def _two_completed_visits(
    factory: Callable[[], Session], study: str, method: str, condition: str, now: datetime
) -> list[int]:
    """Two completed visits of one condition in a new study (seeds 1 and 2): their ids."""
    with factory() as db:
        made = create_study(db, study)
        sessions = [
            create_session(db, made.id, RunSpec(method=method, seed=seed)) for seed in (1, 2)
        ]
        for s in sessions:
            s.condition, s.outcome, s.consented_at = condition, "completed", now
        db.commit()
        return [s.id for s in sessions]


def test_migration_0019_adds_the_feedbacks_correct_action_and_keeps_older_rows(
    tmp_path: Path,
) -> None:
    """A judgement stored under 0018 reads with no correct action (NULL, not a guess) and
    the report gives it no accuracy; one stored after carries its own; the downgrade keeps
    the judgements without the column."""
    now = datetime(2026, 12, 7, tzinfo=UTC)
    judged = {"feedback_index": 0, "global_step": 5, "evaluator": "human", "action": 1,
              "judgement": 1.0, "shaping": 1.0, "greedy_action": 1,
              "observation_hash": "0" * 16, "response_time_s": 1.0, "decision_time_s": 0.5,
              "requested_at": now, "answered_at": now}  # fmt: skip
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        command.upgrade(alembic_config(engine), "0018")
        factory = make_session_factory(engine)
        ids = _two_completed_visits(factory, "ratings before 0019", "autonomous", "rating", now)
        with engine.begin() as c:
            feedback = Table("feedback", MetaData(), autoload_with=c)
            assert "correct_action" not in feedback.c
            c.execute(feedback.insert().values(session_id=ids[0], **judged))
        upgrade(engine)
        with factory() as db:
            write_feedback(db, [FeedbackGiven(session_id=ids[1], **judged, correct_action=1)])
            db.commit()
            stored = list(db.scalars(select(Feedback).order_by(Feedback.session_id)))
            assert [(f.session_id, f.correct_action) for f in stored] == [
                (ids[0], None),
                (ids[1], 1),
            ]
            made = list(db.scalars(select(StudySession).order_by(StudySession.id)))
            people = participants(load_visits(db, made)).set_index("session_id")
        assert people.loc[ids[0], "advice"] == 1 and math.isnan(people.loc[ids[0], "accuracy"])
        assert people.loc[ids[1], "accuracy"] == 1.0, "good of the correct action: right"
        command.downgrade(alembic_config(engine), "0018")
        with engine.connect() as c:
            feedback = Table("feedback", MetaData(), autoload_with=c)
            assert "correct_action" not in feedback.c
            kept = c.execute(select(feedback.c.session_id).order_by(feedback.c.session_id))
            assert [row[0] for row in kept] == ids
        engine.dispose()


def test_migration_0020_adds_every_right_action_and_keeps_older_rows(tmp_path: Path) -> None:
    """Advice stored under 0019 keeps its one correct action (its accuracy reads it alone:
    advice of an action as right is scored wrong, as it was stored); advice stored after
    carries the list, and naming any action of it is accurate; the downgrade keeps the
    advice without the column."""
    now = datetime(2026, 12, 8, tzinfo=UTC)
    given = {"advice_index": 0, "global_step": 5, "advisor": "human", "action": 2,
             "greedy_action": 0, "observation_png": b"", "response_time_s": 1.0,
             "decision_time_s": 0.5, "requested_at": now, "answered_at": now,
             "correct_action": 1}  # fmt: skip
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        command.upgrade(alembic_config(engine), "0019")
        factory = make_session_factory(engine)
        ids = _two_completed_visits(factory, "advice before 0020", "human", "advice", now)
        with engine.begin() as c:
            advice = Table("advice", MetaData(), autoload_with=c)
            assert "correct_actions" not in advice.c
            c.execute(advice.insert().values(session_id=ids[0], **given))
        upgrade(engine)
        with factory() as db:
            write_advice(db, [AdviceGiven(session_id=ids[1], **given, correct_actions=[1, 2])])
            db.commit()
            stored = list(db.scalars(select(Advice).order_by(Advice.session_id)))
            assert [(a.session_id, a.correct_actions) for a in stored] == [
                (ids[0], None),
                (ids[1], [1, 2]),
            ]
            made = list(db.scalars(select(StudySession).order_by(StudySession.id)))
            people = participants(load_visits(db, made)).set_index("session_id")
        assert people.loc[ids[0], "accuracy"] == 0.0, "stored with its one correct action"
        assert people.loc[ids[1], "accuracy"] == 1.0, "2 is as right as 1"
        command.downgrade(alembic_config(engine), "0019")
        with engine.connect() as c:
            advice = Table("advice", MetaData(), autoload_with=c)
            assert "correct_actions" not in advice.c
            kept = c.execute(select(advice.c.session_id).order_by(advice.c.session_id))
            assert [row[0] for row in kept] == ids
        engine.dispose()
