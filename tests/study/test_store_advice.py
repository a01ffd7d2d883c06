"""A person's advice is written once: the first answer stands, and a second write of the
same (session, advice_index) gives back the row that stands, which the route answers with."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import pytest
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError

from learner.run import RunSpec
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Advice
from study.services.advice import AdviceGiven, store_advice
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database


@pytest.fixture
def database(tmp_path: Path) -> Iterator[str]:
    with fresh_database(tmp_path) as url:
        upgrade(make_engine(url))
        yield url


def _advice(session_id: int, action: int) -> AdviceGiven:
    now = datetime.now(UTC)
    return AdviceGiven(
        session_id=session_id, advice_index=0, global_step=7, advisor="human", action=action,
        greedy_action=0, observation_png=b"png", response_time_s=1.5, decision_time_s=1.0,
        requested_at=now, answered_at=now,
    )  # fmt: skip


def test_the_first_answer_stands_and_a_second_gets_it_back(database: str) -> None:
    factory = make_session_factory(make_engine(database))
    with factory() as db:
        study = create_study(db, "advice")
        session_id = create_session(db, study.id, RunSpec(method="human")).id
    assert store_advice(factory, _advice(session_id, 2)) is None
    stood = store_advice(factory, _advice(session_id, 3))
    assert stood is not None and (stood.advice_index, stood.action) == (0, 2)
    with factory() as db:
        assert db.scalar(select(func.count()).select_from(Advice)) == 1
    assert store_advice(factory, replace(_advice(session_id, 1), advice_index=1)) is None


def test_another_integrity_error_is_raised(database: str) -> None:
    factory = make_session_factory(make_engine(database))
    with pytest.raises(IntegrityError):  # no such session: its foreign key
        store_advice(factory, _advice(999, 2))
