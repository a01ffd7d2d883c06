"""One call that writes the paper's analysis: PNG figures, CSV tables, `report.md`.

`write_report` is what `ideeprl report` and the dashboard call. Everything is computed
before the first file is written, so a bad episode table leaves the folder untouched.
The Markdown links its images and tables by relative path: copy the folder anywhere.
"""

from __future__ import annotations

import dataclasses
import platform
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import scipy

from analysis import markdown as md
from analysis.advice import PLACED_COUNTS, advice_quality, quality_correlations
from analysis.audit import Audit, audit, label
from analysis.comparable import comparable
from analysis.comparable_report import COMPARABLE_FILES, comparable_section
from analysis.comparisons import compare
from analysis.csvsafe import safe_frame
from analysis.episodes import PLACEMENTS, EpisodeTableError, agents_of, method_name
from analysis.figures import (
    bands_window,
    example_agents,
    pick_reference_agent,
    plot_confidence_bands,
    plot_correlation,
    plot_cumulative_reward,
    plot_epsilon,
    plot_individual_agents,
    plot_method_curves,
    plot_power,
    save_figure,
    vector_paths,
)
from analysis.formats import FIGURE_FORMATS, figure_formats
from analysis.human import Visits
from analysis.human_report import HUMAN_FILES, human_section
from analysis.markdown import REPORT_FILE
from analysis.paper import PAPER_AGENTS, PAPER_EPISODES, paper_comparison
from analysis.power import DEFAULT_DRAWS, MIN_AGENTS, PowerAnalysis, power_analysis
from analysis.preregistration import Preregistered
from analysis.primary import primary_lines
from analysis.reference import REFERENCES, authors_totals, overlay_authors
from analysis.rescoring import Plans, rescored_by_task, rescored_schemes, rescoring_table
from analysis.rescoring import plan as rescoring_plan
from analysis.stats import AGENT_TOTALS, EPISODE_MEANS
from analysis.summary import Analysis, analyze
from tasks import RescoreError
from tasks.sorting import OPTIONS as SORTING_OPTIONS

FIGURE_FILES: dict[str, str] = {
    "reward_per_method": "figure5_reward_per_method.png",
    "individual_agents": "figure6_individual_agents.png",
    "correlation": "figure7_correlation.png",
    "cumulative_reward": "cumulative_reward.png",
    "confidence_bands": "reward_confidence_bands.png",
    "epsilon": "epsilon.png",
    "power": "power.png",
}
TABLE_FILES: dict[str, str] = {
    "methods": "r_t_per_method.csv",
    "agents": "r_t_per_agent.csv",
    "t_tests": "t_tests.csv",
    "correlation": "correlation.csv",
    "method_correlations": "correlation_per_method.csv",
    "curves": "reward_per_episode.csv",
    "paper": "paper_comparison.csv",
    "intervals": "r_t_intervals.csv",
    "differences": "r_t_differences.csv",
}
OPTIONAL_TABLE_FILES: dict[str, str] = {
    "settings": "settings_per_method.csv",
    "rescored": "r_t_rescored.csv",
    "rescored_agents": "r_t_rescored_per_agent.csv",
    "reference": "authors_reference.csv",
    "comparisons": "primary_and_secondary_tests.csv",
    "advice_quality": "advice_quality.csv",
    "advice_correlations": "advice_quality_per_method.csv",
    "power": "power.csv",
}
"""Tables written when their input is given: the sessions' settings (the audit), the step
logs (rescoring), a reference, two agents per arm and a baseline (power)."""
REPORT_FILES = (
    "report.md",
    *HUMAN_FILES,
    *COMPARABLE_FILES.values(),
    *FIGURE_FILES.values(),
    *TABLE_FILES.values(),
    *OPTIONAL_TABLE_FILES.values(),
)
"""Every file a report may write, each figure by its PNG (its other formats lie beside it):
a new report into the same folder removes an earlier one's first (`_remove_earlier`), so a
table or figure this report has no input for is not the earlier one's."""
MAX_HEATMAP_AGENTS = 24
"""Above this many agents Figure 7 shows the paper's selection; the CSV keeps them all."""


@dataclass(frozen=True)
class ReportResult:
    """What `write_report` wrote, by name, and what it left out and why."""

    out_dir: Path
    """The folder holding everything below."""
    report: Path
    """The Markdown report."""
    figures: dict[str, Path]
    """PNG files by name (keys of `FIGURE_FILES` that were drawn)."""
    tables: dict[str, Path]
    """CSV files by name (keys of `TABLE_FILES`)."""
    notes: tuple[str, ...]
    """Sentences on what the report left out or chose, also printed in it."""
    analysis: Analysis | None
    """The statistics behind the files, for callers that show them another way (None: a
    report of the participants alone, no learner finished yet)."""
    audit: Audit | None = None
    """What each method ran under and which pairs differ (None without a settings table)."""
    rescored: pd.DataFrame | None = None
    """R_T per method under each reward scheme (None without step logs)."""
    power: PowerAnalysis | None = None
    """Agents per arm a future study needs (None without a baseline)."""
    formats: tuple[str, ...] = FIGURE_FORMATS
    """The formats each figure was written in (`analysis.formats.figure_formats`)."""

    @property
    def vector_figures(self) -> list[Path]:
        """Each figure in its other formats (SVG and PDF unless fewer were asked for),
        beside its PNG."""
        return [v for png in self.figures.values() for v in vector_paths(png, self.formats)]

    @property
    def files(self) -> list[Path]:
        """Every file written, the report first."""
        return [self.report, *self.figures.values(), *self.vector_figures, *self.tables.values()]


MAX_INDIVIDUAL_AGENTS = 5
"""Above this many agents Figure 6 shows three examples, as the paper does."""

Plan = tuple[str, str, list[str]]
"""Figure 6's method, reference agent label, and the labels of the agents drawn."""


def human_methods(analysis: Analysis, visits: Visits | None) -> list[str]:
    """The methods (an online study's conditions) whose sessions a participant advised or
    rated: those of the method `human` (or its evaluative arms), and any holding a session
    whose advice or feedback came from a participant (`visits`), whatever its name."""
    by_person = set() if visits is None else visits.advised_by_people
    humans = []
    for method, group in analysis.agents.groupby("method", sort=False):
        named = method == "human" or str(method).startswith("human-")
        if named or by_person & set(group["session_id"]):
            humans.append(str(method))
    return [m for m in analysis.method_order if m in humans]


def _individual_plan(
    analysis: Analysis,
    method: str,
    reference_label: str | None,
    labels: Sequence[str] | None,
    humans: Sequence[str] = (),
) -> tuple[Plan | None, list[str]]:
    """Which agents Figure 6 shows, against which reference agent, and notes on the choice.
    `method` "human" (the paper's choice) stands for any of `humans`, the methods whose
    sessions people advised (`human_methods`)."""
    order, notes = analysis.method_order, []
    method_of = dict(zip(analysis.agents["label"], analysis.agents["method"], strict=True))
    unknown = [
        x for x in [*(labels or []), reference_label] if x is not None and x not in method_of
    ]
    if unknown:
        raise EpisodeTableError(
            f"no agent labelled {', '.join(map(repr, unknown))} for Figure 6; pick from "
            f"{', '.join(method_of)}, or leave it out for the default choice"
        )
    if labels:
        method = method_of[labels[0]]
    elif method not in order:
        others = [m for m in order if m != analysis.baseline]
        advised = [m for m in others if m in humans] if method == "human" else []
        if not others:
            return None, ["Figure 6 is left out: it needs a method besides the baseline."]
        if advised:
            notes.append(
                f"Figure 6 shows the individual {method_name(advised[0])} agents, learners "
                "a participant advised (the paper's shows its human-advised ones)."
            )
            method = advised[0]
        else:
            paper = "the paper's shows the human-advised ones; " if method == "human" else ""
            notes.append(
                f"Figure 6 shows the individual {method_name(others[0])} agents ({paper}this "
                f"report has no {method_name(method)} sessions)."
            )
            method = others[0]
    if reference_label is None:
        candidates = [m for m in [analysis.baseline, *order] if m is not None and m != method]
        if not candidates:
            return None, ["Figure 6 is left out: it needs a reference agent of another method."]
        reference_label = pick_reference_agent(analysis.episodes, candidates[0])
        notes.append(
            f"Figure 6's reference is {reference_label}, the {method_name(candidates[0])} "
            "agent with the median R_T."
        )
    if not labels:
        labels = [x for x, m in method_of.items() if m == method]
        if len(labels) > MAX_INDIVIDUAL_AGENTS:
            notes.append(
                f"Figure 6 draws 3 of the {len(labels)} {method_name(method)} agents, those "
                "with the lowest, median and highest R_T; its table lists them all."
            )
            labels = example_agents(analysis.episodes, method, 3)
    return (method, reference_label, list(labels)), notes


