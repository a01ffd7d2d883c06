"""A study's power analysis: its sessions' R_T per method, and the agents per arm a future
study needs (`analysis.power`).

`ideeprl power` comes here. Sessions are chosen and grouped into methods as the report
chooses them (`study.services.reports.select_sessions`), and R_T is the report's, so the
effect planned for is the one the report's per-agent Welch test measures.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy.orm import Session

from analysis.audit import audit
from analysis.baseline import AUTO, NO_BASELINE
from analysis.csvsafe import safe_frame
from analysis.episodes import (
    EpisodeTableError,
    arm_of,
    method_name,
    order_methods,
    validate_episodes,
)
from analysis.figures import plot_power, save_figure, vector_paths
from analysis.formats import figure_formats
from analysis.power import (
    DEFAULT_DRAWS,
    DEFAULT_MAX_N,
    MIN_AGENTS,
    PowerAnalysis,
    power_analysis,
)
from analysis.report import FIGURE_FILES, OPTIONAL_TABLE_FILES
from analysis.report import power_table as _table
from analysis.stats import agent_totals
from study.services.episodes import load_episodes, session_settings
from study.services.errors import Conflict, Invalid
from study.services.reports import CLI_CHOICE, ReportRequest, select_sessions
from study.services.studies import get_study

MIN_DRAWS = 100
"""Fewer simulated studies leave a power's Monte Carlo error above 5 percentage points."""


@dataclass(frozen=True)
class PowerRequest:
    """Which sessions, which baseline, and how the power is computed."""

    baseline: str = AUTO
    """The method each other is compared with; `auto`: autonomous DeepRL."""
    alpha: float = 0.05
    """The planned test's significance level (two-sided)."""
    draws: int = DEFAULT_DRAWS
    """Simulated studies per number of agents."""
    seed: int = 0
    """Seeds every simulated study: the same seed gives the same numbers."""
    max_n: int = DEFAULT_MAX_N
    """The largest study size searched."""
    at_n: tuple[int, ...] = ()
    """Sizes (agents per arm) to give the power at, besides the sizes needed."""
    sessions: tuple[int, ...] | None = None
    """Session ids (any status); None: the study's finished sessions except advisors."""
    methods: tuple[str, ...] | None = None
    """Keep only these methods."""
    label: str | None = None
    """Keep only sessions with this label (a batch's name)."""
    n_episodes: int | None = None
    """Cut every agent to its first N episodes (runs of unequal length)."""

    def check(self) -> None:
        """Raise `Invalid` naming the first value that makes no sense."""
        if not 0 < self.alpha < 1:
            raise Invalid("alpha", f"alpha must be between 0 and 1 (e.g. 0.05), got {self.alpha}")
        if self.draws < MIN_DRAWS:
            raise Invalid(
                "draws", f"draws must be at least {MIN_DRAWS} (default 2000), got {self.draws}"
            )
        if self.seed < 0:
            raise Invalid("seed", f"seed must be 0 or more, got {self.seed}")
        if self.max_n < MIN_AGENTS:
            raise Invalid("max_n", f"max_n must be at least {MIN_AGENTS}, got {self.max_n}")
        outside = [n for n in self.at_n if not MIN_AGENTS <= n <= self.max_n]
        if outside:
            raise Invalid(
                "at_n",
                f"sizes must be {MIN_AGENTS} to max_n={self.max_n} agents per arm, got "
                f"{', '.join(map(str, outside))}",
            )
        if self.n_episodes is not None and self.n_episodes < 1:
            raise Invalid("n_episodes", f"n_episodes must be at least 1, got {self.n_episodes}")
        if self.baseline == NO_BASELINE:
            raise Invalid("baseline", "power compares each method with a baseline: name one")


