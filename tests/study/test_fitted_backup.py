"""A backup carries the fitted model a session's run names, and a restore points the run
at its new place, as it does for checkpoints."""

from __future__ import annotations

from pathlib import Path

from learner.fitted import Count, FittedModel
from learner.run import RunSpec
from study.db.backup import backup, restore
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import FittedAdvisorModel, StudySession
from study.services.fitting import write_model_file
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database


def test_a_restored_fitted_session_names_its_model_in_the_new_data_folder(
    tmp_path: Path,
) -> None:
    model = FittedModel(
        advice=1, sessions=[], methods=["human"], overall=Count(1, 0), by_group={},
        by_situation={}, wrong_actions=[[0] * 4 for _ in range(4)],
        decision_time_median_s=None, decision_time_sigma=None, decision_time_quantiles=[],
        budget_used=[1.0],
    )  # fmt: skip
    old, new = tmp_path / "old", tmp_path / "new"
    old.mkdir()
    new.mkdir()
    with fresh_database(old) as url:
        engine = make_engine(url)
        upgrade(engine)
        with make_session_factory(engine)() as db:
            study = create_study(db, "fitted backup").id
            row = FittedAdvisorModel(study_id=study, model=model.to_json(), session_ids=[])
            db.add(row)
            db.commit()
            write_model_file(old, row)
            spec = RunSpec.from_json({"method": "fitted", "fitted_model": f"fitted:{row.id}"})
            session_id = create_session(db, study, spec, data_dir=old).id
        engine.dispose()
        taken = backup(url, old, tmp_path / "backup")
    (relative,) = [f for f in taken.files if f.startswith("fitted/")]
    with fresh_database(new) as url:
        restore(tmp_path / "backup", url, new)
        engine = make_engine(url)
        with make_session_factory(engine)() as db:
            session = db.get(StudySession, session_id)
            assert session is not None
            assert session.spec.fitted_model == str(new / relative)
        engine.dispose()
    assert (new / relative).read_text() == (old / relative).read_text()
