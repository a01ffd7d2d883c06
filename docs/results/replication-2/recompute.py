"""Every number of replication 2's write-up, recomputed from the saved state alone.

    cd docs/results/replication-2 && ../../../.venv/bin/python recompute.py > recomputed.md

Reads `state/db/` (merged into a temporary database by `state.py`) and the advisor checks
stored beside the saved advisors (`state/advisors/**/final.pt.check.json`); needs numpy and
scipy, not the platform. R_T is an agent's collected reward summed over its 300 training
episodes (`episodes.stage = 'train'`). A comparison pairs its arms' agents by seed, over
the seeds both arms have finished, and gives the mean difference (second arm minus first)
in R_T and in percent of the first arm's mean over those seeds, its 95 % t interval, the
paired t-test (the plan's primary test), Welch's test, and for the equivalence questions
the 90 % interval and the two one-sided tests at ±3 % of the reference arm's mean. What
the plan pre-registered and what is exploratory is said beside each (docs/results/plan.md).
"""

from __future__ import annotations

import json
import sqlite3
import sys
import tempfile
from collections import Counter
from datetime import datetime
from pathlib import Path

import numpy as np
from scipy import stats

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from state import merge  # noqa: E402

ARMS = {  # name: (study, label, method, precision)
    "B-auto": ("replication-2-paper", "B", "autonomous", "bf16"),
    "B-agent": ("replication-2-paper", "B", "agent", "bf16"),
    "B-procedure": ("replication-2-paper", "B", "procedure", "bf16"),
    "B-auto-alone": ("equivalence-paper-alone", "B-alone", "autonomous", "bf16"),
    "B-agent-alone": ("equivalence-paper-agent-alone", "B-agent-alone", "agent", "bf16"),
    "A-auto": ("replication-2-authors", "A", "autonomous", "bf16"),
    "A-agent": ("replication-2-authors", "A", "agent", "bf16"),
    "A-procedure": ("replication-2-authors", "A", "procedure", "bf16"),
    "A-auto-alone": ("equivalence-authors-alone", "A-auto-alone", "autonomous", "bf16"),
    "A-auto-amx": ("replication-2-authors-amx", "A-auto-amx", "autonomous", "bf16"),
    "A-auto-own": ("replication-2-authors", "A-own", "autonomous", "bf16"),
    "A-auto-fp32": ("replication-2-authors", "A-fp32", "autonomous", "fp32"),
    "A-agent-fp32": ("replication-2-authors", "A-fp32", "agent", "fp32"),
}
PLANNED = {  # the plan's agents per arm (amendments 2 and 3 add the exploratory ones)
    "B-auto": 10,
    "B-agent": 10,
    "B-procedure": 10,
    "A-auto": 10,
    "A-agent": 10,
    "A-procedure": 10,
    "A-auto-own": 10,
    "A-auto-fp32": 3,
    "A-agent-fp32": 3,
    "A-auto-amx": 10,
    "B-agent-alone": 10,
    "B-auto-alone": 10,
    "A-auto-alone": 10,
}
KIND_WAITS = {  # amendment 3: the CPU kind each arm runs on
    "B-procedure": "AMD EPYC with AVX-512 BF16",
    "B-agent-alone": "AMD EPYC with AVX-512 BF16",
    "A-agent": "Intel Xeon with AMX",
    "A-procedure": "Intel Xeon with AMX",
    "A-auto-amx": "Intel Xeon with AMX",
    "A-auto-own": "Intel Xeon with AMX",
    "A-agent-fp32": "Intel Xeon with AMX",
}
PLANNED_TEST = "the plan's equivalence test"
COURSE = (
    "action",
    "action_source",
    "advised_action",
    "reward",
    "terminated",
    "truncated",
    "observation_hash",
)


def short_cpu(cpu: str) -> str:
    if "AMX" in cpu:
        return "Xeon AMX"
    if "BF16" in cpu:
        return "EPYC BF16"
    return "EPYC AVX2" if "EPYC" in cpu else cpu


