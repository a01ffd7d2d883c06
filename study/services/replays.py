"""Replays: a recorded session's advice fed by order to a new run (SPEC section 5, "Replay");
a session of evaluative feedback, its ratings (the i-th judgement to the i-th request).

A replay is a session of method `replayed` whose stream is the source session's advice in
advice order: the i-th advice goes to the i-th request of the replayed run, whatever state
it meets; each records whether it met the image its advisor saw (`advice.same_observation`);
a request beyond the stream is counted against the budget and logged without an action. The
source is a session of this database (`sessions.replay_of`: deleting it, or its participant,
deletes the replay) or of a study export (a zip or folder `ideeprl export` wrote: the replay
then records where it came from, and nothing here can delete the export's copy).

Unchanged (the source's run, only the method changed), a replay takes the original's steps
on the CPU kind and numerics the original recorded: `compare` checks every column that
decides a run's course, step by step, and `why_records_may_differ` says when the machine or
code differ so that a difference is not a fault.
"""

from __future__ import annotations

import json
import math
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict, cast

from sqlalchemy import select
from sqlalchemy.orm import Session

from analysis.replays import same_run
from analysis.replays import unchanged_replays as unchanged_replays_rule
from learner import provenance as provenance_
from learner.config import DQNConfig
from learner.fields import FieldError
from learner.records import observation_hash
from learner.run import RunSpec
from study.db.models import LIVE_STATUSES, Advice, Feedback, Status, Step, StudySession
from study.schemas.sessions import SessionOptions
from study.services.errors import Conflict, Invalid, NotFound
from study.services.sessions import Replay, ReplayStream, StreamSource, create_session

LIVE = {s.value for s in LIVE_STATUSES}
DECIDING = (
    "global_step", "stage", "episode", "episode_step", "action", "action_source",
    "advised_action", "advice_remaining", "reward", "terminated", "truncated",
    "observation_hash",
)  # fmt: skip
"""The step columns that decide a run's course (not its wall times, Q-values or losses):
what an unchanged replay must reproduce exactly."""


class StepRow(TypedDict):
    """A step's `DECIDING` columns, typed as the database holds them."""

    global_step: int
    stage: str
    episode: int
    episode_step: int
    action: int
    action_source: str
    advised_action: int | None
    advice_remaining: int | None
    reward: float
    terminated: bool
    truncated: bool
    observation_hash: str | None


@dataclass(frozen=True)
class Stream:
    """A recorded session, as a replay needs it: its run, its advice in order, and where
    it was computed."""

    run: RunSpec
    """The source's run."""
    actions: tuple[int, ...]
    """Its advice, in advice order."""
    observation_hashes: tuple[str, ...]
    """The hash of the image each advice's advisor saw (`observation_hash`)."""
    source: StreamSource
    """Where it comes from: `study` (name), `session` (id there), `export` (file, or None)."""
    provenance: list[Any] = field(default_factory=list)
    """The source's `sessions.provenance`: the machines and numerics that computed it."""
    steps: list[StepRow] = field(default_factory=list, repr=False)
    """The source's step records (the `DECIDING` columns), for `compare`."""
    session_id: int | None = None
    """The source's id in this database (None: from an export)."""
    finished: bool = True
    """The source ran to its end (else its steps are a prefix of its run's)."""
    judgements: tuple[float | None, ...] | None = None
    """A stream of ratings (the source's feedback was evaluative): its judgements in
    order (None: no answer), `actions` the actions judged; None: a stream of advice."""

    @property
    def rates(self) -> bool:
        return self.judgements is not None

    def stored(self) -> ReplayStream:
        """What the replay's session keeps (`sessions.replay_stream`)."""
        stored = ReplayStream(
            source=self.source,
            actions=list(self.actions),
            observation_hashes=list(self.observation_hashes),
        )
        if self.judgements is not None:
            stored["judgements"] = list(self.judgements)
        return stored


def _png_hash(png: bytes) -> str:
    from study.services.observations import observation_of

    return observation_hash(observation_of(png))


