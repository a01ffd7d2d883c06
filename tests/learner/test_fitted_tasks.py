"""Advisors fitted to people in a task other than the sorting robot: without declared
situations the model is by the run's stage within the correct action, and the fitted
advisor advises that task's actions, wrong where its people were."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from learner.fitted import AdviceSeen, FittedAdvisor, FittedModel, SessionAdvice, fit, situation
from learner.run import RunSpec, RunSpecError
from tasks import get_task

LINE = "tests.tasks.line:line_task"
WRONG_RATE = 0.4
"""The generating people's error rate where action `HARD` is right in pretraining; else none."""
HARD = 1
"""The action whose situations the people get wrong (the grid world's "right", the line's
step -1), advising action 0 instead."""


def recorded(task_name: str, n_advice: int, seed: int = 0) -> list[SessionAdvice]:
    """Advice as a study records it: people advise every step of the real environment, the
    first half of each session in pretraining, the rest in training."""
    task = get_task(task_name)
    env = task.env(None, 30, False)
    rng = np.random.default_rng(seed)
    seen: list[AdviceSeen] = []
    episode = 0
    _, info = env.reset(seed=episode)
    while len(seen) < n_advice:
        stage = "pretrain" if len(seen) % 100 < 50 else "train"
        correct = task.correct(info, {})
        assert correct is not None
        wrong = correct == HARD and stage == "pretrain" and rng.random() < WRONG_RATE
        advised = 0 if wrong else correct
        seen.append(AdviceSeen(*situation(task, info, stage, correct), correct, advised, 1.0))
        _, _, terminated, truncated, info = env.step(advised)
        if terminated or truncated:
            episode += 1
            _, info = env.reset(seed=episode)
    env.close()
    return [SessionAdvice(i, seen[i : i + 100], 100) for i in range(0, n_advice, 100)]


@pytest.mark.parametrize("task_name", [LINE, "gridworld"])
def test_a_model_fitted_in_another_task_is_by_stage_within_the_correct_action(
    task_name: str,
) -> None:
    task = get_task(task_name)
    hard = task.action_words[HARD]
    model = FittedModel.from_json(json.loads(json.dumps(fit(recorded(task_name, 3000),
                                                            task=task).to_json())))  # fmt: skip
    assert model.task == task_name and model.n_actions == task.n_actions
    assert model.places == ["pretrain", "train"] and model.groups == list(task.action_words)
    assert model.by_situation[f"pretrain/{hard}"].advice >= 30
    assert abs(model.error_rate("pretrain", hard) - WRONG_RATE) < 0.15
    assert model.error_rate("train", hard) < model.error_rate("pretrain", hard) / 2
    other = max(
        (a for a in range(task.n_actions) if a != HARD), key=model.correct_actions.__getitem__
    )
    assert model.by_group[task.action_words[other]].advice >= 500  # often right, never wrong:
    assert model.error_rate("pretrain", task.action_words[other]) < 0.05
    assert (
        model.wrong_actions[HARD][0] > 0
        and sum(map(sum, model.wrong_actions)) == (model.wrong_actions[HARD][0])
    )
    summary = model.summary()
    assert summary["task"] == task_name
    assert set(summary["error_rate_by_situation"]) == {
        f"{p}/{w}" for p in ("pretrain", "train") for w in task.action_words
    }


def test_the_fitted_advisor_advises_the_tasks_actions_wrong_where_its_people_were() -> None:
    task = get_task(LINE)
    model = fit(recorded(LINE, 3000), task=task)
    advisor = FittedAdvisor(model, seed=3, task=task)
    wrong: dict[tuple[str, int], float] = {}
    for stage in ("pretrain", "train"):
        for correct in range(task.n_actions):
            info = {"correct_action": correct}  # the ground truth the line task states
            advised = [advisor.advise_in(info, stage) for _ in range(300)]
            assert set(advised) <= set(range(task.n_actions))
            wrong[stage, correct] = sum(a != correct for a in advised) / 300
    assert 0.2 < wrong["pretrain", HARD] < 0.6
    assert wrong["train", HARD] < wrong["pretrain", HARD] / 2
    often = max((a for a in range(5) if a != HARD), key=model.correct_actions.__getitem__)
    assert wrong["pretrain", often] < 0.05 and wrong["train", often] < 0.05
    # shown no ground truth (a page of frames), it names actions as its people did
    blind = [advisor.advise_in(None, "pretrain") for _ in range(500)]
    assert set(blind) <= set(range(task.n_actions)) and len(set(blind)) >= 3


def test_a_fitted_run_in_the_line_task_is_advised_with_its_five_actions(tmp_path: Any) -> None:
    path = tmp_path / "line.json"
    path.write_text(json.dumps(fit(recorded(LINE, 300), task=get_task(LINE)).to_json()))
    config = {"episodes": 2, "pretraining_steps": 40, "advice_budget": 30, "batch_size": 8,
              "memory_size": 200, "max_episode_steps": 25, "torch_threads": 1}  # fmt: skip
    spec = RunSpec.from_json(
        {"task": LINE, "method": "fitted", "fitted_model": str(path), "config": config}
    )
    trainer, _ = spec.build()
    records = []
    while not trainer.done:
        records.append(trainer.step())
    advised = [r.advised_action for r in records if r.advised_action is not None]
    assert len(advised) == 30 and set(advised) <= set(range(5))
    assert len(set(advised)) >= 2
    # a model of one task cannot advise a run of another
    other = RunSpec.from_json({"task": "gridworld", "method": "fitted",
                               "fitted_model": str(path), "config": config})  # fmt: skip
    with pytest.raises(RunSpecError, match=r"of task tests\.tasks\.line:line_task"):
        other.validate().make_advisor()