FIELDS = (
    "id", "study", "label", "method", "seed", "precision", "provenance",
    "created", "started", "finished", "r_t", "episodes",
)  # fmt: skip


class Data:
    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db
        rows = db.execute(
            "select s.id, t.name, s.label, json_extract(s.run, '$.method'), "
            "json_extract(s.run, '$.seed'), json_extract(s.run, '$.config.precision'), "
            "s.provenance, s.created_at, s.started_at, s.finished_at, "
            "(select sum(collected_reward) from episodes e where e.session_id = s.id and "
            "e.stage = 'train'), (select count(*) from episodes e where e.session_id = s.id "
            "and e.stage = 'train') from sessions s join studies t on t.id = s.study_id "
            "where s.status = 'finished' order by s.id"
        ).fetchall()
        self.sessions = [dict(zip(FIELDS, r, strict=True)) for r in rows]
        for s in self.sessions:
            s["provenance"] = json.loads(s["provenance"])

    def arm(self, name: str) -> dict[int, dict]:
        study, label, method, precision = ARMS[name]
        return {
            s["seed"]: s
            for s in self.sessions
            if (s["study"], s["label"], s["method"], s["precision"])
            == (study, label, method, precision)
        }


def fmt_p(p: float) -> str:
    return f"{p:.2g}" if p < 0.001 else f"{p:.3f}"


def describe_arm(data: Data, name: str) -> str:
    arm = data.arm(name)
    if not arm:
        return f"| {name} | 0 of {PLANNED[name]} | | | | | |"
    r = np.array([s["r_t"] for s in arm.values()])
    cpus = Counter(short_cpu(p["cpu"]) for s in arm.values() for p in s["provenance"][:1])
    codes = {p["code"] for s in arm.values() for p in s["provenance"]}
    resumed = sorted(seed for seed, s in arm.items() if len(s["provenance"]) > 1)
    seeds = sorted(arm)
    seed_text = (
        f"{seeds[0]}-{seeds[-1]}"
        if seeds == list(range(seeds[0], seeds[-1] + 1))
        else ",".join(map(str, seeds))
    )
    assert all(s["episodes"] == 300 for s in arm.values()), name
    return (
        f"| {name} | {len(arm)} {'of' if len(arm) <= PLANNED[name] else 'with'} {PLANNED[name]} "
        f"{'' if len(arm) <= PLANNED[name] else 'planned '}(seeds {seed_text}) | {r.mean():.2f} | "
        f"{r.std(ddof=1) if len(r) > 1 else float('nan'):.2f} | "
        f"{', '.join(f'{k} {v}' for k, v in sorted(cpus.items()))} | {', '.join(sorted(codes))} | "
        f"{', '.join(map(str, resumed)) or 'none'} |"
    )