def _heatmap_labels(analysis: Analysis, focus: str) -> tuple[list[str], list[str]]:
    """Figure 7's agents: all of them, or like the paper one agent per method plus the focus."""
    agents = agents_of(analysis.episodes)
    labels = list(agents["label"])
    if len(labels) <= MAX_HEATMAP_AGENTS:
        return labels, []
    chosen = [
        label
        for method, group in agents.groupby("method", sort=False)
        for label in (group["label"] if method == focus else group["label"].iloc[:1])
    ][:MAX_HEATMAP_AGENTS]
    which = f"all {method_name(focus)} agents and " if focus in set(agents["method"]) else ""
    note = (
        f"Figure 7 shows {len(chosen)} of {len(labels)} agents ({which}the first agent of "
        f"each other method, as the paper does); {TABLE_FILES['correlation']} has them all."
    )
    return chosen, [note]


def _describe_test(row: pd.Series, alpha: float) -> str:
    if isinstance(row.get("withheld"), str) and row["withheld"]:
        return f"t-test withheld ({row['withheld']})"
    if np.isnan(row["p"]):
        return f"t-test undefined (n = {row['n_a']} + {row['n_b']}: needs 2+ varying values)"
    verdict = "significant" if row["p"] < alpha else "not significant"
    return f"t = {row['t']:.2f}, p = {md.p_value(row['p'])}, {verdict} at α = {alpha:g}"


def _describe_primary(
    comparisons: pd.DataFrame | None, method: str, alpha: float, against: str | None = None
) -> str:
    """The primary test of the method's comparison (against `against`, else its first: the
    baseline) in words."""
    rows = None if comparisons is None else comparisons[comparisons["method"] == method]
    if rows is not None and against is not None:
        rows = rows[rows["baseline"] == against]
    if rows is None or rows.empty:
        return "Primary test: none"
    row = rows.iloc[0]
    name = "paired t-test over seeds" if row["primary"] == "paired" else "Welch's t-test"
    what = f"Primary test ({name} of the agents' R_T)"
    if isinstance(row.get("withheld"), str) and row["withheld"]:
        return f"{what}: withheld ({row['withheld']})"
    if np.isnan(row["primary_p"]):
        return f"{what}: undefined (n = {row['n']} + {row['n_baseline']}: needs 2+ varying values)"
    verdict = "significant" if row["primary_p"] < alpha else "not significant"
    return (
        f"{what}: t = {row['primary_statistic']:.2f}, p = {md.p_value(row['primary_p'])}, "
        f"{verdict} at α = {alpha:g}; probability of improvement "
        f"{row['probability_of_improvement']:.2f} "
        f"{_interval(row['poi_low'], row['poi_high'])}"
    )


def _pairs(a: Sequence[str], b: Sequence[str]) -> list[str]:
    """Each pair of methods by their display names: "agent-IDeepRL vs autonomous DeepRL"."""
    return [f"{method_name(x)} vs {method_name(y)}" for x, y in zip(a, b, strict=True)]


def _significant(p_values: Sequence[float], alpha: float) -> list[str]:
    return ["–" if np.isnan(p) else ("yes" if p < alpha else "no") for p in p_values]


def _comparisons_section(comparisons: pd.DataFrame | None, alpha: float) -> list[str]:
    """The primary test of each comparison first, then the secondary ones."""
    if comparisons is None or comparisons.empty:
        return []
    frame = comparisons.copy()
    frame["pair"] = _pairs(frame["method"], frame["baseline"])
    frame["n_shown"] = [f"{a} + {b}" for a, b in zip(frame["n"], frame["n_baseline"], strict=True)]
    frame["poi"] = [
        "–" if np.isnan(p) else f"{p:.2f} {_interval(lo, hi)}"
        for p, lo, hi in zip(
            frame["probability_of_improvement"], frame["poi_low"], frame["poi_high"], strict=True
        )
    ]
    frame["significant"] = _significant(frame["primary_p"], alpha)
    columns = {
        "pair": "comparison",
        "n_shown": "agents",
        "difference": "difference in R_T",
        "primary": "primary test",
        "primary_statistic": "t",
        "primary_p": "p",
        "significant": f"p < {alpha:g}",
        "welch_p": "Welch p",
        "permutation_p": "permutation p",
        "mann_whitney_p": "Mann-Whitney p",
        "paired_p": "paired p",
        "poi": "P(improvement)",
    }
    formats = {
        "difference": md.fixed(2),
        "primary_statistic": md.fixed(3),
        "primary_p": md.p_value,
        "welch_p": md.p_value,
        "permutation_p": md.p_value,
        "mann_whitney_p": md.p_value,
        "paired_p": md.p_value,
    }
    return [
        "## The primary test, then the secondary ones",
        "",
        "Each method is compared with the baseline by **one primary test** on the agents' "
        "R_T (the runs are the independent units): Welch's t-test, or the paired t-test over "
        "seeds when the analysis plan fixes it and every agent has a baseline agent of the "
        f"same seed. Its p is the one to read against α = {alpha:g}. The others are "
        "**secondary**, shown so a reader can see whether the conclusion depends on the "
        "test: Welch, a permutation test of the difference in means, Mann-Whitney's U, the "
        "paired t-test where seeds pair, and the probability of improvement (the chance "
        "that an agent of the method beats an agent of the baseline, ties counting half, "
        "with a 95 % bootstrap interval; Agarwal et al. 2021). The paper's own test on the "
        "average curves is further down, labelled so.",
        "",
        md.table(frame, columns, formats),
        "",
    ]


def _summary(
    analysis: Analysis, alpha: float, comparisons: pd.DataFrame | None = None
) -> list[str]:
    """The report's first section: each method's R_T and tests in one sentence."""
    methods = analysis.methods.set_index("method")
    tests = analysis.t_tests.set_index(["method_a", "method_b", "sample"])
    base = analysis.baseline
    lines = []
    for method in analysis.method_order:
        row = methods.loc[method]
        spread = "" if np.isnan(row["R_T_std"]) else f", ± {row['R_T_std']:.2f} across agents"
        head = (
            f"- **{row['name']}** ({'baseline, ' if method == base else ''}"
            f"{md.count(row['agents'], 'agent')} × {md.count(row['episodes'], 'episode')}): "
            f"R_T = {row['R_T']:.2f}"
            f"{spread}"
        )
        if method == base or base is None:
            lines.append(head + ".")
            continue
        more = "more" if row["R_T"] >= methods.loc[base, "R_T"] else "less"
        lines.append(
            f"{head}; it collects {md.versus(row['R_T'], methods.loc[base, 'R_T'])} "
            f"({more} reward) "
            f"compared with {method_name(base)}. "
            + _describe_primary(comparisons, method, alpha)
            + "; the paper's own test on the average curves: "
            f"{_describe_test(tests.loc[(method, base, EPISODE_MEANS)], alpha)}."
        )
    planned = set()
    if comparisons is not None:
        planned = set(zip(comparisons["method"], comparisons["baseline"], strict=True))
    for (a, b, sample), row in tests.iterrows():
        if base in (a, b) or sample != EPISODE_MEANS:
            continue
        if (a, b) in planned or (b, a) in planned:  # an advised method and its control
            method, against = (a, b) if (a, b) in planned else (b, a)
            lines.append(
                f"- {method_name(method)} vs {method_name(against)}: "
                + _describe_primary(comparisons, method, alpha, against)
                + "; the paper's own test on the average curves: "
                f"{_describe_test(row, alpha)}."
            )
            continue
        per_agent = tests.loc[(a, b, AGENT_TOTALS)]
        lines.append(
            f"- {method_name(a)} vs {method_name(b)}: average curves "
            f"{_describe_test(row, alpha)}; agents' R_T {_describe_test(per_agent, alpha)}."
        )
    if base is not None and methods.loc[base, "R_T"] <= 0:
        lines.append(
            f"- {method_name(base)}'s R_T is not positive, so the differences from it are "
            "in points: a percentage of it would read as a gain or loss it is not."
        )
    if analysis.epsilon_reached is not None:
        reached = ", ".join(
            f"{method_name(m)} at episode {int(e)}"
            if not np.isnan(e)
            else f"{method_name(m)} never"
            for m, e in analysis.epsilon_reached.items()
        )
        lines.append(f"- Mean epsilon reaches 1 %: {reached} (the paper: near episode 150).")
    return lines


