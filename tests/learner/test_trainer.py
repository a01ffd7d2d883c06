"""The training loop on the real environment: stages, records, callbacks, advice."""

import numpy as np
import pytest

from learner import DQNConfig, Trainer, make_advisor, make_strategy
from tests.learner.conftest import Recorder, small_config


@pytest.mark.slow
def test_early_advising_takes_exactly_steps_901_to_1000(make_env) -> None:
    config = DQNConfig(memory_size=1200, batch_size=32)
    recorder = Recorder()
    trainer = Trainer(
        make_env(), config, advisor=make_advisor("oracle", seed=1), seed=3, callbacks=[recorder]
    )
    while trainer.stage == "pretrain":
        trainer.step()
    steps = recorder.steps
    assert [s.global_step for s in steps] == list(range(1, 1001))
    advised = [s.global_step for s in steps if s.advised_action is not None]
    assert advised == list(range(901, 1001))
    for s in steps:
        assert s.stage == "pretrain"  # advice is a source, not a stage
        assert s.action_source == ("advisor" if s.global_step > 900 else "random")
        assert s.loss is None and s.epsilon == 1.0
        if s.advised_action is not None:
            assert s.action == s.advised_action
    assert [s.advice_remaining for s in steps[899:]] == list(range(100, -1, -1))
    assert steps[-1].terminated or steps[-1].truncated  # pretraining's last episode is cut
    assert trainer.memory.added == 1000
    assert trainer.step().stage == "train" and trainer.global_step == 1001


def test_records_number_steps_and_episodes_and_add_up(make_env) -> None:
    recorder = Recorder()
    trainer = Trainer(make_env(), small_config(episodes=4), seed=5, callbacks=[recorder])
    finished = trainer.run()
    steps, episodes = recorder.steps, recorder.episodes
    assert trainer.done and [e.episode for e in finished] == [1, 2, 3, 4]
    assert [s.global_step for s in steps] == list(range(1, len(steps) + 1))
    assert [e.episode for e in episodes if e.stage == "train"] == [1, 2, 3, 4]
    pretrain = [e for e in episodes if e.stage == "pretrain"]
    assert [e.episode for e in pretrain] == list(range(1, len(pretrain) + 1))
    assert pretrain[-1].last_global_step == 60
    for episode in episodes:
        own = steps[episode.first_global_step - 1 : episode.last_global_step]
        assert all(s.stage == episode.stage and s.episode == episode.episode for s in own)
        assert [s.episode_step for s in own] == list(range(1, episode.steps + 1))
        assert episode.collected_reward == pytest.approx(sum(s.reward for s in own))
        assert own[-1].terminated == episode.terminated and own[-1].truncated == episode.truncated
        assert episode.steps <= 30
    training = [s for s in steps if s.stage == "train"]
    assert all(
        s.loss is not None and s.action_source in ("greedy", "exploration") for s in training
    )
    assert training[0].epsilon == 1.0
    assert training[-1].epsilon == pytest.approx(0.99 ** (len(training) - 1))
    for s in training:
        q = [s.q_grab, s.q_move_right, s.q_move_left, s.q_drop]
        assert s.greedy_action == int(np.argmax(q))
        if s.action_source == "greedy":
            assert s.action == s.greedy_action
    assert set(steps[0].to_dict()) >= {"global_step", "stage", "action_source", "epsilon"}


def test_same_seed_same_run_other_seed_other_run(make_env) -> None:
    def run(seed: int) -> list[dict]:
        recorder = Recorder()
        Trainer(make_env(), small_config(episodes=2), seed=seed, callbacks=[recorder]).run()
        return [s.to_dict() for s in recorder.steps]

    first = run(11)
    assert run(11) == first
    assert run(12) != first


def test_a_callback_returning_false_stops_the_trainer(make_env) -> None:
    class StopAfter:
        def on_step(self, record):
            return record.global_step < 10

    trainer = Trainer(make_env(), small_config(), callbacks=[StopAfter()])
    trainer.run()
    assert trainer.done and trainer.global_step == 10
    with pytest.raises(RuntimeError, match="done"):
        trainer.step()