def compare(
    data: Data,
    first: str,
    second: str,
    what: str,
    equivalence: bool | str = False,
    only: range | None = None,
) -> dict:
    a, b = data.arm(first), data.arm(second)
    seeds = sorted(s for s in set(a) & set(b) if only is None or s in only)
    out = {"first": first, "second": second, "what": what, "n": len(seeds)}
    if len(seeds) < 2:
        out["text"] = f"- **{second} against {first}** ({what}): {len(seeds)} pairs, not computed."
        return out
    x = np.array([a[s]["r_t"] for s in seeds])
    y = np.array([b[s]["r_t"] for s in seeds])
    d = y - x
    n, mean, sd = len(d), d.mean(), d.std(ddof=1)
    se = sd / np.sqrt(n)
    t_crit95 = stats.t.ppf(0.975, n - 1)
    t_stat, p = stats.ttest_rel(y, x)
    welch = stats.ttest_ind(y, x, equal_var=False).pvalue
    ref = x.mean()
    out.update(
        mean_first=x.mean(),
        mean_second=y.mean(),
        diff=mean,
        pct=100 * mean / ref,
        lo=mean - t_crit95 * se,
        hi=mean + t_crit95 * se,
        t=t_stat,
        p=p,
        welch=welch,
        sd_diff=sd,
    )
    text = (
        f"- **{second} against {first}** ({what}; {n} pairs, seeds {seeds[0]}-{seeds[-1]}): "
        f"R_T {y.mean():.2f} against {x.mean():.2f}, difference {mean:+.2f} "
        f"({100 * mean / ref:+.2f} %), 95 % interval [{mean - t_crit95 * se:+.2f}, "
        f"{mean + t_crit95 * se:+.2f}] ([{100 * (mean - t_crit95 * se) / ref:+.1f} %, "
        f"{100 * (mean + t_crit95 * se) / ref:+.1f} %]); paired t = {t_stat:.2f}, "
        f"p = {fmt_p(p)}; Welch p = {fmt_p(welch)}; SD of the paired differences {sd:.2f}"
    )
    if equivalence:
        margin = 0.03 * ref
        t90 = stats.t.ppf(0.95, n - 1)
        p_low = stats.t.sf((mean + margin) / se, n - 1)
        p_high = stats.t.cdf((mean - margin) / se, n - 1)
        tost = max(p_low, p_high)
        out.update(lo90=mean - t90 * se, hi90=mean + t90 * se, margin=margin, tost=tost)
        text += (
            f"; {PLANNED_TEST if equivalence == 'planned' else 'exploratory'}: "
            f"90 % interval [{mean - t90 * se:+.2f}, {mean + t90 * se:+.2f}] against the "
            f"±{margin:.2f} margin (±3 %), TOST p = {fmt_p(tost)}, "
            + (
                "**equivalent within ±3 %**"
                if tost < 0.05
                else "**not shown equivalent within ±3 %**"
            )
        )
    out["text"] = text + "."
    return out


def identical(data: Data, first: str, second: str) -> str:
    """How many seed pairs of two arms have the same course, step by step, to the bit."""
    a, b = data.arm(first), data.arm(second)
    seeds = sorted(set(a) & set(b))
    same = 0
    for seed in seeds:
        rows = [
            data.db.execute(
                f"select {', '.join(COURSE)}, q_grab, q_move_right, q_move_left, q_drop "
                "from steps where session_id = ? order by global_step",
                (arm[seed]["id"],),
            ).fetchall()
            for arm in (a, b)
        ]
        same += rows[0] == rows[1]
    return (
        f"{second} against {first}: {same} of {len(seeds)} seeds identical to the bit in "
        "every step's course and Q-values"
    )


def advice_quality(data: Data, name: str) -> str:
    arm = data.arm(name)
    if not arm:
        return f"{name}: none"
    placed, misplaced, lost, repeat, count = [], [], [], [], []
    for s in arm.values():
        rows = data.db.execute(
            "select action, outcome from steps where session_id = ? and action_source = "
            "'advisor' order by global_step",
            (s["id"],),
        ).fetchall()
        actions = [r[0] for r in rows]
        outcomes = Counter(r[1] for r in rows)
        best = run = 0
        for i, action in enumerate(actions):
            run = run + 1 if i and action == actions[i - 1] else 1
            best = max(best, run)
        placed.append(outcomes["placed"])
        misplaced.append(outcomes["misplaced"])
        lost.append(outcomes["lost"])
        repeat.append(best)
        count.append(len(actions))
    steps = data.db.execute(
        "select min(global_step), max(global_step) from steps where session_id in "
        f"({','.join(str(s['id']) for s in arm.values())}) and action_source = 'advisor'"
    ).fetchone()
    return (
        f"{name} ({len(arm)} agents): {min(count)}-{max(count)} advice each, at global steps "
        f"{steps[0]}-{steps[1]} of the 1,000 pretraining steps (the practice's last 100); "
        f"placed {min(placed)}-{max(placed)}, misplaced {min(misplaced)}-{max(misplaced)}, "
        f"lost {min(lost)}-{max(lost)}, longest repeat {min(repeat)}-{max(repeat)}"
    )