def _methods_table(analysis: Analysis) -> str:
    columns = {
        "name": "method",
        "agents": "agents",
        "episodes": "episodes",
        "R_T": "R_T",
        "R_T_std": "std of agents' R_T",
        "R_T_min": "min",
        "R_T_max": "max",
        "vs_baseline": "improvement",
    }
    for column in analysis.methods.columns:
        if column.endswith("_per_episode"):
            columns[column] = column.removesuffix("_per_episode").replace("_", " ") + " / episode"
    if "success_rate" in analysis.methods:
        columns["success_rate"] = "success rate (of its episodes)"
    formats = {
        c: md.fixed(2) for c in columns if c not in ("name", "agents", "episodes", "vs_baseline")
    }
    frame = analysis.methods.assign(vs_baseline=_versus_baseline(analysis, analysis.methods))
    return md.table(frame, columns, formats)


def _versus_baseline(analysis: Analysis, frame: pd.DataFrame) -> list[str]:
    """Each row's R_T against the baseline method's (`md.versus`); blank without one."""
    if analysis.baseline is None:
        return ["–"] * len(frame)
    base = float(analysis.methods.set_index("method").loc[analysis.baseline, "R_T"])
    return [md.versus(r, base) for r in frame["R_T"]]


def _tests_table(analysis: Analysis, alpha: float) -> str:
    frame = analysis.t_tests.copy()
    frame["pair"] = _pairs(frame.method_a, frame.method_b)
    frame["what"] = frame["sample"].map(
        {EPISODE_MEANS: "average curves (Table 2)", AGENT_TOTALS: "agents' R_T"}
    )
    frame["n"] = [f"{a} + {b}" for a, b in zip(frame.n_a, frame.n_b, strict=True)]
    frame["significant"] = _significant(frame["p"], alpha)
    columns = {
        "pair": "pair (a vs b)",
        "what": "samples compared",
        "n": "n",
        "mean_a": "mean a",
        "mean_b": "mean b",
        "t": "t",
        "df": "df",
        "p": "p",
        "significant": f"p < {alpha:g}",
        "t_welch": "Welch t",
        "df_welch": "Welch df",
        "p_welch": "Welch p",
    }
    if "withheld" in frame and (frame["withheld"] != "").any():
        frame["withheld"] = [f"withheld: {w}" if w else "" for w in frame["withheld"]]
        columns["withheld"] = "note"
    formats = {
        "mean_a": md.fixed(3),
        "mean_b": md.fixed(3),
        "t": md.fixed(4),
        "df": md.fixed(0),
        "p": md.p_value,
        "t_welch": md.fixed(4),
        "df_welch": md.fixed(1),
        "p_welch": md.p_value,
    }
    return md.table(frame, columns, formats, empty=_nothing_to_compare(analysis))


def _nothing_to_compare(analysis: Analysis) -> str:
    """What an empty comparison table says instead: why there is no pair."""
    if len(analysis.methods) < 2:
        return "No pair of methods to compare: the report has one method."
    return "No pair of methods to compare: each method needs at least two agents."


def _interval(low: float, high: float, digits: int = 2) -> str:
    return "–" if np.isnan(low) else f"[{low:.{digits}f}, {high:.{digits}f}]"


def _intervals_section(analysis: Analysis) -> list[str]:
    """Bootstrap intervals and the IQM (analysis.intervals): what 4-10 agents allow."""
    if analysis.intervals is None or analysis.differences is None:
        return []
    level = (
        f"{(analysis.intervals.confidence.max() if len(analysis.intervals) else 0.95) * 100:g} %"
    )
    frame = analysis.intervals.copy()
    frame["mean_ci"] = [_interval(a, b) for a, b in zip(frame.R_T_low, frame.R_T_high, strict=True)]
    frame["iqm_ci"] = [_interval(a, b) for a, b in zip(frame.IQM_low, frame.IQM_high, strict=True)]
    methods = md.table(
        frame,
        {
            "name": "method",
            "agents": "agents",
            "R_T_mean": "mean of agents' R_T",
            "mean_ci": f"{level} CI",
            "IQM": "IQM of agents' R_T",
            "iqm_ci": f"{level} CI",
        },
        {"R_T_mean": md.fixed(2), "IQM": md.fixed(2)},
    )
    diff = analysis.differences.copy()
    diff["pair"] = [
        f"{method_name(a)} − {method_name(b)}"
        for a, b in zip(diff.method_a, diff.method_b, strict=True)
    ]
    diff["ci"] = [_interval(a, b) for a, b in zip(diff.low, diff.high, strict=True)]
    diff["iqm_ci"] = [_interval(a, b) for a, b in zip(diff.IQM_low, diff.IQM_high, strict=True)]
    differences = md.table(
        diff,
        {
            "pair": "difference (a − b)",
            "difference": "mean R_T",
            "ci": f"{level} CI",
            "IQM_difference": "IQM R_T",
            "iqm_ci": f"{level} CI",
        },
        {"difference": md.fixed(2), "IQM_difference": md.fixed(2)},
        empty=_nothing_to_compare(analysis),
    )
    return [
        "## Confidence intervals and interquartile mean",
        "",
        "Percentile bootstrap over agents (`scipy.stats.bootstrap`, 10,000 resamples, "
        "seed 0; each method's agents resampled on their own). The IQM is the mean of the "
        "middle 50 % of agents' R_T (`scipy.stats.trim_mean(x, 0.25)`), robust to a single "
        "run that failed or took off (Agarwal et al., NeurIPS 2021). With few agents these "
        "intervals describe the runs and are too narrow as a guarantee; an interval needs "
        "2+ agents per method.",
        "",
        methods,
        "",
        differences,
        "",
    ]


def _paper_table(analysis: Analysis) -> str:
    frame = analysis.paper.copy()
    for column in ("paper", "ours"):
        frame[column] = [
            md.p_value(v)
            if q.startswith("p ")
            else (md.fixed(4)(v) if q.startswith("|t|") else md.fixed(2)(v))
            for q, v in zip(frame["quantity"], frame[column], strict=True)
        ]
    columns = {"quantity": "quantity", "paper": "paper", "ours": "ours", "sample": "our sample"}
    return md.table(frame, columns)


def _agents_table(analysis: Analysis, labels: Sequence[str], reference: str | None) -> str:
    frame = analysis.agents.set_index("label").loc[list(labels)].reset_index()
    frame["name"] = frame["method"].map(method_name)
    columns = {"label": "agent", "name": "method"}
    if "seed" in frame:
        columns["seed"] = "seed"
    columns |= {"R_T": "R_T", "vs_baseline": "vs baseline method"}
    formats = {"R_T": md.fixed(2), "seed": md.whole}
    frame["vs_baseline"] = _versus_baseline(analysis, frame)
    if reference is not None:
        base = float(analysis.agents.set_index("label").loc[reference, "R_T"])
        frame["vs_reference"] = [md.versus(r, base) for r in frame["R_T"]]
        columns["vs_reference"] = f"vs {reference}"
    return md.table(frame, columns, formats)