def test_alternating_advice_during_training_is_executed_within_budget(make_env) -> None:
    recorder = Recorder()
    strategy = make_strategy("alternating", budget=7, interval=2)
    config = small_config(episodes=3)
    advisor = make_advisor("oracle", seed=2)
    Trainer(make_env(), config, advisor, strategy, seed=1, callbacks=[recorder]).run()
    advised = [s for s in recorder.steps if s.advised_action is not None]
    assert [s.global_step - 60 for s in advised] == [1, 3, 5, 7, 9, 11, 13]
    assert all(s.stage == "train" and s.action == s.advised_action for s in advised)
    assert strategy.used == 7 and recorder.steps[-1].advice_remaining == 0


def test_advising_needs_an_advisor_and_importance_needs_values(make_env) -> None:
    with pytest.raises(ValueError, match="needs an advisor"):
        Trainer(make_env(), small_config(), strategy="early")
    with pytest.raises(ValueError, match="q_values"):
        Trainer(make_env(), small_config(), make_advisor("oracle"), "importance")
    with pytest.raises(ValueError, match="cannot exceed pretraining_steps"):
        Trainer(make_env(), small_config(), make_advisor("random"), make_strategy("early", 61))


def test_a_bad_advised_action_raises_and_loses_no_step(make_env) -> None:
    class Broken:
        def __init__(self) -> None:
            self.answer = 7

        def advise(self, obs, info):
            return self.answer

    def run(advisor) -> tuple[Trainer, Recorder]:
        recorder = Recorder()
        config = small_config(advice_budget=5)
        return Trainer(make_env(), config, advisor, seed=4, callbacks=[recorder]), recorder

    reference, expected = run(make_advisor("random", seed=0))
    broken_advisor = Broken()
    trainer, recorder = run(broken_advisor)
    for _ in range(55):
        reference.step()
        trainer.step()
    with pytest.raises(ValueError, match=r"valid actions are 0\.\.3"):
        trainer.step()
    assert trainer.global_step == 55 and trainer.strategy.used == 0
    broken_advisor.answer = 2
    reference.advisor = broken_advisor
    for _ in range(10):
        reference.step()
        trainer.step()
    assert [s.to_dict() for s in recorder.steps] == [s.to_dict() for s in expected.steps]


def test_the_environment_must_have_discrete_actions_and_images_the_network_takes(
    make_env,
) -> None:
    import gymnasium as gym
    import numpy as np

    env = make_env()
    env.action_space = gym.spaces.Box(-1, 1, (2,))
    with pytest.raises(ValueError, match="Discrete"):
        Trainer(env, small_config())
    env.action_space = gym.spaces.Discrete(1)
    with pytest.raises(ValueError, match="Discrete"):
        Trainer(env, small_config())
    env.action_space = gym.spaces.Discrete(4)
    env.observation_space = gym.spaces.Box(0, 255, (60, 64, 3), np.uint8)
    with pytest.raises(ValueError, match="multiples of 8"):
        Trainer(env, small_config())


def test_every_step_records_what_it_did_to_the_objects(make_env) -> None:
    """The steps' outcomes add up to their episode's counts, realism on, so all three
    happen: placements, wrong placements and objects knocked off."""
    from learner import make_advisor

    recorder = Recorder()
    env = make_env(knock_off_rate=0.3)
    trainer = Trainer(env, small_config(episodes=4), make_advisor("oracle", error_rate=0.3, seed=1),
                      "early", seed=5, callbacks=[recorder])  # fmt: skip
    trainer.run()
    seen = set()
    for episode in recorder.episodes:
        own = recorder.steps[episode.first_global_step - 1 : episode.last_global_step]
        outcomes = [s.outcome for s in own]
        seen |= set(outcomes)
        assert outcomes.count("placed") == episode.placed_correct
        assert outcomes.count("misplaced") == episode.misplaced
        assert outcomes.count("lost") == episode.lost
    assert {"placed", "none"} <= seen and seen <= {"placed", "misplaced", "lost", "none"}
