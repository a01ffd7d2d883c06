"""Which replays a report leaves out by default: the unchanged ones. One rule for the report
from the database (`ideeprl report`, the API and the dashboard, through
`study.services.reports`) and the one from an export (`python -m analysis EXPORT OUT`, from
its sessions' `run_spec` and `replay_of`).

An unchanged replay re-runs its source's own run, fed its recorded advice (`ideeprl replay
--session ID`, the determinism check): the same agent again, not one of its own, so a
report that counts agents leaves it out unless chosen by id.
"""

from __future__ import annotations

from collections.abc import Mapping

from learner.run import RunSpec

REPLAYED = "replayed"


def same_run(original: RunSpec, run: RunSpec) -> bool:
    """Whether `run` is `original`'s own run as a replay runs it (method `replayed`, no
    advisor's checkpoint, no error rate: its advice comes from the recorded stream)."""
    as_replay = original.replace(method=REPLAYED, advisor_checkpoint=None, error_rate=0.0)
    return as_replay.normalized() == run.normalized()


def unchanged_replays(
    runs: Mapping[int, RunSpec], replay_of: Mapping[int, int], sources: Mapping[int, RunSpec]
) -> dict[int, int]:
    """Of the sessions `runs` (id → run), the replays that run their source's own run, by
    id, with their source's id. `replay_of`: each replay's source (id); `sources`: the runs
    of the sessions known (id → run). A replay whose source is not known counts as changed."""
    found = {}
    for session_id, run in runs.items():
        source = replay_of.get(session_id)
        if run.method != REPLAYED or source is None or source not in sources:
            continue
        if same_run(sources[source], run):
            found[session_id] = source
    return found


def unchanged_replays_note(found: Mapping[int, int]) -> str:
    """The report's note on the unchanged replays it left out (id → source's id)."""
    return (
        f"Left out session(s) {', '.join(map(str, sorted(found)))}: unchanged replay(s) of "
        f"session(s) {', '.join(map(str, sorted(set(found.values()))))} (a check that the "
        "platform reproduces a run, the same agent again, not one of its own); choose "
        "sessions by id to include them."
    )
