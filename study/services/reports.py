"""A study's report: choose its sessions, read their episodes, write the paper's analysis.

`ideeprl report` and `POST /api/studies/{id}/report` both come here. By default a report
covers the study's finished sessions, except those that served as another session's
advisor (the agent trained for agent-IDeepRL is not one of the autonomous agents). A
researcher's previews are never in a report. An online study's report compares its
conditions (the manipulation: they stand where methods stand, so the audit flags any other
difference) at the design's alpha.
"""

from __future__ import annotations

import json
import shlex
import shutil
import threading
import uuid
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import pandas as pd
from sqlalchemy.orm import Session

from analysis.baseline import AUTO, BaselineError, advisors_left_out, compare_conditions
from analysis.baseline import choose_baseline as baseline_rule
from analysis.episodes import EpisodeTableError, arm_of, method_name
from analysis.finished import (
    Choice,
    is_finished,
    left_out_notes,
    not_finished,
    nothing_finished,
    status_of,
)
from analysis.markdown import some
from analysis.replays import unchanged_replays_note
from learner.advisor_check import last_check
from learner.run import RunSpec, run_flags
from study.db.models import StudySession
from study.services.errors import Conflict, Invalid, NotFound
from study.services.replays import unchanged_replays
from study.services.sessions import advisor_sessions, list_sessions
from study.services.studies import design_of, get_study
from study.services.tables import iso_z
from study.settings import Settings

if TYPE_CHECKING:
    from analysis.report import ReportResult

_publishing = threading.Lock()

CLI_CHOICE = Choice("`--sessions ID ...` and `--n-episodes N`", "`--n-episodes {n}`")
"""How `ideeprl report` (and `ideeprl power`) choose sessions by id and cut them to a length."""
API_CHOICE = Choice(
    "the body's `sessions` (their ids) and `n_episodes`", '`"n_episodes": {n}` in the body'
)
"""How `POST /api/studies/{id}/report` does."""


def dashboard_choice(study_id: int) -> Choice:
    """Where the dashboard's researcher chooses sessions (its Build report takes the
    finished ones): the REST API, or the command line."""
    return Choice(
        f"`POST /api/studies/{study_id}/report` (the body's `sessions` and `n_episodes`) or "
        f"`ideeprl report --study {study_id} --sessions ID ... --n-episodes N`; the "
        "dashboard's Build report takes the finished sessions",
        f'`"n_episodes": {{n}}` to `POST /api/studies/{study_id}/report` (or '
        f"`ideeprl report --study {study_id} --n-episodes {{n}}`)",
    )


@dataclass(frozen=True)
class ReportRequest:
    """Which sessions a report covers and how it compares them."""

    sessions: tuple[int, ...] | None = None
    """Session ids (any status); None: the study's finished sessions except advisors."""
    methods: tuple[str, ...] | None = None
    """Keep only these methods."""
    label: str | None = None
    """Keep only sessions with this label (a batch's name)."""
    baseline: str = AUTO
    """The method improvements are measured against: a method, `auto` or `none`."""
    n_episodes: int | None = None
    """Cut every agent to its first N episodes (to compare runs of different lengths)."""
    common_length: bool = False
    """Without `n_episodes`: when the sessions differ in length, cut all to the shortest
    (and say so in the notes) instead of refusing."""
    title: str | None = None
    """The report's title; default: the study's name."""
    notes: tuple[str, ...] = ()
    """Lines under the title (the command, versions, wall time)."""
    allow_mismatch: bool = False
    """Give the t-tests of methods whose settings differ too (the warning stays)."""
    reference: str | None = None
    """`authors`: draw the authors' published curves on Figure 5."""
    primary: str = "welch"
    """Each comparison's primary test: `welch`, or `paired` over seeds where they pair."""
    choose: Choice = CLI_CHOICE
    """How the caller chooses sessions by id and a number of episodes, in its own terms: what
    the report suggests for sessions not finished yet, and for sessions of different lengths
    (`CLI_CHOICE`, `API_CHOICE`, `dashboard_choice`)."""


