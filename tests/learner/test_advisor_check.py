"""The advisor check (SPEC section 5): a stuck advisor is refused, from the states where it
would advise; a working one is not; the check is stored beside its checkpoint."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from learner.advisor_check import (
    AdviceQuality,
    AdvisorCheckFailed,
    check_path,
    checked_advisor,
    longest_repeat,
    stored_check,
)
from learner.run import RunSpec

STATE = Path(__file__).absolute().parents[2] / "docs/results/replication/state"


def _authors(checkpoint: Path) -> RunSpec:
    """The replication's (a) agent runs: the authors' learner, scene and advised arm's rule."""
    return RunSpec.from_json(
        {
            "method": "agent",
            "preset": "authors",
            "seed": 0,
            "advisor_checkpoint": str(checkpoint),
            "scenario": {
                "reward_scheme": "authors-interactive",
                "grasp_failure_rate": 0.05,
                "knock_off_rate": 0.05,
            },
            "config": {"torch_threads": 1},
        }
    )


def test_longest_repeat_and_quality_count_what_the_advice_did() -> None:
    assert longest_repeat([]) == 0
    assert longest_repeat([0, 0, 1, 1, 1, 0]) == 3
    quality = AdviceQuality.of([0, 0, 3, 1], ["none", "none", "placed", "lost"])
    assert (quality.advice, quality.placed, quality.misplaced, quality.lost) == (4, 1, 0, 1)
    assert quality.longest_repeat == 2


@pytest.mark.slow
def test_the_replications_stuck_authors_advisor_is_refused(tmp_path: Path) -> None:
    """The committed `authors` advisor of the replication, checked as its advised runs used
    it (seed 0): from the state where it advised it grabbed 89 times in a row and placed 4
    objects in 100 advice, as the review counted from the step logs."""
    checkpoint = tmp_path / "advisor-authors.pt"
    shutil.copy(STATE / "advisor-authors.pt", checkpoint)
    spec = _authors(checkpoint)
    with pytest.raises(AdvisorCheckFailed, match="failed its check"):
        checked_advisor(checkpoint, spec, advice_seeds=[0], episodes=2)
    check = stored_check(checkpoint, spec, [0], episodes=2)
    assert check is not None and not check.passed and check_path(checkpoint).is_file()
    (quality,) = check.at_advice
    assert quality.advice == 100 and quality.placed == 4 and quality.longest_repeat == 89
    assert any("advice-time states of seed 0" in p for p in check.problems)
    # allowed explicitly, the stored check is returned (not evaluated again) and not raised
    again = checked_advisor(checkpoint, spec, advice_seeds=[0], episodes=2, allow_failed=True)
    assert again == check
    # another run (other seeds) is another check
    assert stored_check(checkpoint, spec, [1], episodes=2) is None


@pytest.mark.slow
def test_the_paper_advisor_advises_like_a_working_policy(tmp_path: Path) -> None:
    checkpoint = tmp_path / "advisor-paper.pt"
    shutil.copy(STATE / "advisor-paper.pt", checkpoint)
    spec = RunSpec.from_json(
        {"method": "agent", "seed": 0, "advisor_checkpoint": str(checkpoint),
         "config": {"torch_threads": 1}}
    )  # fmt: skip
    check = checked_advisor(checkpoint, spec, advice_seeds=[0], episodes=1, allow_failed=True)
    (quality,) = check.at_advice
    assert quality.placed >= 30 and quality.misplaced == 0 and quality.longest_repeat <= 10
    assert not any("advice-time" in p for p in check.problems)


def test_a_grid_world_advisors_check_speaks_of_its_tasks_measures(tmp_path: Path) -> None:
    """The grid world counts no placements: its check's message gives the fresh episodes'
    success rate and the advice's repeats, never the robot's placed, misplaced and lost."""
    config = {"episodes": 1, "pretraining_steps": 30, "advice_budget": 10, "batch_size": 8,
              "memory_size": 100, "max_episode_steps": 20, "torch_threads": 1}  # fmt: skip
    trained = RunSpec.from_json({"task": "gridworld", "method": "autonomous", "config": config})
    trainer, _ = trained.build()
    while not trainer.done:
        trainer.step()
    checkpoint = tmp_path / "advisor-grid.pt"
    trainer.save_checkpoint(checkpoint, trained.to_json(), memory=False)
    spec = trained.replace(method="agent", advisor_checkpoint=str(checkpoint))
    check = checked_advisor(checkpoint, spec, advice_seeds=[0], episodes=3, allow_failed=True)
    (quality,) = check.at_advice
    assert quality.advice == 10 and not check.placements
    assert check.success_rate is not None and 0.0 <= check.success_rate <= 1.0
    summary = check.summary()
    assert f"success rate {check.success_rate:.2f}" in summary
    assert "in 10 advice" in summary
    assert not any(word in summary for word in ("placed", "misplaced", "lost"))
    assert stored_check(checkpoint, spec, [0], episodes=3) == check  # read back as stored
