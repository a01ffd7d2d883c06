"""The three walks through the code, traced (issues 18 and 40): how many of the project's
source files each walk enters, where its value is handed off, and whether it climbs back
into a file it left.

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

Hand-offs. Each walk follows one value, by object identity, in each form it takes (the
hook's `form`): **a** the run: a `RunSpec`, or a record with the fields `method` and
`config` (the request's dict, its pydantic model, the stored document), or JSON text of
one; **b** the advice's action: a record with the fields `action` and `advice_index` (the
request's body, `AdviceGiven`, `AdviceAnswer`, `AdviceResult`, the row's dict) and the int
itself; **c** the batch: a `BatchSpec` or the parsed command line (a `Namespace` with
`methods`), and the runs it becomes (the run's forms, as in a). An int has no identity
(small ints are shared), so the action as an int is its value, and it counts only where the
frame that passes or returns it holds the action already: as an int, or as a record whose
`action` its code takes. Over the walk's entries (walk b: the request, then the worker's
main thread up to `ReplayMemory.add`, the frames still on the stack when the answer comes
included: the value reaches them by return), for each entry F:

- F *has* the value when it arrives as an argument (a closure's free variables count as
  arguments) or comes back from a callee's return (a callee F calls itself, or awaits
  through a thread pool): a form itself, or a form one level inside
  (an attribute, a dict value, an item: `session.run`, `values[run]`; inside `self`, only an
  attribute F's code loads). A comprehension is part of its function.
- It *goes* from F to each project callee whose arguments have it (same object), to F's
  return, into an argument's object that did not hold it before F (a store), or to a
  third-party function F calls itself with it among its arguments (the pipe, the database, a
  serializer, a thread pool; special methods other than `__init__`, `__new__` and
  `__call__` do not count: a descriptor, `isinstance`).
- F *makes* a form when one it did not receive or get back is among what it gives out
  (the arguments themselves of callees it calls itself, its return, a store, a third-party
  call) or in its locals when it returns.
- F *reads* the value when its bytecode (nested functions' included) takes an attribute,
  method or item of a name bound to a form, asks `in` it, or gives it first to `getattr`,
  `hasattr`, `vars`, `len`, `dict`, `list`, `tuple`, `set`, `sorted` or `iter`; for a form
  one level inside an argument, when it reads that form further (`session.run[...]`) or
  (not for `self`) another attribute of the argument (`session.id`; `[]`, `get` and `pop`
  only reach a dict's value).

F is a **translation** when it makes a form of a type it did not have (dict -> RunSpec,
RunSpec -> dict, pydantic model -> dict, record -> int, int -> message); a **pass-on** when it
makes none, reads none and sends each form it has to at most one place, at least one to
one; otherwise **work** (it reads the value, makes a new one of the same type, such as a
pinned `RunSpec`, or sends it to two places). A **pick-up** (listed, not a hand-off) had
nothing of the value and returns or stores a form: where the value comes in from the
database, the pipe or a parser. A walk's *hand-offs* are the places (file, function) with a
translation or pass-on entry; its *translations*, those with a translation entry. The
worker's *advice cycle* (walk b) runs on its main thread from the entry of the outermost
`advise` on the stack when the answer arrives (the advisor being asked) to the entry of
`ReplayMemory.add` (the answer used); its climbs back are counted as above.

Issue 18 asked at most 10, 12 and 15 files; issue 40 asks 8, 8 and 10 hand-offs and no climb
back.
`LIMITS` and `CYCLE_CLIMBS` hold the counts the code meets today, as upper bounds that may
only go down (`docs/architecture.md`, "Three walks through the code", says what the
hand-offs left do and what blocks the file counts). The section between the `walks` markers
there is this test's output: `python tests/test_walks.py --update` rewrites it, and the test
fails when it differs from a fresh trace.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

ROOT = Path(__file__).absolute().parents[1]
TRACER = ROOT / "tests" / "walks"
DOC = ROOT / "docs" / "architecture.md"
BEGIN, END = "<!-- walks: begin (python tests/test_walks.py --update) -->", "<!-- walks: end -->"

LIMITS = {"a": (52, 0, 6), "b": (22, 0, 8), "c": (50, 0, 10)}
"""Walk: (most files, most climbs back, most hand-offs) the code meets today, bounds that may
only go down; issue 18 asked 10, 12 and 15 files, issue 40 asks 8, 8 and 10 hand-offs and
no climb back, which the hand-offs and climbs meet (docs/architecture.md says what blocks
the files). Files that do a walk's work raise its file bound, never its hand-offs: the
session manager's parts (`server/live/session.py`, `workers.py`), the learner's own first
layer (`learner/conv_kernel.py`, a and c), a rating session's turns read at start
(`study/services/feedback.py`, a) and the network that says what it observes
(`learner/network.py`, b). Walk a enters the trainer slots (`server/live/trainers.py`)
where `start_session` shows the session's status."""
CYCLE_CLIMBS = 0
"""The most climbs back over the worker's whole advice cycle (walk b): a bound that may only
go down; the issue asks none."""

