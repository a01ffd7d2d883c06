"""Shared helpers for the scenario's tests: real environments, driven by real actions."""

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pytest

import sim


@pytest.fixture(scope="module")
def fast_env() -> Iterator[sim.SortingEnv]:
    env = sim.SortingEnv(motion="fast")
    yield env
    env.close()


@pytest.fixture(scope="module")
def physics_env() -> Iterator[sim.SortingEnv]:
    env = sim.SortingEnv(motion="physics")
    yield env
    env.close()


def run_oracle(
    env: sim.SortingEnv, seed: int, sort_rule: Any = "color", limit: int = 250
) -> tuple[float, int, bool, bool, dict[str, Any]]:
    """One episode of the oracle policy: (return, steps, terminated, truncated, last info)."""
    _, info = env.reset(seed=seed)
    total, steps = 0.0, 0
    terminated = truncated = False
    while not (terminated or truncated) and steps < limit:
        _, reward, terminated, truncated, info = env.step(sim.oracle_action(info, sort_rule))
        total += reward
        steps += 1
    return total, steps, terminated, truncated, info


def replay(
    env: sim.SortingEnv, seed: int, actions: Sequence[int]
) -> list[tuple[bytes, float, bool, bool, dict[str, Any]]]:
    """Every step's (observation bytes, reward, terminated, truncated, info), reset first."""
    obs, info = env.reset(seed=seed)
    trace: list[tuple[bytes, float, bool, bool, dict[str, Any]]] = [
        (obs.tobytes(), 0.0, False, False, info)
    ]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        trace.append((obs.tobytes(), reward, terminated, truncated, info))
        if terminated or truncated:
            break
    return trace


def seed_whose_first_grab_is(env: sim.SortingEnv, color: str) -> int:
    """A seed for which the first grab picks an object of `color` (the choice is random)."""
    for seed in range(100):
        env.reset(seed=seed)
        _, _, _, _, info = env.step(sim.Action.GRAB)
        if info["held_color"] == color:
            return seed
    raise AssertionError(f"no seed in 0..99 grabs a {color} object first")


def clearly_different(a: np.ndarray, b: np.ndarray) -> int:
    """Pixels where some channel differs by more than 30 levels (out of 255)."""
    diff = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1)
    return int((diff > 30).sum())
