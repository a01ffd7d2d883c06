"""Advisors fitted to people recover the pattern of the advisors that made the data, and
the fitted advisor advises with that pattern."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

import sim
from learner.advisors import OracleAdvisor, make_advisor
from learner.fitted import (
    AdviceSeen,
    Count,
    FittedAdvisor,
    FittedModel,
    SessionAdvice,
    fit,
    read_model,
)
from tasks.sorting import HELD, situation

RULE = sim.SortRule.parse("color")
MEDIAN_S, SIGMA = 2.0, 0.5


class BlueFumbler:
    """The generating advisor: wrong with probability 0.3 while the arm holds a blue
    object, never otherwise; log-normal decision times with a known median."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def advise(self, info: dict[str, Any]) -> tuple[int, float]:
        correct = int(sim.oracle_action(info, RULE))
        wrong = situation(info)[1] == "blue" and self.rng.random() < 0.3
        others = [a for a in range(4) if a != correct]
        action = int(self.rng.choice(others)) if wrong else correct
        return action, float(MEDIAN_S * np.exp(SIGMA * self.rng.standard_normal()))


def advised_sessions(n_advice: int, per_session: int = 100) -> list[SessionAdvice]:
    """Advice as sessions record it: the advisor chooses every action of the real
    environment, each advice with the state it was given in (what the fit's replay
    recovers); every fifth simulated person stops after 40 of their 100 advice."""
    env = sim.SortingEnv(motion="fast", max_episode_steps=60)
    advisor = BlueFumbler(seed=3)
    seen: list[AdviceSeen] = []
    episode = 0
    _, info = env.reset(seed=episode)
    while len(seen) < n_advice:
        action, decision_time = advisor.advise(info)
        station, held = situation(info)
        correct = int(sim.oracle_action(info, RULE))
        seen.append(AdviceSeen(station, held, correct, action, decision_time))
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            episode += 1
            _, info = env.reset(seed=episode)
    env.close()
    chunks = [seen[i : i + per_session] for i in range(0, n_advice, per_session)]
    return [
        SessionAdvice(i, chunk[:40] if i % 5 == 4 else chunk, per_session)
        for i, chunk in enumerate(chunks)
    ]


@pytest.mark.slow
def test_the_fit_recovers_a_situation_dependent_error_rate_and_decision_times() -> None:
    sessions = advised_sessions(3000)
    model = FittedModel.from_json(json.loads(json.dumps(fit(sessions).to_json())))
    assert model.advice >= 2500
    assert abs(model.group_rate("blue") - 0.3) < 0.03
    assert model.group_rate("red") < 0.01 and model.group_rate("nothing") < 0.01
    for key, count in model.by_situation.items():
        station, held = key.split("/")
        truth = 0.3 if held == "blue" else 0.0
        tolerance = 0.01 if truth == 0.0 else 0.06
        if count.advice >= 300:
            assert abs(model.error_rate(station, held) - truth) < tolerance, key
    assert model.decision_time_median_s is not None
    assert abs(model.decision_time_median_s / MEDIAN_S - 1) < 0.10
    assert model.decision_time_sigma is not None and abs(model.decision_time_sigma - SIGMA) < 0.05
    assert model.stop_early_rate == pytest.approx(0.2)
    assert min(model.budget_used) == pytest.approx(0.4)


def _model(blue_rate: float) -> FittedModel:
    """A model wrong at `blue_rate` with a blue object held, never otherwise, firmly."""
    by_held = {h: Count(10_000, int(10_000 * blue_rate) if h == "blue" else 0) for h in HELD}
    return FittedModel(
        advice=30_000, sessions=[1], methods=["human"], overall=Count(30_000, 3_000),
        by_group=by_held, by_situation={}, wrong_actions=[[0] * 4 for _ in range(4)],
        decision_time_median_s=1.5, decision_time_sigma=0.4,
        decision_time_quantiles=[], budget_used=[1.0, 0.5],
    )  # fmt: skip


