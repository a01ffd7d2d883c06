"""The reward schemes (SPEC 1, "Reward accounting"), step by step on fixed action lists."""

import pytest

import sim
from sim.rewards import REWARD_SCHEMES, rescore, step_outcome, step_penalty

RIGHT, LEFT, GRAB, DROP = (
    sim.Action.MOVE_RIGHT,
    sim.Action.MOVE_LEFT,
    sim.Action.GRAB,
    sim.Action.DROP,
)

# What the n-th step without a placement costs, for n = 1..22, read off the rule of each
# scheme (the paper's text; the authors' scripts, shared/reference/README.md).
EXPECTED = {
    "paper": [0.0] * 18 + [-0.01] * 4,
    "authors-autonomous": [0.0] * 19 + [-0.01, -0.02, -0.03],
    "authors-interactive": [-0.01] * 22,
}


@pytest.mark.parametrize("scheme", REWARD_SCHEMES)
def test_steps_without_placement_cost_what_the_scheme_says(scheme) -> None:
    env = sim.SortingEnv(motion="fast", reward_scheme=scheme)
    env.reset(seed=0)
    rewards = []
    for n in range(22):  # back and forth between the side tables: never a placement
        _, reward, terminated, truncated, _ = env.step(RIGHT if n % 2 == 0 else LEFT)
        assert not (terminated or truncated)
        rewards.append(reward)
    assert rewards == pytest.approx(EXPECTED[scheme], abs=1e-12)
    assert [step_penalty(scheme, n) for n in range(1, 23)] == pytest.approx(EXPECTED[scheme])
    env.close()


@pytest.mark.parametrize("scheme", REWARD_SCHEMES)
def test_placements_earn_the_same_under_every_scheme(scheme) -> None:
    env = sim.SortingEnv(motion="fast", reward_scheme=scheme)
    _, info = env.reset(seed=3)
    rewards, done = [], False
    while not done:
        action = sim.oracle_action(info, env.sort_rule)
        _, reward, terminated, truncated, info = env.step(action)
        rewards.append((action, reward))
        done = terminated or truncated
    assert len(rewards) == 18 and info["is_success"]
    placements = [r for a, r in rewards if a == DROP]
    assert placements == pytest.approx([0.4] * 5 + [1.0])
    others = [r for a, r in rewards if a != DROP]
    expected = [step_penalty(scheme, n + 1) for n, (a, _) in enumerate(rewards) if a != DROP]
    assert others == pytest.approx(expected)
    # a wrong placement: -1 and the end, whatever the scheme
    _, info = env.reset(seed=3)
    env.step(GRAB)
    held = env.unwrapped._task.held
    shape, color = env.unwrapped._task.kinds[held]
    wrong = LEFT if env.sort_rule.side(shape, color) == "right" else RIGHT
    env.step(wrong)
    _, reward, terminated, _, _ = env.step(DROP)
    assert reward == -1.0 and terminated
    env.close()


def test_a_bad_scheme_is_refused_naming_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="paper, authors-autonomous, authors-interactive"):
        sim.SortingEnv(motion="fast", reward_scheme="keras")


def test_rescoring_a_constructed_episode() -> None:
    """25 steps: 21 without a placement, correct placements at steps 3, 6 and 24 (+0.4) and
    a wrong one (-1, the end) at step 25; logged under one scheme, rescored to each."""
    placed = {3: 0.4, 6: 0.4, 24: 0.4, 25: -1.0}
    ended = [n == 25 for n in range(1, 26)]

    def logged(scheme: str) -> list[float]:
        return [placed.get(n, step_penalty(scheme, n)) for n in range(1, 26)]

    # by hand: paper 1.2 - 1 - 0.01 x 5 (steps 19-23), authors-autonomous 1.2 - 1 - 0.01 x
    # (1 + 2 + 3 + 4) (steps 20-23), authors-interactive 1.2 - 1 - 0.01 x 21
    totals = {"paper": 0.15, "authors-autonomous": 0.10, "authors-interactive": -0.01}
    for source in REWARD_SCHEMES:
        for target, total in totals.items():
            rescored = rescore(logged(source), ended, source, target)
            assert rescored == pytest.approx(logged(target))
            assert sum(rescored) == pytest.approx(total)


def test_rescoring_by_outcomes_tells_what_the_rewards_cannot() -> None:
    """Three endings the rewards misread: an episode ended because its last object was
    knocked off (terminated, a step cost: no placement), the 119th step under
    authors-autonomous (its cost is -1, a wrong placement's reward) and a real wrong
    placement there."""
    cost = lambda scheme, n: step_penalty(scheme, n)  # noqa: E731
    # knocked off at step 5 (the episode ends), logged under authors-interactive
    rewards = [cost("authors-interactive", n) for n in range(1, 6)]
    ended = [False] * 4 + [True]
    by_rewards = rescore(rewards, ended, "authors-interactive", "paper")
    assert by_rewards[-1] == pytest.approx(-0.01)  # kept as a placement: wrong
    by_outcomes = rescore(rewards, ended, "authors-interactive", "paper", ["none"] * 4 + ["lost"])
    assert by_outcomes == [0.0] * 5  # the paper charges nothing up to step 18
    # step 119 under authors-autonomous: -1.0 either way; only the outcome says which
    n = 119
    assert cost("authors-autonomous", n) == pytest.approx(-1.0)
    rewards = [cost("authors-autonomous", k) for k in range(1, n + 1)]
    for last, kept in (("misplaced", -1.0), ("none", -0.01)):
        rescored = rescore(rewards, [False] * n, "authors-autonomous", "paper",
                           ["none"] * (n - 1) + [last])  # fmt: skip
        assert rescored[-1] == pytest.approx(kept)


def test_a_step_outcome_reads_the_counters_of_two_infos() -> None:
    before = {"placed_correct": 1, "misplaced": 0, "lost": 0}
    assert step_outcome(before, {**before, "placed_correct": 2}) == "placed"
    assert step_outcome(before, {**before, "misplaced": 1}) == "misplaced"
    assert step_outcome(before, {**before, "lost": 1}) == "lost"
    assert step_outcome(before, before) == "none"