def _statuses(sessions: list[StudySession]) -> dict[int, str]:
    """Each session's status as a report names it (`analysis.finished.status_of`)."""
    return {
        s.id: status_of(s.status, s.declined_at is not None and s.consented_at is None)
        for s in sessions
    }


def _ids(sessions: list[StudySession]) -> str:
    return some((s.id for s in sessions), 12)


def failed_advisors(sessions: list[StudySession], advisors: set[int]) -> list[int]:
    """The advisors whose check, stored beside their checkpoint, failed (as last checked)."""
    return [
        s.id
        for s in sessions
        if s.id in advisors
        and s.checkpoint_path
        and (check := last_check(s.checkpoint_path)) is not None
        and not check.passed
    ]


def select_sessions(
    db: Session, study_id: int, request: ReportRequest
) -> tuple[list[StudySession], list[str]]:
    """The sessions the report covers, and sentences on what was left out and why."""
    everything = [s for s in list_sessions(db, study_id) if not s.preview and not s.pooled]
    notes: list[str] = []
    if request.sessions:
        by_id = {s.id: s for s in everything}
        missing = [i for i in request.sessions if i not in by_id]
        if missing:
            raise Invalid(
                "sessions",
                f"session(s) {', '.join(map(str, missing))} are not in study {study_id}; "
                f"its sessions are {_ids(everything) or 'none'}",
            )
        chosen = [by_id[i] for i in dict.fromkeys(request.sessions)]
    else:
        advisors = advisor_sessions(everything)
        checks = unchanged_replays(db, everything)
        others = [s for s in everything if s.id not in advisors and s.id not in checks]
        chosen = [s for s in others if is_finished(s.status)]
        if advisors:
            notes.append(advisors_left_out(advisors, failed_advisors(everything, advisors)))
        if checks:
            notes.append(unchanged_replays_note(checks))
        notes += left_out_notes(not_finished(_statuses(others)), request.choose.sessions)
    if request.label is not None:
        chosen = [s for s in chosen if s.label == request.label]
        notes.append(f"Sessions labelled {request.label!r} only.")
    if request.methods:
        chosen = [s for s in chosen if arm_of(s.spec) in request.methods]
        absent = [m for m in request.methods if m not in {arm_of(s.spec) for s in chosen}]
        if absent:
            notes.append(f"No sessions of method(s) {', '.join(absent)} to include.")
    if not chosen:
        raise Conflict(_nothing_chosen(study_id, everything, request))
    return chosen, notes


def _nothing_chosen(study_id: int, everything: list[StudySession], request: ReportRequest) -> str:
    """Why no session was chosen, naming what the study has."""
    if not everything:
        return (
            f"study {study_id} has no sessions yet: run some first (`ideeprl batch --study "
            f"{study_id} ...`, or participants' sessions)"
        )
    finished = [s for s in everything if is_finished(s.status)]
    if not finished:
        return nothing_finished(f"study {study_id}", _statuses(everything), request.choose.sessions)
    labels = sorted({s.label for s in finished if s.label}, key=str)
    methods = sorted({arm_of(s.spec) for s in finished})
    problems = []
    if request.label is not None and request.label not in labels:
        problems.append(
            f"no finished session is labelled {request.label!r} (its labels: "
            f"{', '.join(map(repr, labels)) or 'none'})"
        )
    if request.methods and not set(request.methods) & set(methods):
        problems.append(
            f"none is of method(s) {', '.join(request.methods)} (its methods: {', '.join(methods)})"
        )
    if not problems:
        problems.append(
            f"no finished session matches the label and methods together (its methods: "
            f"{', '.join(methods)}; labels: {', '.join(map(repr, labels)) or 'none'})"
        )
    return f"study {study_id} has no finished sessions to analyse with these choices: " + (
        "; ".join(problems)
    )


