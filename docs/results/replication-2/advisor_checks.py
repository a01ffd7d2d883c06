"""Every advisor of replication 2 checked by SPEC section 5's rule, as its batch checked it,
the check stored beside the saved advisor (`state/advisors/.../final.pt.check.json`), and
a table of them (`advisor-checks.md`, `advisor-checks.csv`).

    commands.sh restore     # the saved state into DATA (/work/replication-2)
    cd /work/rep2 && PYTHONPATH=/work/rep2 python \\
        /work/main/docs/results/replication-2/advisor_checks.py /work/replication-2 \\
        /work/main/docs/results/replication-2
    commands.sh save        # copies the checks into state/advisors/

Runs with the tag's code (`learner.advisor_check` at `replication-2`). A check stored
beside a checkpoint for the same run is read back, not recomputed (`checked_advisor`): so
the checks a batch made and saved are the ones shown. Each check is made for the run it
gates, as `ideeprl batch` makes it: the advised arm's spec for agent seed 0 with the
advisor's checkpoint, from the advice-time states of agent seeds 0-9:

- the five `authors` advisors (sessions labelled `A advisor`): for A-agent, the `authors`
  preset, realism 0.05/0.05, `authors-interactive`;
- the `paper` advisor (`B advisor`): for B-agent (`paper`) and, by the plan's amendment 1,
  for A-agent (A's scenario).

Each row names the CPU kind that computed the check (kept beside it: `about`, by run key,
says where it was computed and for which arm) (the checks are deterministic
given the network and seeds; a bfloat16 kernel of another CPU kind could change a greedy
action where two Q-values nearly tie).
"""

from __future__ import annotations

import csv
import json
import sqlite3
import sys
from pathlib import Path

from learner.advisor_check import check_path, checked_advisor
from learner.machine import cpu_kind
from learner.run import RunSpec

SEEDS = tuple(range(10))


def span(values: list[int]) -> str:
    return f"{min(values)}-{max(values)}"


def advised_spec(db: sqlite3.Connection, study: str) -> RunSpec:
    """The study's first agent run of seed 0 (bfloat16): the spec its advisor was checked for."""
    (run,) = db.execute(
        "select s.run from sessions s join studies t on t.id = s.study_id where t.name = ? "
        "and json_extract(s.run, '$.method') = 'agent' and json_extract(s.run, '$.seed') = 0 "
        "and json_extract(s.run, '$.config.precision') = 'bf16' order by s.id limit 1",
        (study,),
    ).fetchone()
    return RunSpec.from_json(json.loads(run))


def authors_spec(db: sqlite3.Connection) -> RunSpec:
    """A-agent's spec. Its sessions carry the `paper` advisor (amendment 1); an `authors`
    advisor would have been checked for the same spec with its own checkpoint."""
    return advised_spec(db, "replication-2-authors")


def main(data: Path, out: Path) -> None:
    db = sqlite3.connect(data / "ideeprl.sqlite3")
    advisors = db.execute(
        "select s.id, t.name, s.label, json_extract(s.run, '$.seed'), s.checkpoint_path "
        "from sessions s join studies t on t.id = s.study_id where s.label like '% advisor' "
        "and s.status = 'finished' order by s.id"
    ).fetchall()
    a_spec, b_spec = authors_spec(db), advised_spec(db, "replication-2-paper")
    jobs = []
    for session, study, label, seed, checkpoint in advisors:
        if study == "replication-2-authors":
            jobs.append(
                (
                    session,
                    label,
                    seed,
                    checkpoint,
                    "A-agent (authors, realism 0.05/0.05, authors-interactive)",
                    a_spec,
                )
            )
        else:
            jobs.append((session, label, seed, checkpoint, "B-agent (paper)", b_spec))
            jobs.append(
                (
                    session,
                    label,
                    seed,
                    checkpoint,
                    "A-agent (authors, realism 0.05/0.05, authors-interactive): amendment 1",
                    a_spec,
                )
            )
    cpu = cpu_kind()
    rows = []
    for session, label, seed, checkpoint, gates, spec in jobs:
        check = checked_advisor(checkpoint, spec, SEEDS, allow_failed=True)
        stored = json.loads(check_path(checkpoint).read_text())
        about = stored.setdefault("about", {}).get(check.run_key) or {}
        # computed now, or by a batch on this machine's DATA, unless recorded
        kind = about.get("cpu") or stored.get("computed_on", {}).get(check.run_key) or cpu
        stored.pop("computed_on", None)
        stored["about"][check.run_key] = {"cpu": kind, "for": gates}
        check_path(checkpoint).write_text(json.dumps(stored, indent=2, sort_keys=True))
        at = check.at_advice
        row = {
            "advisor": f"{label}, seed {seed} (session {session})",
            "checked for": gates,
            "passed": "passed" if check.passed else "FAILED",
            "mean reward (fresh, needs 2.5)": f"{check.mean_reward:.2f}",
            "rewards of the 10 fresh episodes": " ".join(f"{r:.2f}" for r in check.rewards),
            "longest repeat (fresh, at most 10)": check.episode_longest_repeat,
            "placed at advice, seeds 0-9": span([q.placed for q in at]),
            "misplaced": f"{min(q.misplaced for q in at)}-{max(q.misplaced for q in at)}",
            "lost": f"{min(q.lost for q in at)}-{max(q.lost for q in at)}",
            "longest repeat at advice": span([q.longest_repeat for q in at]),
            "problems": "; ".join(check.problems) or "none",
            "check": f"{Path(checkpoint).relative_to(data)}.check.json, run key {check.run_key}",
            "computed on": kind,
        }
        rows.append(row)
        print(row["advisor"], "for", gates, ":", check.summary(), flush=True)
    with open(out / "advisor-checks.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    keys = [k for k in rows[0] if k not in ("rewards of the 10 fresh episodes", "check")]
    lines = [
        "# Replication 2: every advisor's check",
        "",
        "Written by [advisor_checks.py](advisor_checks.py) from the saved state; each check is",
        "stored beside its advisor in `state/advisors/checkpoints/session-N/final.pt.check.json`",
        "(each fresh episode's reward, and the advice from each agent seed's advice-time state,",
        "are there). The rule (SPEC section 5, `learner/advisor_check.py`): greedy on 10 fresh",
        "episodes of the advised run's scenario, mean collected reward at least 2.5 and no",
        "action more than 10 times in a row; from the advice-time states of agent seeds 0-9, no",
        "action more than 10 times in a row.",
        "",
        "| " + " | ".join(keys) + " |",
        "|" + "---|" * len(keys),
    ]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    (out / "advisor-checks.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
