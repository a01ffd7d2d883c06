"""R_T rescored from the step logs under each reward scheme.

The same behaviour scores differently under the authors' two accountings: what a method
"collects" depends on the rule as much as on the learner. Rescoring each logged training
step (a placement keeps its reward, every other step costs what the scheme says, see
`sim.rewards.rescore`) shows each method's R_T under every scheme, so methods run under
different schemes can still be compared under one.
"""

from __future__ import annotations

import pandas as pd

from analysis.episodes import method_name, order_methods
from analysis.stats import improvement_pct, student_t_test
from sim.rewards import REWARD_SCHEMES, rescore

STEP_COLUMNS: tuple[str, ...] = (
    "session_id",
    "episode",
    "episode_step",
    "reward",
    "terminated",
)
"""One row per training step (episode 1..N within the session, `episode_step` from 1, every
step of each episode present: a step's cost depends on its number in the episode), and an
optional `outcome` (`sim.rewards.OUTCOMES`; missing in logs recorded before it was kept):
an episode whose steps all have one is rescored by them, else by its rewards."""


def rescored_totals(
    steps: pd.DataFrame, schemes: dict[int, str], n_episodes: int | None = None
) -> pd.DataFrame:
    """Per session: R_T as logged and under each scheme (`R_T_<scheme>` columns), over its
    first `n_episodes` episodes (all when None). `schemes` maps a session to the scheme
    its steps were scored under."""
    table = steps
    if n_episodes is not None:
        table = table[table["episode"] <= n_episodes]
    table = table.sort_values(["session_id", "episode", "episode_step"])
    rows = []
    for session_id, group in table.groupby("session_id", sort=True):
        scheme = schemes[int(session_id)]
        row: dict[str, object] = {
            "session_id": int(session_id),
            "scheme": scheme,
            "R_T_logged": float(group["reward"].sum()),
        }
        episodes = [
            ([float(r) for r in e["reward"]], [bool(t) for t in e["terminated"]], _outcomes(e))
            for _, e in group.groupby("episode", sort=True)
        ]
        row["by_outcomes"] = all(outcomes is not None for _, _, outcomes in episodes)
        for target in REWARD_SCHEMES:
            row[f"R_T_{target}"] = sum(
                sum(rescore(rewards, ended, scheme, target, outcomes))
                for rewards, ended, outcomes in episodes
            )
        rows.append(row)
    return pd.DataFrame(rows)


def _outcomes(episode: pd.DataFrame) -> list[str | None] | None:
    """The episode's step outcomes, or None when any is unknown (an older log)."""
    if "outcome" not in episode:
        return None
    values = list(episode["outcome"])
    if any(v is None or (isinstance(v, float) and v != v) for v in values):
        return None
    return [str(v) for v in values]


def rescoring_table(
    totals: pd.DataFrame, methods: dict[int, str], baseline: str | None = None
) -> pd.DataFrame:
    """Per method: the schemes its sessions were scored under, mean R_T as logged and under
    each scheme, and (with a baseline) the improvement in percent under each scheme and,
    under each scheme, Welch's p for the agents' R_T against the baseline's (NaN with
    fewer than two agents on a side)."""
    frame = totals.assign(method=totals["session_id"].map(methods))
    out = []
    for method in order_methods(frame["method"], baseline):
        group = frame[frame["method"] == method]
        row: dict[str, object] = {
            "method": method,
            "name": method_name(method),
            "agents": len(group),
            "logged_under": " | ".join(sorted(set(group["scheme"]))),
            "R_T_logged": group["R_T_logged"].mean(),
        }
        for scheme in REWARD_SCHEMES:
            row[f"R_T_{scheme}"] = group[f"R_T_{scheme}"].mean()
        out.append(row)
    table = pd.DataFrame(out)
    if baseline is not None and baseline in set(table["method"]):
        base = table.set_index("method")
        for logged_or_scheme in ("logged", *REWARD_SCHEMES):
            column = f"R_T_{logged_or_scheme}"
            reference = float(base.loc[baseline, column])
            table[f"improvement_{logged_or_scheme}"] = [
                improvement_pct(value, reference) for value in table[column]
            ]
        # Under one scheme the agents' R_T are comparable, so they can be tested.
        ours = frame["method"] == baseline
        for scheme in REWARD_SCHEMES:
            column = f"R_T_{scheme}"
            table[f"p_welch_{scheme}"] = [
                float("nan")
                if method == baseline
                else student_t_test(
                    frame.loc[frame["method"] == method, column].to_numpy(),
                    frame.loc[ours, column].to_numpy(),
                    equal_var=False,
                )[1]
                for method in table["method"]
            ]
    return table