def baseline_next_step(db: Session, study_id: int, chosen: list[StudySession]) -> str:
    """How to give a report without autonomous sessions its baseline: the study's finished
    autonomous sessions that the choice left out, or else the batch that runs them with the
    chosen sessions' settings (the first one's run, as an autonomous run; the report
    still flags any setting that differs)."""
    everything = [s for s in list_sessions(db, study_id) if not s.preview and not s.pooled]
    advisors = advisor_sessions(everything)
    left_out = [
        s
        for s in everything
        if s.method == "autonomous" and is_finished(s.status) and s.id not in advisors
    ]
    if left_out:
        return (
            f"Study {study_id} has finished autonomous DeepRL sessions this choice left out "
            f"({_ids(left_out)}): include them (the methods or label chosen excluded them) "
            "to compare against them."
        )
    first = RunSpec.from_json(chosen[0].run)
    seeds = [s.seed for s in chosen if s.method == chosen[0].method]
    spec = first.replace(method="autonomous", seed=min(seeds))
    command = ["ideeprl", "batch", "--study", str(study_id), "--methods", "autonomous"]
    command += ["--agents", str(len(seeds)), "--label", "autonomous", *run_flags(spec)]
    return (
        "To add the baseline with the same settings as the first session here ("
        f"{chosen[0].id}), one agent for each of its method's seeds: "
        f"`{shlex.join(command)}` (with `--data-dir` or `--database-url` as the server's)."
    )


def choose_baseline(methods: set[str], baseline: str) -> tuple[str | None, list[str]]:
    """`analysis.baseline.choose_baseline`, its error a 422 on `baseline`."""
    try:
        return baseline_rule(methods, baseline)
    except BaselineError as error:
        raise Invalid("baseline", str(error)) from None


@dataclass(frozen=True)
class StudyReport:
    """A written report and how its sessions were chosen."""

    result: ReportResult
    """What `write_report` wrote."""
    notes: tuple[str, ...]
    """What the choice of sessions and baseline left out or decided (also in the report)."""


def strategy_of(spec: RunSpec) -> str | None:
    """The run's advising strategy; None for a run without advice."""
    return spec.strategy if spec.advised else None


