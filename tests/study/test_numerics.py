"""A run's numerics are pinned when its session is created, and a resume on a machine that
cannot honour them is refused with the reason, or overridden and recorded."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy.orm import Session

from learner import machine, provenance
from learner.run import RunSpec
from runs.worker.worker import WorkerOptions, run_session
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import upgrade
from study.db.models import Status, StudySession
from study.services.export import export_study
from study.services.numerics import NumericsRefused
from study.services.sessions import create_session, set_status
from study.services.studies import create_study
from tests.server.live import fresh_database

TINY = {"pretraining_steps": 30, "batch_size": 8, "memory_size": 300, "episodes": 1,
        "max_episode_steps": 15, "advice_budget": 5}  # fmt: skip


@pytest.fixture
def database(tmp_path: Path) -> Iterator[str]:
    with fresh_database(tmp_path) as url:
        upgrade(make_engine(url))
        yield url


def _stopped_bf16_session(url: str) -> int:
    """A session pinned to bfloat16 convolutions that stopped before its end."""
    with make_session_factory(make_engine(url))() as db:
        study = create_study(db, "numerics")
        spec = RunSpec.from_json({"method": "oracle", "config": TINY})
        session = create_session(db, study.id, spec)
        assert session.run["config"]["device"] in ("cpu", "cuda")  # pinned when created
        assert session.run["config"]["torch_threads"] >= 1
        session.run = {**session.run, "config": {**session.run["config"], "precision": "bf16",
                                                 "device": "cpu"}}  # fmt: skip
        db.commit()
        set_status(db, session.id, Status.stopped, "stopped for the test")
        return session.id


def test_a_resume_the_machine_cannot_honour_is_refused_or_overridden_and_recorded(
    database: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session_id = _stopped_bf16_session(database)
    monkeypatch.setattr(machine, "bf16_native_cpu", lambda: False)  # a CPU without BF16
    options = WorkerOptions(data_dir=tmp_path / "data")
    with pytest.raises(NumericsRefused, match="bfloat16") as refused:
        run_session(session_id, database, options)
    assert "override_numerics" in str(refused.value)
    factory = make_session_factory(make_engine(database))
    with factory() as db:
        session = db.get(StudySession, session_id)
        assert session is not None and session.status == Status.stopped  # untouched
        assert session.numerics_overrides == []

    status = run_session(session_id, database, WorkerOptions(
        data_dir=tmp_path / "data", override_numerics=True))  # fmt: skip
    assert status == "finished"
    with factory() as db:
        session = db.get(StudySession, session_id)
        assert session is not None
        [override] = session.numerics_overrides
        assert override["from"]["precision"] == "bf16" and override["to"]["precision"] == "fp32"
        assert "bfloat16" in override["why"] and override["machine"]
        assert session.spec.config.precision == "fp32"
        study = session.study_id
        export_study(db, study, tmp_path / "export")
    with (tmp_path / "export" / "sessions.csv").open() as f:
        import csv

        (row,) = list(csv.DictReader(f))
    assert json.loads(row["numerics_overrides"])[0]["to"]["precision"] == "fp32"
    [computed] = json.loads(row["provenance"])  # the refused start computed nothing
    assert row["code_version"] == computed["code"] == provenance.code_version()
    assert computed["cpu"] == machine.cpu_kind() and computed["from_step"] == 0
    assert computed["numerics"]["precision"] == "fp32"


def test_ideeprl_train_refuses_to_resume_on_other_numerics(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from cli.main import main
    from learner.checkpoint import read_checkpoint, write_checkpoint

    small = [f"--{k.replace('_', '-')}={v}" for k, v in TINY.items()]
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), "--no-progress", "--precision", "bf16", *small]) == 0
    checkpoint = out / "checkpoint.pt"
    monkeypatch.setattr(machine, "bf16_native_cpu", lambda: False)
    state = read_checkpoint(checkpoint)
    assert state["metadata"]["config"]["precision"] == "bf16"
    write_checkpoint(checkpoint, state)
    assert main(["train", "--resume", str(checkpoint), "--episodes", "2", "--no-progress"]) == 2
    assert "bfloat16" in capsys.readouterr().err
    code = main(["train", "--resume", str(checkpoint), "--episodes", "2", "--no-progress",
                 "--override-numerics"])  # fmt: skip
    assert code == 0 and "numerics overridden" in capsys.readouterr().err


def test_sessions_are_pinned_where_they_are_created(database: str) -> None:
    with Session(make_engine(database)) as db:
        study = create_study(db, "pinned")
        made = create_session(db, study.id, RunSpec.from_json({"config": TINY}), threads=1)
        config = made.spec.config
    native = machine.bf16_native_cpu() or config.device == "cuda"
    assert config.precision == ("bf16" if native else "fp32")
    assert config.torch_threads == 1 and config.device in ("cpu", "cuda")


def test_a_session_pins_the_first_layer_kernel_the_switch_and_the_cpu_decide(
    database: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    fp32 = {**TINY, "precision": "fp32", "device": "cpu"}
    with Session(make_engine(database)) as db:
        study = create_study(db, "kernel")
        monkeypatch.delenv(machine.CONV_KERNEL_SWITCH, raising=False)
        off = create_session(db, study.id, RunSpec.from_json({"config": fp32}), threads=1)
        assert off.spec.config.conv_kernel == "none"  # the default: PyTorch's first layer
        monkeypatch.setenv(machine.CONV_KERNEL_SWITCH, "on")
        on = create_session(db, study.id, RunSpec.from_json({"config": fp32}), threads=1)
        assert on.spec.config.conv_kernel == machine.conv_kernel_for("fp32")
        monkeypatch.setattr(machine, "cpu_flags", lambda: frozenset({"sse2"}))  # no AVX2
        bare = create_session(db, study.id, RunSpec.from_json({"config": fp32}), threads=1)
        assert bare.spec.config.conv_kernel == "none"


def _stopped_kernel_session(url: str, kernel: str = "avx2:1-3") -> int:
    """A session pinned to the AVX2 kernels (float32) for `kernel`'s layers that stopped
    early."""
    with make_session_factory(make_engine(url))() as db:
        study = create_study(db, f"kernel {db.query(StudySession).count()}")
        config = {**TINY, "precision": "fp32", "device": "cpu", "conv_kernel": kernel}
        spec = RunSpec.from_json({"method": "oracle", "config": config})
        session = create_session(db, study.id, spec, threads=1)
        assert session.spec.config.conv_kernel == kernel  # a pinned choice stays
        set_status(db, session.id, Status.stopped, "stopped for the test")
        return session.id


def test_a_resume_where_the_kernel_does_not_run_is_refused_or_overridden_and_recorded(
    database: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session_id = _stopped_kernel_session(database)  # runs anywhere: it never computes avx2
    monkeypatch.setenv(machine.CONV_KERNEL_SWITCH, "on")
    monkeypatch.setattr(machine, "cpu_flags", lambda: frozenset({"sse2"}))  # a CPU without AVX2
    with pytest.raises(NumericsRefused, match="avx2 variant of the compiled convolutions") as no:
        run_session(session_id, database, WorkerOptions(data_dir=tmp_path / "data"))
    assert "override_numerics" in str(no.value)
    factory = make_session_factory(make_engine(database))
    with factory() as db:
        session = db.get(StudySession, session_id)
        assert session is not None and session.status == Status.stopped
        assert session.numerics_overrides == []

    status = run_session(session_id, database, WorkerOptions(
        data_dir=tmp_path / "data", override_numerics=True))  # fmt: skip
    assert status == "finished"
    with factory() as db:
        session = db.get(StudySession, session_id)
        assert session is not None
        [override] = session.numerics_overrides
        assert override["from"]["conv_kernel"] == "avx2:1-3"
        assert override["to"]["conv_kernel"] == "none"
        assert override["from"]["precision"] == override["to"]["precision"] == "fp32"
        assert "avx2" in override["why"]
        assert session.spec.config.conv_kernel == "none"
        export_study(db, session.study_id, tmp_path / "export")
    with (tmp_path / "export" / "sessions.csv").open() as f:
        import csv

        (row,) = list(csv.DictReader(f))
    assert json.loads(row["numerics_overrides"])[0]["to"]["conv_kernel"] == "none"
    [computed] = json.loads(row["provenance"])
    assert computed["numerics"]["conv_kernel"] == "none"


def test_a_session_pinned_to_the_kernel_resumes_with_it_where_it_runs(
    database: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    if not machine.conv_kernel_runs("avx2"):
        pytest.skip("the AVX2 kernel does not run here (no AVX2, or `make kernels` not run)")
    session_id = _stopped_kernel_session(database)
    monkeypatch.delenv(machine.CONV_KERNEL_SWITCH, raising=False)  # the pin decides, not it
    status = run_session(session_id, database, WorkerOptions(data_dir=tmp_path / "data"))
    assert status == "finished"
    with make_session_factory(make_engine(database))() as db:
        session = db.get(StudySession, session_id)
        assert session is not None and session.numerics_overrides == []
        [computed] = session.provenance
        assert computed["numerics"]["conv_kernel"] == "avx2:1-3"


def test_a_session_pinned_to_the_first_layer_kernel_alone_resumes_with_that_layer_alone(
    database: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run pinned to `avx2` (the first layer's kernel, the rest in PyTorch) resumes with
    that layer set where this code computes it; where it does not, the resume is refused,
    or overridden and recorded, from the layer set it was pinned to to the one it takes."""
    if not machine.conv_kernel_runs("avx2"):
        pytest.skip("the AVX2 kernel does not run here (no AVX2, or `make kernels` not run)")
    monkeypatch.setenv(machine.CONV_KERNEL_SWITCH, "on")
    first = _stopped_kernel_session(database, "avx2")
    assert run_session(first, database, WorkerOptions(data_dir=tmp_path / "a")) == "finished"
    factory = make_session_factory(make_engine(database))
    with factory() as db:
        session = db.get(StudySession, first)
        assert session is not None and session.numerics_overrides == []
        assert session.spec.config.conv_kernel == "avx2"
        [computed] = session.provenance
        assert computed["numerics"]["conv_kernel"] == "avx2"

    session_id = _stopped_kernel_session(database, "avx2")
    monkeypatch.setattr(machine, "CONV_KERNEL_LAYER_SETS", (frozenset({1, 2, 3}),))
    with pytest.raises(NumericsRefused, match=r"layers 1 \(conv_kernel avx2\)"):
        run_session(session_id, database, WorkerOptions(data_dir=tmp_path / "b"))
    status = run_session(session_id, database, WorkerOptions(
        data_dir=tmp_path / "b", override_numerics=True))  # fmt: skip
    assert status == "finished"
    with factory() as db:
        session = db.get(StudySession, session_id)
        assert session is not None
        [override] = session.numerics_overrides
        assert override["from"]["conv_kernel"] == "avx2"
        to = override["to"]  # all three layers, in the precision a run pinned here takes
        assert to["conv_kernel"] == machine.conv_kernel_for(to["precision"])
        assert machine.conv_kernel_parts(to["conv_kernel"])[1] == frozenset({1, 2, 3})
        assert "layers 1, 2, 3" in override["why"]
        [computed] = session.provenance
        assert computed["numerics"]["conv_kernel"] == to["conv_kernel"]


def test_ideeprl_train_refuses_to_resume_where_the_pinned_kernel_does_not_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    if not machine.conv_kernel_runs("avx2"):
        pytest.skip("the AVX2 kernel does not run here (no AVX2, or `make kernels` not run)")
    from cli.main import main
    from learner.checkpoint import read_checkpoint

    small = [f"--{k.replace('_', '-')}={v}" for k, v in TINY.items()]
    out = tmp_path / "run"
    pinned = ["--precision", "fp32", "--conv-kernel", "avx2"]
    assert main(["train", "--out", str(out), "--no-progress", *pinned, *small]) == 0
    checkpoint = out / "checkpoint.pt"
    assert read_checkpoint(checkpoint)["metadata"]["config"]["conv_kernel"] == "avx2"
    monkeypatch.setattr(machine, "cpu_flags", lambda: frozenset({"sse2"}))  # no AVX2
    assert main(["train", "--resume", str(checkpoint), "--episodes", "2", "--no-progress"]) == 2
    assert "avx2 variant" in capsys.readouterr().err
    code = main(["train", "--resume", str(checkpoint), "--episodes", "2", "--no-progress",
                 "--override-numerics"])  # fmt: skip
    assert code == 0 and "numerics overridden" in capsys.readouterr().err
