"""Arrivals at an online study's public link: who they are, and which condition they get.

Conditions are assigned by block randomization: block b is the conditions in an order
drawn from `random.Random(f"{seed}/{b}")` (the study's `assignment_seed`), so the same seed
gives the same order and another seed another. A position whose condition has reached its
target (completed plus in progress) is skipped. A place freed by a visit that ended early
(declined, excluded, timed out) is refilled first, by the next arrival, with its block and
position. Every assignment is a row (`Assignment`).

A person is recognised by their panel id (the design's first panel parameter; kept apart,
in `PanelId`), else by the cookie their browser got on the first arrival: the same person
always gets their own session again, never a second one.

Callers serialise arrivals of one process (`ARRIVALS`): the next position is read, then
written.
"""

from __future__ import annotations

import random
import secrets
import threading
from dataclasses import dataclass, field
from datetime import timedelta
from pathlib import Path

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from learner.run import RunSpec, declared
from study.db.models import (
    ENDED_EARLY,
    Assignment,
    Outcome,
    PanelId,
    Status,
    Study,
    StudySession,
    utcnow,
)
from study.schemas.design import StudyDesign
from study.schemas.sessions import SessionOptions
from study.services.errors import NotFound
from study.services.sessions import create_session, session_for_token

ARRIVALS = threading.Lock()
"""One arrival at a time in this process: positions and places are read, then taken."""
EARLY = [s.value for s in ENDED_EARLY]
POOL_LIVE = [Status.created.value, Status.running.value, Status.paused.value]
"""A pooled session being made, practising, or ready."""
SEEDS = 2**31
"""A run's seeds (0 to 2**31 - 1): a participant's seed wraps around within them."""


@dataclass
class ConditionCounts:
    """A condition's participants by where their visit is (previews not counted)."""

    target: int
    completed: int = 0
    in_progress: int = 0
    declined: int = 0
    excluded: int = 0
    timed_out: int = 0

    @property
    def short(self) -> bool:
        """Still wants arrivals: completed and in progress below the target."""
        return self.completed + self.in_progress < self.target


@dataclass
class Arrival:
    """Where an arrival goes: its session's token, or the study full (`token` None, and
    why: `full` or `capacity`); with the panel parameters it brought (for the return URL)."""

    token: str | None
    full_reason: str = ""
    params: dict[str, str] = field(default_factory=dict)
    session_id: int | None = None
    """The session given to a new arrival, or a pool's given to a preview (None for a
    returning one, a preview made anew, a full study)."""


def study_for_key(db: Session, key: str) -> tuple[Study, StudyDesign]:
    if not key or len(key) > 64 or "\x00" in key:
        raise NotFound("no study has this link")
    study = db.scalar(select(Study).where(Study.join_key == key))
    if (
        study is None
        or study.design is None
        or not secrets.compare_digest(study.join_key or "", key)
    ):
        raise NotFound("no study has this link")
    return study, StudyDesign.model_validate(study.design)


def counts(db: Session, study: Study, design: StudyDesign) -> dict[str, ConditionCounts]:
    """Per condition: target, completed, in progress, declined, excluded, timed out."""
    out = {name: ConditionCounts(c.target) for name, c in design.conditions.items()}
    rows = db.execute(
        select(StudySession.condition, StudySession.outcome, StudySession.status).where(
            StudySession.study_id == study.id,
            StudySession.condition.is_not(None),
            StudySession.preview.is_(False),
            StudySession.pooled.is_(False),
        )
    )
    for condition, outcome, status in rows:
        found = out.get(condition or "")
        if found is None:  # a condition the design no longer has
            continue
        if outcome == Outcome.completed:
            found.completed += 1
        elif outcome in EARLY or status in EARLY:
            name = outcome if outcome in EARLY else status
            setattr(found, name, getattr(found, name) + 1)
        else:
            found.in_progress += 1
    return out


def expire_unopened(db: Session, study: Study, design: StudyDesign) -> int:
    """Visits whose link was never opened (no worker ever ran: a bot, a closed tab before
    the redirect) time out after the idle limit like any other, freeing their place."""
    cutoff = utcnow() - timedelta(seconds=design.idle_limit_s)
    result = db.execute(
        update(StudySession)
        .where(
            StudySession.study_id == study.id,
            StudySession.condition.is_not(None),
            StudySession.status == Status.created.value,
            StudySession.pooled.is_(False),
            StudySession.outcome.is_(None),
            StudySession.created_at < cutoff,
        )
        .values(
            status=Status.timed_out.value,
            status_detail="its link was never opened within the study's idle limit",
            outcome=Outcome.timed_out.value,
            outcome_at=utcnow(),
        )
    )
    db.commit()
    return int(result.rowcount)  # type: ignore[attr-defined]