def advisor_checks(data: Data, state: Path) -> list[str]:
    lines = []
    advisors = {s["id"]: s for s in data.sessions if s["label"].endswith(" advisor")}
    for path in sorted(
        state.glob("advisors/checkpoints/session-*/final.pt.check.json"),
        key=lambda p: int(p.parent.name.split("-")[1]),
    ):
        session = int(path.parent.name.split("-")[1])
        s = advisors.get(session)
        stored = json.loads(path.read_text())
        for check in stored["checks"]:
            about = stored.get("about", {}).get(check["run_key"], {})
            at = check["at_advice"]
            mean = sum(check["rewards"]) / len(check["rewards"])
            lines.append(
                f"- {s['label'] if s else '?'} seed {s['seed'] if s else '?'} (session {session}, "
                f"trained on {short_cpu(s['provenance'][0]['cpu']) if s else '?'}), checked for "
                f"{about.get('for', 'run key ' + check['run_key'])} on "
                f"{short_cpu(about.get('cpu', '?'))}: "
                f"**{'FAILED' if check['problems'] else 'passed'}**; "
                f"greedy mean reward {mean:.2f} (needs 2.5; episodes "
                f"{' '.join(f'{r:.2f}' for r in check['rewards'])}), longest repeat "
                f"{check['episode_longest_repeat']} (at most 10); from the advice-time states of "
                f"seeds {check['advice_seeds'][0]}-{check['advice_seeds'][-1]}: placed "
                f"{min(q['placed'] for q in at)}-{max(q['placed'] for q in at)}, misplaced "
                f"{min(q['misplaced'] for q in at)}-{max(q['misplaced'] for q in at)}, lost "
                f"{min(q['lost'] for q in at)}-{max(q['lost'] for q in at)}, longest repeat "
                f"{min(q['longest_repeat'] for q in at)}-{max(q['longest_repeat'] for q in at)}"
                + (f". Problems: {'; '.join(check['problems'])}" if check["problems"] else "")
            )
    return lines


def tost_power(sd: float, margin: float, n: int, alpha: float) -> float:
    """Power of the paired two one-sided tests at ±margin, true difference 0."""
    se, t = sd / np.sqrt(n), stats.t.ppf(1 - alpha, n - 1)
    lo, hi = -margin / se + t, margin / se - t
    return max(0.0, stats.t.cdf(hi, n - 1) - stats.t.cdf(lo, n - 1))


def detect_power(sd: float, effect: float, n: int, alpha: float) -> float:
    """Power of the two-sided paired t-test at `alpha` against a true `effect`."""
    df, nc = n - 1, effect / (sd / np.sqrt(n))
    t = stats.t.ppf(1 - alpha / 2, df)
    return stats.nct.sf(t, df, nc) + stats.nct.cdf(-t, df, nc)


def pairs_for_tost(sd: float, margin: float, target: float = 0.8, alpha: float = 0.05) -> int:
    """Pairs for the two one-sided tests at ±margin to reach `target` power when the true
    difference is 0 (paired; the t distribution with the SD taken as known)."""
    for n in range(3, 2000):
        se = sd / np.sqrt(n)
        t = stats.t.ppf(1 - alpha, n - 1)
        # power = P(-margin/se + t < T < margin/se - t) under the central t (true diff 0)
        lo, hi = -margin / se + t, margin / se - t
        if hi > lo and stats.t.cdf(hi, n - 1) - stats.t.cdf(lo, n - 1) >= target:
            return n
    return -1


def pairs_to_detect(sd: float, effect: float, target: float = 0.8, alpha: float = 0.05) -> int:
    """Pairs for the two-sided paired t-test at `alpha` to detect `effect` with `target` power."""
    for n in range(3, 2000):
        df, nc = n - 1, effect / (sd / np.sqrt(n))
        t = stats.t.ppf(1 - alpha / 2, df)
        if stats.nct.sf(t, df, nc) + stats.nct.cdf(-t, df, nc) >= target:
            return n
    return -1


