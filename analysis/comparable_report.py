"""The report's section on learning outcomes that compare like with like
(`analysis.comparable`): the shared window, each strategy's rule, where each condition's
advice fell, the learners' scores and curves, and Welch's t between conditions with the
participant's learner as the unit."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import combinations
from pathlib import Path

import pandas as pd
from matplotlib.figure import Figure

from analysis import markdown as md
from analysis.between import holm, welch
from analysis.comparable import Comparable, rule, timing_notes
from analysis.csvsafe import safe_frame
from analysis.figures import _new_figure, save_figure

COMPARABLE_FILES = {
    "scores": "comparable_scores.csv",
    "timing": "advice_timing.csv",
    "tests": "comparable_tests.csv",
    "curves": "comparable_curves.png",
}
"""Every file the section may write (an earlier report's are removed first)."""
TESTS = ["condition_a", "condition_b", "n_a", "n_b", "statistic", "p", "p_holm", "significant",
         "estimate", "low", "high", "no_test"]  # fmt: skip


def comparable_tests(scores: pd.DataFrame, alpha: float) -> pd.DataFrame:
    """Welch's t on the score for every pair of conditions, Holm's correction over the
    pairs (one family)."""
    rows = []
    conditions = list(dict.fromkeys(scores["condition"]))
    for a, b in combinations(conditions, 2):
        x = [float(v) for v in scores.loc[scores["condition"] == a, "score"]]
        y = [float(v) for v in scores.loc[scores["condition"] == b, "score"]]
        tested = welch(x, y, alpha)
        rows.append({"condition_a": a, "condition_b": b, **tested.__dict__})
    table = pd.DataFrame(rows, columns=[c for c in TESTS if c not in ("p_holm", "significant")])
    table["p_holm"] = holm(list(table["p"])) if len(table) else []
    table["significant"] = [None if pd.isna(p) else bool(p < alpha) for p in table["p_holm"]]
    return table[TESTS]


def plot_curves(found: Comparable) -> Figure:
    """Each condition's mean score per episode of the window, its learners' curves faint."""
    figure, ax = _new_figure(7.0, 4.5)
    for i, (name, group) in enumerate(found.curves.groupby("condition", sort=False)):
        colour = f"C{i}"
        for _, one in group.groupby("session_id"):
            ax.plot(one["episode"], one["score"], color=colour, alpha=0.25, linewidth=0.8)
        mean = group.groupby("episode")["score"].mean()
        ax.plot(mean.index, mean.to_numpy(), color=colour, linewidth=2, label=str(name))
    ax.set_xlabel("training episode")
    ax.set_ylabel("collected reward less advised steps' rewards")
    ax.set_title(f"Learning over the shared window (episodes {found.first}-{found.last})")
    if len(found.curves):
        ax.legend()
    return figure


def comparable_section(
    found: Comparable,
    strategies: Mapping[int, str | None],
    out: Path,
    alpha: float,
    exploratory: bool = False,
    figure_formats: Sequence[str] | None = None,
) -> tuple[list[str], list[Path]]:
    """Write the section's tables and figure (in `figure_formats`, `save_figure`'s) into `out`;
    its Markdown lines and files (the figure by its PNG). `exploratory`: a primary test
    leads the report, and these tests say they are not it."""
    used = sorted({strategies.get(int(i)) or "" for i in found.scores["session_id"]})
    rules = [f"- {s or 'no advice'}: {rule(s or None)}." for s in used]
    files = [out / COMPARABLE_FILES["timing"]]
    safe_frame(found.timing).to_csv(files[0], index=False)
    lines = [
        "## Learning outcomes that compare like with like",
        "",
        "R_T counts every training episode, and with it the reward of advised training "
        "steps (the advisor's choices, not the learner's); advice given in pretraining it "
        "never counts. The score here is each learner's collected reward over a window of "
        "training episodes every condition shares, less the reward of any advised step in "
        "it. For each strategy:",
        "",
        *rules,
        "",
        "Where the advice fell (means per learner; the first and last training episode "
        "advised over the condition's learners):",
        "",
        md.table(found.timing, {c: c.replace("_", " ") for c in found.timing.columns}),
        "",
        *[f"- {note}" for note in timing_notes(found.timing)],
        "",
    ]
    if found.empty:
        lines += [
            f"No shared window: the last advised episode ({found.first - 1}) is the last "
            f"episode every learner has ({found.last}) or later; no score is compared.",
            "",
        ]
        return lines, files
    tests = comparable_tests(found.scores, alpha)
    if exploratory:
        tests["role"] = "exploratory"
    for name, frame in (("scores", found.scores), ("tests", tests)):
        path = out / COMPARABLE_FILES[name]
        safe_frame(frame).to_csv(path, index=False)
        files.append(path)
    files.append(
        save_figure(plot_curves(found), out / COMPARABLE_FILES["curves"], formats=figure_formats)
    )
    by_condition = found.scores.groupby("condition", sort=False).agg(
        learners=("score", "size"), score=("score", "mean"), sd=("score", "std"),
        advised_steps=("advised_steps", "mean"), advised_reward=("advised_reward", "mean"),
    ).reset_index()  # fmt: skip
    verdicts = [
        f"no test: {r['no_test']}" if r["no_test"]
        else ("significant" if r["significant"] else "not significant")
        for _, r in tests.iterrows()
    ]  # fmt: skip
    summary_columns = {
        "condition": "condition", "learners": "learners", "score": "mean score", "sd": "sd",
        "advised_steps": "advised steps in the window (mean)",
        "advised_reward": "their reward, left out (mean)",
    }  # fmt: skip
    test_columns = {
        "condition_a": "a", "condition_b": "b", "n_a": "n a", "n_b": "n b",
        "estimate": "difference", "low": "low", "high": "high", "p": "p",
        "p_holm": "p (Holm)", "verdict": "verdict",
    }  # fmt: skip
    two = md.fixed(2)
    lines += [
        f"The shared window: training episodes {found.first}-{found.last} "
        f"({found.last - found.first + 1} episodes).",
        "",
        md.table(by_condition, summary_columns, {c: two for c in list(summary_columns)[2:]}),
        "",
        f"![Learning over the shared window]({COMPARABLE_FILES['curves']})",
        "",
        ("Exploratory: " if exploratory else "")
        + f"Welch's t on the score, the participant's learner as the unit, Holm's correction "
        f"over the pairs, at α = {alpha:g}; the difference in means (a - b) with its "
        f"{100 * (1 - alpha):g} % interval.",
        "",
        md.table(
            tests.assign(verdict=verdicts),
            test_columns,
            {"estimate": two, "low": two, "high": two, "p": md.p_value, "p_holm": md.p_value},
            empty="One condition: nothing to compare.",
        ),
        "",
    ]
    return lines, files