INLINE = (".<listcomp>", ".<dictcomp>", ".<setcomp>", ".<genexpr>")
"""Comprehensions: their frames are their function's (Python 3.12 runs them inline)."""
CREATE = "creation_router.<locals>.create_session"
LATER = {"pretrain": "false"}
"""A session made by the walk is started by its own request, not when it is made."""
ADVISED = 1
"""The action the walk's participant advises (move right). An int has no identity of its own
(CPython shares small ints), so the action is followed as an int by its value, where the
frame that has it holds the advice already (module docstring)."""

pytestmark = pytest.mark.slow


@dataclass(frozen=True)
class Form:
    """A walk's value as one argument, local or returned object holds it."""

    kind: str
    """`run`, `batch` or `action` (tests/walks/walk_tracer.py's `form`)."""
    type: str
    ident: str
    """The object's identity (`int=N`: an int's value)."""
    where: str
    """The name holding it: `spec`, `session.run`, `values[run]`, `return`."""


def read_forms(text: str) -> tuple[Form, ...]:
    return tuple(Form(*f.split(",", 3)) for f in text.split(";") if f)


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
    seq: int = 0
    """The frame's number in its process."""
    parent: int = 0
    """The number of the project frame that called it (0: none)."""
    direct: bool = True
    """That frame called it itself, not through third-party code (or awaited it through a
    thread pool)."""
    forms: tuple[Form, ...] = ()
    """The values among its arguments."""
    reads: tuple[str, ...] = ()
    """Which of those its code reads."""
    stack: tuple[str, ...] = ()
    """`answer`: the project frames on the stack, `FILE:FUNCTION:SEQ`, outermost first."""


@dataclass(frozen=True)
class Return:
    ns: int
    seq: int
    returned: tuple[Form, ...]
    held: tuple[Form, ...]
    """The values in its arguments and locals when it returned."""
    stored: tuple[Form, ...]
    """The values its arguments' objects hold after it and did not before."""
    reads: tuple[str, ...]


@dataclass
class Trace:
    entries: list[Entry]
    returns: list[Return]


def read_trace(path: Path) -> Trace:
    entries, returns = [], []
    for line in path.read_text().splitlines():
        ns, event, thread, task, file, function, *rest = line.split("\t")
        kind, caller = event.split(" ")
        if kind == "return":
            seq, _, returned, held, stored, read = rest
            returns.append(
                Return(
                    int(ns), int(seq), read_forms(returned), read_forms(held),
                    read_forms(stored), tuple(r for r in read.split(",") if r),
                )
            )  # fmt: skip
            continue
        if kind in ("answer", "leave"):
            kind, caller = event, "-"
        climb = caller.endswith("!")
        seq, parent, forms, read = rest
        entries.append(
            Entry(
                int(ns), kind, caller.rstrip("!"), climb, thread, int(task), file, function,
                int(seq), int(parent.rstrip("~^")), not parent.endswith("~"),
                read_forms(forms) if not kind.startswith("answer") else (),
                tuple(r for r in read.split(",") if r),
                tuple(forms.split(";")) if kind.startswith("answer") else (),
            )
        )  # fmt: skip
    return Trace(entries, returns)


def traces(folder: Path) -> dict[int, Trace]:
    """Each process's entries and returns, by pid."""
    return {int(p.stem.split("-")[1]): read_trace(p) for p in sorted(folder.glob("trace-*.tsv"))}


@dataclass(frozen=True)
class Part:
    """A stretch of one process's walk: its entries and the returns up to its end."""

    entries: list[Entry]
    returns: list[Return]
    leaves: list[Entry]
    """Its frames' calls into third-party code with the value."""


def part(trace: Trace, entries: list[Entry], end_ns: int | None = None) -> Part:
    end = entries[-1].ns if end_ns is None else end_ns
    seqs = {e.seq for e in entries}
    returns = [r for r in trace.returns if r.seq in seqs and r.ns <= end]
    leaves = [
        e for e in trace.entries if e.kind.startswith("leave") and e.seq in seqs and e.ns <= end
    ]
    return Part(entries, returns, leaves)


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
class Place:
    """A function entry that holds the walk's value, and what it does with it."""

    file: str
    function: str
    kind: str
    """`pass-on`, `translation A → B`, `work` or `pick-up` (module docstring)."""

    @property
    def hand_off(self) -> bool:
        return self.kind == "pass-on" or self.kind.startswith("translation")