def main() -> None:
    state = HERE / "state"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "state.sqlite3"
        merge(state, path)
        data = Data(sqlite3.connect(path))
        print("# Replication 2, recomputed from the saved state\n")
        print("Written by [recompute.py](recompute.py) from `state/` alone; do not edit by hand.\n")
        codes = Counter(p["code"] for s in data.sessions for p in s["provenance"])
        commits = Counter(p.get("commit", "?")[:7] for s in data.sessions for p in s["provenance"])
        print(
            f"{len(data.sessions)} finished sessions, {sum(codes.values())} starts and resumes: "
            f"code versions {dict(codes)}; commits {dict(commits)}.\n"
        )
        print("## The arms\n")
        print("| arm | agents | R_T mean | SD | CPU kind (agents) | code | resumed seeds |")
        print("|---|---|---:|---:|---|---|---|")
        for name in ARMS:
            print(describe_arm(data, name))
        missing = [
            f"{name}: {PLANNED[name] - len(data.arm(name))} ({KIND_WAITS.get(name, 'any kind')})"
            for name in ARMS
            if len(data.arm(name)) < PLANNED[name]
        ]
        print(
            "\nStill to run (agents, and the CPU kind each waits for, plan.md amendment 3): "
            + ("; ".join(missing) or "none")
            + ".\n"
        )
        print(
            "## Pre-registered comparisons "
            "(the plan's primary test: paired t, two-sided, α = 0.05)\n"
        )
        c1 = compare(
            data,
            "A-procedure",
            "A-agent",
            "1: does the advice help beyond the procedure? `authors` learner, "
            "advised by the `paper` advisor (amendment 1)",
            equivalence=True,
        )
        c2 = compare(
            data,
            "A-auto-amx",
            "A-agent",
            "2: does the advising procedure help? primary by amendment 3: "
            "both arms on the Xeon with AMX",
        )
        c3a = compare(
            data,
            "B-auto",
            "B-agent",
            "3: does advice help the `paper` learner? advised by the `paper` advisor",
            equivalence=True,
        )
        c3b = compare(data, "B-procedure", "B-agent", "3, against the procedure control")
        for c in (c1, c2, c3a, c3b):
            print(c["text"])
        print("\n## Secondary and exploratory\n")
        c2x = compare(
            data,
            "A-auto",
            "A-agent",
            "2 across CPU kinds: A-agent on the Xeon with AMX, A-auto on the EPYC "
            "with AVX-512 BF16; secondary by amendment 3",
        )
        cpx = compare(
            data, "A-auto", "A-procedure", "the procedure alone, across CPU kinds; exploratory"
        )
        cpa = compare(
            data, "A-auto-amx", "A-procedure", "the procedure alone, one CPU kind; exploratory"
        )
        ckind = compare(
            data,
            "A-auto",
            "A-auto-amx",
            "the CPU kind alone: the same seeds on the Xeon with AMX against the EPYC "
            "with AVX-512 BF16; exploratory (amendment 3)",
            equivalence=True,
        )
        cb = compare(
            data, "B-auto", "B-procedure", "the procedure alone, `paper` learner; exploratory"
        )
        for c in (c2x, cpx, cpa, ckind, cb):
            print(c["text"])
        print()
        print("## Precision (float32 against bfloat16, `authors` learner)\n")
        # the plan's three pairs (seeds 0-2), then all ten (amendment 2, exploratory)
        p3 = compare(
            data,
            "A-auto",
            "A-auto-fp32",
            "the plan's estimate, seeds 0-2; float32 on the AVX2-only EPYC, "
            "bfloat16 on the EPYC with AVX-512 BF16",
            equivalence="planned",
            only=range(3),
        )
        p10 = compare(
            data,
            "A-auto",
            "A-auto-fp32",
            "all ten seeds, exploratory (amendment 2)",
            equivalence=True,
        )
        pa = compare(
            data,
            "A-agent",
            "A-agent-fp32",
            "the plan's advised pair, seeds 0-2, both on the Xeon with AMX",
            equivalence="planned",
            only=range(3),
        )
        for c in (p3, p10, pa):
            print(c["text"])
        print("\n## Populations and resumes (to the bit)\n")
        for first, second in (
            ("B-auto", "B-auto-alone"),
            ("A-auto", "A-auto-alone"),
            ("B-agent", "B-agent-alone"),
        ):
            print("- " + identical(data, first, second) + ".")
        print("\n## Advice where it was given (read from the steps the advisor chose)\n")
        for name in ("B-agent", "A-agent", "B-agent-alone", "A-agent-fp32"):
            print("- " + advice_quality(data, name) + ".")
        print("\n## The advisors' checks (stored beside each saved advisor)\n")
        for line in advisor_checks(data, state):
            print(line + ".")
        print("\n## The next study's size (from comparison 1's own spread)\n")
        if "sd_diff" in c1:
            sd, ref = c1["sd_diff"], c1["mean_first"]
            m3, e2 = 0.03 * ref, 0.02 * ref
            sd_high = sd * np.sqrt((c1["n"] - 1) / stats.chi2.ppf(0.2, c1["n"] - 1))
            print(
                f"- SD of A-agent minus A-procedure over {c1['n']} pairs: {sd:.2f}; A-procedure's "
                f"mean {ref:.2f}, so ±3 % is ±{m3:.2f} and +2 % is {e2:.2f}.\n"
                f"- Pairs to bound the difference within ±3 % (TOST, α = 0.05 each side, 80 % "
                f"power if the true difference is 0): **{pairs_for_tost(sd, m3)}**.\n"
                f"- Pairs to detect +2 % (paired t, two-sided α = 0.05, 80 % power): "
                f"**{pairs_to_detect(sd, e2)}**; +3 %: {pairs_to_detect(sd, m3)}.\n"
                f"- With the SD's 80 % upper confidence bound "
                f"({sd_high:.2f}): "
                f"{pairs_for_tost(sd_high, m3)} pairs for ±3 %, "
                f"{pairs_to_detect(sd_high, e2)} to detect +2 %.\n"
                f"- The next study's two looks (../authors-advice/plan.md: 40 and 80 pairs, "
                f"each at 0.0294): equivalence within ±3 % found with power "
                f"{tost_power(sd, m3, 40, 0.0294):.2f} at 40 pairs and "
                f"{tost_power(sd, m3, 80, 0.0294):.3f} at 80 if the true difference is 0; "
                f"+2 % detected with power {detect_power(sd, e2, 80, 0.0294):.2f} at 80 pairs; "
                f"the 97.06 % interval's half-width at 80 pairs "
                f"±{100 * stats.t.ppf(1 - 0.0294 / 2, 79) * sd / np.sqrt(80) / ref:.2f} %."
            )
        print("\n## Wall time of each run (started to finished), by arm and CPU kind\n")
        for name in ARMS:
            arm = data.arm(name)
            if not arm:
                continue
            minutes = [
                (
                    datetime.fromisoformat(s["finished"]) - datetime.fromisoformat(s["started"])
                ).total_seconds()
                / 60
                for s in arm.values()
            ]
            kinds = sorted({short_cpu(p["cpu"]) for s in arm.values() for p in s["provenance"]})
            print(
                f"- {name}: {min(minutes):.1f}-{max(minutes):.1f} min a run ({', '.join(kinds)}; "
                f"first started {min(s['started'] for s in arm.values())[:16]}, last finished "
                f"{max(s['finished'] for s in arm.values())[:16]} UTC)"
            )


if __name__ == "__main__":
    main()
