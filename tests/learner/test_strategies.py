"""Advising strategies decide by their rule and never exceed their budget."""

import numpy as np
import pytest

from learner import make_strategy
from learner.strategies import STRATEGY_NAMES, AdviceMoment

IMAGE = np.zeros((64, 64, 3), dtype=np.uint8)


class ScriptedAdvisor:
    """Advises `action`; its Q-values spread by `spread` (a test stand-in for an agent)."""

    def __init__(self, action: int = 1, spread: float = 1.0) -> None:
        self.action, self.spread, self.asked = action, spread, 0

    def advise(self, obs, info) -> int:
        self.asked += 1
        return self.action

    def q_values(self, obs) -> np.ndarray:
        return np.array([0.0, self.spread, 0.0, 0.0], dtype=np.float32)


def moments(pretraining: int = 1000, training: int = 2000, intended: int = 0):
    for step in range(1, pretraining + training + 1):
        stage = "pretrain" if step <= pretraining else "train"
        yield AdviceMoment(IMAGE, {}, stage, step, pretraining, intended, intended)


def advised_steps(strategy, advisor, **kwargs) -> list[int]:
    return [m.global_step for m in moments(**kwargs) if strategy.advise(m, advisor) is not None]


def test_early_advising_takes_the_last_budget_steps_of_pretraining() -> None:
    assert advised_steps(make_strategy("early", 100), ScriptedAdvisor()) == list(range(901, 1001))
    assert advised_steps(make_strategy("early", 0), ScriptedAdvisor()) == []
    assert advised_steps(make_strategy("early", 30), ScriptedAdvisor(), pretraining=200) == list(
        range(171, 201)
    )


@pytest.mark.parametrize("name", STRATEGY_NAMES)
def test_first_advice_step_is_the_first_step_a_strategy_advises_at(name: str) -> None:
    """What the server tells a waiting participant (the steps before their first turn)."""
    for pretraining, budget in [(1000, 100), (200, 30)]:
        strategy = make_strategy(name, budget)
        steps = advised_steps(
            strategy, ScriptedAdvisor(spread=1.0, action=1), pretraining=pretraining
        )
        assert steps and steps[0] == make_strategy(name, budget).first_advice_step(pretraining)


def test_alternating_advises_every_interval_from_the_first_training_step() -> None:
    steps = advised_steps(make_strategy("alternating", 5), ScriptedAdvisor())
    assert steps == [1001, 1003, 1005, 1007, 1009]
    steps = advised_steps(make_strategy("alternating", 3, interval=4), ScriptedAdvisor())
    assert steps == [1001, 1005, 1009]


def test_importance_advises_only_where_the_advisors_values_spread() -> None:
    strategy = make_strategy("importance", 10, threshold=0.5)
    assert advised_steps(strategy, ScriptedAdvisor(spread=0.4)) == []
    assert advised_steps(strategy, ScriptedAdvisor(spread=0.6)) == list(range(1001, 1011))


def test_mistake_correcting_spends_advice_only_on_disagreement() -> None:
    strategy = make_strategy("mistake_correcting", 10, threshold=0.5)
    agreeing = ScriptedAdvisor(action=0, spread=1.0)
    assert advised_steps(strategy, agreeing, intended=0) == [] and strategy.used == 0
    assert agreeing.asked == 2000
    assert advised_steps(strategy, ScriptedAdvisor(action=2), intended=0) == list(range(1001, 1011))
    strategy = make_strategy("mistake_correcting", 10, threshold=0.5)
    assert advised_steps(strategy, ScriptedAdvisor(action=2, spread=0.1), intended=0) == []


@pytest.mark.parametrize("name", STRATEGY_NAMES)
@pytest.mark.parametrize("budget", [0, 1, 37])
def test_no_strategy_exceeds_its_budget(name: str, budget: int) -> None:
    strategy = make_strategy(name, budget)
    advisor = ScriptedAdvisor(action=3, spread=5.0)
    given = advised_steps(strategy, advisor, pretraining=500, training=500, intended=0)
    assert len(given) == strategy.used == budget and strategy.remaining == 0


def test_strategy_state_round_trips_and_refuses_another_strategy() -> None:
    strategy = make_strategy("alternating", 20, interval=3)
    advised_steps(strategy, ScriptedAdvisor(), training=30)
    restored = make_strategy("alternating", 20, interval=3)
    restored.load_state_dict(strategy.state_dict())
    assert restored.used == strategy.used == 10
    with pytest.raises(ValueError, match="interval"):
        make_strategy("alternating", 20, interval=2).load_state_dict(strategy.state_dict())


@pytest.mark.parametrize(
    ("call", "words"),
    [
        (lambda: make_strategy("eager"), ["eager", "early, alternating"]),
        (lambda: make_strategy("early", -1), ["budget"]),
        (lambda: make_strategy("early", 2.5), ["budget"]),
        (lambda: make_strategy("alternating", 5, interval=0), ["interval"]),
        (lambda: make_strategy("importance", 5, threshold=-1), ["threshold"]),
        (lambda: make_strategy("early", 5, threshold=1), ["early", "threshold"]),
    ],
)
def test_bad_strategy_arguments_say_what_is_wrong(call, words: list[str]) -> None:
    with pytest.raises(ValueError) as error:
        call()
    for word in words:
        assert word in str(error.value)


def test_a_recorded_stream_is_fed_by_order_and_past_its_end_the_requests_count_unanswered():
    from learner.advisors import RecordedAdvisor
    from learner.records import observation_hash

    other = np.full((64, 64, 3), 7, dtype=np.uint8)
    seen = observation_hash(IMAGE)
    stream = RecordedAdvisor([3, 1, 2], [seen, seen, "not this image"])
    strategy = make_strategy("alternating", budget=5, interval=1)
    answers, same = [], []
    for step, image in enumerate([IMAGE, other, IMAGE, IMAGE, IMAGE, IMAGE], start=11):
        moment = AdviceMoment(image, {}, "train", step, 10, 0, 0)
        answers.append(strategy.advise(moment, stream))
        same.append(stream.same_observation)
    assert answers == [3, 1, 2, None, None, None]  # by order, whatever the state
    assert same == [True, False, False, None, None, None]
    assert stream.count == 5  # asked five times: three answered, two beyond the stream
    assert strategy.used == 5 and strategy.remaining == 0  # the sixth step asks no more
