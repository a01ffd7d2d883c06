"""The shipped advisors: oracle (with its error rate), random, and a trained agent."""

import numpy as np
import pytest

import sim
from learner import Advisor, Trainer, ValueAdvisor, make_advisor
from tests.learner.conftest import small_config


def oracle_situations(make_env, count: int = 60) -> list[dict]:
    """Ground truth of states along oracle-played episodes."""
    env = make_env()
    infos = []
    _, info = env.reset(seed=0)
    while len(infos) < count:
        infos.append(info)
        _, _, terminated, truncated, info = env.step(sim.oracle_action(info, "color"))
        if terminated or truncated:
            _, info = env.reset(seed=len(infos))
    return infos


def test_oracle_without_errors_is_the_simulators_correct_action(make_env) -> None:
    oracle = make_advisor("oracle", sort_rule="color", error_rate=0.0, seed=1)
    assert isinstance(oracle, Advisor) and not isinstance(oracle, ValueAdvisor)
    infos = oracle_situations(make_env)
    assert [oracle.advise(None, i) for i in infos] == [sim.oracle_action(i, "color") for i in infos]


@pytest.mark.parametrize("error_rate", [0.3, 1.0])
def test_oracle_errs_at_its_error_rate(make_env, error_rate: float) -> None:
    oracle = make_advisor("oracle", error_rate=error_rate, seed=2)
    infos = oracle_situations(make_env) * 20
    wrong = np.mean([oracle.advise(None, i) != sim.oracle_action(i, "color") for i in infos])
    assert wrong == pytest.approx(error_rate, abs=0.05)


def test_random_advisor_is_uniform_and_seeded() -> None:
    advice = [make_advisor("random", seed=3).advise(None, {}) for _ in range(1)]
    advisor = make_advisor("random", seed=3)
    many = [advisor.advise(None, {}) for _ in range(4000)]
    assert many[0] == advice[0]
    assert np.allclose(np.bincount(many, minlength=4) / 4000, 0.25, atol=0.03)


def test_agent_advisor_acts_greedily_like_the_saved_learner(make_env, tmp_path) -> None:
    trainer = Trainer(make_env(), small_config(episodes=1), seed=9)
    trainer.run()
    trainer.save_checkpoint(tmp_path / "teacher.pt")
    agent = make_advisor("agent", checkpoint=tmp_path / "teacher.pt", device="cpu")
    assert isinstance(agent, ValueAdvisor)
    env = make_env()
    obs, info = env.reset(seed=1)
    for action in (0, 1, 3, 0):
        obs, *_ = env.step(action)
        values = agent.q_values(obs)
        assert np.array_equal(values, trainer.agent.q_values(obs))
        assert agent.advise(obs, info) == int(np.argmax(values))


@pytest.mark.parametrize(
    ("kind", "options", "words"),
    [
        ("human", {}, ["human", "agent, fitted, oracle, random"]),
        ("agent", {}, ["checkpoint"]),
        ("fitted", {}, ["model=PATH", "ideeprl fit"]),
        ("oracle", {"error_rate": 1.5}, ["error_rate"]),
        ("oracle", {"errors": 0.1}, ["oracle", "errors"]),
    ],
)
def test_bad_advisor_requests_say_what_is_wrong(kind: str, options: dict, words: list) -> None:
    with pytest.raises(ValueError) as error:
        make_advisor(kind, **options)
    for word in words:
        assert word in str(error.value)
