"""Which sessions a report covers by default, the finished ones, and what it says of the
others: one rule for the report from the database (`ideeprl report`, the API and the
dashboard, through `study.services.reports`) and the one from an export
(`python -m analysis EXPORT OUT`, from its sessions' `status` column).

A session that is not finished is either not finished *yet* (not started, running or
paused: it may still finish, so the report says to wait, or to include it as it is by
choosing it, cut to a number of episodes every session has), or it ended without
finishing (stopped, interrupted, abandoned, failed; an online visit declined, excluded or
timed out): the report names it and why, and never suggests including it. Either is
included where sessions are chosen by id (any status).

Statuses are those of `study.db.models.Status` (spelled out here: the analysis reads no
database); one this version does not know counts as ended. A lab session whose participant
declined consent stays `created` (they may still consent): a report names it as declined
(`status_of`), not as one to wait for.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from analysis.markdown import count, some

FINISHED = "finished"

UNDER_WAY = {"created": "not started", "running": "running", "paused": "paused"}
"""Statuses of sessions not finished yet (they may still finish), as a report names them."""

ENDED = {
    "stopped": "stopped by the researcher",
    "interrupted": "interrupted: its worker or the server stopped",
    "abandoned": "abandoned: no advice within its idle limit",
    "failed": "failed",
    "declined": "declined consent",
    "excluded": "excluded by the comprehension check",
    "timed_out": "timed out",
}
"""Statuses of sessions that ended without finishing, as a report names them."""


@dataclass(frozen=True)
class Choice:
    """How a report's caller chooses sessions and their length, in its own terms (the
    command line's flags, the REST body's fields): what its messages suggest."""

    sessions: str
    """Choosing sessions by id with a number of episodes, e.g. "`--sessions ID ...` and
    `--n-episodes N`": how to include sessions not finished yet."""
    length: str
    """Keeping the first N episodes of every session, a template with `{n}`, e.g.
    "`--n-episodes {n}`": how to compare sessions of different lengths
    (`analysis.episodes.EpisodeTableError.worded`)."""


SHOWN = 12
"""Session ids named per status before the rest are counted."""


def status_of(status: str, declined: bool = False) -> str:
    """The status a report goes by: `declined` for a session not started whose participant
    declined consent and has not consented since (`declined`: `declined_at` without
    `consented_at`, as the dashboard shows it), else its own."""
    return "declined" if declined and status == "created" else status


def is_finished(status: object) -> bool:
    return status == FINISHED


def not_finished(statuses: Mapping[int, str]) -> dict[int, str]:
    """The sessions (id → status) a report leaves out unless chosen: all but the finished."""
    return {i: s for i, s in statuses.items() if not is_finished(s)}


def left_out_notes(left_out: Mapping[int, str], choose: str, after: str = "") -> list[str]:
    """The report's notes on the sessions (id → status) left out for not being finished:
    those not finished yet (wait, `after`: what then; or include them as they are with
    `choose`: the caller's own options), and those that ended without finishing (named,
    never suggested)."""
    under_way, ended = _split(left_out)
    notes = []
    if under_way:
        notes.append(
            f"Left out {count(len(under_way), 'session')} not finished yet: "
            f"{_listing(under_way)}; {_wait(under_way, choose, after)}."
        )
    if ended:
        notes.append(
            f"Left out {count(len(ended), 'session')} that ended without finishing: "
            f"{_listing(ended)}."
        )
    return notes


def nothing_finished(
    subject: str, statuses: Mapping[int, str], choose: str, after: str = ""
) -> str:
    """Why `subject` ("study 3", "the export") has nothing to report on by default: none of
    its sessions (id → status) is finished; what to do about those not finished yet."""
    under_way, ended = _split(statuses)
    text = f"{subject} has no finished session"
    if under_way:
        text += f". Not finished yet: {_listing(under_way)}; {_wait(under_way, choose, after)}"
    if ended:
        text += f". Ended without finishing: {_listing(ended)}"
    return text


def _split(statuses: Mapping[int, str]) -> tuple[dict[int, str], dict[int, str]]:
    left = not_finished(statuses)
    under_way = {i: s for i, s in left.items() if s in UNDER_WAY}
    return under_way, {i: s for i, s in left.items() if s not in UNDER_WAY}


def _wait(sessions: Mapping[int, str], choose: str, after: str) -> str:
    one = len(sessions) == 1
    return (
        f"wait until {'it finishes' if one else 'they finish'}{after}, or include "
        f"{'it as it is' if one else 'them as they are'} with {choose}"
    )


def _listing(sessions: Mapping[int, str]) -> str:
    """`session 4 (running), sessions 5, 6 (not started)`: ids grouped by status."""
    by_status: dict[str, list[int]] = {}
    for session_id, status in sorted(sessions.items()):
        by_status.setdefault(status, []).append(session_id)
    groups = []
    for status, ids in by_status.items():
        name = UNDER_WAY.get(status) or ENDED.get(status) or f"status {status}"
        groups.append(f"session{'' if len(ids) == 1 else 's'} {some(ids, SHOWN)} ({name})")
    return ", ".join(groups)
