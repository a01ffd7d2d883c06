"""Made-up learning curves shaped like the paper's, to demonstrate the report.

Nothing here is a result: `python -m analysis --demo OUT` uses it to show what a
report looks like before any agent has been trained, and the dashboard can use it as an
example. Advised agents learn earlier than autonomous ones, as in the paper's Figure 5.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

DEFAULT_AGENTS: dict[str, int] = {"autonomous": 10, "agent": 10, "human": 11}
"""The paper's study: ten autonomous, ten agent-advised, eleven human-advised agents."""

_MIDPOINT: dict[str, float] = {"autonomous": 0.45, "agent": 0.16, "human": 0.19, "oracle": 0.12}
"""When an agent is half-way through learning, as a fraction of the run."""


def demo_episodes(
    agents: Mapping[str, int] | None = None, *, n_episodes: int = 300, seed: int = 0
) -> pd.DataFrame:
    """An episode table with made-up but plausible curves (see the module docstring)."""
    agents = DEFAULT_AGENTS if agents is None else agents
    rng = np.random.default_rng(seed)
    episode = np.arange(1, n_episodes + 1)
    frames = []
    session = 0
    for method, count in agents.items():
        for k in range(count):
            session += 1
            midpoint = _MIDPOINT.get(method, 0.5) * n_episodes * rng.uniform(0.7, 1.3)
            width = n_episodes * rng.uniform(0.04, 0.08)
            learned = 1.0 / (1.0 + np.exp(-(episode - midpoint) / width))
            misplaced = (rng.random(n_episodes) < 0.9 * (1 - learned)).astype(int)
            lost = ((rng.random(n_episodes) < 0.08) & (misplaced == 0)).astype(int)
            placed = np.where(misplaced == 1, rng.integers(0, 6, n_episodes), 6 - lost)
            dithering = rng.poisson(150 * (1 - learned))
            steps = np.minimum(
                250, np.where(misplaced == 1, 3 * placed + 3 + dithering // 2, 18 + dithering)
            )
            reward = np.where(
                misplaced == 1,
                0.4 * placed - 1.0 - 0.01 * np.maximum(steps - 18, 0),
                0.4 * (placed - 1) + 1.0 - 0.01 * np.maximum(steps - 18, 0),
            )
            epsilon = np.maximum(0.01, 0.9995 ** (1000 + np.cumsum(steps)))
            frames.append(
                pd.DataFrame(
                    {
                        "session_id": session,
                        "method": method,
                        "seed": seed * 1000 + k,
                        "episode": episode,
                        "collected_reward": reward,
                        "steps": steps,
                        "placed_correct": placed,
                        "misplaced": misplaced,
                        "lost": lost,
                        "epsilon": epsilon,
                    }
                )
            )
    return pd.concat(frames, ignore_index=True)