@dataclass
class _Frame:
    entry: Entry
    held: dict[str, Form]
    """What it was given and what its callees gave back, by identity."""
    places: dict[str, set[str]]
    """Where each value it holds went: callees' numbers, `return`, `store`."""
    new: dict[str, Form]
    """Values it passed on, returned, stored or kept that it was not given or got back."""
    reads: set[str]
    brought: bool = False
    """It returned or stored a value it was not given and did not get back (a pick-up)."""

    def holds_action(self, ints: bool) -> bool:
        """It holds the action as an int, or (`ints`) as a record whose `action` it takes."""
        kinds = {f.type for f in self.held.values() if f.kind == "action"}
        return "int" in kinds or (ints and bool(kinds) and "@action" in self.reads)


def places(kinds: set[str], walk_part: Part) -> list[Place]:
    """What each entry of the part that holds the value of `kinds` does with it, in the
    order entered (module docstring)."""
    frames: dict[int, _Frame] = {}
    inline: set[int] = set()
    events = sorted(
        [(e.ns, 0, e) for e in walk_part.entries if e.kind == "call"]
        + [(e.ns, 0, e) for e in walk_part.leaves]
        + [(r.ns, 1, r) for r in walk_part.returns],
        key=lambda x: (x[0], x[1]),
    )

    def mine(forms: tuple[Form, ...], frame: _Frame | None) -> list[Form]:
        """The forms of the walk's kinds; an int is the action only where `frame` (which
        passes or returns it) holds the action already (small ints have no identity of
        their own)."""
        kept = [f for f in forms if f.kind in kinds]
        ints = frame is not None and frame.holds_action(ints=True)
        return [f for f in kept if f.type != "int" or ints]

    for _, _, event in events:
        if isinstance(event, Entry) and event.kind.startswith("leave"):
            frame = frames.get(event.seq)
            if frame is None:
                continue
            for f in mine(event.forms, frame):
                if f.ident in frame.held:
                    frame.places.setdefault(f.ident, set()).add(event.kind)
                elif frame.held and "." not in f.where and "[" not in f.where:
                    frame.new.setdefault(f.ident, f)
            continue
        if isinstance(event, Entry) and event.function.endswith(INLINE):
            if event.parent in frames:  # a comprehension is its function's own code
                frames[event.seq] = frames[event.parent]
                inline.add(event.seq)
            continue
        if isinstance(event, Entry):
            caller = frames.get(event.parent)
            given = mine(event.forms, caller)
            frame = _Frame(event, {f.ident: f for f in given}, {}, {}, set())
            frame.reads |= {r for r in event.reads if r == "@action"}
            names = {f.where for f in given}
            frame.reads |= {r for r in event.reads if r in names}
            frames[event.seq] = frame
            if caller is not None:
                for f in given:
                    if f.ident in caller.held:
                        caller.places.setdefault(f.ident, set()).add(str(event.seq))
                    elif caller.held and event.direct and "." not in f.where and "[" not in f.where:
                        caller.new.setdefault(f.ident, f)
            continue
        frame = frames.get(event.seq)
        if frame is None:
            continue
        if event.seq in inline:  # what it made is its function's
            made = mine(event.returned, frame) + mine(event.held, frame)
            for f in made:
                if f.ident not in frame.held:
                    frame.new.setdefault(f.ident, f)
            names = {f.where for f in made}
            frame.reads |= {r for r in event.reads if r in names}
            continue
        caller = frames.get(frame.entry.parent)
        for f in mine(event.returned, frame):
            if f.ident in frame.held:
                frame.places.setdefault(f.ident, set()).add("return")
            else:
                frame.new.setdefault(f.ident, f)
                frame.brought = frame.brought or not frame.held
            if caller is not None and frame.entry.direct:
                caller.held.setdefault(f.ident, f)
        for f in mine(event.stored, frame):
            if f.ident in frame.held:
                frame.places.setdefault(f.ident, set()).add("store")
            else:
                frame.new.setdefault(f.ident, f)
                frame.brought = frame.brought or not frame.held
        held = mine(event.held, frame)
        for f in held:
            if f.ident not in frame.held:
                frame.new.setdefault(f.ident, f)
        names = {f.where for f in held} | {f.where for f in frame.held.values()}
        frame.reads |= {r for r in event.reads if r in names}

    found = []
    for seq, frame in frames.items():
        if seq in inline:
            continue
        e = frame.entry
        if not frame.held:
            if frame.brought:
                found.append(Place(e.file, e.function, "pick-up"))
            continue
        had = {f.type for f in frame.held.values()}
        other = [f for f in frame.new.values() if f.type not in had]
        if other:
            before = "/".join(sorted(had))
            after = "/".join(sorted({f.type for f in other}))
            found.append(Place(e.file, e.function, f"translation {before} → {after}"))
        elif (
            not frame.new
            and not frame.reads - {"@action"}
            and frame.places
            and all(len(p) == 1 for p in frame.places.values())
        ):
            found.append(Place(e.file, e.function, "pass-on"))
        else:
            found.append(Place(e.file, e.function, "work"))
    return found