def stream_of_session(db: Session, session_id: int) -> Stream:
    """The stream of a session of this database."""
    session = db.get(StudySession, session_id)
    if session is None:
        raise NotFound(f"no session with id {session_id}")
    if session.status in LIVE:
        raise Conflict(
            f"session {session_id} is {session.status}: its advice is still being recorded; "
            "replay it once it has finished or stopped"
        )
    steps = db.execute(
        select(*(getattr(Step, c) for c in DECIDING))
        .where(Step.session_id == session_id)
        .order_by(Step.global_step)
    )
    if session.spec.feedback == "evaluative":
        ratings = list(
            db.scalars(
                select(Feedback)
                .where(Feedback.session_id == session_id)
                .order_by(Feedback.feedback_index)
            )
        )
        actions = tuple(int(f.action) for f in ratings)
        hashes = tuple(f.observation_hash for f in ratings)
        judgements: tuple[float | None, ...] | None = tuple(f.judgement for f in ratings)
    else:
        advice = list(
            db.scalars(
                select(Advice)
                .where(Advice.session_id == session_id, Advice.action.is_not(None))
                .order_by(Advice.advice_index)
            )
        )
        actions = tuple(int(a.action) for a in advice)  # type: ignore[arg-type]
        hashes = tuple(_png_hash(a.observation_png) for a in advice)
        judgements = None
    return Stream(
        run=session.spec,
        actions=actions,
        observation_hashes=hashes,
        judgements=judgements,
        source=StreamSource(study=session.study.name, session=session_id, export=None),
        provenance=list(session.provenance),
        steps=[cast(StepRow, dict(row._mapping)) for row in steps],
        session_id=session_id,
        finished=session.status == Status.finished.value,
    )


def stream_of_export(path: Path, session_id: int) -> Stream:
    """The stream of session `session_id` of a study export (its zip, or its folder)."""
    from analysis.exported import ExportError, _provenance, _table, _with_stage, run_of

    path = Path(path)
    if path.is_file() and zipfile.is_zipfile(path):
        with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(path) as archive:
            archive.extractall(tmp)
            found = stream_of_export(Path(tmp), session_id)
            return Stream(**{**vars(found), "source": {**found.source, "export": str(path)}})
    if not path.is_dir():
        raise NotFound(f"no study export at {path}")
    try:
        sessions = _of(_table(path, "sessions"), session_id)
        if not sessions:
            raise NotFound(f"the export at {path} has no session {session_id}")
        info = path / "study.json"
        study = json.loads(info.read_text()) if info.is_file() else {}
        run = run_of(sessions[0])
        judgements: tuple[float | None, ...] | None = None
        if run.feedback == "evaluative":
            ratings = _of(_table(path, "feedback"), session_id)
            ratings.sort(key=lambda r: int(r["feedback_index"]))
            actions = tuple(int(r["action"]) for r in ratings)
            hashes = tuple(str(r["observation_hash"]) for r in ratings)
            judgements = tuple(
                None if _missing(r["judgement"]) else float(r["judgement"]) for r in ratings
            )
        else:
            advice = [
                r for r in _of(_table(path, "advice"), session_id) if not _missing(r["action"])
            ]
            advice.sort(key=lambda r: int(r["advice_index"]))
            actions = tuple(int(r["action"]) for r in advice)
            hashes = tuple(_png_hash((path / r["observation_file"]).read_bytes()) for r in advice)
        steps = _of(_with_stage(_table(path, "steps")), session_id)  # old exports' `phase`
        recorded = (_provenance(_table(path, "sessions")) or {}).get(session_id, [])
    except (ExportError, OSError, KeyError, ValueError) as error:
        if isinstance(error, NotFound):
            raise
        raise Invalid("export", f"{path}: not a study export this version reads ({error})") from (
            None
        )
    return Stream(
        finished=sessions[0].get("status") == Status.finished.value,
        run=run,
        actions=actions,
        observation_hashes=hashes,
        judgements=judgements,
        source=StreamSource(study=study.get("name"), session=session_id, export=str(path)),
        provenance=recorded,
        steps=[_typed_step(r) for r in sorted(steps, key=lambda r: int(r["global_step"]))],
    )


def _of(table: Any, session_id: int) -> list[dict[str, Any]]:
    """The rows of one session in an exported table."""
    return [dict(row) for _, row in table[table["session_id"].astype(int) == session_id].iterrows()]


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value)) or value == ""


def _typed_step(row: Mapping[str, Any]) -> StepRow:
    """An exported step row's deciding columns, typed as the database holds them."""
    kinds: dict[str, Callable[[Any], float | bool]] = {
        "reward": float,
        "terminated": _bool,
        "truncated": _bool,
    }
    typed: dict[str, Any] = {}
    for name in DECIDING:
        value = row.get(name)
        if value is None or _missing(value):
            typed[name] = None
        elif name in kinds:
            typed[name] = kinds[name](value)
        elif name in ("stage", "action_source", "observation_hash"):
            typed[name] = str(value)
        else:
            typed[name] = int(value)
    return cast(StepRow, typed)