def _correlation_summary(analysis: Analysis) -> str:
    frame = analysis.method_correlations.copy()
    frame["pair"] = [
        f"{method_name(a)} – {method_name(b)}"
        for a, b in zip(frame.method_a, frame.method_b, strict=True)
    ]
    columns = {"pair": "agents of", "pairs": "pairs of agents", "mean_r": "mean Pearson's r"}
    return md.table(frame, columns, {"mean_r": md.fixed(3)})


def _agent_counts(analysis: Analysis) -> str:
    return ", ".join(
        f"{n} {method_name(m)}"
        for m, n in zip(analysis.methods.method, analysis.methods.agents, strict=True)
    )


def _scale_note(analysis: Analysis, humans: Sequence[str] = ()) -> str:
    """How these runs stand to the paper's; `humans`: the methods people advised."""
    if not len(analysis.paper) and humans:
        named = ", ".join(method_name(m) for m in humans)
        return (
            f"Participants advised the learners of {named}, as in the paper's human-IDeepRL, "
            "but under this study's own conditions, not the paper's methods (autonomous, "
            "agent, human): nothing here is set beside the paper's numbers."
        )
    if not len(analysis.paper):
        return "None of the paper's methods (autonomous, agent, human) is in these sessions."
    methods = analysis.methods
    if (methods["episodes"] == PAPER_EPISODES).all() and (methods["agents"] == PAPER_AGENTS).all():
        return "Same scale as the paper: 10 agents per method, 300 episodes each."
    if analysis.n_episodes == PAPER_EPISODES:
        return (
            f"Same number of episodes as the paper ({PAPER_EPISODES}); the paper had "
            f"{PAPER_AGENTS} agents per method, these runs {_agent_counts(analysis)}."
        )
    return (
        f"The paper ran {PAPER_AGENTS} agents × {PAPER_EPISODES} episodes per method; these "
        f"runs have {analysis.n_episodes} episodes per agent. R_T grows with the number of "
        "episodes, so compare the improvement in percent and the direction and significance "
        "of the tests, not R_T itself."
    )


def write_report(
    episodes_df: pd.DataFrame,
    out_dir: str | Path,
    *,
    title: str = "IDeepRL study: the paper's analysis",
    baseline: str | None = "autonomous",
    notes: str | Sequence[str] | None = None,
    n_episodes: int | None = None,
    individual_method: str = "human",
    individual_labels: Sequence[str] | None = None,
    reference_label: str | None = None,
    smoothing: int = 1,
    alpha: float = 0.05,
    equal_var: bool = True,
    settings: pd.DataFrame | None = None,
    steps: pd.DataFrame | None = None,
    allow_mismatch: bool = False,
    reference: str | None = None,
    advice: pd.DataFrame | None = None,
    primary: str = "welch",
    power_draws: int = DEFAULT_DRAWS,
    power_seed: int = 0,
    visits: Visits | None = None,
    strategies: Mapping[int, str | None] | None = None,
    preregistered: Preregistered | None = None,
    formats: str | Sequence[str] | None = None,
) -> ReportResult:
    """Write Figures 5-7, the CSV tables and `report.md` for these episodes into `out_dir`.

    `episodes_df` follows the contract in `analysis.episodes` (one row per session
    and episode). `notes` (text or a list of lines: the command, versions, wall time) go
    under the title. `n_episodes` cuts every agent to its first N episodes;
    `individual_method`, `individual_labels` and `reference_label` choose Figure 6's
    agents (by default up to three human-IDeepRL examples against the median autonomous
    agent); `smoothing` is a moving-average window for Figures 5 and 6 only. An earlier
    report's files in `out_dir` are removed first (`REPORT_FILES`), other files are left;
    nothing is written if the table is invalid.

    `settings` (one row per session: `analysis.audit.FIXED_COLUMNS` and one column
    per setting) adds the comparability audit: the settings per method, a warning at the
    top for methods that differ, and no t-test for such a pair unless `allow_mismatch`
    (the warning stays).
    `steps` (training steps, `analysis.rescoring.STEP_COLUMNS`) with `settings` adds
    R_T rescored under each reward scheme. `reference="authors"` draws the authors' mean
    curves on Figure 5 and lists the paper's R_T beside them. `advice` (the advised steps,
    `analysis.advice.ADVICE_COLUMNS`) adds each advised session's advice quality.
    `primary` is each comparison's primary test (`analysis.comparisons`): Welch's
    test of the agents' R_T, or the paired t-test where seeds pair; the rest are secondary.
    The Power section plans a future study from these agents' R_T (`analysis.power`,
    `power_draws` simulated studies per size, seeded by `power_seed`) at `alpha`.
    `visits` (an online study's) adds the participants' section (`analysis.human_report`),
    and with `advice` and each session's strategy (`strategies`, None: no advice) the
    learning outcomes that compare like with like (`analysis.comparable`); `preregistered`
    (the design's primary measure and test) leads the report (`analysis.primary`) and
    makes every other test exploratory. `formats` are the figures' (`figure_formats`: by
    default `IDEEPRL_FIGURE_FORMATS`, else PNG, SVG and PDF).
    """
    formats = figure_formats(formats)
    if reference is not None and reference not in REFERENCES:
        raise EpisodeTableError(
            f"unknown reference {reference!r}; available: {', '.join(REFERENCES)}"
        )
    sorting = _ran_sorting(settings)
    if not sorting:  # the robot's placements: all 0 in another task, and meaningless
        episodes_df = episodes_df.drop(columns=[c for c in PLACEMENTS if c in episodes_df])
    analysis = analyze(episodes_df, baseline=baseline, n_episodes=n_episodes, equal_var=equal_var)
    if settings is not None:
        settings = _without_sorting_settings(settings)
    checked = None
    if settings is not None:
        kept = settings[settings["session_id"].isin(analysis.episodes["session_id"])]
        checked = audit(kept, baseline)
        analysis = _withhold_tests(analysis, checked, allow_mismatch)
    rescored = rescored_agents = None
    rescoring = _Rescoring()
    if steps is not None and settings is not None and not steps.empty:  # none: nothing to do
        kept = settings[settings["session_id"].isin(analysis.episodes["session_id"])]
        try:
            planned = rescoring_plan(kept)
        except RescoreError as error:
            rescoring = _Rescoring(not_rescored=str(error))
        else:
            methods = dict(zip(settings["session_id"], settings["method"], strict=True))
            kept_steps = steps[steps["session_id"].isin(analysis.episodes["session_id"])]
            totals = rescored_by_task(kept_steps, planned, analysis.n_episodes)
            if totals.empty:  # none of the rescored tasks' sessions logged a training step
                why = [*planned.not_rescored.values(), "no training steps were logged"]
                rescoring = _Rescoring(not_rescored="; ".join(why))
            else:
                rescored = rescoring_table(totals, methods, baseline)
                if checked is not None and not allow_mismatch:
                    rescored = _withhold_rescored(rescored, checked, baseline, kept)
                rescored_agents = totals.assign(method=totals["session_id"].map(methods))
                rescoring = _rescoring(planned, totals)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise EpisodeTableError(f"{out} is a file; pass a folder for the report")
    humans = human_methods(analysis, visits)
    plan, plan_notes = _individual_plan(
        analysis, individual_method, reference_label, individual_labels, humans
    )
    heatmap_labels, heatmap_notes = _heatmap_labels(analysis, plan[0] if plan else "")
    report_notes = [*plan_notes, *heatmap_notes, *_bands_notes(analysis)]
    power = _power(analysis, alpha, power_draws, power_seed)
    out.mkdir(parents=True, exist_ok=True)
    _remove_earlier(out)  # an earlier report's: none of its files may outlive it

    tables = {
        "methods": analysis.methods,
        "agents": analysis.agents,
        "t_tests": analysis.t_tests,
        "correlation": analysis.correlation,
        "method_correlations": analysis.method_correlations,
        "curves": analysis.curves,
        "paper": analysis.paper,
        "intervals": analysis.intervals,
        "differences": analysis.differences,
    }
    if checked is not None:
        tables["settings"] = checked.methods
    if rescored is not None:
        tables["rescored"] = rescored
        tables["rescored_agents"] = rescored_agents
    if reference == "authors":
        tables["reference"] = authors_totals(analysis.n_episodes)
    comparisons = compare(analysis.episodes, baseline, primary)
    if checked is not None and not allow_mismatch and len(comparisons):
        comparisons["withheld"] = [
            "the methods differ in " + " and ".join(checked.differ(m, b))
            if checked.differ(m, b) else ""
            for m, b in zip(comparisons["method"], comparisons["baseline"], strict=True)
        ]  # fmt: skip
        tested = [c for c in comparisons.columns if c.endswith(("_p", "_t", "_statistic"))]
        comparisons.loc[comparisons["withheld"] != "", tested] = np.nan
    if len(comparisons):
        tables["comparisons"] = comparisons
    quality = None
    if advice is not None:
        quality = advice_quality(advice, analysis.agents)
        if len(quality) and sorting:
            tables["advice_quality"] = quality
            tables["advice_correlations"] = quality_correlations(quality)
        elif len(quality):
            quality = _task_advice_quality(quality, analysis.episodes)
            tables["advice_quality"] = quality
        else:
            quality = None
    if power is not None and power.comparisons:
        tables["power"] = power_table(power)
    table_paths = {}
    for name, frame in tables.items():
        table_paths[name] = out / {**TABLE_FILES, **OPTIONAL_TABLE_FILES}[name]
        safe_frame(frame).to_csv(table_paths[name], index=name == "correlation")

    figure5 = plot_method_curves(analysis.episodes, baseline=baseline, smoothing=smoothing)
    if reference == "authors":
        overlay_authors(figure5, analysis.method_order, analysis.n_episodes)
    figures = {
        "reward_per_method": figure5,
        "correlation": plot_correlation(analysis.correlation.loc[heatmap_labels, heatmap_labels]),
        "cumulative_reward": plot_cumulative_reward(analysis.episodes, baseline=baseline),
    }
    if not _bands_notes(analysis):
        figures["confidence_bands"] = plot_confidence_bands(analysis.episodes, baseline=baseline)
    if plan is not None:
        figures["individual_agents"] = plot_individual_agents(
            analysis.episodes,
            method=plan[0],
            labels=plan[2],
            reference_label=plan[1],
            smoothing=smoothing,
        )
    if "epsilon" in analysis.episodes:
        figures["epsilon"] = plot_epsilon(analysis.episodes, baseline=baseline)
    if power is not None and power.comparisons:
        figures["power"] = plot_power(power)
    figure_paths = {
        name: save_figure(figures[name], out / FIGURE_FILES[name], formats=formats)
        for name in FIGURE_FILES
        if name in figures
    }

    report = out / REPORT_FILE
    extra = _Extras(
        checked, rescored, tables.get("reference"), allow_mismatch, rescoring, quality,
        tables.get("advice_correlations"), tables.get("comparisons"), power, humans, formats,
    )  # fmt: skip
    text = _markdown(analysis, title, notes, plan, report_notes, alpha, smoothing, equal_var, extra)
    if visits is not None:
        marked = preregistered is not None
        lines, files = human_section(visits, out, alpha, marked, formats)
        scores = None
        if advice is not None and strategies is not None:
            found = comparable(analysis.episodes, advice, strategies)
            learning, more = comparable_section(found, strategies, out, alpha, marked, formats)
            lines, files = [*learning, *lines], [*more, *files]
            scores = None if found.empty else found.scores
        text = text.rstrip("\n") + "\n\n" + "\n".join(lines)
        if preregistered is not None:
            text = leading(text, primary_lines(preregistered, visits, scores, alpha))
        figure_paths |= {p.stem: p for p in files if p.suffix == ".png"}
        table_paths |= {p.stem: p for p in files if p.suffix == ".csv"}
    report.write_text(text, encoding="utf-8")
    warnings = tuple(checked.warnings()) if checked is not None else ()
    return ReportResult(
        out, report, figure_paths, table_paths, (*warnings, *report_notes), analysis,
        checked, rescored, power, formats,
    )  # fmt: skip


