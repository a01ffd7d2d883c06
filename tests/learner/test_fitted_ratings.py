"""Evaluators fitted to people's ratings recover the pattern of the raters that made the
data (how often they misjudge a right move and a wrong one, how often they stay silent,
how long they take), and the fitted evaluator rates with that pattern."""

from __future__ import annotations

import functools
import json
from typing import Any

import numpy as np
import pytest

import sim
from learner.evaluators import BAD, GOOD
from learner.fitted import read_model
from learner.fitted_ratings import (
    FittedEvaluator,
    FittedEvaluatorModel,
    RatingSeen,
    SessionRatings,
    fit_ratings,
    model_from_json,
    read_evaluator_model,
)
from learner.run import RunSpec, RunSpecError
from tasks.sorting import situation

RULE = sim.SortRule.parse("color")
MEDIAN_S, SIGMA = 1.2, 0.4
WRONG_ON_RIGHT, WRONG_ON_WRONG = 0.1, 0.4
"""The generating raters' errors: a right move called Bad 10 % of the time, a wrong move
called Good 40 % of the time (a trainer's positive bias)."""
SILENT = (0.0, 0.3)
"""Half the raters answer every turn, the other half let 30 % pass."""


@functools.cache
def _states(n: int, seed: int) -> list[tuple[dict[str, Any], int, int]]:
    """(info, move, correct action) along real episodes whose learner acts at random."""
    env = sim.SortingEnv(motion="fast", max_episode_steps=60)
    rng = np.random.default_rng(seed)
    found = []
    episode = 0
    _, info = env.reset(seed=episode)
    while len(found) < n:
        move = int(rng.integers(4))
        found.append((info, move, int(sim.oracle_action(info, RULE))))
        _, _, terminated, truncated, info = env.step(move)
        if terminated or truncated:
            episode += 1
            _, info = env.reset(seed=episode)
    env.close()
    return found


def rated_sessions(n_sessions: int = 20, per_session: int = 150) -> list[SessionRatings]:
    """Rating turns as sessions record them: a random learner's moves, each rated by the
    generating rater of its session."""
    rng = np.random.default_rng(7)
    states = _states(3000, seed=0)
    sessions = []
    for i in range(n_sessions):
        silent = SILENT[i % 2]
        turns = []
        for info, move, correct in states[i * per_session : (i + 1) * per_session]:
            station, held = situation(info)
            right = move == correct
            if rng.random() < silent:
                turns.append(RatingSeen(station, held, right, None))
                continue
            flip = rng.random() < (WRONG_ON_RIGHT if right else WRONG_ON_WRONG)
            judgement = GOOD if right != flip else BAD
            time_s = float(MEDIAN_S * np.exp(SIGMA * rng.standard_normal()))
            turns.append(RatingSeen(station, held, right, judgement, time_s))
        sessions.append(SessionRatings(i, turns))
    return sessions


@pytest.mark.slow
def test_the_fit_recovers_the_raters_errors_silence_and_times() -> None:
    sessions = rated_sessions()
    model = model_from_json(json.loads(json.dumps(fit_ratings(sessions).to_json())))
    assert isinstance(model, FittedEvaluatorModel)
    assert model.turns == 3000 and 0.8 * 3000 < model.answered < 0.9 * 3000
    assert abs(model.move_rate(True) - WRONG_ON_RIGHT) < 0.04
    assert abs(model.move_rate(False) - WRONG_ON_WRONG) < 0.04
    assert abs(model.silent_rate() - 0.15) < 0.03
    assert model.silent_shares[::2] == [0.0] * 10
    assert abs(float(np.mean(model.silent_shares[1::2])) - 0.3) < 0.03
    assert model.decision_time_median_s is not None and model.decision_time_sigma is not None
    assert abs(model.decision_time_median_s / MEDIAN_S - 1) < 0.05
    assert abs(model.decision_time_sigma - SIGMA) < 0.03
    summary = model.summary()
    assert summary["kind"] == "evaluative" and summary["ratings"] == 3000
    assert set(summary["error_rate_by_move"]) == {"right", "wrong"}


@pytest.mark.slow
def test_the_fitted_evaluator_rates_as_the_recorded_rates_say(tmp_path: Any) -> None:
    """Over many moves of a random learner, the fitted evaluator calls a right move Bad and
    a wrong one Good at the rates fitted from the recorded ratings, and stays silent at a
    rate one of the fitted people had."""
    model = fit_ratings(rated_sessions())
    path = tmp_path / "evaluator.json"
    path.write_text(json.dumps(model.to_json()))
    evaluator = FittedEvaluator(read_evaluator_model(path), seed=3)
    assert evaluator.silent_rate in model.silent_shares
    counts = {True: [0, 0], False: [0, 0]}
    silent, times = 0, []
    obs = np.zeros((64, 64, 3), np.uint8)
    for info, move, correct in _states(3000, seed=0) * 2:
        judgement = evaluator.judge(obs, info, move)
        if judgement is None:
            silent += 1
            assert evaluator.last_decision_time_s is None
            continue
        right = move == correct
        counts[right][0] += 1
        counts[right][1] += (judgement == GOOD) != right
        times.append(evaluator.last_decision_time_s)
    for right in (True, False):
        rated, wrong = counts[right]
        assert abs(wrong / rated - model.move_rate(right)) < 0.04, (right, rated, wrong)
    assert abs(silent / 6000 - evaluator.silent_rate) < 0.03
    median = float(np.median(times))
    assert model.decision_time_median_s is not None
    assert abs(median / model.decision_time_median_s - 1) < 0.1

    resumed = FittedEvaluator(model, seed=99)  # a resumed run rates as the whole one
    resumed.load_state_dict(evaluator.state_dict())
    info, move, _ = _states(3000, seed=0)[5]
    assert resumed.judge(obs, info, move) == evaluator.judge(obs, info, move)


def test_advice_and_ratings_models_are_not_taken_for_one_another(tmp_path: Any) -> None:
    rated = tmp_path / "evaluator.json"
    rated.write_text(json.dumps(fit_ratings(rated_sessions(2, 20)).to_json()))
    with pytest.raises(ValueError, match="fitted to ratings"):
        read_model(rated)  # an advisor cannot be made of it
    advised = tmp_path / "advisor.json"
    from tests.learner.test_fitted import _model

    advised.write_text(json.dumps(_model(0.2).to_json()))
    with pytest.raises(ValueError, match="fitted to advice"):
        read_evaluator_model(advised)
    with pytest.raises(ValueError, match="no rating turns"):
        fit_ratings([SessionRatings(1, [])])

    def spec(feedback: str, model: Any) -> RunSpec:
        return RunSpec(method="fitted", feedback=feedback, fitted_model=str(model)).validate()  # type: ignore[arg-type]

    assert isinstance(spec("evaluative", rated).make_evaluator(), FittedEvaluator)
    with pytest.raises(RunSpecError, match="fitted to advice"):
        spec("evaluative", advised).make_evaluator()
    with pytest.raises(RunSpecError, match="fitted to ratings"):
        spec("advice", rated).make_advisor()