def build_report(
    db: Session, study_id: int, out_dir: str | Path, request: ReportRequest | None = None
) -> StudyReport:
    """Write the report of the chosen sessions into `out_dir` (see `write_report`). The
    analysis (pandas' tables, scipy's tests, matplotlib's figures) loads here, when a report
    is built, not with the web app."""
    from analysis.advice import replayed_advice_notes
    from analysis.human import learners_finished
    from analysis.report import write_human_report, write_report
    from study.services.episodes import (
        load_advised_steps,
        load_episodes,
        load_replayed_advice,
        load_training_steps,
        load_visits,
        session_settings,
    )

    request = request or ReportRequest()
    study = get_study(db, study_id)
    design = design_of(study)
    visits = learners = None
    plan = None if design is None else design.preregistered()
    if design is not None:  # the participants' measures wait for no learner
        everything = [s for s in list_sessions(db, study_id) if not s.preview and not s.pooled]
        visits = load_visits(db, everything)
    if visits is not None and len(visits.visits):
        learners = learners_finished(visits)
    try:
        sessions, notes = select_sessions(db, study_id, request)
    except Conflict:
        if visits is None or visits.completed.empty or request.sessions:
            raise
        assert learners is not None
        title = request.title or f"{study.name}: the participants"
        lines = [learners, *request.notes, f"Study {study.id} ({study.name})."]
        alpha = design.alpha if design is not None else 0.05
        result = write_human_report(
            visits, out_dir, title=title, notes=lines, alpha=alpha, preregistered=plan
        )
        return StudyReport(result, (learners,))
    group = {s.id: (s.condition if design and s.condition else arm_of(s.spec)) for s in sessions}
    baseline, baseline_notes = choose_baseline(set(group.values()), request.baseline)
    if baseline is None and request.baseline == AUTO and design is None:
        baseline_notes.append(baseline_next_step(db, study_id, sessions))
    episodes = load_episodes(db, [s.id for s in sessions])
    settings = session_settings(sessions)
    if design is not None:  # the conditions are what is compared
        episodes, settings, note = compare_conditions(episodes, settings, group, design.alpha)
        notes.append(note)
    elif any(group[s.id] != s.method for s in sessions):  # evaluative feedback: arms of its own
        notes.append(
            "Runs given evaluative feedback are compared as arms of their own "
            "(METHOD-evaluative, and METHOD-evaluative-rating_model where a model of the "
            "ratings shapes the steps not rated), apart from the same advisor's advice."
        )
    steps = load_training_steps(db, [s.id for s in sessions])
    advice = load_advised_steps(db, [s.id for s in sessions])
    replayed = {s.id: group[s.id] for s in sessions if s.method == "replayed"}
    if replayed:
        notes += replayed_advice_notes(load_replayed_advice(db, list(replayed)), replayed)
    empty = sorted({s.id for s in sessions} - set(episodes["session_id"]))
    if empty:
        raise Conflict(
            f"session(s) {', '.join(map(str, empty))} have no training episodes yet; "
            "leave them out, or wait until they have run"
        )
    n_episodes = request.n_episodes
    if n_episodes is None and request.common_length:
        lengths = episodes.groupby("session_id")["episode"].count()
        if lengths.nunique() > 1:
            n_episodes = int(lengths.min())
            notes.append(
                f"The sessions differ in length ({int(lengths.min())} to {int(lengths.max())} "
                f"training episodes): every session is compared over its first {n_episodes} "
                "episodes, the length they have in common."
            )
    counts = ", ".join(
        f"{sum(group[s.id] == m for s in sessions)} {method_name(m)}"
        for m in dict.fromkeys(group[s.id] for s in sessions)
    )
    lines = [
        *([learners] if learners else []),
        *request.notes,
        f"Study {study.id} ({study.name}); sessions {_ids(sessions)}: {counts}.",
        *notes,
        *baseline_notes,
    ]
    try:
        result = write_report(
            episodes,
            out_dir,
            title=request.title or f"{study.name}: the paper's analysis",
            baseline=baseline,
            notes=lines,
            n_episodes=n_episodes,
            settings=settings,
            steps=steps,
            allow_mismatch=request.allow_mismatch,
            reference=request.reference,
            advice=advice,
            primary=request.primary,
            alpha=design.alpha if design is not None else 0.05,  # write_report's default
            visits=visits if visits is not None and len(visits.visits) else None,
            strategies={s.id: strategy_of(s.spec) for s in sessions},
            preregistered=plan,
        )
    except EpisodeTableError as error:
        reason = error.worded(request.choose.length)
        raise Conflict(f"these sessions cannot be compared as they are: {reason}") from None
    return StudyReport(result, (*notes, *baseline_notes, *result.notes))


# --- the report a researcher builds on the server ----------------------------------------
def reports_dir(settings: Settings) -> Path:
    """Where the server keeps each study's last report."""
    return settings.data_dir / "reports"


def report_dir(reports_dir: Path, study_id: int) -> Path:
    return reports_dir / f"study-{study_id}"


class ReportFileEntry(TypedDict):
    name: str
    kind: str
    """report (Markdown), figure (PNG, SVG, PDF) or table (CSV)."""


class ReportMethodEntry(TypedDict):
    method: str
    name: str
    agents: int
    episodes: int
    R_T: float
    improvement_pct: float | None
    difference: float | None


class ReportDescription(TypedDict):
    """What a published report says about itself: saved beside it as JSON
    (`study-ID.json`), read back as-is (`ReportPublic` adds its URLs)."""

    study_id: int
    created_at: str
    sessions: list[int]
    baseline: str | None
    n_episodes: int
    notes: list[str]
    files: list[ReportFileEntry]
    methods: list[ReportMethodEntry]


