"""The authors' comparison through the real command line: a reward scheme per method, the
authors preset and realism stored with each session, and a report that flags the mismatch
and withholds the t-tests unless asked."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

pytestmark = pytest.mark.slow

AUTHORS = [
    "batch", "--study", "authors", "--methods", "autonomous", "agent", "--agents", "2",
    "--preset", "authors", "--per-method", "autonomous:reward_scheme=authors-autonomous",
    "--per-method", "agent:reward_scheme=authors-interactive", "--knock-off-rate", "0.1",
    "--workers", "2",
]  # fmt: skip


def test_schemes_per_method_and_the_report_flags_them(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, output = in_process(place, capsys, *AUTHORS, *SCALE)
    assert code == 0, output
    engine = place.engine()
    rows = sessions(engine, study_id(engine, "authors"))
    assert [s.status for s in rows] == ["finished"] * 5, [s.status_detail for s in rows]
    for s in rows:
        expected = "authors-interactive" if s.method == "agent" else "authors-autonomous"
        assert s.spec.scenario.to_dict() == {
            "reward_scheme": expected, "grasp_failure_rate": 0.0, "knock_off_rate": 0.1,
        }  # fmt: skip
        assert s.spec.config.fit == "keras" and s.spec.config.head == "softmax"
    # the same command again finds every run: nothing new is created
    code, output = in_process(place, capsys, *AUTHORS, *SCALE)
    assert code == 0 and len(sessions(engine, study_id(engine, "authors"))) == 5, output

    out = tmp_path / "strict"
    code, output = in_process(place, capsys, "report", "--study", "authors", "--out", str(out))
    assert code == 0, output
    assert "warning: autonomous DeepRL and agent-IDeepRL" in output
    text = (out / "report.md").read_text()
    assert text.split("\n\n")[1].startswith("> **Comparability warning.**")
    tests = pd.read_csv(out / "t_tests.csv")
    assert tests["p"].isna().all() and tests["withheld"].str.contains("reward scheme").all()
    rescored = pd.read_csv(out / "r_t_rescored.csv").set_index("method")
    assert rescored.loc["autonomous", "logged_under"] == "authors-autonomous"
    assert rescored.loc["agent", "logged_under"] == "authors-interactive"
    for method in ("autonomous", "agent"):
        row = rescored.loc[method]
        logged = "R_T_" + row["logged_under"]
        assert row["R_T_logged"] == pytest.approx(row[logged])

    out = tmp_path / "allowed"
    args = ["report", "--study", "authors", "--out", str(out), "--allow-mismatch"]
    code, output = in_process(place, capsys, *args, "--reference", "authors")
    assert code == 0, output
    assert pd.read_csv(out / "t_tests.csv")["p"].notna().all()
    assert "Comparability warning" in (out / "report.md").read_text()
    assert (out / "authors_reference.csv").is_file()
