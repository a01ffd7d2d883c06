"""The records fixture: short seeded runs of each method that has a run of its own
(autonomous, agent, oracle, and a person's advice replayed from a recorded stream), in
float32 on one thread, as the code recorded them in `tests/fixtures/records/`.

A change to the run (a task, a feedback kind, a kernel in the numerics) proves that old
records still come out the same by running these again (`tests/learner/test_records.py`).
`python -m tests.learner.records` records them anew on this CPU kind (the reference kind's
in the folder itself, another kind's in a folder of its own) and adds the kind to the list
of kinds they were checked on; do that only when a change is meant to alter the records,
or for a CPU kind that has none, and say why in its commit.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

from learner.advisors import RecordedAdvisor
from learner.machine import cpu_kind
from learner.records import StepRecord
from learner.run import RunSpec
from tests.learner.conftest import Recorder

FOLDER = Path(__file__).parents[1] / "fixtures" / "records"
ADVISOR = FOLDER / "advisor.pt"
"""The agent advisor: the autonomous run's learner at its end (weights only)."""
KINDS = FOLDER / "cpu_kinds.json"
"""The CPU kinds on which a fresh run matched the records."""
METHODS = ("autonomous", "agent", "oracle", "replayed")
CONFIG = {
    "pretraining_steps": 60,
    "advice_budget": 20,
    "episodes": 3,
    "max_episode_steps": 30,
    "batch_size": 16,
    "memory_size": 500,
    "epsilon_decay": 0.99,
    "update": "fast",
    "precision": "fp32",
    "conv_kernel": "none",
    "device": "cpu",
    "torch_threads": 1,
}
"""The paper's learner at a scale a test affords, its numerics pinned (float32, PyTorch's
first layer, one thread)."""
STREAM = [0, 1, 3, 0, 2, 3, 0, 0, 1, 3, 2, 2, 0, 1, 3, 0, 2, 3, 1, 0]
"""The person's recorded advice (20 choices, some of them wrong), fed by order."""
EXACT = (
    "global_step", "stage", "episode", "episode_step", "action", "action_source",
    "greedy_action", "advised_action", "advice_remaining", "reward", "terminated",
    "truncated", "outcome", "observation_hash", "epsilon",
)  # fmt: skip
"""What a run must repeat exactly."""
CLOSE = ("q_grab", "q_move_right", "q_move_left", "q_drop", "loss")
"""What it must repeat within rtol 1e-5 (floating point)."""


def spec(method: str) -> RunSpec:
    run: dict[str, Any] = {"method": method, "seed": 11, "config": CONFIG}
    if method == "agent":
        run["advisor_checkpoint"] = str(ADVISOR)
    if method == "oracle":
        run["error_rate"] = 0.2
    return RunSpec.from_json(run)


def run(method: str, save_advisor: Path | None = None) -> list[StepRecord]:
    """Every step of the method's run, as the code records it now."""
    recorder = Recorder()
    described = spec(method).validate()
    env = described.make_env()
    advisor = (
        RecordedAdvisor(STREAM, [None] * len(STREAM))
        if method == "replayed"
        else described.make_advisor()
    )
    trainer = described.make_trainer(env, advisor, [recorder])
    try:
        trainer.run()
        if save_advisor is not None:
            trainer.save_checkpoint(save_advisor, memory=False)  # type: ignore[call-arg]
    finally:
        env.close()
    return list(recorder.steps)


REFERENCE_KIND = "Intel(R) Xeon(R) Processor (AVX-512, AVX-512 BF16, AMX)"
"""The CPU kind the records in `FOLDER` itself were made on. float32 on another instruction
set rounds differently, and training carries the difference on until the learner ranks
two actions the other way (the EPYC with AVX-512 BF16: step 96 of the agent run); such a
kind's own records are in `FOLDER/<kind>/`."""


def kind_folder(kind: str) -> Path:
    words = "".join(c if c.isalnum() else " " for c in kind.lower()).split()
    return FOLDER / "-".join(words)


def path(method: str, kind: str = REFERENCE_KIND) -> Path:
    folder = FOLDER if kind == REFERENCE_KIND else kind_folder(kind)
    return folder / f"{method}.json"


def has_own(kind: str) -> bool:
    """Whether `kind` has records of its own (the reference kind's are `FOLDER`'s)."""
    return path(METHODS[0], kind).exists()


def read(method: str, kind: str = REFERENCE_KIND) -> list[dict[str, Any]]:
    return json.loads(path(method, kind).read_text())  # type: ignore[no-any-return]


def checked_kinds() -> list[str]:
    return json.loads(KINDS.read_text()) if KINDS.exists() else []  # type: ignore[no-any-return]


def record_all() -> None:
    """Records this CPU kind's runs: the reference records (and the advisor) on the
    reference kind, that kind's own folder on another (`--kind`, the advisor kept)."""
    kind = cpu_kind()
    reference = kind == REFERENCE_KIND
    path(METHODS[0], kind).parent.mkdir(parents=True, exist_ok=True)
    for method in METHODS:
        keep = ADVISOR if method == "autonomous" and reference else None
        steps = run(method, save_advisor=keep)
        rows = [dataclasses.asdict(s) for s in steps]
        path(method, kind).write_text(json.dumps(rows, indent=0) + "\n")
        print(f"{method}: {len(rows)} steps", file=sys.stderr)
    KINDS.write_text(json.dumps(sorted({*checked_kinds(), cpu_kind()}), indent=1) + "\n")


if __name__ == "__main__":
    record_all()