def expire_unopened_everywhere(db: Session) -> int:
    """`expire_unopened` for every online study with a visit waiting to be opened: the web
    process's reaper calls it, so a place frees on time even when nobody arrives after."""
    waiting = select(StudySession.study_id).where(
        StudySession.condition.is_not(None),
        StudySession.status == Status.created.value,
        StudySession.pooled.is_(False),
        StudySession.outcome.is_(None),
    )
    expired = 0
    for study in db.scalars(select(Study).where(Study.id.in_(waiting))):
        if study.design is not None:
            expired += expire_unopened(db, study, StudyDesign.model_validate(study.design))
    return expired


def block_order(seed: int, block: int, conditions: list[str]) -> list[str]:
    """Block `block`'s conditions in the order the study's seed gives."""
    return random.Random(f"{seed}/{block}").sample(sorted(conditions), len(conditions))


def _refill(db: Session, study: Study, tally: dict[str, ConditionCounts]) -> Assignment | None:
    """The earliest place freed by an early end whose condition still wants people."""
    refilled = select(Assignment.refills).where(
        Assignment.study_id == study.id, Assignment.refills.is_not(None)
    )
    freed = db.scalars(
        select(Assignment)
        .join(StudySession, StudySession.id == Assignment.session_id)
        .where(
            Assignment.study_id == study.id,
            Assignment.id.not_in(refilled),
            (StudySession.outcome.in_(EARLY)) | (StudySession.status.in_(EARLY)),
        )
        .order_by(Assignment.id)
    )
    for place in freed:
        if place.condition in tally and tally[place.condition].short:
            return place
    return None


def _next_place(
    db: Session, study: Study, tally: dict[str, ConditionCounts]
) -> tuple[str, int, int]:
    """(condition, block, position) of the next place in the sequence that wants people."""
    names = list(tally)
    last = db.execute(
        select(Assignment.block, Assignment.position)
        .where(Assignment.study_id == study.id, Assignment.refills.is_(None))
        .order_by(Assignment.block.desc(), Assignment.position.desc())
        .limit(1)
    ).first()
    index = 0 if last is None else last.block * len(names) + last.position + 1
    seed = study.assignment_seed or 0
    while True:  # some condition is short (the caller checked): found within one block
        block, position = divmod(index, len(names))
        condition = block_order(seed, block, names)[position]
        if tally[condition].short:
            return condition, block, position
        index += 1


def returning(db: Session, study: Study, panel_id: str | None, cookie: str | None) -> str | None:
    """The token of the session this person already has in the study, if any."""
    if panel_id:
        participant = db.scalar(
            select(PanelId.participant_id).where(
                PanelId.study_id == study.id, PanelId.panel_id == panel_id
            )
        )
        if participant is None:
            return None
        return db.scalar(
            select(StudySession.participant_token)
            .where(StudySession.participant_id == participant)
            .order_by(StudySession.id.desc())
            .limit(1)
        )
    if cookie:
        session = session_for_token(db, cookie)
        if session is not None and session.study_id == study.id and not session.preview:
            return cookie
    return None


def full_reason(design: StudyDesign, tally: dict[str, ConditionCounts]) -> str:
    """Why an arrival cannot get a place now ('' when it can)."""
    if not any(c.short for c in tally.values()):
        return "full"
    if sum(c.in_progress for c in tally.values()) >= design.capacity:
        return "capacity"
    return ""


def arrive(
    db: Session,
    study: Study,
    design: StudyDesign,
    params: dict[str, str],
    cookie: str | None,
    data_dir: Path | None = None,
    threads: int | None = None,
    preview: bool = False,
) -> Arrival:
    """Give an arrival their session: the one they have, a refilled place, or the next
    place; `Arrival(None, full_reason=...)` when the study is full or at capacity. A
    preview takes no place and no assignment row (a full study has one too), and is never
    recognised again."""
    kept = {name: params[name] for name in design.panel.params if params.get(name)}
    panel_id = kept.get(design.panel.params[0])
    if not preview:
        token = returning(db, study, panel_id, cookie)
        if token is not None:
            return Arrival(token, params=kept)
    expire_unopened(db, study, design)
    tally = counts(db, study, design)
    if preview:  # the condition the next arrival would get, or the first of a full study
        condition = next((name for name, c in tally.items() if c.short), next(iter(tally)))
        taken = _take_pooled(db, study, condition)  # practised, as an arrival's would be
        session = taken or _session(db, study, design, condition, 0, data_dir, threads)
        session.preview = True
        db.commit()
        return Arrival(session.participant_token, session_id=session.id if taken else None)
    reason = full_reason(design, tally)
    if reason:
        return Arrival(None, full_reason=reason, params=kept)
    place = _refill(db, study, tally)
    if place is not None:
        condition, block, position = place.condition, place.block, place.position
    else:
        condition, block, position = _next_place(db, study, tally)
    taken = _take_pooled(db, study, condition)
    session = taken or _session(
        db, study, design, condition, _next_number(study), data_dir, threads
    )
    db.add(
        Assignment(
            study_id=study.id,
            session_id=session.id,
            condition=condition,
            block=block,
            position=position,
            seed=study.assignment_seed or 0,
            refills=place.id if place is not None else None,
        )
    )
    if panel_id:
        assert session.participant_id is not None
        db.add(
            PanelId(
                study_id=study.id,
                participant_id=session.participant_id,
                panel_id=panel_id,
                params=kept,
            )
        )
    db.commit()
    return Arrival(session.participant_token, params=kept, session_id=session.id)