def write_human_report(
    visits: Visits,
    out_dir: str | Path,
    *,
    title: str,
    notes: Sequence[str] = (),
    alpha: float = 0.05,
    preregistered: Preregistered | None = None,
    formats: str | Sequence[str] | None = None,
) -> ReportResult:
    """The report of the participants alone, while no learner has finished: the section
    of `analysis.human_report` under the title and `notes`, led by the primary test where
    the design fixed one; its figures in `formats` (`write_report`'s)."""
    formats = figure_formats(formats)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _remove_earlier(out)
    lines, files = human_section(visits, out, alpha, preregistered is not None, formats)
    report = out / REPORT_FILE
    head = [f"# {title}", "", *(f"- {n}" for n in notes), ""]
    if preregistered is not None:
        head += primary_lines(preregistered, visits, None, alpha)
    report.write_text("\n".join([*head, *lines]), encoding="utf-8")
    return ReportResult(
        out, report, {p.stem: p for p in files if p.suffix == ".png"},
        {p.stem: p for p in files if p.suffix == ".csv"}, (), None, formats=formats,
    )  # fmt: skip


def _remove_earlier(out: Path) -> None:
    """Remove an earlier report's files from `out` (`REPORT_FILES`, and each figure in
    every format, whichever this report writes)."""
    for name in REPORT_FILES:
        path = out / name
        path.unlink(missing_ok=True)
        if path.suffix == ".png":
            for vector in vector_paths(path, FIGURE_FORMATS):
                vector.unlink(missing_ok=True)


def leading(text: str, lines: Sequence[str]) -> str:
    """`text` with `lines` before its first section (after the title and notes)."""
    at = text.find("\n## ")
    if at < 0:
        return text.rstrip("\n") + "\n\n" + "\n".join(lines)
    return text[: at + 1] + "\n".join(lines) + "\n" + text[at + 1 :]


def _bands_notes(analysis: Analysis) -> list[str]:
    """Why the bootstrap-band figure is left out, if it is: a one-episode run has no
    curve to draw a band along."""
    if analysis.n_episodes >= 2:
        return []
    return [
        "The bootstrap-band figure is left out: the run has "
        f"{md.count(analysis.n_episodes, 'episode')}, no curve to draw a band along."
    ]


def _bands_section(analysis: Analysis) -> list[str]:
    """The bootstrap-band figure and what it shows, or why it is left out."""
    if notes := _bands_notes(analysis):
        return [*notes, ""]
    window = bands_window(analysis.n_episodes)
    smoothing = (
        f"moving average over {window} episodes"
        if window > 1
        else "no moving average: the run is too short for one"
    )
    return [
        f"![Mean collected reward with 95 % bootstrap bands]({FIGURE_FILES['confidence_bands']})",
        "",
        f"The same curves as a mean with a 95 % bootstrap interval over agents ({smoothing}), "
        "as `rliable` draws them: where the bands of two methods part, the difference is "
        "larger than the agents' spread explains.",
        "",
    ]


@dataclass(frozen=True)
class _Rescoring:
    """What the report says of its rescoring beside the table."""

    about: str = ""
    """How the task rescores a step (`tasks.RewardSchemes.about`; each task's, named, where
    the study ran several)."""
    not_rescored: str = ""
    """Why the sessions, or some schemes, were not rescored ("": all were)."""
    by_outcomes: tuple[int, int] | None = None
    """Sessions rescored by their steps' outcomes, of all rescored (a task with outcomes)."""
    tasks: tuple[tuple[str, tuple[str, ...]], ...] = ()
    """Each rescored task and the schemes its sessions were rescored under."""
    skipped: tuple[tuple[str, str], ...] = ()
    """Each task whose sessions were not rescored, and why."""


def _rescoring(planned: Plans, totals: pd.DataFrame) -> _Rescoring:
    """What the report says of the rescoring of these tasks' sessions (`totals`)."""
    declared = [(p.task, p.task.reward_schemes) for p in planned.tasks]
    abouts = [(task.name, s.about) for task, s in declared if s is not None and s.about]
    several = len(declared) + len(planned.not_rescored) > 1
    with_outcomes = totals["task"].isin([task.name for task, _ in declared if task.outcomes])
    return _Rescoring(
        about=" ".join(f"{name}: {about}" if several else about for name, about in abouts),
        not_rescored="; ".join(r for r in dict.fromkeys(totals["not_rescored"]) if r),
        by_outcomes=(int(totals.loc[with_outcomes, "by_outcomes"].sum()), int(with_outcomes.sum()))
        if with_outcomes.any()
        else None,
        tasks=tuple((task.name, s.names) for task, s in declared if s is not None),
        skipped=tuple(planned.not_rescored.items()),
    )


