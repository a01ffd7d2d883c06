"""Episode tables built from curves written out by hand."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import pandas as pd


def episodes_from_curves(
    curves: Mapping[str, tuple[str, Sequence[float]]], **extra: Mapping[str, Sequence[float]]
) -> pd.DataFrame:
    """One row per (agent, episode) from {label: (method, rewards)}; session ids 1, 2, ..."""
    rows = []
    for session, (label, (method, rewards)) in enumerate(curves.items(), start=1):
        for episode, reward in enumerate(rewards, start=1):
            row = {
                "session_id": session,
                "method": method,
                "label": label,
                "episode": episode,
                "collected_reward": reward,
            }
            for column, values in extra.items():
                row[column] = values[label][episode - 1]
            rows.append(row)
    return pd.DataFrame(rows)


HAND_CASE = {
    "DeepRL1": ("autonomous", [1.0, 0.0, 2.0]),
    "DeepRL2": ("autonomous", [2.0, 1.0, 2.0]),
    "agent-IDeepRL1": ("agent", [2.0, 2.0, 2.0]),
    "agent-IDeepRL2": ("agent", [1.0, 3.0, 4.0]),
    "human-IDeepRL1": ("human", [3.0, 3.0, 3.0]),
}
"""R_T per agent 3, 5, 6, 8, 9; per method 4 (autonomous), 7 (agent), 9 (human)."""
