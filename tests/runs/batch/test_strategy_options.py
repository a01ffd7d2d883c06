"""A strategy's options given to `ideeprl batch` reach every advised run's trainer, are
part of the run's identity, and are refused with a reason for a strategy that has none."""

from __future__ import annotations

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from study.db.models import Advice, StudySession
from study.services.episodes import session_settings
from tests.runs.batch.helpers import SCALE, Place, read_csv, sessions, study_id
from tests.runs.batch.helpers import in_process as run

pytestmark = pytest.mark.slow
PRETRAINING = 20  # SCALE's --pretraining-steps
ALTERNATING = ["--methods", "random", "--agents", "1", "--strategy", "alternating"]


def test_the_interval_reaches_the_trainer_and_names_the_run(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["batch", "--study", "options", *ALTERNATING, "--interval", "3", *SCALE]
    code, out = run(place, capsys, *args, "--workers", "1")
    assert code == 0, out
    engine = place.engine()
    study = study_id(engine, "options")
    (session,) = sessions(engine, study)
    assert session.status == "finished" and session.spec.strategy_options.given() == {"interval": 3}
    with Session(engine) as db:
        steps = list(db.scalars(select(Advice.global_step).where(Advice.session_id == session.id)))
    training = [step - PRETRAINING for step in steps]
    assert len(training) >= 2 and all((t - 1) % 3 == 0 for t in training), training

    out_dir = place.data_dir / "options-export"
    code, out = run(place, capsys, "export", "--study", "options", "--out", str(out_dir))
    assert code == 0, out
    (row,) = read_csv(out_dir / "sessions.csv")
    assert row["strategy_interval"] == "3" and row["strategy_threshold"] == ""
    with Session(engine) as db:
        (settings,) = session_settings([db.get(StudySession, session.id)]).to_dict("records")
    assert settings["advice"] == "alternating (interval 3), budget 8", settings

    code, out = run(place, capsys, *args, "--dry-run")  # the same batch finds its run
    assert code == 0 and f"session {session.id}: finished" in out, out
    other = ["batch", "--study", "options", *ALTERNATING, "--interval", "2", *SCALE]
    code, out = run(place, capsys, *other, "--dry-run")  # another interval is another run
    assert code == 0 and "new" in out and f"session {session.id}" not in out, out


def test_an_option_the_strategy_does_not_take_is_refused(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["batch", "--study", "refused options", *ALTERNATING, "--threshold", "0.3", *SCALE]
    code, out = run(place, capsys, *args)
    assert code == 2 and "the alternating strategy takes no option threshold" in out, out
