"""`ideeprl train` as a person runs it: a real process writing real files."""

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from cli.main import main
from learner.checkpoint import read_checkpoint

SMALL = [
    "--set", "pretraining_steps=60", "--set", "batch_size=16", "--set", "memory_size=500",
    "--set", "max_episode_steps=30", "--set", "advice_budget=20", "--no-progress",
]  # fmt: skip


def train(*args: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "cli", "train", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=300)


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.mark.slow
def test_train_writes_records_plot_and_checkpoint_and_resumes(tmp_path: Path) -> None:
    out = tmp_path / "run"
    done = train("--out", str(out), "--episodes", "2", "--method", "oracle", *SMALL)
    assert done.returncode == 0, done.stderr
    assert "R_T" in done.stdout
    steps, episodes = rows(out / "steps.csv"), rows(out / "episodes.csv")
    assert [r["episode"] for r in episodes if r["stage"] == "train"] == ["1", "2"]
    assert [int(r["global_step"]) for r in steps] == list(range(1, len(steps) + 1))
    assert sum(r["action_source"] == "advisor" for r in steps) == 20
    assert (out / "learning_curve.png").read_bytes()[:4] == b"\x89PNG"
    state = read_checkpoint(out / "checkpoint.pt")
    assert state["global_step"] == len(steps) and state["metadata"]["method"] == "oracle"

    more = train("--resume", str(out / "checkpoint.pt"), "--episodes", "3", "--no-progress")
    assert more.returncode == 0, more.stderr
    steps_after = rows(out / "steps.csv")
    assert steps_after[: len(steps)] == steps
    assert [int(r["global_step"]) for r in steps_after] == list(range(1, len(steps_after) + 1))
    assert [r["episode"] for r in rows(out / "episodes.csv") if r["stage"] == "train"] == [
        "1", "2", "3",
    ]  # fmt: skip


@pytest.mark.slow
def test_train_runs_the_scenario_options_it_is_given(tmp_path: Path) -> None:
    """--reward-scheme and the realism rates reach the scene: under authors-interactive a
    step without a placement costs -0.01 from the first step (the paper's rule: 0 up to
    step 18), and the checkpoint records the options."""
    small = [("advice_budget=0" if a == "advice_budget=20" else a) for a in SMALL]
    for scheme, first_cost in (("authors-interactive", -0.01), ("paper", 0.0)):
        out = tmp_path / scheme
        done = train(
            "--out", str(out), "--episodes", "1", "--reward-scheme", scheme,
            "--grasp-failure-rate", "0.5", "--knock-off-rate", "0.2", *small,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        first = rows(out / "steps.csv")[0]
        assert first["episode_step"] == "1" and float(first["reward"]) == first_cost
        scenario = read_checkpoint(out / "checkpoint.pt")["metadata"]["scenario"]
        assert scenario == {
            "reward_scheme": scheme, "grasp_failure_rate": 0.5, "knock_off_rate": 0.2,
        }  # fmt: skip


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--set", "gamma=2"], "gamma must be a number from 0 to 1"),
        (["--set", "epsilon=0.1"], "unknown field epsilon"),
        (["--method", "agent"], "advisor_checkpoint"),
        (["--resume", "no-such-file.pt"], "no checkpoint at no-such-file.pt"),
    ],
)
def test_train_explains_bad_arguments(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    assert main(["train", "--out", str(tmp_path), *args]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "steps.csv").exists()


def test_ideeprl_lists_the_train_command() -> None:
    from cli.main import build_parser

    args = build_parser().parse_args(["train", "--episodes", "5", "--method", "random"])
    assert args.command == "train" and args.func.__module__ == "cli.commands.train"
    assert args.spec__episodes == 5 and args.spec__method == "random"
