"""Evaluative feedback's second learner method: a model of the rating, trained on the
judgements received, shapes the steps nobody judged (TAMER+RL, Deep TAMER)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from learner import Trainer
from learner.rating_model import RatingModel, features
from learner.run import RunSpec, RunSpecError
from learner.strategies import AdviceMoment, make_strategy
from tests.learner.conftest import Recorder, small_config


class Scripted:
    """Judges by a script, in turn (None: no answer), keeping every moment it was shown;
    its place in the script is checkpointed."""

    def __init__(self, script: list[float | None]) -> None:
        self.script = script
        self.moments: list[AdviceMoment] = []
        self.given = 0

    def judge_at(self, moment: AdviceMoment) -> float | None:
        self.moments.append(moment)
        self.given += 1
        return self.script[(self.given - 1) % len(self.script)]

    def state_dict(self) -> dict[str, int]:
        return {"given": self.given}

    def load_state_dict(self, state: dict[str, int]) -> None:
        self.given = int(state["given"])


class Seen(gym.Wrapper):
    """Keeps the observation each action was taken on."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.taken: list[tuple[np.ndarray, int]] = []

    def reset(self, **kwargs):
        self.obs, info = self.env.reset(**kwargs)
        return self.obs, info

    def step(self, action):
        self.taken.append((self.obs, int(action)))
        self.obs, *rest = self.env.step(action)
        return (self.obs, *rest)


def _run(make_env, evaluator, strategy="early", **options) -> tuple[Trainer, Recorder, Seen]:
    recorder, env = Recorder(), Seen(make_env())
    config = small_config()
    trainer = Trainer(
        env, config, strategy=make_strategy(strategy, config.advice_budget), seed=4,
        callbacks=[recorder], evaluator=evaluator, feedback_weight=0.5, **options,
    )  # fmt: skip
    trainer.run()
    return trainer, recorder, env


def _image(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (64, 64, 3), dtype=np.uint8)


def test_the_models_prediction_moves_toward_the_ratings_it_is_given() -> None:
    model = RatingModel(4, (64, 64, 3))
    good, bad = _image(1), _image(2)
    assert [model.predict(good, a) for a in range(4)] == [0.0] * 4  # nothing rated yet
    before = [model.predict(good, 2), model.predict(bad, 2)]
    for step in range(5):
        model.learn(good, 2, 1.0, step)
        model.learn(bad, 2, -1.0, step)
    assert model.predict(good, 2) > before[0] + 0.5 and model.predict(bad, 2) < before[1] - 0.5
    assert model.predict(good, 1) == 0.0  # an action never rated shapes nothing
    assert model.ratings == 10 and model.last_rated_step == 4
    assert features(good).shape == (8 * 8 * 3 + 1,)
    vector = RatingModel(2, (4,))
    for step in range(20):
        vector.learn(np.array([1.0, 0.0, 0.5, -0.5], np.float32), 0, -1.0, step)
    assert vector.predict(np.array([1.0, 0.0, 0.5, -0.5], np.float32), 0) < -0.9


def test_the_model_shapes_the_steps_not_judged(make_env) -> None:
    evaluator = Scripted([1.0, -1.0, None, 1.0, -1.0])
    trainer, recorder, env = _run(make_env, evaluator, feedback_method="rating_model")
    assert trainer.rating_model is not None
    judged = {
        m.global_step: j for m, j in zip(evaluator.moments, evaluator.script * 4, strict=True)
    }
    assert sorted(judged) == list(range(41, 61))
    # the model the run ends with: trained on the judgements given, in order
    expected = RatingModel(trainer.n_actions, env.observation_space.shape)
    for moment in evaluator.moments:
        if judged[moment.global_step] is not None:
            expected.learn(moment.obs, moment.intended_action, judged[moment.global_step], 0)
    assert trainer.rating_model.ratings == 16
    np.testing.assert_allclose(trainer.rating_model.state_dict()["weights"], expected._weights)
    rewards = trainer.memory.rewards
    moved = 0
    for step in recorder.steps:
        obs, action = env.taken[step.global_step - 1]
        assert action == step.action
        index = step.global_step - 1
        if step.global_step <= 40:  # before the first judgement: the environment's reward
            assert rewards[index] == np.float32(step.reward)
        elif step.global_step in judged:  # judged: the judgement itself, none: no shaping
            judgement = judged[step.global_step]
            shaped = step.reward + (0.0 if judgement is None else 0.5 * judgement)
            assert rewards[index] == np.float32(shaped)
        else:  # after the window: the model's rating of what was done
            rating = expected.predict(obs, action)
            assert rewards[index] == np.float32(step.reward + 0.5 * rating), step
            moved += rating != 0.0
    assert moved > 20