def numbered_seed(db: Session, study_id: int, spec: RunSpec) -> RunSpec:
    """A human session whose run gives no seed, made by hand (the REST API, the dashboard):
    the study's next number added to the run's seed, as an online arrival's is, so each
    participant's learner differs (its first weights, its random practice) and every one is
    reproducible; a run that gives its seed keeps it."""
    study = db.get(Study, study_id)
    if study is None:
        raise NotFound(f"no study {study_id}")
    return spec.replace(seed=(spec.seed + _next_number(study)) % SEEDS)


def _next_number(study: Study) -> int:
    """The number of the study's next session (its seed adds it), never given twice."""
    number = study.sessions_made or 0
    study.sessions_made = number + 1
    return number


def _take_pooled(db: Session, study: Study, condition: str) -> StudySession | None:
    """The condition's oldest pooled session whose worker runs (practising or ready): the
    arrival's now, its seed and condition as they were fixed when it was made."""
    session = db.scalar(
        select(StudySession)
        .where(
            StudySession.study_id == study.id,
            StudySession.condition == condition,
            StudySession.pooled.is_(True),
            StudySession.status == Status.running.value,
        )
        .order_by(StudySession.id)
        .limit(1)
    )
    if session is not None:
        session.pooled = False
    return session


@dataclass
class PoolGap:
    """A condition of a study whose pool wants `missing` more sessions."""

    study_id: int
    condition: str
    missing: int


def pool_gaps(db: Session, limit: int) -> list[PoolGap]:
    """What the online studies' pools want, within `limit` pooled sessions in all: each
    condition still short of its target keeps up to the design's `pool` sessions (never
    more than the places it still has), the studies' conditions served in turn."""
    pooled = dict(
        db.execute(
            select(StudySession.study_id, func.count())
            .where(StudySession.pooled.is_(True), StudySession.status.in_(POOL_LIVE))
            .group_by(StudySession.study_id)
        ).all()
    )
    room = limit - sum(pooled.values())
    gaps: list[PoolGap] = []
    studies = db.scalars(select(Study).where(Study.join_key.is_not(None)).order_by(Study.id))
    for study in studies:
        if study.design is None:
            continue
        design = StudyDesign.model_validate(study.design)
        tally = counts(db, study, design)
        have = dict(
            db.execute(
                select(StudySession.condition, func.count())
                .where(
                    StudySession.study_id == study.id,
                    StudySession.pooled.is_(True),
                    StudySession.status.in_(POOL_LIVE),
                )
                .group_by(StudySession.condition)
            ).all()
        )
        for name, count in tally.items():
            places = count.target - count.completed - count.in_progress
            missing = min(design.pool, places) - have.get(name, 0)
            if missing > 0 and room > 0:
                gaps.append(PoolGap(study.id, name, min(missing, room)))
                room -= gaps[-1].missing
    return gaps


def make_pooled(
    db: Session,
    study_id: int,
    condition: str,
    data_dir: Path | None = None,
    threads: int | None = None,
) -> int:
    """A session of `condition` made ahead of its arrival, into the pool; its id."""
    study = db.get(Study, study_id)
    assert study is not None and study.design is not None, "pools belong to online studies"
    design = StudyDesign.model_validate(study.design)
    number = _next_number(study)
    session = _session(db, study, design, condition, number, data_dir, threads)
    session.pooled = True
    db.commit()
    return session.id


def stale_pooled(db: Session) -> list[int]:
    """Pooled sessions whose worker no longer runs (a server restart, a failure): nobody's
    data, deleted and made again."""
    return list(
        db.scalars(
            select(StudySession.id).where(
                StudySession.pooled.is_(True), StudySession.status.not_in(POOL_LIVE)
            )
        )
    )


def _session(
    db: Session,
    study: Study,
    design: StudyDesign,
    condition: str,
    number: int,
    data_dir: Path | None,
    threads: int | None,
) -> StudySession:
    """A human session of `condition`'s run; the arrival's number added to the run's seed,
    so each participant's learner differs and every one is reproducible."""
    spec = declared().from_json(design.conditions[condition].run)
    spec = spec.replace(seed=(spec.seed + number) % SEEDS)
    options = SessionOptions(label=condition, idle_limit_s=design.idle_limit_s)
    session = create_session(db, study.id, spec, options, data_dir, threads)
    session.condition = condition
    db.commit()
    return session


def panel_person_sessions(db: Session, study_id: int, panel_id: str) -> list[int]:
    """The sessions of the person with this panel id (deleting them deletes their
    participant, and with it their panel ids)."""
    participant = db.scalar(
        select(PanelId.participant_id).where(
            PanelId.study_id == study_id, PanelId.panel_id == panel_id
        )
    )
    if participant is None:
        raise NotFound(f"study {study_id} has nobody with this panel id")
    return list(
        db.scalars(select(StudySession.id).where(StudySession.participant_id == participant))
    )
