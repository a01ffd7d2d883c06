"""Agents alone against the same seeds in populations: the equivalence study of
`ideeprl batch --population` (issue "The paper's experiment in half an hour", point 3).

    python docs/results/populations/compare.py DATABASE \
        --pair paper replication-2-paper:B equivalence-paper-alone:B-alone \
        --pair authors replication-2-authors:A-auto equivalence-authors-alone:A-auto-alone \
        --out docs/results/populations

Each pair names a population arm and an alone arm (study name:session label) of one
database; their autonomous sessions pair up by seed. `--roles` names the two arms
otherwise, so that any two arms of one learner compare the same way: the float32 control
against its bfloat16 arm (`--roles fp32 bf16`, ../replication-2/precision/).

For every pair of sessions it compares the step logs in the columns that decide an
agent's course (action, its source, the advised action, reward, termination, truncation
and the observation's hash) and the Q-values; it tests the R_T difference for equivalence
within 3 % of the reference arm's mean (paired TOST, `analysis.equivalence`), and draws
both arms' mean curves and R_T.
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


def compare(
    db: sqlite3.Connection,
    name: str,
    population: str,
    alone: str,
    roles: tuple[str, str] = ("population", "alone"),
) -> dict:
    """`population` against `alone` (the reference), seed by seed; `roles` names them in
    the table's columns."""
    other, ref = roles
    pop, solo = sessions(db, population), sessions(db, alone)
    seeds = [
        s
        for s in pop.index
        if s in solo.index and pop.at[s, "status"] == solo.at[s, "status"] == "finished"
    ]
    rows, curves = [], {ref: [], other: []}
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
        curves[ref].append(ra)
        curves[other].append(rb)
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
                f"{ref}_session": int(solo.at[seed, "session_id"]),
                f"{other}_session": int(pop.at[seed, "session_id"]),
                "population_sizes": " ".join(map(str, sizes)),
                f"steps_{ref}": len(a),
                f"steps_{other}": len(b),
                "course_identical_steps": agree,
                "first_difference_at_step": first_diff,
                "q_max_abs_difference_while_identical": q_diff,
                f"R_T_{ref}": float(ra.sum()),
                f"R_T_{other}": float(rb.sum()),
                f"minutes_{ref}": hours(solo.at[seed, "started"], solo.at[seed, "finished"]),
                f"minutes_{other}": hours(pop.at[seed, "started"], pop.at[seed, "finished"]),
            }
        )
    table = pd.DataFrame(rows)
    result = None
    if len(table) >= 2:
        margin = relative_margin(table[f"R_T_{ref}"], 0.03)
        result = paired_tost(table[f"R_T_{ref}"], table[f"R_T_{other}"], margin)
    return {
        "name": name,
        "roles": roles,
        "table": table,
        "tost": result,
        "curves": curves,
        "population": population,
        "alone": alone,
    }


def figure(results: list[dict], out: Path) -> None:
    fig, axes = plt.subplots(2, len(results), figsize=(6 * len(results), 8), squeeze=False)
    for column, r in enumerate(results):
        other, ref = r["roles"]
        ax = axes[0][column]
        for arm, colour in ((ref, "tab:blue"), (other, "tab:orange")):
            if not r["curves"][arm]:
                continue
            length = min(len(c) for c in r["curves"][arm])
            data = np.stack([c[:length] for c in r["curves"][arm]])
            mean = data.mean(0)
            band = 1.96 * data.std(0, ddof=1) / np.sqrt(len(data)) if len(data) > 1 else 0 * mean
            x = np.arange(1, length + 1)
            style = "-" if arm == ref else "--"
            ax.plot(x, mean, style, color=colour, label=f"{arm} ({len(data)} agents)")
            ax.fill_between(x, mean - band, mean + band, color=colour, alpha=0.15)
        ax.set_title(f"{r['name']}: mean collected reward per episode (95 % band)")
        ax.set_xlabel("episode")
        ax.set_ylabel("collected reward")
        ax.legend()
        ax = axes[1][column]
        t = r["table"]
        if not t.empty:
            x, y = t[f"R_T_{ref}"], t[f"R_T_{other}"]
            ax.scatter(x, y, color="tab:purple")
            for seed, xi, yi in zip(t["seed"], x, y, strict=True):
                ax.annotate(str(seed), (xi, yi))
            low, high = min(x.min(), y.min()), max(x.max(), y.max())
            ax.plot([low, high], [low, high], color="grey", lw=0.8)
        ax.set_title(f"{r['name']}: R_T per seed, {other} against {ref}")
        ax.set_xlabel(f"R_T {ref}")
        ax.set_ylabel(f"R_T {other}")
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
    parser.add_argument(
        "--roles", nargs=2, default=("population", "alone"), metavar=("FIRST", "REFERENCE")
    )
    args = parser.parse_args()
    db = sqlite3.connect(f"file:{args.database}?mode=ro", uri=True)
    results = [compare(db, *pair, roles=tuple(args.roles)) for pair in args.pair]
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