@dataclass(frozen=True)
class Walk:
    files: list[tuple[str, str]]
    """Each file entered, in the order first entered, with the first function entered there."""
    climbs: list[tuple[str, str, str]]
    """Each distinct call that climbs back: (caller's file, callee's file, callee)."""
    value: list[Place]
    """Each entry that holds the walk's value, in the order entered, and what it does."""
    cycle_climbs: list[tuple[str, str, str]] | None = None
    """Walk b: the climbs back over the worker's whole advice cycle."""
    cycle_from: str = ""
    """Walk b: the function whose entry begins that cycle (the advisor being asked)."""

    @property
    def hand_offs(self) -> dict[tuple[str, str], list[Place]]:
        """Each place (file, function) that hands the value off, in the order first entered,
        with its entries that do."""
        found: dict[tuple[str, str], list[Place]] = {}
        for p in self.value:
            if p.hand_off:
                found.setdefault((p.file, p.function), []).append(p)
        return found

    @property
    def translations(self) -> int:
        """The places among `hand_offs` where the value becomes another form."""
        return sum(any(p.kind != "pass-on" for p in e) for e in self.hand_offs.values())

    @property
    def pick_ups(self) -> list[tuple[str, str]]:
        found = {(p.file, p.function): None for p in self.value if p.kind == "pick-up"}
        return list(found)


def climbs_in(entries: list[Entry]) -> list[tuple[str, str, str]]:
    climbs: dict[tuple[str, str, str], None] = {}
    for e in entries:
        if e.climb:
            climbs[(e.caller, e.file, e.function)] = None
    return list(climbs)


def walk(kinds: set[str], parts: list[Part], value: list[Part] | None = None) -> Walk:
    """The walk over `parts`; its value followed over `value` (default: the same parts)."""
    files: dict[str, str] = {}
    for p in parts:
        for e in p.entries:
            files.setdefault(e.file, e.function)
    entries = [e for p in parts for e in p.entries]
    held = [place for p in (parts if value is None else value) for place in places(kinds, p)]
    return Walk(list(files.items()), climbs_in(entries), held)


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
            # a session first, so that the walk's is not number 1, the action it advises
            spare = session_body("human", advice_budget=2, participant="P00")
            made = f"/api/studies/{study['id']}/sessions"
            assert api.post(made, json=spare, params=LATER).status_code == 201
            t0 = time_ns()
            created = api.post(made, json=body, params=LATER)
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
            assert participant.advise(0, ADVISED).status_code == 200
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
    workers = [t for t in found.values() if any(e.kind == "answer 0" for e in t.entries)]
    assert len(workers) == 1, {pid: len(t.entries) for pid, t in found.items()}
    (worker,) = workers
    a = walk(
        {"run"},
        [
            part(server, request(server.entries, t0, t1, CREATE), t1),
            part(server, request(server.entries, t1, t2, "start_session"), t2),
            part(worker, until(worker.entries, "sim/env.py", "reset")),
        ],
    )
    answered = next(i for i, e in enumerate(worker.entries) if e.kind == "answer 0")
    answer = worker.entries[answered]
    after = until(worker.entries[answered:], "learner/replay.py", "add")
    advice = part(server, request(server.entries, t3, t4, "give_advice"), t4)
    cycle = advice_cycle(worker.entries, answer, after)
    before = [e for e in worker.entries[:answered] if e.kind == "call" and e.thread == "MainThread"]
    b = walk(
        {"action"},
        [advice, part(worker, [answer, *after])],
        [advice, part(worker, [*before, *after])],
    )
    return a, replace(b, cycle_climbs=climbs_in(cycle), cycle_from=cycle[0].function)


