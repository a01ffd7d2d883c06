"""The batch checks the agent runs' advisor before it advises: a given one that fails is
refused; a trained one that fails is trained again from the next seed, every attempt kept."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from learner.advisor_check import check_path
from tests.runs.batch.helpers import SCALE, Place, in_process, sessions, study_id

STUCK = Path(__file__).absolute().parents[3] / "docs/results/replication/state/advisor-authors.pt"
REQUIRE = [a for a in SCALE if a not in ("--advisor-check", "record")]
"""The reduced scale with the default rule: a failing advisor is refused."""


def test_a_given_advisor_that_fails_its_check_is_refused(
    place: Place, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    checkpoint = tmp_path / "stuck.pt"
    shutil.copy(STUCK, checkpoint)
    args = ["batch", "--study", "stuck advisor", "--methods", "agent", "--agents", "1"]
    code, out = in_process(place, capsys, *args, *REQUIRE, "--advisor-checkpoint", str(checkpoint))
    assert code == 2 and "failed its check" in out and "--advisor-check record" in out
    assert check_path(checkpoint).is_file()  # the evaluation is kept beside the checkpoint
    assert sessions(place.engine(), study_id(place.engine(), "stuck advisor")) == []


@pytest.mark.slow
def test_a_trained_advisor_that_fails_is_trained_again_from_the_next_seed(
    place: Place, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["batch", "--study", "retrained", "--methods", "agent", "--agents", "1"]
    code, out = in_process(place, capsys, *args, *REQUIRE, "--advisor-attempts", "2")
    # at this scale no advisor can pass: two are trained (seeds 100000, 100001), then it stops
    assert code == 2 and "2 trained advisors failed their check" in out, out
    assert "training the advisor of seed 100001" in out
    runs = sessions(place.engine(), study_id(place.engine(), "retrained"))
    assert sorted(s.seed for s in runs) == [100000, 100001]
    assert all(s.status == "finished" and check_path(s.checkpoint_path).is_file() for s in runs)
    # run again: the attempts are found, not trained again, and it stops the same way
    code, again = in_process(place, capsys, *args, *REQUIRE, "--advisor-attempts", "2")
    assert code == 2 and "2 trained advisors failed" in again
    assert len(sessions(place.engine(), study_id(place.engine(), "retrained"))) == 2
