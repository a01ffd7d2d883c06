"""A run stopped at any step and resumed from its checkpoint continues as if never stopped."""

import pytest

from learner import DQNConfig, Trainer, make_advisor, make_strategy
from tests.learner.conftest import Recorder, small_config


def build(make_env, config: DQNConfig, recorder: Recorder) -> Trainer:
    # an erring oracle and early advising: the advisor's random state must resume too
    advisor = make_advisor("oracle", error_rate=0.3, seed=8)
    return Trainer(
        make_env(), config, advisor, make_strategy("early", 20), seed=6, callbacks=[recorder]
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("preset", "stop_at"),
    [("paper", 50), ("paper", 75), ("paper", -8), ("modern", 88)],
    ids=["in-advice", "training", "training-later", "modern"],
)
def test_resumed_run_gives_identical_records(make_env, tmp_path, preset: str, stop_at: int):
    """`stop_at`: steps before the stop; negative counts back from the run's end (how long
    the run is depends on the CPU: bfloat16 or float32 convolutions learn differently)."""
    modern = {"target_network": True, "double_dqn": True, "loss": "huber", "grad_clip_norm": 1.0}
    config = small_config(
        episodes=6, target_update_interval=10, **(modern if preset == "modern" else {})
    )
    whole = Recorder()
    build(make_env, config, whole).run()
    if stop_at < 0:
        stop_at += len(whole.steps)
        assert stop_at > config.pretraining_steps  # a stop in the training stage
    assert len(whole.steps) >= stop_at + 8

    before = Recorder()
    first = build(make_env, config, before)
    for _ in range(stop_at):
        first.step()
    mid_episode = first.observation is not None
    first.save_checkpoint(tmp_path / "run.pt")
    del first

    after = Recorder()
    second = build(make_env, config, after)
    second.load_checkpoint(tmp_path / "run.pt")
    assert (second.observation is not None) == mid_episode
    second.run()
    assert [r.to_dict() for r in before.steps + after.steps] == [r.to_dict() for r in whole.steps]
    assert [r.to_dict() for r in before.episodes + after.episodes] == [
        r.to_dict() for r in whole.episodes
    ]


def test_checkpoint_of_another_config_or_strategy_is_refused(make_env, tmp_path) -> None:
    trainer = build(make_env, small_config(), Recorder())
    for _ in range(5):
        trainer.step()
    trainer.save_checkpoint(tmp_path / "run.pt")
    with pytest.raises(ValueError, match="gamma"):
        build(make_env, small_config(gamma=0.5), Recorder()).load_checkpoint(tmp_path / "run.pt")
    with pytest.raises(ValueError, match="advising strategy"):
        Trainer(make_env(), small_config()).load_checkpoint(tmp_path / "run.pt")
    longer = build(make_env, small_config(episodes=9), Recorder())
    longer.load_checkpoint(tmp_path / "run.pt")  # more episodes: allowed
    assert longer.global_step == 5
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not a learner checkpoint"):
        longer.load_checkpoint(tmp_path / "junk.pt")


def test_resume_refuses_an_environment_that_does_not_replay(make_env, tmp_path) -> None:
    import gymnasium as gym

    trainer = Trainer(make_env(), small_config(), seed=1)
    for _ in range(12):
        trainer.step()
    assert trainer.observation is not None
    trainer.save_checkpoint(tmp_path / "run.pt")
    inverted = gym.wrappers.TransformObservation(
        make_env(), lambda image: 255 - image, make_env().observation_space
    )
    with pytest.raises(RuntimeError, match="not deterministic"):
        Trainer(inverted, small_config(), seed=1).load_checkpoint(tmp_path / "run.pt")


@pytest.mark.slow
def test_a_replayed_stream_resumes_where_it_stopped(make_env, tmp_path) -> None:
    """A replay stopped in the middle of its stream, and again past its end, continues with
    the next recorded advice (and the requests it counted) as if never stopped."""
    from learner.advisors import RecordedAdvisor

    def replay(recorder: Recorder) -> Trainer:
        stream = RecordedAdvisor([0, 1, 2, 3] * 3, ["none"] * 12)  # 12 advice, budget 16
        strategy = make_strategy("alternating", 16, interval=2)
        return Trainer(make_env(), small_config(), stream, strategy, seed=4, callbacks=[recorder])

    whole = Recorder()
    replay(whole).run()
    advised = [r.advised_action for r in whole.steps if r.advised_action is not None]
    assert advised == [0, 1, 2, 3] * 3
    assert whole.steps[60 + 31 - 1].advice_remaining == 0  # four requests beyond the stream
    for stop_at in (60 + 11, 60 + 27):  # six advice in; then past the stream's end
        before, after = Recorder(), Recorder()
        first = replay(before)
        for _ in range(stop_at):
            first.step()
        first.save_checkpoint(tmp_path / "replay.pt")
        second = replay(after)
        second.load_checkpoint(tmp_path / "replay.pt")
        second.run()
        assert [r.to_dict() for r in before.steps + after.steps] == [
            r.to_dict() for r in whole.steps
        ]
