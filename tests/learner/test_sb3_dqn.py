"""Stable-Baselines3's DQN behind the Trainer's contract: the paper's hyperparameters mapped,
the paper's stages, SB3's learner, and a resume that continues exactly."""

from __future__ import annotations

import pytest

from learner import DQNConfig
from learner.sb3_spec import exploration_steps, sb3_hyperparameters
from tests.learner.conftest import Recorder, small_config

pytest.importorskip("stable_baselines3")


def test_the_papers_hyperparameters_become_sb3s() -> None:
    paper = sb3_hyperparameters(DQNConfig())
    assert (paper["sb3_learning_rate"], paper["sb3_gamma"], paper["sb3_batch_size"]) == (
        1e-3,
        0.9,
        128,
    )
    assert (paper["sb3_buffer_size"], paper["sb3_learning_starts"]) == (20_000, 1000)
    assert (paper["sb3_train_freq"], paper["sb3_target_update_interval"]) == (1, 1)
    # 0.9995 ** 9208 is still above 1 %, 0.9995 ** 9209 below: the floor is reached there.
    assert 0.9995**9208 > 0.01 > 0.9995**9209 and paper["sb3_exploration_steps"] == 9209
    modern = sb3_hyperparameters(DQNConfig.preset("modern", target_update_interval=300))
    assert modern["sb3_target_update_interval"] == 300 and modern["sb3_max_grad_norm"] == 10.0
    assert exploration_steps(DQNConfig(epsilon_decay=1.0)) == 0


def _trainer(make_env, config: DQNConfig, recorder: Recorder):
    from learner.sb3_dqn import SB3DQNTrainer

    return SB3DQNTrainer(make_env(max_episode_steps=30), config, seed=4, callbacks=[recorder])


@pytest.mark.slow
def test_stages_records_and_an_exact_resume(make_env, tmp_path) -> None:
    config = small_config(episodes=3, epsilon_decay=0.9, torch_threads=1)
    whole = Recorder()
    trainer = _trainer(make_env, config, whole)
    trainer.run()
    pretraining = [s for s in whole.steps if s.stage == "pretrain"]
    training = [s for s in whole.steps if s.stage == "train"]
    assert len(pretraining) == config.pretraining_steps
    assert {s.action_source for s in pretraining} == {"random"}
    assert all(s.loss is not None for s in training) and all(s.loss is None for s in pretraining)
    assert [e.episode for e in whole.episodes if e.stage == "train"] == [1, 2, 3]
    # SB3's linear schedule, counted in training steps: 1.0 at the first, then down.
    assert training[0].epsilon == 1.0 and training[-1].epsilon < 1.0
    assert trainer.model.num_timesteps == len(whole.steps)

    stop_at = config.pretraining_steps + 7  # in the training stage, mid-episode
    before = Recorder()
    first = _trainer(make_env, config, before)
    for _ in range(stop_at):
        first.step()
    first.save_checkpoint(tmp_path / "sb3.pt")
    after = Recorder()
    resumed = _trainer(make_env, config, after)
    resumed.load_checkpoint(tmp_path / "sb3.pt")
    resumed.run()
    assert before.steps + after.steps == whole.steps
    assert before.episodes + after.episodes == whole.episodes

    first.save_checkpoint(tmp_path / "final.pt", memory=False)
    with pytest.raises(ValueError, match="without its replay buffer"):
        _trainer(make_env, config, Recorder()).load_checkpoint(tmp_path / "final.pt")
    with pytest.raises(ValueError, match="another config: gamma"):
        _trainer(make_env, config.replace(gamma=0.5), Recorder()).load_checkpoint(
            tmp_path / "sb3.pt"
        )
