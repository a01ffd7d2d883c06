"""Sessions: create (the run checked and pinned once) and read. Who owns a running one is
`study.services.ownership`'s (its names are re-exported here)."""

from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any, NamedTuple, NotRequired, TypedDict, cast

from sqlalchemy import select
from sqlalchemy.orm import Session

from learner.run import RunSpec
from study.db.models import (
    ADVISOR_ROLE,
    Episode,
    Participant,
    StudySession,
    located,
    stored_path,
)
from study.schemas.sessions import SessionOptions
from study.services.errors import Invalid, NotFound
from study.services.fitted_files import resolve
from study.services.ownership import claim as claim
from study.services.ownership import mark_dead_interrupted as mark_dead_interrupted
from study.services.ownership import set_status as set_status
from study.services.ownership import silent_sessions as silent_sessions
from study.services.studies import get_study


class StreamSource(TypedDict):
    """Where a replay's recorded stream comes from."""

    study: str | None
    """The source study's name."""
    session: int
    """The source session's id there."""
    export: str | None
    """The export it was read from; None: this database."""


class ReplayStream(TypedDict):
    """What a replay's session keeps of its source (`sessions.replay_stream`, JSON as-is):
    the advice it is fed in order, and the image hash each advice's advisor saw; a stream
    of ratings (evaluative feedback) also keeps the judgements, in order, and `actions`
    are the actions judged."""

    source: StreamSource
    actions: list[int]
    observation_hashes: list[str]
    judgements: NotRequired[list[float | None]]


class Replay(NamedTuple):
    """A replayed run's source: its session in this database (None: from an export) and the
    stream it is fed."""

    source_id: int | None
    stream: ReplayStream


def participant_url(base_url: str, token: str) -> str:
    return f"{base_url}/p/{token}"


def advisor_path(
    db: Session, spec: str, data_dir: Path | None, shared_root: Path | None = None
) -> str:
    """The checkpoint file an `agent` session's advisor names: `session:ID` (a session of
    this installation with a checkpoint), or a path that must lie under `data_dir` (the
    API's rule; the batch runner and the command line, run by the researcher, pass None).
    `shared_root`: the storage root a Ray cluster's nodes share (`Settings.shared_root`),
    where the sessions' checkpoints lie: a session's is found there, and a file must lie
    there; either is kept relative to it, as a session's own row keeps its checkpoint, so
    each node reads it where it mounts the root."""
    if spec.startswith("session:"):
        number = spec.removeprefix("session:")
        found = db.get(StudySession, int(number)) if number.isdigit() and len(number) < 10 else None
        root = shared_root or data_dir or Path()
        file = located(found.checkpoint_path, root) if found is not None else None
        if found is None or file is None or not file.is_file():
            raise Invalid(
                "run.advisor_checkpoint",
                "run.advisor_checkpoint names no session of this installation with a "
                "checkpoint; name a finished session, e.g. session:12",
            )
        if found.method == "sb3-dqn":
            raise Invalid(
                "run.advisor_checkpoint",
                "run.advisor_checkpoint names an sb3-dqn session: its checkpoint is "
                "Stable-Baselines3's, which cannot advise; name a session of the paper's learner",
            )
        if shared_root is not None:
            return stored_path(file.absolute(), shared_root)
        return str(file.resolve())
    # a file every node reads: under the cluster's storage root, kept relative to it
    under = shared_root if shared_root is not None else data_dir
    try:
        path = Path(spec).resolve()
        inside = under is None or path.is_relative_to(under.resolve())
        present = inside and path.is_file()
    except (OSError, ValueError):
        inside = present = False
    if not inside:
        where = (
            "the storage root the cluster's nodes share (IDEEPRL_STORAGE_ROOT)"
            if shared_root is not None
            else "the server's data folder"
        )
        raise Invalid(
            "run.advisor_checkpoint",
            "run.advisor_checkpoint must be session:ID (a session of this installation) or a "
            f"checkpoint file under {where}",
        )
    if not present:
        raise Invalid("run.advisor_checkpoint", "run.advisor_checkpoint: no such file")
    if shared_root is not None:
        return str(path.relative_to(shared_root.resolve()))
    return str(path)