def _bool(value: Any) -> bool:
    return value is True or str(value).lower() == "true"


def replay_run(original: RunSpec, values: Mapping[str, Any]) -> RunSpec:
    """The source's run as a replay (method `replayed`), with `values` changed by leaf name
    (`RunSpec.with_values`). A new `preset` takes that preset's config, keeping the fields
    the original set apart from its own preset (its scale: episodes, pretraining steps,
    budget; its pinned numerics); `Invalid` names a field that cannot be."""
    if original.method == "procedure":
        raise Invalid(
            "run.method",
            "a procedure control's advice is random by design, its schedule its own; replay "
            "the advised session it follows instead",
        )
    values = dict(values)
    values.pop("method", None)
    preset = values.pop("preset", original.preset)
    run = original.replace(method="replayed", advisor_checkpoint=None, error_rate=0.0)
    try:
        if preset != original.preset:
            base = DQNConfig.preset(original.preset).to_dict()
            kept = {k: v for k, v in original.config.to_dict().items() if v != base[k]}
            document = {**run.to_json(), "preset": preset, "config": kept}
            run = RunSpec.from_json(document)
        return (run.with_values(values) if values else run).validate()
    except (FieldError, ValueError) as error:
        raise Invalid(f"run.{getattr(error, 'field', '')}".rstrip("."), str(error)) from None


def unchanged(stream: Stream, run: RunSpec) -> bool:
    """Whether `run` is the source's own run (only its method differs)."""
    return same_run(stream.run, run)


def unchanged_replays(db: Session, sessions: Iterable[StudySession]) -> dict[int, int]:
    """Of these sessions, the replays that run their source's own run (the determinism
    check, `analysis.replays.unchanged_replays`), by id, with their source's id: the same
    agent again, not one of its own. Only a source in this database is known; a replay of
    an export counts as changed."""
    replays = [s for s in sessions if s.method == "replayed" and s.replay_of is not None]
    replay_of = {s.id: s.replay_of for s in replays if s.replay_of is not None}
    sources = {i: db.get(StudySession, i) for i in set(replay_of.values())}
    known = {i: source.spec for i, source in sources.items() if source is not None}
    return unchanged_replays_rule({s.id: s.spec for s in replays}, replay_of, known)


def create_replay(
    db: Session, study_id: int, stream: Stream, run: RunSpec, label: str = ""
) -> StudySession:
    """The replay's session, `created`, its run pinned here and its stream copied: ratings
    only into a run of evaluative feedback, advice only into a run of advice."""
    if stream.rates != (run.feedback == "evaluative"):
        recorded, other = ("ratings", "advice") if stream.rates else ("advice", "ratings")
        raise Invalid(
            "run.feedback",
            f"session {stream.source['session']} recorded {recorded}; a replay feeds them to "
            f"a run of the same feedback, not one that asks for {other}",
        )
    return create_session(
        db,
        study_id,
        run,
        SessionOptions(label=label or f"replay of session {stream.source['session']}"),
        replay=Replay(stream.session_id, stream.stored()),
    )


def why_records_may_differ(stream: Stream, run: RunSpec) -> str | None:
    """Why the replay's records may differ from the original's without a fault: the
    original was computed (in part) on another CPU kind, torch, code or numerics than this
    machine computes the replay with, or its provenance is unknown; None when they match."""
    problem = run.numerics_problem()
    if problem:
        return problem
    if not stream.provenance:
        return (
            "the original recorded no provenance (computed before sessions kept it): its CPU "
            "kind and numerics are unknown"
        )
    here: Mapping[str, object] = provenance_.record(run.config)  # read by key
    reasons = []
    for entry in stream.provenance:
        for key, what in (("cpu", "CPU"), ("torch", "torch"), ("code", "code version")):
            if entry.get(key) != here[key]:
                reasons.append(
                    f"the original was computed with {what} {entry.get(key)} from step "
                    f"{entry.get('from_step', 0)}, this replay with {here[key]}"
                )
        if entry.get("numerics") != here["numerics"]:
            reasons.append(
                f"the original's numerics were {entry.get('numerics')}, the replay's "
                f"{here['numerics']}"
            )
    return "; ".join(dict.fromkeys(reasons)) or None


