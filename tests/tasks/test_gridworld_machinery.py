"""The grid world through the machinery the sorting robot's studies use: agents trained
together in one population are the agents they are alone."""

from __future__ import annotations

import gymnasium as gym
import pytest

from learner import Trainer, make_advisor, make_strategy
from learner.population import Member, Population
from tasks import get_task
from tests.learner.conftest import Recorder, small_config

GRID = get_task("gridworld")


def _member(seed: int, advised: str | None, recorder: Recorder) -> Member:
    """An agent of the grid world: autonomous, oracle-advised early, or random-advised in
    turns."""
    env: gym.Env = GRID.env(None, 30, False)
    if advised == "oracle":
        advisor = make_advisor("oracle", task=GRID, error_rate=0.2, seed=seed)
        return Member(env, seed, advisor, make_strategy("early", 10), [recorder])
    if advised == "random":
        advisor = make_advisor("random", seed=seed, n_actions=GRID.n_actions)
        strategy = make_strategy("alternating", 10, interval=3)
        return Member(env, seed, advisor, strategy, [recorder])
    return Member(env, seed, callbacks=[recorder])


@pytest.mark.slow
def test_grid_world_agents_in_one_population_take_the_courses_they_take_alone() -> None:
    config = small_config()
    steps = config.pretraining_steps + 15
    kinds = [(1, None), (2, "oracle"), (3, "random")]
    alone = []
    for seed, advised in kinds:
        recorder = Recorder()
        member = _member(seed, advised, recorder)
        trainer = Trainer(
            member.env, config, member.advisor, member.strategy, member.seed, [recorder]
        )
        for _ in range(steps):
            trainer.step()
        assert trainer.n_actions == GRID.n_actions
        alone.append(recorder)
    recorders = [Recorder() for _ in kinds]
    members = [_member(s, a, r) for (s, a), r in zip(kinds, recorders, strict=True)]
    population = Population(config, members, layout="stacked", workers=1)
    for _ in range(steps):
        assert sorted(population.step()) == [0, 1, 2]
    population.close()
    for expected, recorder in zip(alone, recorders, strict=True):
        assert [s.to_dict() for s in recorder.steps] == [s.to_dict() for s in expected.steps]
        assert [e.to_dict() for e in recorder.episodes] == [e.to_dict() for e in expected.episodes]
    advised = [[s.global_step for s in r.steps if s.advised_action is not None] for r in recorders]
    assert advised[0] == [] and advised[1] == list(range(51, 61))
    assert advised[2] == [61, 64, 67, 70, 73]
    assert all(s.action in range(4) for r in recorders for s in r.steps)
