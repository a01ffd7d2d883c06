"""Agents alone against the same seeds in populations: the equivalence study of
`ideeprl batch --population` (issue "The paper's experiment in half an hour", point 3).

    python docs/results/populations/compare.py DATABASE \
        --pair paper replication-2-paper:B equivalence-paper-alone:B-alone \
        --pair authors replication-2-authors:A-auto equivalence-authors-alone:A-auto-alone \
        --out docs/results/populations

Each pair names a population arm and an alone arm (study name:session label) of one
database; their autonomous sessions pair up by seed. For every pair of sessions it
compares the step logs in the columns that decide an agent's course (action, its source,
the advised action, reward, termination, truncation and the observation's hash) and the
Q-values; it tests the R_T difference for equivalence within 3 % of the alone arm's mean
(paired TOST, `analysis.equivalence`), and draws both arms' mean curves and R_T.
Writes `README.md` (numbers), `pairs.csv` and the figure (PNG and SVG) to --out.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys
from datetime import datetime
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from analysis.equivalence import paired_tost, relative_margin

COURSE = (
    "action",
    "action_source",
    "advised_action",
    "reward",
    "terminated",
    "truncated",
    "observation_hash",
)
Q = ("q_grab", "q_move_right", "q_move_left", "q_drop")


def sessions(db: sqlite3.Connection, arm: str) -> pd.DataFrame:
    study, label = arm.split(":", 1)
    rows = db.execute(
        "select s.id, json_extract(s.run, '$.seed'), s.status, s.started_at, s.finished_at, "
        "s.provenance from sessions s join studies t on t.id = s.study_id where t.name = ? "
        "and s.label = ? and json_extract(s.run, '$.method') = 'autonomous'",
        (study, label),
    ).fetchall()
    table = pd.DataFrame(
        rows, columns=["session_id", "seed", "status", "started", "finished", "provenance"]
    )
    if table.empty:
        sys.exit(f"no autonomous sessions labelled {label!r} in study {study!r}")
    return table.set_index("seed").sort_index()


def steps(db: sqlite3.Connection, session_id: int) -> pd.DataFrame:
    columns = ", ".join(("global_step", *COURSE, *Q))
    return pd.read_sql_query(
        f"select {columns} from steps where session_id = ? order by global_step",
        db,
        params=(session_id,),
    )


def episode_rewards(db: sqlite3.Connection, session_id: int) -> np.ndarray:
    rows = db.execute(
        "select collected_reward from episodes where session_id = ? and stage = 'train' "
        "order by episode",
        (session_id,),
    ).fetchall()
    return np.array([r[0] for r in rows], dtype=float)


def hours(start: str | None, end: str | None) -> float:
    if not (start and end):
        return float("nan")
    return (datetime.fromisoformat(end) - datetime.fromisoformat(start)).total_seconds() / 60


def compare(db: sqlite3.Connection, name: str, population: str, alone: str) -> dict:
    pop, solo = sessions(db, population), sessions(db, alone)
    seeds = [
        s
        for s in pop.index
        if s in solo.index and pop.at[s, "status"] == solo.at[s, "status"] == "finished"
    ]
    rows, curves = [], {"population": [], "alone": []}
    for seed in seeds:
        a, b = (
            steps(db, int(solo.at[seed, "session_id"])),
            steps(db, int(pop.at[seed, "session_id"])),
        )
        n = min(len(a), len(b))
        same = (
            a[list(COURSE)].iloc[:n].reset_index(drop=True).fillna(-1)
            == b[list(COURSE)].iloc[:n].reset_index(drop=True).fillna(-1)
        ).all(axis=1)
        first_diff = (
            int(a["global_step"].iloc[int(np.argmin(same.values))]) if not same.all() else None
        )
        qa, qb = a[list(Q)].iloc[:n].to_numpy(), b[list(Q)].iloc[:n].to_numpy()
        agree = n if first_diff is None else int(np.argmin(same.values))
        q_diff = float(np.abs(qa[:agree] - qb[:agree]).max()) if agree else float("nan")
        ra, rb = (
            episode_rewards(db, int(solo.at[seed, "session_id"])),
            episode_rewards(db, int(pop.at[seed, "session_id"])),
        )
        curves["alone"].append(ra)
        curves["population"].append(rb)
        sizes = sorted(
            {
                (e.get("population") or {}).get("population_size", 1)
                for e in json.loads(pop.at[seed, "provenance"] or "[]")
            }
        )
        rows.append(
            {
                "preset": name,
                "seed": int(seed),
                "alone_session": int(solo.at[seed, "session_id"]),
                "population_session": int(pop.at[seed, "session_id"]),
                "population_sizes": " ".join(map(str, sizes)),
                "steps_alone": len(a),
                "steps_population": len(b),
                "course_identical_steps": agree,
                "first_difference_at_step": first_diff,
                "q_max_abs_difference_while_identical": q_diff,
                "R_T_alone": float(ra.sum()),
                "R_T_population": float(rb.sum()),
                "minutes_alone": hours(solo.at[seed, "started"], solo.at[seed, "finished"]),
                "minutes_population": hours(pop.at[seed, "started"], pop.at[seed, "finished"]),
            }
        )
    table = pd.DataFrame(rows)
    result = None
    if len(table) >= 2:
        margin = relative_margin(table["R_T_alone"], 0.03)
        result = paired_tost(table["R_T_alone"], table["R_T_population"], margin)
    return {
        "name": name,
        "table": table,
        "tost": result,
        "curves": curves,
        "population": population,
        "alone": alone,
    }


def figure(results: list[dict], out: Path) -> None:
    fig, axes = plt.subplots(2, len(results), figsize=(6 * len(results), 8), squeeze=False)
    for column, r in enumerate(results):
        ax = axes[0][column]
        for arm, colour in (("alone", "tab:blue"), ("population", "tab:orange")):
            if not r["curves"][arm]:
                continue
            length = min(len(c) for c in r["curves"][arm])
            data = np.stack([c[:length] for c in r["curves"][arm]])
            mean = data.mean(0)
            band = 1.96 * data.std(0, ddof=1) / np.sqrt(len(data)) if len(data) > 1 else 0 * mean
            x = np.arange(1, length + 1)
            style = "-" if arm == "alone" else "--"
            ax.plot(x, mean, style, color=colour, label=f"{arm} ({len(data)} agents)")
            ax.fill_between(x, mean - band, mean + band, color=colour, alpha=0.15)
        ax.set_title(f"{r['name']}: mean collected reward per episode (95 % band)")
        ax.set_xlabel("episode")
        ax.set_ylabel("collected reward")
        ax.legend()
        ax = axes[1][column]
        t = r["table"]
        if not t.empty:
            ax.scatter(t["R_T_alone"], t["R_T_population"], color="tab:purple")
            for _, row in t.iterrows():
                ax.annotate(str(row["seed"]), (row["R_T_alone"], row["R_T_population"]))
            low = min(t["R_T_alone"].min(), t["R_T_population"].min())
            high = max(t["R_T_alone"].max(), t["R_T_population"].max())
            ax.plot([low, high], [low, high], color="grey", lw=0.8)
        ax.set_title(f"{r['name']}: R_T per seed, alone against in a population")
        ax.set_xlabel("R_T alone")
        ax.set_ylabel("R_T in a population")
    fig.tight_layout()
    for suffix in ("png", "svg"):
        fig.savefig(out / f"equivalence.{suffix}", dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("database")
    parser.add_argument(
        "--pair", nargs=3, action="append", required=True, metavar=("NAME", "POPULATION", "ALONE")
    )
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    db = sqlite3.connect(f"file:{args.database}?mode=ro", uri=True)
    results = [compare(db, *pair) for pair in args.pair]
    args.out.mkdir(parents=True, exist_ok=True)
    pd.concat([r["table"] for r in results]).to_csv(args.out / "pairs.csv", index=False)
    figure(results, args.out)
    for r in results:
        t = r["table"]
        print(f"## {r['name']}: {r['population']} against {r['alone']}")
        print(
            f"- pairs: {len(t)}; course identical through the whole run: "
            f"{int((t['first_difference_at_step'].isna()).sum()) if len(t) else 0} of {len(t)}"
        )
        if r["tost"] is not None:
            print(f"- R_T: {r['tost'].sentence()}")


if __name__ == "__main__":
    main()