def _by_task_note(rescoring: _Rescoring) -> str:
    """Which tasks were rescored under which schemes, and which were not and why, where
    the study ran several tasks ("" for one)."""
    if len(rescoring.tasks) + len(rescoring.skipped) < 2:
        return ""
    under = "; ".join(f"{name} under {', '.join(schemes)}" for name, schemes in rescoring.tasks)
    note = (
        " The sessions ran several tasks, and a task's schemes score only its own runs: each "
        f"session is rescored under its own task's schemes ({under}) and compared with its "
        "own task's baseline. A task's row is left empty under the schemes it does not declare."
    )
    if rescoring.skipped:
        note += (
            " Not rescored: "
            + "; ".join(f"the sessions of task {name} ({why})" for name, why in rescoring.skipped)
            + "."
        )
    return note


@dataclass(frozen=True)
class _Extras:
    """The audit, rescoring and reference parts of a report (each may be absent)."""

    audit: Audit | None
    rescored: pd.DataFrame | None
    reference: pd.DataFrame | None
    allow_mismatch: bool
    rescoring: _Rescoring = _Rescoring()
    advice_quality: pd.DataFrame | None = None
    advice_correlations: pd.DataFrame | None = None
    comparisons: pd.DataFrame | None = None
    power: PowerAnalysis | None = None
    humans: Sequence[str] = ()
    """The methods whose sessions participants advised or rated (`human_methods`)."""
    formats: tuple[str, ...] = FIGURE_FORMATS
    """The formats the figures are written in (`figure_formats`)."""


def _outcomes_note(by_outcomes: tuple[int, int] | None) -> str:
    """Which sessions' placements come from their steps' outcomes, and which from rewards."""
    if by_outcomes is None:
        return ""
    known, total = by_outcomes
    if known == total:
        return " A placement is a step that placed an object (the steps' recorded outcomes)."
    return (
        f" {known} of {total} sessions are rescored by their steps' recorded outcomes; the "
        "others (logged before outcomes were kept) by their rewards, which count an episode "
        "ended by a lost object as a placement (`ideeprl outcomes --study ID` replays them)."
    )


def _withhold_tests(analysis: Analysis, checked: Audit, allow_mismatch: bool) -> Analysis:
    """The analysis with the t-tests of pairs that differ in their settings withheld (t,
    p and df of every test, Student's and Welch's, left empty, the reason in
    `withheld`), unless `allow_mismatch`."""
    tests = analysis.t_tests.copy()
    reasons = [
        "" if allow_mismatch or not checked.differ(a, b)
        else "the methods differ in " + " and ".join(checked.differ(a, b))
        for a, b in zip(tests["method_a"], tests["method_b"], strict=True)
    ]  # fmt: skip
    tests["withheld"] = reasons
    mask = tests["withheld"] != ""
    statistics = [c for c in tests.columns if c.split("_")[0] in ("t", "df", "p")]
    tests.loc[mask, statistics] = np.nan
    paper = paper_comparison(analysis.methods, tests, baseline=analysis.baseline)
    return dataclasses.replace(analysis, t_tests=tests, paper=paper)


def _ran_sorting(settings: pd.DataFrame | None) -> bool:
    """Whether a session ran the sorting robot (or the settings cannot say: runs without a
    task ran it), whose placements the report counts."""
    return settings is None or "task" not in settings or (settings["task"] == "sorting").any()


def _task_advice_quality(quality: pd.DataFrame, episodes: pd.DataFrame) -> pd.DataFrame:
    """The advice quality of a task other than the sorting robot: without the robot's
    placements, with each session's success rate where the task defines success."""
    kept = quality.drop(columns=[*PLACED_COUNTS, "unknown_outcome"])
    if "success" not in episodes:
        return kept
    rates = episodes.groupby("session_id")["success"].mean()
    return kept.assign(success_rate=kept["session_id"].map(rates).astype(float))


def _without_sorting_settings(settings: pd.DataFrame) -> pd.DataFrame:
    """The settings without the sorting robot's own (its motion, rule and scenario, which
    the rescoring reads) when no session ran the sorting task: they mean nothing there."""
    if "task" not in settings or (settings["task"] == "sorting").any():
        return settings
    return settings.drop(columns=[c for c in SORTING_OPTIONS if c in settings])


def _withhold_rescored(
    table: pd.DataFrame, checked: Audit, baseline: str | None, settings: pd.DataFrame
) -> pd.DataFrame:
    """The rescoring table with Welch's p left empty for the methods that differ from the
    baseline in more than their reward scheme (the reason in `withheld`): scoring every run
    under one scheme removes that difference and no other. Where the sessions ran several
    tasks, each task's methods are compared within that task, so the audit of that task's
    sessions (`settings`) says how they differ."""
    tested = [c for c in table.columns if c.startswith("p_welch_")]
    if baseline is None or not tested:
        return table
    by_task = {}
    if "task" in table and "task" in settings and settings["task"].nunique() > 1:
        by_task = {t: audit(group, baseline) for t, group in settings.groupby("task")}
    scheme = label("reward_scheme")
    reasons = []
    for row in table.to_dict("records"):
        differ = by_task.get(row.get("task"), checked).differ(row["method"], baseline)
        other = [what for what in differ if what != scheme]
        reasons.append("the methods differ in " + " and ".join(other) if other else "")
    table = table.assign(withheld=reasons)
    table.loc[table["withheld"] != "", tested] = np.nan
    return table


def _rescored_versus(
    table: pd.DataFrame, schemes: Sequence[str], baseline: str
) -> dict[str, list[str]]:
    """Each row's R_T under each scheme against its own task's baseline row (`vs_<scheme>`
    columns; a dash where its task has no baseline row or no R_T under the scheme)."""
    rows = table.to_dict("records")
    bases = {row.get("task"): row for row in rows if row["method"] == baseline}
    return {
        f"vs_{scheme}": [
            md.versus(row[f"R_T_{scheme}"], bases[row.get("task")][f"R_T_{scheme}"])
            if row.get("task") in bases
            else "–"
            for row in rows
        ]
        for scheme in schemes
    }


