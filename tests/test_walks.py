"""The three walks through the code, traced (issue 18): how many of the project's source
files a value passes through, and whether the walk climbs back into a file it left.

What is counted. A profiler hook (`tests/walks/walk_tracer.py`, installed by
`tests/walks/sitecustomize.py` in the server's process, the session workers it spawns and
`ideeprl batch`'s processes) notes every *entry*: a function of a project source file
(any `.py` under sim, learner, study, runs, server, analysis, cli; tests excluded) begins.
Not entries: module and class bodies and everything they call (import time); a suspended
generator or coroutine resuming (it was entered when it began); returns; third-party
frames (transparent: a route entered by FastAPI counts as the route's file). Middleware,
dependencies and helpers are entries like any other function.

A walk's *files* are the distinct files of its entries (listed in the order first
entered). A *climb back* is an entry whose file is already on the stack further up, under
a frame of another file: A -> B -> A (a callback into an outer layer, or a layer calling
back into the one that called it); `climbs` counts the distinct (caller's file, callee)
pairs. A loop that calls B and then C again and again climbs nothing: neither is on the
stack when it is called.

- **a. create and start** (human session, REST on a real uvicorn, a real worker): the
  request `POST /api/studies/ID/sessions`, then the request `POST /api/sessions/ID/start`
  (each: every entry on the request's asyncio task and the thread-pool calls it makes, from
  the request's first middleware to its response), then the spawned worker's main thread
  from its first entry to the entry of `reset` in `sim/env.py`.
- **b. one human advice**: the request `POST /api/participant/advice` (as above: it writes
  the advice row and sends the answer down the pipe), then the worker's main thread from
  `WorkerLink._recv` returning that `AdviceAnswer` (`runs/worker/link.py`, the first file)
  to the entry of `ReplayMemory.add` (`learner/replay.py`).
- **c. a tiny `ideeprl batch`** (one autonomous session): the runner's main thread from
  its first entry to the entry of `LocalBackend.start` (`runs/batch/backends.py`: it hands
  the run to a worker process), then the worker process's main thread from its first entry
  to the first entry of `Recorder.on_episode` (the first episode's record, which it writes
  at once with the steps before it).

The issue asks at most 10, 12 and 15 files and no climb back. `LIMITS` holds the counts
the code meets today, as upper bounds that may only go down (`docs/architecture.md`,
"Three walks through the code", says what blocks the issue's). The section between the
`walks` markers there is this test's output: `python tests/test_walks.py --update`
rewrites it, and the test fails when it differs from a fresh trace.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).absolute().parents[1]
TRACER = ROOT / "tests" / "walks"
DOC = ROOT / "docs" / "architecture.md"
BEGIN, END = "<!-- walks: begin (python tests/test_walks.py --update) -->", "<!-- walks: end -->"

LIMITS = {"a": (47, 0), "b": (19, 0), "c": (51, 0)}
"""Walk: (most files, most climbs back) the code meets today, bounds that may only go down;
the issue asks 10, 12 and 15 files and no climb back (docs/architecture.md says what blocks
it)."""

pytestmark = pytest.mark.slow


@dataclass(frozen=True)
class Entry:
    ns: int
    kind: str
    """`call` or `answer N`."""
    caller: str
    """The calling project frame's file (`-`: none)."""
    climb: bool
    """The call climbs back (module docstring)."""
    thread: str
    task: int
    file: str
    function: str


def read_trace(path: Path) -> list[Entry]:
    entries = []
    for line in path.read_text().splitlines():
        ns, event, thread, task, file, function = line.split("\t")
        kind, caller = event.split(" ")
        if kind == "answer":
            kind, caller = event, "-"
        climb = caller.endswith("!")
        entries.append(
            Entry(int(ns), kind, caller.rstrip("!"), climb, thread, int(task), file, function)
        )
    return entries


def traces(folder: Path) -> dict[int, list[Entry]]:
    """Each process's entries, by pid."""
    return {int(p.stem.split("-")[1]): read_trace(p) for p in sorted(folder.glob("trace-*.tsv"))}