@dataclass(frozen=True)
class StudyPower:
    """A study's power analysis, the sessions it read and the files it wrote."""

    study_id: int
    sessions: tuple[int, ...]
    n_episodes: int
    """Training episodes per agent in R_T."""
    notes: tuple[str, ...]
    """What the choice of sessions left out, and a caution for each arm whose baseline ran
    under other settings (the report's audit)."""
    analysis: PowerAnalysis
    files: tuple[Path, ...] = ()
    """power.png (with .svg and .pdf) and power.csv, when a folder was given."""


def _baseline(methods: set[str], baseline: str, asked: tuple[str, ...] | None) -> str:
    chosen = "autonomous" if baseline == AUTO else baseline
    if asked and chosen not in asked:
        raise Invalid(
            "baseline",
            f"the baseline {method_name(chosen)} is not among --methods ({', '.join(asked)}): "
            f"add it (--methods {' '.join([*asked, chosen])}), or name one of them as the "
            "baseline (--baseline METHOD)",
        )
    if chosen not in methods:
        named = "no autonomous DeepRL sessions" if baseline == AUTO else f"no {chosen!r} sessions"
        raise Invalid(
            "baseline",
            f"{named} to compare with (methods: {', '.join(sorted(methods))}); "
            "name the baseline method (--baseline METHOD)",
        )
    return chosen


def study_power(
    db: Session,
    study_id: int,
    request: PowerRequest | None = None,
    out_dir: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> StudyPower:
    """The power analysis of the study's finished sessions (as the report picks them); with
    `out_dir`, the figure (PNG and SVG) and the table written there."""
    request = request or PowerRequest()
    request.check()
    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise Invalid("out", f"{out_dir} is a file; pass a folder")
    get_study(db, study_id)
    chosen = ReportRequest(sessions=request.sessions, methods=request.methods, label=request.label)
    sessions, notes = select_sessions(db, study_id, chosen)
    baseline = _baseline(
        {arm_of(s.spec) for s in sessions},
        request.baseline,
        request.methods,
    )
    episodes = load_episodes(db, [s.id for s in sessions])
    empty = sorted({s.id for s in sessions} - set(episodes["session_id"]))
    if empty:
        raise Conflict(
            f"session(s) {', '.join(map(str, empty))} have no training episodes yet; "
            "leave them out (--sessions, --methods), or wait until they have run"
        )
    try:
        table = validate_episodes(episodes, n_episodes=request.n_episodes)
    except EpisodeTableError as error:
        reason = error.worded(CLI_CHOICE.length)  # `ideeprl power` is its one caller
        raise Conflict(f"these sessions cannot be compared as they are: {reason}") from None
    agents = agent_totals(table, baseline=None)
    r_t = {
        m: agents.loc[agents["method"] == m, "R_T"].to_numpy(dtype=float)
        for m in order_methods(agents["method"], baseline)
    }
    analysis = power_analysis(
        r_t, baseline, alpha=request.alpha, draws=request.draws, seed=request.seed,
        max_n=request.max_n, at_n=request.at_n, progress=progress,
    )  # fmt: skip
    if not analysis.comparisons:
        why = "; ".join(analysis.skipped) or f"only {method_name(baseline)} has sessions"
        raise Conflict(
            f"too few sessions for a power analysis: {why}. Run at least {MIN_AGENTS} "
            "finished sessions of the baseline and of another method"
        )
    used = set(table["session_id"])
    checked = audit(session_settings([s for s in sessions if s.id in used]), baseline)
    notes += checked.power_cautions([c.method for c in analysis.comparisons], baseline)
    files: tuple[Path, ...] = ()
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        figure = plot_power(analysis)
        csv = out_dir / OPTIONAL_TABLE_FILES["power"]
        safe_frame(_table(analysis)).to_csv(csv, index=False)
        formats = figure_formats()
        png = save_figure(figure, out_dir / FIGURE_FILES["power"], formats=formats)
        files = (png, *vector_paths(png, formats), csv)
    ids = tuple(int(i) for i in table["session_id"].unique())
    return StudyPower(study_id, ids, int(table["episode"].max()), tuple(notes), analysis, files)