def test_the_fitted_advisor_errs_where_its_model_says_and_draws_decision_times(
    tmp_path: Any,
) -> None:
    path = tmp_path / "model.json"
    path.write_text(json.dumps(_model(0.5).to_json()))
    advisor = make_advisor("fitted", model=path, seed=1)
    assert isinstance(advisor, FittedAdvisor)
    env = sim.SortingEnv(motion="fast", max_episode_steps=40)
    _, info = env.reset(seed=0)
    wrong = {"blue": [0, 0], "other": [0, 0]}
    times = []
    for _ in range(300):  # the oracle's actions walk the arm through every situation
        correct = int(sim.oracle_action(info, RULE))
        advised = advisor.advise(np.zeros((64, 64, 3), np.uint8), info)
        times.append(advisor.last_decision_time_s)
        tally = wrong["blue" if situation(info)[1] == "blue" else "other"]
        tally[0] += 1
        tally[1] += advised != correct
        _, _, terminated, truncated, info = env.step(correct)
        if terminated or truncated:
            _, info = env.reset()
    env.close()
    assert wrong["other"][1] == 0
    assert 0.3 < wrong["blue"][1] / wrong["blue"][0] < 0.7
    assert all(t is not None and t > 0 for t in times)
    assert 1.2 < float(np.median(times)) < 1.8  # type: ignore[arg-type]
    assert read_model(path) == _model(0.5)
    again = FittedAdvisor(read_model(path), seed=1)  # the same seed advises the same
    state = again.state_dict()
    assert FittedAdvisor(read_model(path), seed=1).state_dict() == state


def test_a_fitted_person_leaves_early_as_the_fitted_people_did() -> None:
    """Budget use [1.0, 0.5]: a run's advisor gives its whole budget or half of it, then
    answers NO_ADVICE (asked, counted, none given), and keeps that on resume."""
    from learner.advisors import NO_ADVICE

    env = sim.SortingEnv(motion="fast", max_episode_steps=40)
    _, info = env.reset(seed=0)
    obs = np.zeros((64, 64, 3), np.uint8)
    given = set()
    for seed in range(12):
        advisor = FittedAdvisor(_model(0.0), seed=seed, budget=10)
        answers = [advisor.advise(obs, info) for _ in range(10)]
        count = sum(a is not NO_ADVICE for a in answers)
        assert answers[count:] == [NO_ADVICE] * (10 - count)  # once left, gone
        given.add(count)
        resumed = FittedAdvisor(_model(0.0), seed=99, budget=10)
        resumed.load_state_dict(advisor.state_dict())
        assert (resumed.advise(obs, info) is NO_ADVICE) == (count < 10)
    env.close()
    assert given == {5, 10}
    assert FittedAdvisor(_model(0.0), seed=0).leaves_after is None  # no budget: never leaves


def test_a_bad_model_file_is_refused_with_what_to_do(tmp_path: Any) -> None:
    with pytest.raises(ValueError, match="ideeprl fit"):
        read_model(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text(json.dumps({"version": 1, "advice": 3}))
    with pytest.raises(ValueError, match="not a fitted model"):
        read_model(tmp_path / "bad.json")
    with pytest.raises(ValueError, match="no advice"):
        fit([SessionAdvice(1, [], 100)])


def test_oracle_decision_times_leave_its_advice_unchanged() -> None:
    env = sim.SortingEnv(motion="fast", max_episode_steps=30)
    _, info = env.reset(seed=4)
    plain = OracleAdvisor(error_rate=0.4, seed=9)
    timed = OracleAdvisor(error_rate=0.4, seed=9, decision_time_median_s=3.0)
    obs = np.zeros((64, 64, 3), np.uint8)
    for _ in range(40):
        action = plain.advise(obs, info)
        assert timed.advise(obs, info) == action
        assert plain.last_decision_time_s is None
        assert timed.last_decision_time_s is not None and timed.last_decision_time_s > 0
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            _, info = env.reset()
    env.close()


@pytest.mark.parametrize("kind", ["fitted", "oracle"])
def test_advice_and_decision_times_resume_from_the_advisors_state(kind: str, tmp_path: Any) -> None:
    """A run resumed from its checkpoint gets the advice and times it would have got."""
    path = tmp_path / "model.json"
    path.write_text(json.dumps(_model(0.5).to_json()))

    def advisor() -> Any:
        if kind == "fitted":
            return make_advisor("fitted", model=path, seed=5)
        return make_advisor("oracle", error_rate=0.5, seed=5, decision_time_median_s=2.0)

    infos = [
        {"station": station, "held": held, "held_color": held.split("/")[-1]}
        for station in ("center", "left", "right")
        for held in ("", "cube/blue", "disk/red")
    ]
    obs = np.zeros((64, 64, 3), np.uint8)
    whole = advisor()
    given = [(whole.advise(obs, i), whole.last_decision_time_s) for i in infos]
    first = advisor()
    for info in infos[:4]:
        first.advise(obs, info)
    resumed = advisor()
    resumed.load_state_dict(json.loads(json.dumps(first.state_dict())))
    again = [(resumed.advise(obs, i), resumed.last_decision_time_s) for i in infos[4:]]
    assert again == given[4:]