def test_shaping_alone_leaves_the_steps_not_judged_alone(make_env) -> None:
    evaluator = Scripted([1.0, -1.0])
    trainer, recorder, _ = _run(make_env, evaluator)
    assert trainer.rating_model is None
    for step in recorder.steps:
        if step.global_step > 60:
            assert trainer.memory.rewards[step.global_step - 1] == np.float32(step.reward)


def test_the_model_shapes_a_declared_number_of_steps_after_the_latest_judgement(
    make_env,
) -> None:
    evaluator = Scripted([1.0, -1.0])
    trainer, recorder, _ = _run(
        make_env, evaluator, feedback_method="rating_model", rating_model_steps=10
    )
    rewards = trainer.memory.rewards
    after = [s for s in recorder.steps if s.global_step > 60]
    shaped = [s.global_step for s in after if rewards[s.global_step - 1] != np.float32(s.reward)]
    assert shaped and max(shaped) <= 70
    assert all(rewards[s.global_step - 1] == np.float32(s.reward) for s in after[10:])


def test_a_modelled_run_resumed_from_its_checkpoint_goes_on_as_if_never_stopped(
    make_env, tmp_path
) -> None:
    def build() -> Trainer:
        return Trainer(
            make_env(), small_config(), strategy=make_strategy("alternating", 20), seed=6,
            evaluator=Scripted([1.0, -1.0, 1.0]), feedback_method="rating_model",
        )  # fmt: skip

    whole = build()
    whole.run()
    first = build()
    for _ in range(75):  # inside the alternating window (training steps 61 to 99)
        first.step()
    first.save_checkpoint(tmp_path / "run.pt")
    second = build()
    second.load_checkpoint(tmp_path / "run.pt")
    second.run()
    added = whole.memory.added
    assert second.memory.added == added
    assert (second.memory.rewards[:added] == whole.memory.rewards[:added]).all()
    unmodelled = Trainer(
        make_env(), small_config(), strategy=make_strategy("alternating", 20), seed=6,
        evaluator=Scripted([1.0]),
    )  # fmt: skip
    with pytest.raises(ValueError, match="rating model"):
        unmodelled.load_checkpoint(tmp_path / "run.pt")


def test_a_run_declares_how_the_learner_uses_a_judgement(make_env) -> None:
    assert RunSpec().feedback_method == "shaping" and RunSpec().rating_model_steps is None
    spec = RunSpec.from_json(
        {"method": "oracle", "feedback": "evaluative", "feedback_method": "rating_model",
         "rating_model_steps": 500, "config": small_config().to_dict()}
    ).validate()  # fmt: skip
    assert (spec.feedback_method, spec.rating_model_steps) == ("rating_model", 500)
    trainer = spec.make_trainer(make_env(), None, evaluator=spec.make_evaluator())
    assert isinstance(trainer, Trainer) and trainer.rating_model is not None
    assert trainer.rating_model.steps == 500
    advised = RunSpec(method="oracle", feedback_method="rating_model").validate()
    assert advised.feedback_method == "shaping"  # advice takes no rating model
    with pytest.raises(RunSpecError) as error:
        RunSpec(method="oracle", feedback="evaluative", rating_model_steps=5).validate()
    assert error.value.field == "rating_model_steps"
