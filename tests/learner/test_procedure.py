"""The procedure control follows its advised run's procedure step by step: the same steps
take advice (random actions instead of the advisor's), the same pretraining steps are
followed by a fit, and epsilon is the same at every recorded step."""

from __future__ import annotations

from pathlib import Path

import pytest

from learner.procedure import Schedule
from learner.run import RunSpec, RunSpecError

TINY = {
    "episodes": 4,
    "max_episode_steps": 30,
    "pretraining_steps": 60,
    "advice_budget": 20,
    "batch_size": 8,
    "memory_size": 500,
    "torch_threads": 1,
    # the authors' options that make advice change the procedure: fits during advice, none
    # on an episode's final step
    "update_during_advice": True,
    "update_on_final_step": False,
}


def _records(spec: RunSpec) -> list:
    trainer, env = spec.build()
    try:
        records = []
        while not trainer.done:
            records.append(trainer.step())
        return records
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("strategy", ["early", "alternating"])
def test_the_control_repeats_the_advised_runs_schedule(tmp_path: Path, strategy: str) -> None:
    advised = RunSpec.from_json(
        {"method": "oracle", "seed": 3, "strategy": strategy, "config": TINY}
    )
    original = _records(advised)
    schedule = Schedule.from_steps(
        ((r.global_step, r.stage, r.action_source, r.loss, r.epsilon) for r in original),
        TINY["pretraining_steps"],
        "test",
    )
    path = schedule.save(tmp_path / "schedule.json")
    assert Schedule.load(path) == schedule
    control = _records(advised.replace(method="procedure", schedule=str(path)))

    common = min(len(original), len(control))

    def advice(records: list) -> list[int]:
        return [r.global_step for r in records[:common] if r.action_source == "advisor"]

    def fits(records: list) -> list[int]:
        return [r.global_step for r in records if r.stage == "pretrain" and r.loss is not None]

    assert advice(control) == advice(original) and len(advice(original)) == TINY["advice_budget"]
    assert fits(control) == fits(original)
    assert bool(fits(original)) == (strategy == "early")  # advice in pretraining is fitted
    assert [r.epsilon for r in control[:common]] == [r.epsilon for r in original[:common]]
    # uninformed actions: the control's advised actions are not the oracle's
    differ = [
        (a.action, b.action)
        for a, b in zip(original, control, strict=False)
        if a.action_source == "advisor" and a.action != b.action
    ]
    assert differ


def test_a_control_needs_its_schedule_and_only_a_control_takes_one(tmp_path: Path) -> None:
    with pytest.raises(RunSpecError, match="method procedure needs schedule"):
        RunSpec.from_json({"method": "procedure"}).validate()
    with pytest.raises(RunSpecError, match="only method procedure takes a schedule"):
        RunSpec.from_json({"method": "oracle", "schedule": "x.json"}).validate()
    missing = RunSpec.from_json({"method": "procedure", "schedule": str(tmp_path / "no.json")})
    with pytest.raises(RunSpecError, match="no schedule at"):
        missing.make_schedule()


def _judged(spec: RunSpec) -> tuple[list, dict[int, float]]:
    """A judged run's records and its judgements by step (an answer given)."""
    trainer, env = spec.build()
    try:
        records, judged = [], {}
        while not trainer.done:
            records.append(trainer.step())
            last = trainer.last_judgement  # type: ignore[union-attr]
            if last is not None and last[0] == records[-1].global_step and last[1] is not None:
                judged[last[0]] = last[1]
        return records, judged
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("strategy", ["early", "alternating"])
def test_the_control_of_a_judged_run_is_judged_uninformed_at_its_judged_steps(
    tmp_path: Path, strategy: str
) -> None:
    judged_run = RunSpec.from_json(
        {"method": "oracle", "feedback": "evaluative", "seed": 3, "strategy": strategy,
         "config": TINY}
    )  # fmt: skip
    original, judgements = _judged(judged_run)
    schedule = Schedule.from_steps(
        ((r.global_step, r.stage, r.action_source, r.loss, r.epsilon) for r in original),
        TINY["pretraining_steps"],
        "test",
        judgements,
    )
    assert schedule.judged == frozenset(judgements) and not schedule.advised
    path = schedule.save(tmp_path / "schedule.json")
    assert Schedule.load(path) == schedule
    control_spec = judged_run.replace(method="procedure", schedule=str(path)).validate()
    assert control_spec.feedback == "evaluative"
    control, uninformed = _judged(control_spec)

    def fits(records: list) -> list[int]:
        return [r.global_step for r in records if r.stage == "pretrain" and r.loss is not None]

    assert sorted(uninformed) == sorted(judgements) and len(judgements) == TINY["advice_budget"]
    assert fits(control) == fits(original) and bool(fits(original)) == (strategy == "early")
    common = min(len(original), len(control))
    assert [r.epsilon for r in control[:common]] == [r.epsilon for r in original[:common]]
    assert all(r.action_source != "advisor" for r in control)  # its own actions, judged
    # uninformed: the same actions judged otherwise than the oracle judged them
    assert set(uninformed.values()) <= {1.0, -1.0}
    same_action = [s for s in judgements if original[s - 1].action == control[s - 1].action]
    assert any(uninformed[s] != judgements[s] for s in same_action)