def create_session(
    db: Session,
    study_id: int,
    spec: RunSpec,
    options: SessionOptions | None = None,
    data_dir: Path | None = None,
    threads: int | None = None,
    replay: Replay | None = None,
    shared_root: Path | None = None,
) -> StudySession:
    """A new session in `created` state, its run validated and pinned on this machine and
    stored whole; a human one gets its participant and token. `data_dir`: where an advisor's
    checkpoint file must lie (see `advisor_path`; None: anywhere, for the researcher's own
    command line); `threads`: torch threads of a run that leaves them open; `replay`: a
    replayed run's source session (None: not in this database) and its recorded stream
    (`study.services.replays`, the only maker of replays); `shared_root`: a Ray cluster's
    storage root, where a `session:ID` advisor's checkpoint lies (`advisor_path`)."""
    options = options or SessionOptions()
    if (spec.method == "replayed") != (replay is not None):
        raise Invalid(
            "run.method",
            "method replayed is made from a recorded session by `ideeprl replay`, which gives "
            "it the session's advice stream; choose another method",
        )
    get_study(db, study_id)
    if spec.advisor_checkpoint and spec.method == "agent":
        checkpoint = advisor_path(db, spec.advisor_checkpoint, data_dir, shared_root)
        spec = spec.replace(advisor_checkpoint=checkpoint)
    if spec.fitted_model and spec.method == "fitted":
        spec = spec.replace(fitted_model=resolve(db, spec.fitted_model, data_dir))
    spec = spec.validate().pinned(threads)
    if options.participant and spec.method != "human":
        raise Invalid("participant", "only method human has a participant")
    session = StudySession(
        study_id=study_id,
        label=options.label,
        run=spec.to_json(),
        numerics_overrides=[],
        provenance=[],
        keep_replay_memory=options.keep_replay_memory,
        idle_limit_s=options.idle_limit_s,
    )
    if replay is not None:
        session.replay_of = replay.source_id
        session.replay_stream = cast(dict[str, Any], replay.stream)  # JSON, stored as-is
    if spec.method == "human":
        pseudonym = options.participant or f"p-{secrets.token_hex(4)}"
        participant = db.scalar(
            select(Participant).where(
                Participant.study_id == study_id, Participant.pseudonym == pseudonym
            )
        )
        if participant is None:
            participant = Participant(study_id=study_id, pseudonym=pseudonym)
        session.participant = participant
        session.participant_token = secrets.token_urlsafe(32)
    db.add(session)
    db.commit()
    return session


def get_session(db: Session, session_id: int) -> StudySession:
    session = db.get(StudySession, session_id)
    if session is None:
        raise NotFound(f"no session with id {session_id}; GET /api/studies/ID/sessions lists them")
    return session


def list_sessions(db: Session, study_id: int) -> list[StudySession]:
    get_study(db, study_id)
    query = select(StudySession).where(StudySession.study_id == study_id)
    return list(db.scalars(query.order_by(StudySession.id)))


def session_for_token(db: Session, token: str) -> StudySession | None:
    """The one session a participant token reaches, or None.

    Tokens are 256-bit random strings, so looking one up by equality reveals nothing an
    attacker could use; we still compare the stored value in constant time."""
    if not token or len(token) > 100 or "\x00" in token:  # PostgreSQL refuses a NUL
        return None
    session = db.scalar(select(StudySession).where(StudySession.participant_token == token))
    if session is None or not secrets.compare_digest(session.participant_token or "", token):
        return None
    return session


def list_episodes(db: Session, session_id: int) -> list[Episode]:
    get_session(db, session_id)
    query = (
        select(Episode).where(Episode.session_id == session_id).order_by(Episode.first_global_step)
    )
    return list(db.scalars(query))


def advisor_sessions(sessions: list[StudySession]) -> set[int]:
    """The advisors among these sessions, which a report leaves out of the compared agents:
    every advisor a batch trained for its `agent` runs (`role` advisor, each attempt, passed
    its check or not, used or not), and any session whose checkpoint advises another of
    these sessions (method `agent`)."""
    # the stored document's one field, not the whole run read back: a report reads old
    # sessions whose runs another declaration may have stored
    advising = {
        str(Path(c).resolve()) for s in sessions if (c := (s.run or {}).get("advisor_checkpoint"))
    }
    return {
        s.id
        for s in sessions
        if s.role == ADVISOR_ROLE
        or (s.checkpoint_path and str(Path(s.checkpoint_path).resolve()) in advising)
    }