def _comparability(extra: _Extras, baseline: str | None) -> list[str]:
    """The audit's warning (for the top) and its table; the rescoring and reference tables."""
    out: list[str] = []
    if extra.audit is not None:
        shown = [c for c in extra.audit.methods.columns if c not in ("method", "name")]
        columns = {
            "name": "method",
            **{c: c if c == "sessions" else label(c) for c in shown if c != "advice"},
            "advice": "advice (the treatment)",
        }
        out += [
            "## Comparability: what each method ran under",
            "",
            "Compared methods must share everything but the treatment (who advises, how, "
            "how much). "
            + (
                "They do here."
                if extra.audit.comparable
                else "**They do not here**: "
                + " ".join(extra.audit.warnings())
                + (
                    " The t-tests of those pairs are given because they were asked for "
                    "(`--allow-mismatch`); read them with that in mind."
                    if extra.allow_mismatch
                    else " The t-tests of those pairs are withheld (`--allow-mismatch` gives them)."
                )
            ),
            "",
            md.table(extra.audit.methods, columns),
            "",
        ]
    if extra.rescored is not None:
        columns = {"name": "method", "agents": "agents", "logged_under": "logged under",
                   "R_T_logged": "R_T as logged"}  # fmt: skip
        formats: dict[str, object] = {"R_T_logged": md.fixed(2)}
        schemes = rescored_schemes(extra.rescored)
        for scheme in schemes:
            columns[f"R_T_{scheme}"] = f"R_T under {scheme}"
            formats[f"R_T_{scheme}"] = md.fixed(2)
            if f"improvement_{scheme}" in extra.rescored:
                columns[f"vs_{scheme}"] = f"vs baseline under {scheme}"
                columns[f"p_welch_{scheme}"] = f"Welch's p under {scheme}"
                formats[f"p_welch_{scheme}"] = md.p_value
        rescored, withheld = extra.rescored, ""
        if len(extra.rescoring.tasks) > 1:
            columns = {"task": "task", **columns}
        if baseline is not None and any(f"improvement_{s}" in rescored for s in schemes):
            rescored = rescored.assign(**_rescored_versus(rescored, schemes, baseline))
        if "withheld" in rescored and (rescored["withheld"] != "").any():
            rescored = rescored.assign(
                withheld=[f"withheld: {w}" if w else "" for w in rescored["withheld"]]
            )
            columns["withheld"] = "note"
            withheld = (
                " Welch's p is withheld for a method that differs from the baseline in more "
                "than its reward scheme: one scheme makes their scores alike in that and "
                "nothing else (`--allow-mismatch` gives it)."
            )
        out += [
            "## R_T rescored under each reward scheme",
            "",
            "The same logged behaviour scored under each of the task's reward schemes. "
            + (f"{extra.rescoring.about} " if extra.rescoring.about else "")
            + (
                "Compare methods within one task and one column."
                if len(extra.rescoring.tasks) > 1
                else "Compare methods within one column."
            )
            + _by_task_note(extra.rescoring)
            + _outcomes_note(extra.rescoring.by_outcomes)
            + withheld
            + (
                f" Left empty where the task cannot say: {extra.rescoring.not_rescored}."
                if extra.rescoring.not_rescored
                else ""
            ),
            "",
            md.table(rescored, columns, formats),  # type: ignore[arg-type]
            "",
        ]
    elif extra.rescoring.not_rescored:
        out += [
            "## R_T rescored under each reward scheme",
            "",
            f"Not rescored: {extra.rescoring.not_rescored}.",
            "",
        ]
    if extra.reference is not None:
        out += [
            "## The authors' curves (reference)",
            "",
            "Figure 5's dashed lines are the authors' published mean curves "
            "(`analysis/data/`), each scored under its own script's rule, so they "
            "are not comparable with each other, and compare with ours only under the "
            "same rule.",
            "",
            md.table(
                extra.reference,
                {
                    "name": "method",
                    "scheme": "their scheme",
                    "episodes": "episodes",
                    "authors_curve_R_T": "R_T of their curve",
                    "paper_R_T": "R_T in the paper",
                },
                {"authors_curve_R_T": md.fixed(2), "paper_R_T": md.fixed(2)},
            ),
            "",
        ]
    return out


def _advice_section(extra: _Extras) -> list[str]:
    """Each advised session's advice: what it did, and whether better advice went with a
    better outcome."""
    quality, per_method = extra.advice_quality, extra.advice_correlations
    if quality is not None and "placed" not in quality:
        return _task_advice_section(quality)
    if quality is None or per_method is None:
        return []
    rows = [
        f"| {r.label} | {method_name(r.method)} | {r.advice} | {r.placed} | {r.misplaced} | "
        f"{r.lost} | {r.longest_repeat} | {r.R_T:.2f} |"
        for r in quality.itertuples()
    ]
    rhos = [
        f"- {method_name(r.method)}: {r.agents} agents, {r.mean_placed:.1f} correct placements "
        "on average; Spearman's rho between an agent's correct placements and its R_T "
        + ("not defined (fewer than 3 agents, or no variation)" if np.isnan(r.spearman_rho)
           else f"{r.spearman_rho:+.2f} (p {r.spearman_p:.3g})")
        for r in per_method.itertuples()
    ]  # fmt: skip
    unknown = int(quality["unknown_outcome"].sum())
    return [
        "## Advice quality",
        "",
        "What each advised session's advice did, counted from the steps whose action came "
        "from the advisor: objects placed where they belong, placed on the wrong side, "
        "knocked off, and the most advised steps in a row with one action (a working "
        "policy crossing the scene repeats a move at most twice; an advisor stuck in a "
        "state repeats one action until its budget ends). An effect of advice is only "
        "credible where the advice was good.",
        "",
        "| agent | method | advice | placed | misplaced | lost | longest repeat | R_T |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
        *rhos,
        *_unknown_outcomes(unknown),
        "",
    ]


def _task_advice_section(quality: pd.DataFrame) -> list[str]:
    """The advice quality of a task other than the sorting robot: its own measures."""
    success = "success_rate" in quality
    rows = [
        f"| {r.label} | {method_name(r.method)} | {r.advice} | {r.longest_repeat} | "
        + (f"{r.success_rate:.2f} | " if success else "")
        + f"{r.R_T:.2f} |"
        for r in quality.itertuples()
    ]
    return [
        "## Advice quality",
        "",
        "What each advised session's advice did, counted from the steps whose action came "
        "from the advisor: the most advised steps in a row with one action (an advisor "
        "stuck in a state repeats one action until its budget ends), and the agent's own "
        "measures: the share of its episodes that succeeded (where the task defines "
        "success) and its R_T. An effect of advice is only credible where the advice was "
        "good.",
        "",
        "| agent | method | advice | longest repeat | "
        + ("success rate | " if success else "")
        + "R_T |",
        "|---|---|---:|---:|" + ("---:|" if success else "") + "---:|",
        *rows,
        "",
    ]


def _unknown_outcomes(unknown: int) -> list[str]:
    if not unknown:
        return []
    return [
        f"- {unknown} advised steps have no recorded outcome (logged before outcomes were "
        "kept): run `ideeprl outcomes --study ID` to replay them."
    ]


