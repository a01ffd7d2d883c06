"""Evaluative feedback (reward shaping): the learner takes its own actions, an evaluator
judges them on the strategy's steps, and the memory keeps the environment's reward plus
the weighted judgement."""

from __future__ import annotations

import numpy as np
import pytest

from learner import Trainer
from learner.advisors import OracleAdvisor
from learner.evaluators import AdvisorEvaluator
from learner.run import RunSpec, RunSpecError
from learner.strategies import AdviceMoment, make_strategy
from tests.learner.conftest import Recorder, small_config


class Scripted:
    """Judges by a script, in turn (None: no answer), keeping every moment it was shown."""

    def __init__(self, script: list[float | None]) -> None:
        self.script = script
        self.moments: list[AdviceMoment] = []

    def judge_at(self, moment: AdviceMoment) -> float | None:
        self.moments.append(moment)
        return self.script[(len(self.moments) - 1) % len(self.script)]


def _run(make_env, strategy: str = "early", **trainer_options) -> tuple[Trainer, Recorder]:
    """A short run judged or advised as `trainer_options` say (neither: autonomous)."""
    recorder = Recorder()
    config = small_config()
    given = trainer_options and make_strategy(strategy, config.advice_budget)
    trainer = Trainer(
        make_env(), config, strategy=given or None, seed=4, callbacks=[recorder],
        **trainer_options,
    )  # fmt: skip
    trainer.run()
    return trainer, recorder


def test_the_remembered_reward_is_the_environments_plus_the_weighted_judgement(make_env) -> None:
    evaluator = Scripted([1.0, -1.0, None, 0.5])
    trainer, recorder = _run(make_env, evaluator=evaluator, feedback_weight=0.25)
    script = evaluator.script * 5
    judged = {m.global_step: j for m, j in zip(evaluator.moments, script, strict=True)}
    assert sorted(judged) == list(range(41, 61))  # early: the last 20 pretraining steps
    assert len(recorder.steps) < trainer.memory.capacity  # every transition still there
    for step in recorder.steps:
        judgement = judged.get(step.global_step)
        shaped = step.reward + (0.0 if judgement is None else 0.25 * judgement)
        assert trainer.memory.rewards[step.global_step - 1] == np.float32(shaped), step
    shaped_steps = [s for s, j in judged.items() if j]
    rewards = trainer.memory.rewards
    assert any(rewards[s - 1] != recorder.steps[s - 1].reward for s in shaped_steps)
    # the records are the environment's: rewards, collected rewards, no advice
    collected = sum(e.collected_reward for e in recorder.episodes if e.stage == "train")
    assert collected == pytest.approx(sum(s.reward for s in recorder.steps if s.stage == "train"))
    assert trainer.strategy is not None and trainer.strategy.remaining == 0


def test_the_learners_own_action_is_taken_and_judged(make_env) -> None:
    evaluator = Scripted([-1.0])
    _, judged_run = _run(make_env, evaluator=evaluator)
    _, alone = _run(make_env)
    by_step = {s.global_step: s for s in judged_run.steps}
    for moment in evaluator.moments:
        step = by_step[moment.global_step]
        assert step.action == moment.intended_action and step.action_source == "random"
    assert all(s.advised_action is None for s in judged_run.steps)
    assert {s.action_source for s in judged_run.steps} <= {"random", "greedy", "exploration"}
    # pretraining takes the same random actions as a run without feedback (no fits in it)
    pretraining = [s.action for s in alone.steps if s.stage == "pretrain"]
    assert [s.action for s in judged_run.steps if s.stage == "pretrain"] == pretraining


def test_evaluators_get_the_steps_advice_would_get(make_env) -> None:
    class Advisor:
        def __init__(self) -> None:
            self.steps: list[int] = []

        def advise_at(self, moment: AdviceMoment) -> int:
            self.steps.append(moment.global_step)
            return 0

    advisor, evaluator = Advisor(), Scripted([1.0])
    _run(make_env, "alternating", advisor=advisor)
    _run(make_env, "alternating", evaluator=evaluator)
    assert [m.global_step for m in evaluator.moments] == advisor.steps
    assert len(advisor.steps) == 20 and advisor.steps[0] == 61


def test_the_oracle_evaluator_judges_good_the_correct_action_only() -> None:
    class Fixed:
        def advise(self, obs, info) -> int:
            return 2

    obs = np.zeros((64, 64, 3), np.uint8)
    right = AdvisorEvaluator(Fixed(), seed=1)
    assert [right.judge(obs, {}, a) for a in range(4)] == [-1.0, -1.0, 1.0, -1.0]
    wrong = AdvisorEvaluator(Fixed(), error_rate=1.0, seed=1)
    assert [wrong.judge(obs, {}, a) for a in range(4)] == [1.0, 1.0, -1.0, 1.0]
    noisy = AdvisorEvaluator(Fixed(), error_rate=0.25, seed=1)
    flipped = np.mean([noisy.judge(obs, {}, 2) == -1.0 for _ in range(4000)])
    assert abs(flipped - 0.25) < 0.03