def request(entries: list[Entry], start_ns: int, end_ns: int, handler: str) -> list[Entry]:
    """The entries of the one request in [start_ns, end_ns] whose task enters `handler`:
    on its task (main thread) and in the thread-pool calls it makes."""
    window = [e for e in entries if start_ns <= e.ns <= end_ns and e.kind == "call"]
    tasks = {e.task for e in window if e.function == handler}
    assert len(tasks) == 1, f"{handler}: {len(tasks)} requests in the window"
    return [e for e in window if e.task in tasks]


def until(entries: list[Entry], file: str, function: str) -> list[Entry]:
    """Entries of the main thread up to and including the first entry of `function`."""
    mine = [e for e in entries if e.thread == "MainThread" and e.kind == "call"]
    for i, e in enumerate(mine):
        if e.file == file and e.function.split(".")[-1] == function:
            return mine[: i + 1]
    raise AssertionError(f"{file}:{function} was never entered")


@dataclass(frozen=True)
class Walk:
    files: list[tuple[str, str]]
    """Each file entered, in the order first entered, with the first function entered there."""
    climbs: list[tuple[str, str, str]]
    """Each distinct call that climbs back: (caller's file, callee's file, callee)."""


def walk(*parts: list[Entry]) -> Walk:
    files: dict[str, str] = {}
    climbs: dict[tuple[str, str, str], None] = {}
    for part in parts:
        for e in part:
            files.setdefault(e.file, e.function)
            if e.climb:
                climbs[(e.caller, e.file, e.function)] = None
    return Walk(list(files.items()), list(climbs))


def env(folder: Path) -> dict[str, str]:
    return {
        "IDEEPRL_WALK_TRACE": str(folder),
        "PYTHONPATH": os.pathsep.join([str(TRACER), str(ROOT)]),
    }


def trace_server(tmp: Path) -> tuple[Walk, Walk]:
    """Walks a and b on a live server and its worker."""
    from tests.server.live import serving
    from tests.server.participant import SimulatedParticipant
    from tests.server.scale import session_body, wait_for_status

    folder = tmp / "server-trace"
    (tmp / "data").mkdir()
    saved = {k: os.environ.get(k) for k in ("IDEEPRL_WALK_TRACE", "PYTHONPATH", "DATABASE_URL")}
    os.environ.update(env(folder))
    os.environ.pop("DATABASE_URL", None)  # SQLite always: the documented walks are its own
    try:
        with serving(tmp / "data", heartbeat_s=600, pool_limit=0) as live, live.client() as api:
            study = api.post("/api/studies", json={"name": "walks"}).json()
            body = session_body("human", advice_budget=2, participant="P01")
            body["run"]["config"]["pretraining_steps"] = 20
            t0 = time_ns()
            created = api.post(f"/api/studies/{study['id']}/sessions", json=body)
            t1 = time_ns()
            assert created.status_code == 201, created.text
            session = created.json()
            started = api.post(f"/api/sessions/{session['id']}/start")
            t2 = time_ns()
            assert started.status_code == 200, started.text
            participant = SimulatedParticipant(live.url, session["participant_token"])
            participant.begin()
            state = participant.next_request()
            assert state["advice_wanted"] and state["advice_index"] == 0, state
            t3 = time_ns()
            assert participant.advise(0, 1).status_code == 200
            t4 = time_ns()
            wait_for_status(api, session["id"], {"running", "finished"})
            assert participant.next_request()["advice_index"] == 1
            api.post(f"/api/sessions/{session['id']}/stop")
            wait_for_status(api, session["id"], {"stopped", "finished"})
            participant.close()
            server_pid = live.process.pid if live.process else 0
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    marks = {"server": server_pid, "t": [t0, t1, t2, t3, t4]}
    (tmp / "marks.json").write_text(json.dumps(marks))
    return server_walks(tmp)


def server_walks(tmp: Path) -> tuple[Walk, Walk]:
    marks = json.loads((tmp / "marks.json").read_text())
    t0, t1, t2, t3, t4 = marks["t"]
    found = traces(tmp / "server-trace")
    server = found.pop(marks["server"])
    workers = [t for t in found.values() if any(e.kind == "answer 0" for e in t)]
    assert len(workers) == 1, {pid: len(t) for pid, t in found.items()}
    (worker,) = workers
    a = walk(
        request(server, t0, t1, "creation_router.<locals>.create_session"),
        request(server, t1, t2, "start_session"),
        until(worker, "sim/env.py", "reset"),
    )
    answered = next(i for i, e in enumerate(worker) if e.kind == "answer 0")
    b = walk(
        request(server, t3, t4, "give_advice"),
        [worker[answered], *until(worker[answered:], "learner/replay.py", "add")],
    )
    return a, b


