"""The population benchmark's committed logs read back as the numbers they print, and drawn."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.plot_population_batch import plot, read_log

LOGS = Path(__file__).parent.parent / "benchmarks" / "logs"


def test_reads_the_summary_and_the_profile_of_a_log() -> None:
    run = read_log(LOGS / "population-batch-2026-12-04-avx2-quiet.log")
    assert run["kind"] == "AMD EPYC (no AVX-512)"
    assert run["rates"] == {1: (10.5, 1.0, 555), 2: (11.9, 1.13, 298), 4: (11.9, 1.13, 173)}
    assert run["parts"][4]["update"] == 79.11
    assert sum(run["parts"][1].values()) == pytest.approx(87.62, abs=0.02)


def test_a_log_without_a_summary_is_refused(tmp_path: Path) -> None:
    log = tmp_path / "population-batch-x.log"
    log.write_text("bench_population_batch  at 20261204T081829Z\nround 1, N=1: ...\n")
    with pytest.raises(SystemExit, match="no summary"):
        read_log(log)


def test_draws_every_kind(tmp_path: Path) -> None:
    logs = [
        LOGS / "population-batch-2026-12-03-quiet.log",
        LOGS / "population-batch-2026-12-04-avx2-quiet.log",
        LOGS / "population-batch-2026-12-04-avx2-padded.log",
    ]
    out = plot(logs, tmp_path / "population_batch.png")
    assert out.read_bytes().startswith(b"\x89PNG")
    svg = out.with_suffix(".svg").read_text()
    assert "AVX-512 BF16" in svg
    assert "2026-12-04-avx2-quiet" in svg and "2026-12-04-avx2-padded" in svg  # told apart