def test_the_grid_worlds_oracle_judges_every_move_nearer_good_and_errs_only_off_them() -> None:
    """Where right and down both bring the agent nearer the goal, the oracle evaluator calls
    both good and the others bad; the oracle advisor, erring, names a move that is not
    right (a move as short would be no mistake)."""
    from tasks import get_task

    task = get_task("gridworld")
    env = task.env({}, 250, False)
    obs = np.zeros((64, 64, 3), np.uint8)
    states = [env.reset(seed=seed)[1] for seed in range(8)]
    both = [info for info in states if info["correct_actions"] == [1, 2]]
    assert both, "some start is above and left of the goal"
    judge = AdvisorEvaluator(OracleAdvisor(task=task), seed=1)
    for info in both:
        assert [judge.judge(obs, info, a) for a in range(4)] == [-1.0, 1.0, 1.0, -1.0]
    erring = OracleAdvisor(task=task, error_rate=1.0, seed=3)
    named = [erring.advise(obs, info) for info in both for _ in range(50)]
    assert set(named) == {0, 3}, "every mistake is a move away from the goal"


def test_an_oracle_run_judges_the_correct_action_good(make_env) -> None:
    oracle = OracleAdvisor()
    judgements: list[tuple[bool, float | None]] = []

    class Watched(AdvisorEvaluator):
        def judge(self, obs, info, action):
            judged = super().judge(obs, info, action)
            judgements.append((action == oracle.advise(obs, info), judged))
            return judged

    _run(make_env, evaluator=Watched(OracleAdvisor(), seed=0))
    assert len(judgements) == 20 and {good for good, _ in judgements} == {True, False}
    assert all((judged == 1.0) == good for good, judged in judgements)


def test_a_run_declares_its_feedback_kind() -> None:
    assert RunSpec().feedback == "advice" and RunSpec().to_json()["feedback"] == "advice"
    spec = RunSpec.from_json({"method": "oracle", "feedback": "evaluative", "error_rate": 0.1})
    spec = spec.validate()
    assert spec.make_advisor() is None
    evaluator = spec.make_evaluator()
    assert isinstance(evaluator, AdvisorEvaluator) and evaluator.error_rate == 0.1
    assert isinstance(evaluator.advisor, OracleAdvisor) and evaluator.advisor.error_rate == 0.0
    assert RunSpec(method="oracle").make_evaluator() is None
    person = RunSpec(method="human", feedback="evaluative", rating_time_out_s=4.0).validate()
    assert person.make_evaluator() is None and person.rating_time_out_s == 4.0  # the worker's
    assert RunSpec(method="human", rating_time_out_s=4.0).validate().rating_time_out_s == 10
    replayed = RunSpec(method="replayed", feedback="evaluative").validate()
    assert replayed.feedback == "evaluative" and replayed.make_evaluator() is None  # the stream's
    unadvised = RunSpec(method="autonomous", feedback="evaluative", feedback_weight=3.0)
    assert unadvised.validate().feedback == "advice" and unadvised.validate().feedback_weight == 1
    for changes, field in [
        ({"method": "random"}, "feedback"),
        ({"method": "agent", "advisor_checkpoint": "x.pt", "strategy": "mistake_correcting"},
         "strategy"),
    ]:  # fmt: skip
        with pytest.raises(RunSpecError) as error:
            RunSpec(feedback="evaluative", **changes).validate()  # type: ignore[arg-type]
        assert error.value.field == field


def test_an_evaluator_cannot_take_a_strategy_that_decides_by_the_advisors_action(
    make_env,
) -> None:
    with pytest.raises(ValueError, match="mistake_correcting"):
        Trainer(
            make_env(), small_config(), strategy=make_strategy("mistake_correcting", 5),
            evaluator=Scripted([1.0]),
        )  # fmt: skip


def test_a_judged_run_resumed_from_its_checkpoint_goes_on_as_if_never_stopped(
    make_env, tmp_path
) -> None:
    def build(recorder: Recorder) -> Trainer:
        # an erring oracle evaluator: its random state must resume too
        evaluator = AdvisorEvaluator(OracleAdvisor(), error_rate=0.3, seed=8)
        return Trainer(
            make_env(), small_config(), strategy=make_strategy("early", 20), seed=6,
            callbacks=[recorder], evaluator=evaluator,
        )  # fmt: skip

    whole = Recorder()
    uninterrupted = build(whole)
    uninterrupted.run()
    before, after = Recorder(), Recorder()
    first = build(before)
    for _ in range(50):  # inside the window (steps 41 to 60)
        first.step()
    first.save_checkpoint(tmp_path / "run.pt")
    second = build(after)
    second.load_checkpoint(tmp_path / "run.pt")
    second.run()
    assert [r.to_dict() for r in before.steps + after.steps] == [r.to_dict() for r in whole.steps]
    added = uninterrupted.memory.added
    assert second.memory.added == added
    assert (second.memory.rewards[:added] == uninterrupted.memory.rewards[:added]).all()