def advice_cycle(entries: list[Entry], answer: Entry, after: list[Entry]) -> list[Entry]:
    """The worker's main thread from the entry of the outermost `advise` on the stack when
    the answer came (the advisor being asked) to the entry of `ReplayMemory.add` (the
    answer used)."""
    asked = [int(s.rsplit(":", 1)[1]) for s in answer.stack if s.split(":")[1].endswith("advise")]
    assert asked, f"no advise on the stack of the answer: {answer.stack}"
    start = next(e for e in entries if e.kind == "call" and e.seq == asked[0])
    return [e for e in entries if e.kind == "call" and e.thread == "MainThread"
            and start.ns <= e.ns <= after[-1].ns]  # fmt: skip


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
    found = sorted(
        (t for t in traces(tmp / "batch-trace").values() if t.entries),
        key=lambda t: t.entries[0].ns,
    )
    runner, *others = found
    parts = [part(runner, until(runner.entries, "runs/batch/backends.py", "start"))]
    for trace in others:
        if any(e.function == "Recorder.on_episode" for e in trace.entries):
            parts.append(part(trace, until(trace.entries, "runs/worker/recorder.py", "on_episode")))
    return walk({"batch", "run"}, parts)


def time_ns() -> int:
    import time

    return time.monotonic_ns()


WALKS = {
    "a": "**a. Creating and starting a session**, down to `env.reset`",
    "b": "**b. One human advice**, from its HTTP request to the replay memory and the row",
    "c": "**c. A tiny `ideeprl batch`**, to its first records",
}


VALUES = {"a": "the run", "b": "the action", "c": "the batch"}


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'s' * (n != 1)}"


def render(walks: dict[str, Walk]) -> str:
    lines = [BEGIN, ""]
    lines.append(
        "| walk | files entered | hand-offs (translations) | climbs back | over an advice cycle |"
    )
    lines.append("|---|---|---|---|---|")
    for key, w in walks.items():
        cycle = "" if w.cycle_climbs is None else str(len(w.cycle_climbs))
        lines.append(
            f"| {key} | {len(w.files)} | {len(w.hand_offs)} ({w.translations}) "
            f"| {len(w.climbs)} | {cycle} |"
        )
    lines.append("")
    for key, title in WALKS.items():
        w = walks[key]
        lines.append(
            f"{title}: {_count(len(w.files), 'file')}, {_count(len(w.climbs), 'climb')} back."
        )
        lines.append("")
        for file, function in w.files:
            lines.append(f"1. `{file}` (`{function}`)")
        if w.climbs:
            lines.append("")
            lines.append(
                "Climbs back: " + ", ".join(f"`{a}` → `{b}` (`{f}`)" for a, b, f in w.climbs) + "."
            )
        lines.append("")
        hand_offs = _count(len(w.hand_offs), "hand-off")
        lines.append(
            f"Where {VALUES[key]} is handed off: {hand_offs}, {w.translations} translated."
        )
        lines.append("")
        for (file, function), entries in w.hand_offs.items():
            kinds = ", ".join(dict.fromkeys(p.kind for p in entries))
            times = f", {len(entries)} entries" if len(entries) > 1 else ""
            lines.append(f"1. `{file}` (`{function}`): {kinds}{times}")
        if w.pick_ups:
            lines.append("")
            lines.append(
                "Picked up (not hand-offs): "
                + ", ".join(f"`{file}` (`{function}`)" for file, function in w.pick_ups)
                + "."
            )
        if w.cycle_climbs is not None:
            lines.append("")
            climbs = _count(len(w.cycle_climbs), "climb")
            lines.append(
                f"Over the worker's whole advice cycle (from `{w.cycle_from}` to "
                f"`ReplayMemory.add`): {climbs} back"
                + "".join(
                    f"{', ' if i else ': '}`{a}` → `{b}` (`{f}`)"
                    for i, (a, b, f) in enumerate(w.cycle_climbs)
                )
                + "."
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
    files, climbs, hand_offs = len(w.files), len(w.climbs), len(w.hand_offs)
    most_files, most_climbs, most_hand_offs = LIMITS[key]
    assert files <= most_files and climbs <= most_climbs and hand_offs <= most_hand_offs, (
        f"walk {key}: {files} files, {climbs} climbs back, {hand_offs} hand-offs; at most "
        f"{LIMITS[key]}\n" + render(traced)
    )


def test_the_advice_cycle_climbs_back_no_more(traced: dict[str, Walk]) -> None:
    climbs = traced["b"].cycle_climbs
    assert climbs is not None and len(climbs) <= CYCLE_CLIMBS, (
        f"the advice cycle climbs back {climbs}; at most {CYCLE_CLIMBS}\n" + render(traced)
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
