"""The report's section on the participants of an online study (`analysis.human`): the
flow as a CONSORT-style figure, each measure per condition, the tests between conditions;
written with the learners' analysis, or alone while the learners still train."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis import markdown as md
from analysis.csvsafe import safe_frame
from analysis.figures import _new_figure, save_figure
from analysis.human import (
    Visits,
    between_conditions,
    check_rates,
    flow,
    given_words,
    participants,
    turns,
)

FIGURE_FILES = {"flow": "participants_flow.png", "decision_times": "decision_times.png"}
TABLE_FILES = {
    "flow": "participants_flow.csv",
    "participants": "participants.csv",
    "tests": "participants_tests.csv",
}
HUMAN_FILES = (*FIGURE_FILES.values(), *TABLE_FILES.values())
"""Every file the section may write (an earlier report's are removed first)."""


def plot_flow(counts: pd.DataFrame) -> Figure:
    """A CONSORT-style diagram: per condition, arrived, then who left (declined, excluded
    by the check, timed out) beside the main line, then consented and completed."""
    figure, ax = _new_figure(3.6 * max(len(counts), 1), 5.0)
    ax.set_axis_off()
    ax.set_xlim(0, len(counts))
    ax.set_ylim(0, 4)
    for i, row in enumerate(counts.itertuples(index=False)):
        main = [
            (3.5, f"{row.condition}\narrived: {row.arrived}"),
            (2.4, f"consented: {row.consented}"),
            (1.3, f"completed: {row.completed}"),
        ]
        side = [
            (2.95, f"declined: {row.declined}"),
            (1.85, f"excluded by the check: {row.excluded}\ntimed out: {row.timed_out}"),
            (0.5, f"still under way: {row.under_way}"),
        ]
        for y, text in main:
            _box(ax, i + 0.3, y, text)
        for y, text in side:
            _box(ax, i + 0.75, y, text, small=True)
        for upper, lower in ((3.5, 2.4), (2.4, 1.3)):
            ax.annotate("", (i + 0.3, lower + 0.22), (i + 0.3, upper - 0.22),
                        arrowprops={"arrowstyle": "->"})  # fmt: skip
    figure.suptitle("Participants by condition (flow)")
    return figure


def _box(ax: object, x: float, y: float, text: str, small: bool = False) -> None:
    ax.text(  # type: ignore[attr-defined]
        x, y, text, ha="center", va="center", fontsize=8 if small else 9,
        bbox={"boxstyle": "round,pad=0.4", "fc": "#f4f4f4" if small else "white", "ec": "black"},
    )  # fmt: skip


def plot_decision_times(visits: Visits) -> Figure:
    """Every decision time of the completed visits (their advice or ratings) per condition
    on a log scale, each participant's median marked."""
    figure, ax = _new_figure(7.0, 4.5)
    people = participants(visits)
    advice = turns(visits)
    advice = advice[advice["session_id"].isin(people["session_id"])]
    advice = advice[advice["decision_time_s"].notna() & advice["answered"].astype(bool)]
    condition = people.set_index("session_id")["condition"]
    rng = np.random.default_rng(0)
    for i, name in enumerate(visits.conditions):
        times = advice.loc[advice["session_id"].map(condition) == name, "decision_time_s"]
        ax.scatter(i + rng.uniform(-0.15, 0.15, len(times)), times, s=8, alpha=0.4)
        medians = people.loc[people["condition"] == name, "median_decision_s"].dropna()
        ax.scatter([i] * len(medians), medians, marker="_", s=400, color="black")
    if len(advice):
        ax.set_yscale("log")
    else:
        ax.text(0.5, 0.5, "no decision times yet", ha="center", transform=ax.transAxes)
    ax.set_xticks(range(len(visits.conditions)), visits.conditions)
    ax.set_ylabel("decision time [s] (log scale)")
    ax.set_title("Decision times; a bar per participant's median")
    return figure


def _by_condition(visits: Visits) -> pd.DataFrame:
    people = participants(visits)
    rates = check_rates(visits).set_index("condition")
    rows = []
    for name in visits.conditions:
        group = people[people["condition"] == name]
        row: dict[str, object] = {
            "condition": name,
            "participants": len(group),
            "gave": " and ".join(sorted(set(group["gave"]))) or "–",
            "advice": group["advice"].mean(),
            "accuracy": group["accuracy"].mean(),
            "median_decision_s": group["median_decision_s"].median(),
            "check": f"{rates.loc[name, 'first_try']} / {rates.loc[name, 'passed']} of "
            f"{rates.loc[name, 'took']}",
        }
        for column in [c for c in people.columns if c.startswith("scale_")]:
            row[column] = group[column].mean()
        rows.append(row)
    return pd.DataFrame(rows)


def _accuracy_note(people: pd.DataFrame) -> str:
    """What the accuracy column means for the advice and the ratings given, and where it
    is not available."""
    notes = []
    for gave, right, missing in (
        (
            "advice",
            "Accuracy of advice is the share of a participant's advice that named the "
            "task's correct action, or an action as right where the task records several "
            "(the grid world's moves equally near the goal).",
            "No accuracy for advice: no correct action is recorded beside it (the task "
            "cannot say, or the advice was stored before it was recorded).",
        ),
        (
            "ratings",
            "Accuracy of ratings is the share of a participant's ratings that were right: "
            "good of the task's correct action (or an action as right), bad of another.",
            "No accuracy for ratings: the feedback table records no correct action beside "
            "a rating (the task cannot say, or the ratings were stored before it was "
            "recorded), so whether a good or a bad was right is not available.",
        ),
    ):
        group = people[people["gave"] == gave]
        if len(group):
            notes.append(right if group["accuracy"].notna().any() else missing)
    return " ".join(notes)


def _interval(row: pd.Series) -> str:
    if row["no_test"]:
        return "–"
    return f"{row['estimate']:.2f} [{row['low']:.2f}, {row['high']:.2f}]"


def human_section(
    visits: Visits,
    out: Path,
    alpha: float,
    exploratory: bool = False,
    figure_formats: Sequence[str] | None = None,
) -> tuple[list[str], list[Path]]:
    """Write the section's tables and figures (in `figure_formats`, `save_figure`'s) into `out`;
    its Markdown lines and files (each figure by its PNG). `exploratory`: a primary test
    leads the report, and these tests say they are not it."""
    counts = flow(visits)
    people = participants(visits)
    tests = between_conditions(visits, alpha)
    if exploratory:
        tests["role"] = "exploratory"
    files = []
    for name, frame in (("flow", counts), ("participants", people), ("tests", tests)):
        path = out / TABLE_FILES[name]
        safe_frame(frame).to_csv(path, index=False)
        files.append(path)
    for name, figure in (
        ("flow", plot_flow(counts)),
        ("decision_times", plot_decision_times(visits)),
    ):
        files.append(save_figure(figure, out / FIGURE_FILES[name], formats=figure_formats))
    summary = _by_condition(visits)
    gave = set(people["gave"])
    columns = {"condition": "condition", "participants": "completed", "gave": "gave",
               "advice": given_words(gave), "accuracy": "accuracy",
               "median_decision_s": "median decision time [s]",
               "check": "check: first try / passed of took"}  # fmt: skip
    columns |= {c: c.removeprefix("scale_") for c in summary.columns if c.startswith("scale_")}
    plain = ("condition", "participants", "gave", "check")
    formats = {c: md.fixed(2) for c in columns if c not in plain}
    shown = tests.assign(interval=[_interval(r) for _, r in tests.iterrows()])
    shown["verdict"] = [
        f"no test: {r['no_test']}" if r["no_test"] else
        ("significant" if r["significant"] else "not significant")
        for _, r in shown.iterrows()
    ]  # fmt: skip
    accuracy = _accuracy_note(people)
    lines = [
        "## The participants (the unit of the human study)",
        "",
        f"![Participants' flow by condition]({FIGURE_FILES['flow']})",
        "",
        md.table(counts, {c: c.replace("_", " ") for c in counts.columns}),
        "",
        "Per condition, over completed visits (each participant counts once; the check over "
        "everyone who took it). " + accuracy,
        "",
        md.table(summary, columns, formats),
        "",
        f"![Decision times by condition]({FIGURE_FILES['decision_times']})",
        "",
        (
            "Exploratory tests (the pre-registered primary test leads the report): "
            if exploratory
            else ""
        )
        + f"Tests between conditions, the participant as the unit, at α = {alpha:g}, Holm's "
        "correction within each family (advice; scales; items; rates): Welch's t for "
        "continuous measures (decision times on a log scale), Mann-Whitney's U for Likert "
        "items and NASA-TLX subscales, Fisher's exact test for rates; the effect with its "
        f"{100 * (1 - alpha):g} % interval.",
        "",
        md.table(
            shown,
            {
                "family": "family",
                "measure": "measure",
                "condition_a": "a",
                "condition_b": "b",
                "test": "test",
                "n_a": "n a",
                "n_b": "n b",
                "p": "p",
                "p_holm": "p (Holm)",
                "effect": "effect",
                "interval": "estimate [interval]",
                "verdict": "verdict",
            },
            {"p": md.p_value, "p_holm": md.p_value},
            empty="One condition: nothing to compare.",
        ),
        "",
    ]
    return lines, files
