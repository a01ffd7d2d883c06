"""What each advised session's advice did: the check a reviewer asks for before believing
that an advised arm's effect comes from the advice (docs/results: the replication's stuck
advisor placed 4 objects in 100 advice and its seed still had the best R_T).

From the steps whose action came from the advisor (`action_source` advisor, any stage):
placements right and wrong, objects lost, and the longest run of one advised action; and,
per advised method, how the number of correct placements relates to the agents' R_T
(Spearman's rank correlation: with 5-10 agents, a rough sign, not a test).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from analysis.episodes import method_name

ADVICE_COLUMNS = ["session_id", "global_step", "action", "outcome", "stage", "episode", "reward"]
"""The advised steps a report needs, in step order per session (`stage` as
`learner.records` spells it: `pretrain`, `train`)."""
REPLAYED_ADVICE_COLUMNS = ["session_id", "action", "same_observation"]
"""A replay's advice rows: `action` missing for a request past the recorded stream,
`same_observation` whether the replayed advice met the image its advisor saw."""
PLACED_COUNTS = ("placed", "misplaced", "lost")
"""The sorting robot's placements by advised actions, which only its advice has."""
QUALITY_COLUMNS = [
    "session_id", "method", "label", "advice", "placed", "misplaced", "lost",
    "unknown_outcome", "longest_repeat", "R_T",
]  # fmt: skip


def _longest_repeat(actions: np.ndarray) -> int:
    if len(actions) == 0:
        return 0
    changes = np.flatnonzero(np.diff(actions) != 0)
    bounds = np.concatenate(([-1], changes, [len(actions) - 1]))
    return int(np.diff(bounds).max())


def advice_quality(advice: pd.DataFrame, agents: pd.DataFrame) -> pd.DataFrame:
    """One row per advised session (`QUALITY_COLUMNS`); `agents` is the report's per-agent
    table (session_id, method, label, R_T). Sessions without advice are left out."""
    rows = []
    for session_id, steps in advice.sort_values(["session_id", "global_step"]).groupby(
        "session_id"
    ):
        agent = agents.loc[agents["session_id"] == session_id]
        if agent.empty:
            continue
        outcome = steps["outcome"]
        rows.append(
            {
                "session_id": int(session_id),
                "method": agent["method"].iloc[0],
                "label": agent["label"].iloc[0],
                "advice": len(steps),
                "placed": int((outcome == "placed").sum()),
                "misplaced": int((outcome == "misplaced").sum()),
                "lost": int((outcome == "lost").sum()),
                "unknown_outcome": int(outcome.isna().sum()),
                "longest_repeat": _longest_repeat(steps["action"].to_numpy()),
                "R_T": float(agent["R_T"].iloc[0]),
            }
        )
    return pd.DataFrame(rows, columns=QUALITY_COLUMNS)


def quality_correlations(quality: pd.DataFrame) -> pd.DataFrame:
    """Per advised method: agents, mean correct placements, and Spearman's rho (and p)
    between an agent's correct placements and its R_T (NaN below 3 agents or without
    variation)."""
    rows = []
    for method, group in quality.groupby("method", sort=False):
        rho = p = float("nan")
        if len(group) >= 3 and group["placed"].nunique() > 1 and group["R_T"].nunique() > 1:
            result = stats.spearmanr(group["placed"], group["R_T"])
            rho, p = float(result.statistic), float(result.pvalue)
        rows.append(
            {
                "method": method,
                "agents": len(group),
                "mean_placed": float(group["placed"].mean()),
                "mean_longest_repeat": float(group["longest_repeat"].mean()),
                "spearman_rho": rho,
                "spearman_p": p,
            }
        )
    return pd.DataFrame(
        rows,
        columns=["method", "agents", "mean_placed", "mean_longest_repeat", "spearman_rho",
                 "spearman_p"],
    )  # fmt: skip


def replayed_advice_notes(advice: pd.DataFrame, arms: dict[int, str]) -> list[str]:
    """Per replayed arm (`arms`: a replay's session id to its arm), how much of its advice
    met the image its advisor saw. Advice fed by order to another learner meets other
    states as the runs part; advice given on another image is a person's answer to a
    question the learner did not ask, and the arm's effect is that much less the people's."""
    notes = []
    for arm in dict.fromkeys(arms.values()):
        rows = advice[advice["session_id"].map(arms) == arm]
        given = rows[rows["action"].notna()]
        met = int(given["same_observation"].fillna(False).astype(bool).sum())
        past = len(rows) - len(given)
        replays = sum(a == arm for a in arms.values())
        note = (
            f"The {method_name(arm)} arm ({replays} replay{'s' if replays != 1 else ''}): "
            f"{met} of {len(given)} replayed advice met the image its advisor saw "
            "(`same_observation`)"
        )
        if met < len(given):
            note += "; the rest answered another state than the one the learner was in"
        if past:
            note += f"; {past} request(s) came after the recorded advice ran out and got none"
        notes.append(note + ".")
    return notes