def describe_report(study_id: int, built: StudyReport) -> ReportDescription:
    """What the API says about a report: its sessions, choices, files and R_T per method."""
    result = built.result
    analysis = result.analysis
    files = [("report", result.report)]
    files += [("figure", p) for p in result.figures.values()]
    files += [("figure", p) for p in result.vector_figures]
    files += [("table", p) for p in result.tables.values()]
    return {
        "study_id": study_id,
        "created_at": iso_z(datetime.now(UTC)),
        "sessions": []
        if analysis is None
        else sorted(int(i) for i in analysis.episodes["session_id"].unique()),
        "baseline": None if analysis is None else analysis.baseline,
        "n_episodes": 0 if analysis is None else analysis.n_episodes,
        "notes": list(built.notes),
        "files": [ReportFileEntry(name=path.name, kind=kind) for kind, path in files],
        "methods": [
            ReportMethodEntry(
                method=str(row["method"]),
                name=str(row["name"]),
                agents=int(row["agents"]),
                episodes=int(row["episodes"]),
                R_T=float(row["R_T"]),
                improvement_pct=None
                if pd.isna(row["improvement_pct"])
                else float(row["improvement_pct"]),
                difference=None
                if pd.isna(row.get("difference", float("nan")))
                else float(row["difference"]),
            )
            for _, row in (pd.DataFrame() if analysis is None else analysis.methods).iterrows()
        ],
    }


def publish_report(
    db: Session, study_id: int, reports_dir: Path, request: ReportRequest
) -> ReportDescription:
    """Build the study's report into `reports_dir/study-ID/`, replacing the previous one
    only once the new one is complete; returns its description (also saved as JSON)."""
    reports_dir.mkdir(parents=True, exist_ok=True)
    building = reports_dir / f".study-{study_id}-{uuid.uuid4().hex[:8]}"
    try:
        description = describe_report(study_id, build_report(db, study_id, building, request))
        with _publishing:
            final = report_dir(reports_dir, study_id)
            old = reports_dir / f".old-study-{study_id}-{uuid.uuid4().hex[:8]}"
            if final.exists():
                final.rename(old)
            building.rename(final)
            (reports_dir / f"study-{study_id}.json").write_text(json.dumps(description, indent=2))
            shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(building, ignore_errors=True)
    return description


def published_report(reports_dir: Path, study_id: int) -> ReportDescription:
    path = reports_dir / f"study-{study_id}.json"
    if not path.is_file() or not report_dir(reports_dir, study_id).is_dir():
        raise NotFound(
            f"study {study_id} has no report: none was built, or the last one was removed "
            "when a session was deleted; build one (the dashboard's Build report, or POST "
            f"/api/studies/{study_id}/report)"
        )
    return json.loads(path.read_text())


def report_built_at(reports_dir: Path, study_id: int) -> str | None:
    """When the study's published report was built (its `created_at`), None without one:
    what a page polls to know whether the report it shows is still the one there is."""
    try:
        return published_report(reports_dir, study_id)["created_at"]
    except (NotFound, OSError, ValueError, KeyError):
        return None


def report_file(reports_dir: Path, study_id: int, name: str) -> Path:
    """A file of the study's report, by name (only the names the report lists)."""
    description = published_report(reports_dir, study_id)
    if name not in {f["name"] for f in description["files"]}:
        names = ", ".join(f["name"] for f in description["files"])
        raise NotFound(f"the report of study {study_id} has no file {name!r}; it has {names}")
    return report_dir(reports_dir, study_id) / name


def report_zip(reports_dir: Path, study_id: int, scratch: Path) -> Path:
    """The report's folder as one zip in a fresh folder under `scratch`."""
    published_report(reports_dir, study_id)
    folder = scratch / uuid.uuid4().hex
    folder.mkdir(parents=True)
    base = folder / f"study-{study_id}-report"
    return Path(shutil.make_archive(str(base), "zip", report_dir(reports_dir, study_id)))