def trace_batch(tmp: Path) -> Walk:
    folder = tmp / "batch-trace"
    data = tmp / "batch"
    data.mkdir()
    run = subprocess.run(
        [sys.executable, "-m", "cli", "batch", "--study", "walk", "--methods", "autonomous",
         "--agents", "1", "--episodes", "1", "--pretraining-steps", "10",
         "--max-episode-steps", "10", "--set", "batch_size=8", "--set", "memory_size=100",
         "--no-progress", "--workers", "1",
         "--data-dir", str(data), "--database-url", f"sqlite:///{data / 'study.sqlite3'}"],
        cwd=ROOT, env={**{k: v for k, v in os.environ.items() if k != "DATABASE_URL"},
                       **env(folder), "IDEEPRL_HEARTBEAT_S": "600"},
        capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    return batch_walk(tmp)


def batch_walk(tmp: Path) -> Walk:
    found = sorted((t for t in traces(tmp / "batch-trace").values() if t), key=lambda t: t[0].ns)
    runner, *others = found
    parts = [until(runner, "runs/batch/backends.py", "start")]
    for entries in others:
        if any(e.function == "Recorder.on_episode" for e in entries):
            parts.append(until(entries, "runs/worker/recorder.py", "on_episode"))
    return walk(*parts)


def time_ns() -> int:
    import time

    return time.monotonic_ns()


WALKS = {
    "a": "**a. Creating and starting a session**, down to `env.reset`",
    "b": "**b. One human advice**, from its HTTP request to the replay memory and the row",
    "c": "**c. A tiny `ideeprl batch`**, to its first records",
}


def render(walks: dict[str, Walk]) -> str:
    lines = [BEGIN, ""]
    for key, title in WALKS.items():
        w = walks[key]
        climbs = len(w.climbs)
        lines.append(f"{title}: {len(w.files)} files, {climbs} climb{'s' * (climbs != 1)} back.")
        lines.append("")
        for file, function in w.files:
            lines.append(f"1. `{file}` (`{function}`)")
        if w.climbs:
            lines.append("")
            lines.append(
                "Climbs back: " + ", ".join(f"`{a}` → `{b}` (`{f}`)" for a, b, f in w.climbs) + "."
            )
        lines.append("")
    lines.append(END)
    return "\n".join(lines)


def documented() -> str:
    text = DOC.read_text()
    assert BEGIN in text and END in text, f"{DOC} has no walks markers"
    return text[text.index(BEGIN) : text.index(END) + len(END)]


@pytest.fixture(scope="module")
def traced(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Walk]]:
    tmp = tmp_path_factory.mktemp("walks")
    a, b = trace_server(tmp)
    yield {"a": a, "b": b, "c": trace_batch(tmp)}


@pytest.mark.parametrize("key", ["a", "b", "c"])
def test_the_walk_stays_within_its_bounds(traced: dict[str, Walk], key: str) -> None:
    w = traced[key]
    most_files, most_climbs = LIMITS[key]
    files, climbs = len(w.files), len(w.climbs)
    assert files <= most_files and climbs <= most_climbs, (
        f"walk {key}: {files} files, {climbs} climbs back; at most {LIMITS[key]}\n" + render(traced)
    )


def test_the_documented_walks_are_the_traced_ones(traced: dict[str, Walk]) -> None:
    assert documented() == render(traced), "run: python tests/test_walks.py --update"


if __name__ == "__main__":
    import tempfile

    sys.path.insert(0, str(ROOT))

    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(os.environ.get("WALKS_KEEP") or folder)
        a, b = trace_server(tmp)
        fresh = render({"a": a, "b": b, "c": trace_batch(tmp)})
    print(fresh)
    if "--update" in sys.argv:
        text = DOC.read_text()
        DOC.write_text(text.replace(documented(), fresh))
