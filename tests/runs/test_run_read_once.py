"""A worker reads its session's stored run once: the document becomes a `RunSpec` in one
place and that object is passed on (the claim, the provenance, the scene, the learner)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.server.live import fresh_database

TINY = {
    "pretraining_steps": 20,
    "advice_budget": 5,
    "episodes": 1,
    "max_episode_steps": 10,
    "batch_size": 8,
    "memory_size": 100,
}


@pytest.mark.parametrize("method", ["autonomous", "oracle"])
def test_a_worker_reads_its_run_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, method: str
) -> None:
    with fresh_database(tmp_path) as url:
        engine = make_engine(url)
        upgrade(engine)
        with make_session_factory(engine)() as db:
            study = create_study(db, "reads")
            spec = RunSpec.from_json({"method": method, "seed": 2, "config": TINY})
            session_id = create_session(db, study.id, spec).id
        engine.dispose()

        reads: list[dict[str, Any]] = []
        original = RunSpec.from_json.__func__  # type: ignore[attr-defined]

        def counted(cls: type[RunSpec], data: Any) -> RunSpec:
            reads.append(dict(data))
            return original(cls, data)  # type: ignore[no-any-return]

        monkeypatch.setattr(RunSpec, "from_json", classmethod(counted))
        status = run_session(session_id, url, WorkerOptions(data_dir=tmp_path / "data"))
        assert status == "finished"
        assert len(reads) == 1, f"the worker read its run {len(reads)} times"