def _markdown(
    analysis: Analysis,
    title: str,
    notes: str | Sequence[str] | None,
    plan: Plan | None,
    report_notes: list[str],
    alpha: float,
    smoothing: int,
    equal_var: bool,
    extra: _Extras,
) -> str:
    agents = agents_of(analysis.episodes)
    out = [f"# {title}", ""]
    if extra.audit is not None and not extra.audit.comparable:
        out += [
            "> **Comparability warning.** " + " ".join(extra.audit.warnings()),
            "",
        ]
    if notes:
        out += [notes if isinstance(notes, str) else "\n".join(f"- {n}" for n in notes), ""]
    out += [
        f"{md.count(len(agents), 'agent')} in {md.count(len(analysis.method_order), 'method')}, "
        f"{md.count(analysis.n_episodes, 'episode')} each. Baseline: "
        f"{method_name(analysis.baseline) if analysis.baseline else 'none'}. "
        "R_T is the total collected reward over all episodes.",
        "",
        "## In short",
        "",
        *_summary(analysis, alpha, extra.comparisons),
        *(f"- {n}" for n in report_notes),
        "",
        *_comparability(extra, analysis.baseline),
        *_comparisons_section(extra.comparisons, alpha),
        "## Average collected reward per method (the paper's Figure 5)",
        "",
        "![Figure 5: average collected reward per episode per method]"
        f"({FIGURE_FILES['reward_per_method']})",
        "",
        "Lines: the mean over a method's agents of the reward collected in each episode; "
        "shaded: ±1 sample standard deviation across those agents"
        + (f"; smoothed by a moving average over {smoothing} episodes." if smoothing > 1 else ".")
        + " A method's R_T is the sum of its line over the episodes, which is also the mean of "
        "its agents' R_T.",
        "",
        _methods_table(analysis),
        "",
        f"![Cumulative collected reward per method]({FIGURE_FILES['cumulative_reward']})",
        "",
        *_bands_section(analysis),
        "Every figure is also written as SVG and PDF beside its PNG.",
        "",
    ]
    if plan is not None:
        method, reference, _ = plan
        labels = [*agents.loc[agents["method"] == method, "label"], reference]
        out += [
            "## Individual agents against a reference (the paper's Figure 6)",
            "",
            f"![Figure 6: {method_name(method)} agents against {reference}]"
            f"({FIGURE_FILES['individual_agents']})",
            "",
            _agents_table(analysis, labels, reference),
            "",
        ]
    out += [
        "## The paper's own test: t-tests between methods (the paper's Table 2)",
        "",
        "Each pair of methods is compared twice, with the independent two-sample "
        + (
            "Student t-test (two-sided, equal variances, `scipy.stats.ttest_ind`):"
            if equal_var
            else "Welch t-test (two-sided, unequal variances, `scipy.stats.ttest_ind`):"
        ),
        "",
        "1. **Average curves** — the paper's Table 2: each method's average collected reward "
        f"per episode, one value per episode ({analysis.n_episodes} per method). The paper's "
        "t = 7.6829, p = 6.3947e-14 is this test with 300 + 300 values (598 degrees of "
        "freedom). Successive episodes of a learning curve are not independent, so these "
        "p-values are smaller than a test across runs would give.",
        "2. **Agents' R_T** — one value per agent: the test across independent runs.",
        "",
        "t > 0 means the first method's sample (a) has the larger mean; against the "
        "baseline, t > 0 means more reward than the baseline (the paper prints |t|).",
        "",
        _tests_table(analysis, alpha),
        "",
        *_intervals_section(analysis),
        *_power_section(extra.power, extra.audit, extra.formats),
        "## Correlation between agents (the paper's Figure 7)",
        "",
        f"![Figure 7: Pearson's correlation between agents]({FIGURE_FILES['correlation']})",
        "",
        "Pearson's r between two agents' collected reward per episode over the episodes. "
        "Mean r between the agents of two methods:",
        "",
        _correlation_summary(analysis),
        "",
    ]
    if analysis.epsilon_reached is not None:
        out += [
            "## Exploration",
            "",
            f"![Epsilon per episode]({FIGURE_FILES['epsilon']})",
            "",
        ]
    out += _advice_section(extra)
    out += ["## Compared with the paper", "", _scale_note(analysis, extra.humans), ""]
    if len(analysis.paper):
        out += [_paper_table(analysis), ""]
    out += [
        "## R_T per agent",
        "",
        _agents_table(analysis, list(agents["label"]), None),
        "",
        "## Files",
        "",
        *(f"- [{f}]({f})" for f in TABLE_FILES.values()),
        *(
            f"- [{OPTIONAL_TABLE_FILES[name]}]({OPTIONAL_TABLE_FILES[name]})"
            for name, part in (
                ("settings", extra.audit),
                ("rescored", extra.rescored),
                ("rescored_agents", extra.rescored),
                ("reference", extra.reference),
                ("comparisons", extra.comparisons),
                ("advice_quality", extra.advice_quality),
                ("advice_correlations", extra.advice_correlations),
                ("power", extra.power if extra.power and extra.power.comparisons else None),
            )
            if part is not None
        ),
        "",
        f"numpy {np.__version__}, pandas {pd.__version__}, scipy {scipy.__version__}, "
        f"matplotlib {matplotlib.__version__}, Python {platform.python_version()}.",
        "",
    ]
    return "\n".join(out)


def _power(analysis: Analysis, alpha: float, draws: int, seed: int) -> PowerAnalysis | None:
    """The power analysis of every method against the baseline (None without one)."""
    if analysis.baseline is None:
        return None
    agents = analysis.agents
    r_t = {
        m: agents.loc[agents["method"] == m, "R_T"].to_numpy(dtype=float)
        for m in analysis.method_order
    }
    return power_analysis(r_t, analysis.baseline, alpha=alpha, draws=draws, seed=seed)


def power_table(power: PowerAnalysis) -> pd.DataFrame:
    """One row per comparison and target power: the effect, the spreads, agents needed
    (empty: more than `max_n`, or no effect)."""
    rows = [
        {
            "method": c.method,
            "baseline": c.baseline,
            "agents": c.agents,
            "baseline_agents": c.baseline_agents,
            "mean_R_T": c.mean,
            "baseline_mean_R_T": c.baseline_mean,
            "effect": c.delta,
            "sd": c.sd,
            "baseline_sd": c.baseline_sd,
            "d": c.d,
            "alpha": power.alpha,
            "power": size.target,
            "n_bootstrap": size.bootstrap,
            "n_fitted": size.fitted,
            "n_closed_form": size.closed_form,
            "max_n": power.max_n,
            "draws": power.draws,
            "seed": power.seed,
        }
        for c in power.comparisons
        for size in c.sample_sizes
    ]
    counts = {f"n_{k}": "Int64" for k in ("bootstrap", "fitted", "closed_form")}
    return pd.DataFrame(rows).astype(counts)


def _needed(n: int | None, max_n: int) -> str:
    return f"> {max_n}" if n is None else str(n)


def _power_rows(power: PowerAnalysis) -> pd.DataFrame:
    return pd.DataFrame(
        [
            {
                "pair": f"{method_name(c.method)} vs {method_name(c.baseline)}",
                "effect": f"{c.delta:+.2f} (d = {c.d:.2f})",
                "sd": f"{c.sd:.2f} / {c.baseline_sd:.2f}",
                "agents": f"{c.agents} + {c.baseline_agents}",
                "power": f"{size.target * 100:g} %",
                "bootstrap": _needed(size.bootstrap, power.max_n),
                "fitted": _needed(size.fitted, power.max_n),
                "closed": _needed(size.closed_form, power.max_n),
            }
            for c in power.comparisons
            for size in c.sample_sizes
        ]
    )


def _power_section(
    power: PowerAnalysis | None,
    checked: Audit | None = None,
    formats: tuple[str, ...] = FIGURE_FORMATS,
) -> list[str]:
    """Planning information: the agents per arm a future study needs, or why it is left out;
    a caution for each arm whose baseline ran under other settings (`checked`); the figure
    linked in each of its `formats`."""
    head = ["## Power: how many participants a study needs (planning, not a test)", ""]
    if power is None:
        why = "power compares each method with a baseline, and this report has none"
        return [*head, f"Left out: {why} (name one with `--baseline`).", ""]
    if not power.comparisons:
        why = "; ".join(power.skipped) or "there is no method besides the baseline"
        return [*head, f"Left out: {why}. Run at least {MIN_AGENTS} agents per arm.", ""]
    table = md.table(
        _power_rows(power),
        {
            "pair": "pair (a vs baseline)",
            "effect": "observed effect on R_T (a − baseline)",
            "sd": "sd of R_T (a / baseline)",
            "agents": "pilot agents",
            "power": "power",
            "bootstrap": "n per arm: simulated, bootstrap",
            "fitted": "n per arm: simulated, normal fit",
            "closed": "n per arm: closed form",
        },
    )
    return [
        *head,
        "Planning information for a future study, not a test of this one: taking these "
        "agents' observed effect and spreads as true, how many agents (participants) per "
        f"arm the report's per-agent Welch test (two-sided, α = {power.alpha:g}) needs to "
        "detect the effect with 80 % and 90 % probability. Simulated: "
        f"{power.draws} studies per size (seed {power.seed}), their agents drawn from each "
        "arm's observed R_T (bootstrap) or from a normal with its mean and sd; closed form: "
        "n = (z_{1−α/2} + z_power)² (sd_a² + sd_b²) / effect². With few pilot agents the "
        "effect and sd are rough, and the bootstrap, which never draws beyond the observed "
        "values, underestimates the spread (its variance is (k − 1)/k of the sample's for "
        "k agents): plan with the largest n and some margin.",
        "",
        table,
        "",
        *_power_cautions(power, checked),
        *(f"Left out: {s}." for s in power.skipped),
        *([""] if power.skipped else []),
        f"![Power against agents per arm]({FIGURE_FILES['power']})" + _other_formats(formats),
        "",
    ]


def _other_formats(formats: tuple[str, ...]) -> str:
    """Links to the power figure's other formats, after its PNG: " ([SVG](power.svg), ...)",
    or nothing where the PNG is the only one."""
    links = [
        f"[{p.suffix[1:].upper()}]({p})" for p in vector_paths(Path(FIGURE_FILES["power"]), formats)
    ]
    return f" ({', '.join(links)})" if links else ""


def _power_cautions(power: PowerAnalysis, checked: Audit | None) -> list[str]:
    if checked is None:
        return []
    methods = [c.method for c in power.comparisons]
    cautions = checked.power_cautions(dict.fromkeys(methods), power.comparisons[0].baseline)
    return [line for caution in cautions for line in (f"**{caution}**", "")]