@dataclass(frozen=True)
class Comparison:
    """An unchanged replay's steps against the original's."""

    steps: int
    """Steps compared."""
    difference: dict[str, Any] | None
    """The first difference: `global_step`, `column`, `original`, `replay`; None if none."""

    @property
    def equal(self) -> bool:
        return self.difference is None


def replay_steps(db: Session, session_id: int) -> list[StepRow]:
    query = (
        select(*(getattr(Step, c) for c in DECIDING))
        .where(Step.session_id == session_id)
        .order_by(Step.global_step)
    )
    return [cast(StepRow, dict(row._mapping)) for row in db.execute(query)]


def compare(
    original: Iterable[StepRow],
    replay: Iterable[StepRow],
    complete: bool = True,
) -> Comparison:
    """The first step and column where the replay differs from the original (`DECIDING`);
    an original that did not run to its end (not `complete`) is compared as the prefix it
    is, and one recorded before steps kept their observation hash without it."""
    before: list[Mapping[str, object]] = list(original)  # read column by column
    after: list[Mapping[str, object]] = list(replay)
    if not complete:
        after = after[: len(before)]
    for mine, theirs in zip(before, after, strict=False):
        for column in DECIDING:
            if column == "observation_hash" and mine[column] is None:
                continue  # recorded before steps kept it (0012): compared without it
            if mine[column] != theirs[column]:
                return Comparison(
                    len(before),
                    {"global_step": mine["global_step"], "column": column,
                     "original": mine[column], "replay": theirs[column]},
                )  # fmt: skip
    if len(before) != len(after):
        return Comparison(
            len(before),
            {"global_step": min(len(before), len(after)) + 1, "column": "steps",
             "original": len(before), "replay": len(after)},
        )  # fmt: skip
    return Comparison(len(before), None)


@dataclass(frozen=True)
class AdviceSummary:
    """What became of a replay's stream."""

    replayed: int
    """Advice fed from the stream."""
    same_observation: int
    """Of them, those that met the image their advisor saw."""
    beyond_stream: int
    """Requests after the stream ran out (none given)."""
    first_different: int | None
    """Global step of the first advice that met another image (None: all the same)."""


def ratings_summary(db: Session, session_id: int, stream: Stream) -> AdviceSummary:
    """What became of a replay's stream of ratings: the i-th feedback row of the replay
    took the i-th recorded rating, on the image that rating was given on or not."""
    hashes = list(
        db.scalars(
            select(Feedback.observation_hash)
            .where(Feedback.session_id == session_id)
            .order_by(Feedback.feedback_index)
        )
    )
    given = hashes[: len(stream.judgements or ())]
    different = [
        i
        for i, (mine, theirs) in enumerate(zip(given, stream.observation_hashes, strict=False))
        if mine != theirs
    ]
    first = None
    if different:
        first = db.scalar(
            select(Feedback.global_step).where(
                Feedback.session_id == session_id, Feedback.feedback_index == different[0]
            )
        )
    return AdviceSummary(
        replayed=len(given),
        same_observation=len(given) - len(different),
        beyond_stream=len(hashes) - len(given),
        first_different=first,
    )


def advice_summary(db: Session, session_id: int) -> AdviceSummary:
    rows = db.execute(
        select(Advice.action, Advice.same_observation, Advice.global_step)
        .where(Advice.session_id == session_id)
        .order_by(Advice.advice_index)
    ).all()
    given = [r for r in rows if r.action is not None]
    different = [r.global_step for r in given if not r.same_observation]
    return AdviceSummary(
        replayed=len(given),
        same_observation=sum(bool(r.same_observation) for r in given),
        beyond_stream=len(rows) - len(given),
        first_different=different[0] if different else None,
    )


def replays_of(db: Session, session_ids: Iterable[int]) -> list[StudySession]:
    """Every replay made from these sessions, replays of replays included (what deleting
    them deletes with them)."""
    found: list[StudySession] = []
    frontier = list(session_ids)
    seen = set(frontier)
    while frontier:
        query = select(StudySession).where(StudySession.replay_of.in_(frontier))
        children = [s for s in db.scalars(query) if s.id not in seen]
        seen.update(s.id for s in children)
        found += children
        frontier = [s.id for s in children]
    return found
