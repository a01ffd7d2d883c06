"""How many people the study server holds at once, and an hour, on this machine; against a
real server on loopback at its default settings (physics motion, the 3-D view in real
time); two scenarios.

`crowd`: N participants (default 30) arrive within a minute (evenly spread) at an online
study's link (`/join/KEY` with Prolific's parameters, each from an address of its own), whose
one condition keeps a pool of `--pool` practised sessions (the server's pool limit set to
it; the crowd arrives once the pool is full; 0: each arrival's robot practises when its link
opens). `--browsers` of them (default 2) are real Chromium pages with the 3-D
view open, clicking the first action button whenever the buttons come on; the others are
clients that speak the page's protocol: its HTTP calls (consent, Start, the long-poll of
the state, advice with `wait`) and the viewer's websocket (`/viewer/p/TOKEN`, the camera
message viser's client sends, every scene message read). Each reads the induction for
`--reading-s`, then advises `--advice` times, thinking `--think-s` between advice.
Reported: each one's first-turn wait (Start to the first request); the advice round trip
(advice sent to the next request received: for protocol clients, measured at the client
on loopback, so it is the server's time plus a loopback hop; for browsers, click to the
buttons on again, which includes the 3-D view animating the move) at p50 and p95; the
server's own part of it, from its stamps in the database (each advice's answer to the next
advice's request: the worker's step, the database, the messages); a bare
`GET /api/health` measured at the same time; the proportional memory (PSS) of every
process of the server (the web process, the fork server, the workers) sampled during the
advice, per waiting worker and in all, against the machine's memory; the CPU the clients
themselves used (this process's threads, and Chromium with its Playwright driver), which the
server did not get, and the server's CPU by part (web process, participants' workers,
training), every process sampled each second while it runs (Chromium's processes end
before the run does and are nobody's waited-for children: counted at the end, as before
2026-12-04, they went missing); and
how fast the finished sessions train in the server's trainer slots, extrapolated to
participants an hour at the paper's scale.

`pollers`: P participants (default 100) polling `GET /api/participant/state` once a second
on sessions without a live worker (made, never started), and `GET /api/health` measured
meanwhile and alone: p50 and p95 (the aim: p95 under 50 ms).

With `--browsers-idle` the Chromium participants run in Linux's SCHED_IDLE class, so that
they take only the CPU the server leaves, as they would from the participants' own
machines. Without a GPU their 3-D view is drawn in software, about a core each; and
Chromium run as root (as here) raises its display threads to nice -8, above the server,
so a niceness would not hold them back.

    python -m benchmarks.bench_capacity [--scenario crowd|pollers|all] [--participants 30]
        [--browsers 2] [--advice 20] [--think-s 1.5] [--reading-s 5] [--arrival-s 60]
        [--pollers 100] [--pool 8] [--browsers-idle]
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import msgspec
import viser
from viser._messages import ViewerCameraMessage
from websockets.sync.client import connect

from benchmarks.bench_participant_page import ARGS, CHROMIUM, ENABLED
from benchmarks.bench_server import _server_turnarounds
from tests.server.live import LiveServer
from tests.server.scale import rest_body

RESEARCHER = {"X-API-Key": "test-researcher-key"}
OFF_OR_GONE = """() => { const b = document.querySelector('button.action');
    return !b || !b.disabled; }"""
"""The buttons are on again (the next turn), or gone (the page moved on)."""
PAPER_TRAINING_STEPS = 6_700
"""Training steps of a paper-scale session after its advice (300 episodes; issue 19's
measurement of the paper preset): what one trainer slot spends on one participant."""


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1)))] if values else 0.0


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def cpu_kind() -> str:
    flags = Path("/proc/cpuinfo").read_text()
    model = next(
        (ln.split(":", 1)[1].strip() for ln in flags.splitlines() if "model name" in ln), "?"
    )
    extras = [f for f in ("avx512_bf16", "amx_tile") if f in flags]
    return f"{model} ({', '.join(extras) or 'no AVX-512 BF16'})"


# --- processes ------------------------------------------------------------------------
def _stat(pid: int) -> list[str] | None:
    """The fields of /proc/PID/stat after the command's name (None: the process is gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _children() -> dict[int, list[int]]:
    tree: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (fields := _stat(int(entry.name))) is not None:
            tree.setdefault(int(fields[1]), []).append(int(entry.name))
    return tree


def descendants(pid: int, tree: dict[int, list[int]] | None = None) -> list[int]:
    """`pid` and every process under it (the fork server's workers included); `tree`: a
    `_children()` already read."""
    tree = _children() if tree is None else tree
    found, todo = [], [pid]
    while todo:
        current = todo.pop()
        found.append(current)
        todo.extend(tree.get(current, []))
    return found


def pss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def _is_browser(pid: int) -> bool:
    try:
        command = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False
    return b"chrom" in command or b"playwright" in command  # Chromium, or Playwright's driver


class CpuMeter:
    """The CPU each part of the machine uses over a run, sampled every `every_s` while it
    runs, so processes that end before the run does (a browser closed, a worker done) are
    counted up to their last sample (counting at the end would miss them: Chromium's
    processes are not waited for by this one). Parts: the server's (web process,
    participants' workers, training: nice 10 or SCHED_IDLE, as the trainer slots run them)
    and the clients' (this process's threads, and Chromium with its Playwright driver)."""

    def __init__(self, server_pid: int, every_s: float = 1.0) -> None:
        self._server = server_pid
        self._every = every_s
        self._tick = os.sysconf("SC_CLK_TCK")
        self._first: dict[int, float] = {}
        self._last: dict[int, tuple[float, str]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._started = False

    def _part(self, pid: int, fields: list[str], server: set[int]) -> str:
        if pid == self._server:
            return "web process"
        if pid in server:
            if int(fields[16]) >= 10 or int(fields[38]) == os.SCHED_IDLE:
                return "training"
            return "participants' workers"
        return "browsers" if _is_browser(pid) else "protocol clients"

    def sample(self) -> None:
        tree = _children()
        server = set(descendants(self._server, tree))
        for pid in set(descendants(os.getpid(), tree)) | server:
            fields = _stat(pid)
            if fields is None:
                continue
            cpu = (int(fields[11]) + int(fields[12])) / self._tick
            part = self._part(pid, fields, server)
            self._first.setdefault(pid, 0.0 if self._started else cpu)
            self._last[pid] = (cpu, part)

    def _loop(self) -> None:
        while not self._stop.wait(self._every):
            self.sample()

    def start(self) -> CpuMeter:
        self.sample()  # what every process had used before: not counted
        self._started = True
        self._thread.start()
        return self

    def stop(self) -> dict[str, float]:
        """CPU seconds of each part since `start` (a process that began meanwhile counts
        from zero)."""
        self._stop.set()
        self._thread.join()
        self.sample()
        parts = dict.fromkeys(
            ("web process", "participants' workers", "training", "protocol clients", "browsers"),
            0.0,
        )
        for pid, (cpu, part) in self._last.items():
            parts[part] += cpu - self._first.get(pid, 0.0)
        return parts


def machine_mb() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemTotal:"):
            return int(line.split()[1]) / 1024
    return float("nan")


# --- the crowd ------------------------------------------------------------------------
class Results:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.first_turn: dict[str, list[float]] = {"protocol": [], "browser": []}
        self.round_trip: dict[str, list[float]] = {"protocol": [], "browser": []}
        self.errors: list[str] = []
        self.advising = 0

    def add(self, table: dict[str, list[float]], kind: str, value: float) -> None:
        with self.lock:
            table[kind].append(value)


def online_study(server: LiveServer, args: argparse.Namespace) -> dict[str, Any]:
    """One condition at default settings (1,000 pretraining steps, physics motion) with
    `--advice` advice; room for everyone; no check or questionnaire (they take no server
    time worth measuring); its pool `--pool` sessions."""
    run = rest_body(method="human", advice_budget=args.advice)["run"]
    design = {
        "conditions": {"a": {"run": run, "target": args.participants}},
        "capacity": args.participants,
        "pool": args.pool,
        "check": None,
        "questionnaire": None,
        "panel": {"kind": "prolific"},
    }
    with httpx.Client(base_url=server.url, headers=RESEARCHER, timeout=120) as api:
        made = api.post("/api/studies", json={"name": "capacity", "design": design})
        made.raise_for_status()
        return dict(made.json())


def arrive(server: LiveServer, study: dict[str, Any], number: int) -> dict[str, Any]:
    """One arrival at the study's link with Prolific's parameters, from an address of its
    own (the server trusts loopback's X-Forwarded-For, as it trusts its reverse proxy)."""
    headers = {"X-Forwarded-For": f"10.7.{number // 250}.{number % 250 + 1}"}
    query = {"PROLIFIC_PID": f"P{number:04d}", "STUDY_ID": "cap", "SESSION_ID": f"s{number}"}
    path = urlsplit(study["join_url"]).path
    with httpx.Client(base_url=server.url, headers=headers, timeout=120) as client:
        response = client.get(path, params=query)
    assert response.status_code == 303, f"arrival {number}: {response.status_code}"
    location = response.headers["location"]
    return {
        "id": number,
        "participant_token": location.removeprefix("/p/"),
        "participant_url": server.url + location,
    }


def wait_for_pool(server: LiveServer, study: dict[str, Any], size: int) -> float:
    """Seconds until the pool holds `size` sessions that have practised."""
    started = time.perf_counter()
    with httpx.Client(base_url=server.url, headers=RESEARCHER, timeout=120) as api:
        while True:
            rows = api.get(f"/api/studies/{study['id']}/sessions").json()
            pooled = [r for r in rows if r["pooled"]]
            ready = 0
            for row in pooled:
                token = row["participant_url"].rsplit("/", 1)[1]
                state = api.get(
                    "/api/participant/readiness", headers={"Authorization": f"Bearer {token}"}
                )
                ready += bool(state.json().get("ready"))
            if ready >= size:
                return time.perf_counter() - started
            assert time.perf_counter() - started < 900, "the pool never filled"
            time.sleep(2)


def view(server: LiveServer, token: str, stop: threading.Event) -> None:
    """The viewer's websocket as viser's client uses it: a camera message, then every
    scene message read until the visit ends."""
    url = server.url.replace("http://", "ws://") + f"/viewer/p/{token}"
    camera = ViewerCameraMessage(
        wxyz=(1.0, 0.0, 0.0, 0.0),
        position=(1.5, 0.0, 1.2),
        fov=0.9,
        near=0.01,
        far=100.0,
        image_height=480,
        image_width=640,
        look_at=(0.0, 0.0, 0.4),
        up_direction=(0.0, 0.0, 1.0),
    )
    with connect(url, subprotocols=[f"viser-v{viser.__version__}"], max_size=None) as socket:
        socket.send(msgspec.msgpack.encode(camera.as_serializable_dict()))
        while not stop.is_set():
            try:
                socket.recv(timeout=1)
            except TimeoutError:
                continue


def protocol_participant(
    server: LiveServer, session: dict[str, Any], args: argparse.Namespace, out: Results
) -> None:
    token = session["participant_token"]
    stop = threading.Event()
    viewer = threading.Thread(target=view, args=(server, token, stop), daemon=True)
    viewer.start()
    headers = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=server.url, headers=headers, timeout=120) as client:
        try:
            shown = client.get("/api/participant/consent").json()
            client.post(
                "/api/participant/consent",
                json={"agree": True, "texts_version": shown["texts_version"]},
            )
            time.sleep(args.reading_s)
            started = time.perf_counter()
            state = client.post("/api/participant/start").json()
            while not state["advice_wanted"] and state["status"] in ("created", "running"):
                state = client.get(
                    "/api/participant/state", params={"after": state["version"], "timeout": 20}
                ).json()
            out.add(out.first_turn, "protocol", time.perf_counter() - started)
            with out.lock:
                out.advising += 1
            while state["advice_wanted"]:
                time.sleep(random.uniform(0.5, 1.5) * args.think_s)
                sent = time.perf_counter()
                receipt = client.post(
                    "/api/participant/advice",
                    params={"wait": 30},
                    json={"advice_index": state["advice_index"], "action": 0},
                ).json()
                state = receipt["state"]
                while not state["advice_wanted"] and state["status"] == "running":
                    if state.get("advice_left", 1) == 0:
                        break
                    state = client.get(
                        "/api/participant/state",
                        params={"after": state["version"], "timeout": 20},
                    ).json()
                if state["advice_wanted"]:
                    out.add(out.round_trip, "protocol", time.perf_counter() - sent)
        except Exception as error:
            out.errors.append(f"session {session['id']}: {error!r}")
        finally:
            with out.lock:
                out.advising -= 1
            stop.set()


def browser_participant(
    server: LiveServer, session: dict[str, Any], args: argparse.Namespace, out: Results
) -> None:
    """A person in Chromium (its own Playwright and browser: the sync API belongs to the
    thread that made it), the 3-D view open, clicking the first button each turn."""
    from playwright.sync_api import sync_playwright

    if args.browsers_idle:  # this thread's class, which the driver and Chromium inherit
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
        with out.lock:
            out.advising += 1
        try:
            page.goto(session["participant_url"])
            page.click("#agree")
            page.click("#next")
            page.click("#next")
            page.wait_for_selector("#start")
            time.sleep(args.reading_s)
            started = time.perf_counter()
            page.click("#start")
            page.wait_for_function(ENABLED, timeout=600_000, polling=50)
            out.add(out.first_turn, "browser", time.perf_counter() - started)
            for _ in range(args.advice - 1):
                time.sleep(random.uniform(0.5, 1.5) * args.think_s)
                clicked = time.perf_counter()
                page.click("button.action")
                page.wait_for_function(OFF_OR_GONE, timeout=600_000, polling=20)
                if "/advise" not in page.url or not page.evaluate(ENABLED):
                    break
                out.add(out.round_trip, "browser", time.perf_counter() - clicked)
        except Exception as error:
            out.errors.append(f"browser session {session['id']}: {error!r}")
        finally:
            with out.lock:
                out.advising -= 1
            browser.close()


def health_loop(url: str, stop: threading.Event, out: list[float], every_s: float = 0.2) -> None:
    with httpx.Client(base_url=url, timeout=30) as client:
        while not stop.is_set():
            started = time.perf_counter()
            client.get("/api/health")
            out.append(time.perf_counter() - started)
            time.sleep(every_s)


def crowd(args: argparse.Namespace) -> None:
    results = Results()
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer(
            Path(tmp), f"sqlite:///{tmp}/bench.sqlite3", pool_limit=args.pool
        ).start()
        assert server.process is not None
        try:
            online = online_study(server, args)
            study = online["id"]
            if args.pool:
                filled = wait_for_pool(server, online, args.pool)
                print(f"the pool of {args.pool} practised in {filled:.0f} s; {load()}")
            health: list[float] = []
            stop = threading.Event()
            threading.Thread(target=health_loop, args=(server.url, stop, health)).start()
            threads: list[threading.Thread] = []
            memory: list[tuple[int, float, float]] = []
            started = time.perf_counter()
            meter = CpuMeter(server.process.pid).start()
            for i in range(args.participants):
                arrival = started + i * args.arrival_s / args.participants
                while time.perf_counter() < arrival:
                    time.sleep(min(0.5, arrival - time.perf_counter()))
                session = arrive(server, online, i)
                who = browser_participant if i < args.browsers else protocol_participant
                thread = threading.Thread(target=who, args=(server, session, args, results))
                thread.start()
                threads.append(thread)
                memory.append(_memory(server, study, results.advising))
            while any(t.is_alive() for t in threads):
                memory.append(_memory(server, study, results.advising))
                time.sleep(2)
            wall = time.perf_counter() - started
            parts = meter.stop()
            with httpx.Client(base_url=server.url, headers=RESEARCHER) as api:
                rows = api.get(f"/api/studies/{study}/sessions", params={"limit": 1000}).json()
                training_rate = _training_rate(api, rows)
            stop.set()
        finally:
            server.stop()
        server_side = _server_turnarounds(f"{tmp}/bench.sqlite3")
    _report_crowd(args, results, health, memory, wall, training_rate, server_side, parts)


def _memory(server: LiveServer, study: int, advising: int) -> tuple[int, float, float]:
    """(participants advising, median PSS of a live worker, PSS of all the server's
    processes: the web process, the fork server, the workers) in MB."""
    assert server.process is not None
    with httpx.Client(base_url=server.url, headers=RESEARCHER, timeout=60) as api:
        rows = api.get(f"/api/studies/{study}/sessions", params={"limit": 1000}).json()
    workers = [pss_mb(r["worker_pid"]) for r in rows if r.get("worker_pid")]
    total = sum(pss_mb(p) for p in descendants(server.process.pid))
    return advising, statistics.median([w for w in workers if w] or [0.0]), total


def _training_rate(api: httpx.Client, rows: list[dict[str, Any]]) -> float:
    """Training steps a second of the sessions in the trainer slots, over 20 s."""

    def steps() -> int:
        return sum(
            api.get(f"/api/sessions/{r['id']}/progress").json().get("global_step", 0) for r in rows
        )

    before = steps()
    time.sleep(20)
    return (steps() - before) / 20


def _report_crowd(
    args: argparse.Namespace,
    results: Results,
    health: list[float],
    memory: list[tuple[int, float, float]],
    wall: float,
    training_rate: float,
    server_side: list[float],
    parts: dict[str, float],
) -> None:
    ms = 1000
    print(
        f"{args.participants} participants ({args.browsers} in Chromium with the 3-D view, "
        f"{args.participants - args.browsers} protocol clients with the viewer's websocket) "
        f"arriving over {args.arrival_s:.0f} s, {args.advice} advice each, thinking "
        f"{args.think_s} s; {wall:.0f} s in all; {cpu_kind()}; {load()}"
    )
    print(f"{'':34}{'n':>6}{'p50':>10}{'p95':>10}{'max':>10}")
    rows = [
        ("first turn, protocol (s)", results.first_turn["protocol"], 1),
        ("first turn, browser (s)", results.first_turn["browser"], 1),
        ("advice round trip, protocol (ms)", results.round_trip["protocol"], ms),
        ("advice round trip, browser (ms)", results.round_trip["browser"], ms),
        ("server side: answer -> next asked", server_side, ms),
        ("GET /api/health meanwhile (ms)", health, ms),
    ]
    for name, values, scale in rows:
        if values:
            print(
                f"{name:34}{len(values):>6}{percentile(values, 50) * scale:>10.2f}"
                f"{percentile(values, 95) * scale:>10.2f}{max(values) * scale:>10.2f}"
            )
    if memory:
        most = max(memory, key=lambda m: m[0])
        peak = max(m[2] for m in memory)
        print(
            f"memory: {most[0]} advising at once -> {most[1]:.0f} MB PSS per worker (median); "
            f"all server processes at most {peak:.0f} MB PSS, {100 * peak / machine_mb():.0f} % "
            f"of the machine's {machine_mb() / 1024:.1f} GiB"
        )
    machine = wall * (os.cpu_count() or 1)
    clients = parts["protocol clients"] + parts["browsers"]
    idle = ", in SCHED_IDLE" if args.browsers_idle else ""
    print(
        f"clients' own CPU: {clients:.0f} s over {wall:.0f} s ({100 * clients / machine:.0f} % "
        f"of the machine), taken from the server: protocol clients "
        f"{parts['protocol clients']:.0f} s, Chromium {parts['browsers']:.0f} s "
        f"({100 * parts['browsers'] / machine:.0f} %{idle})"
    )
    server_parts = ("web process", "participants' workers", "training")
    print(
        "server's CPU meanwhile: "
        + ", ".join(f"{part} {parts[part]:.0f} s" for part in server_parts)
    )
    if training_rate > 0:
        per_hour = training_rate * 3600 / PAPER_TRAINING_STEPS
        print(
            f"training queue: the trainer slots ran {training_rate:.1f} training steps/s "
            f"together: about {per_hour:.1f} participants an hour at the paper's scale "
            f"({PAPER_TRAINING_STEPS} training steps each)"
        )
    for error in results.errors[:10]:
        print("  error:", error)


# --- pollers --------------------------------------------------------------------------
def poll_loop(url: str, token: str, stop: threading.Event, every_s: float = 1.0) -> None:
    headers = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=url, headers=headers, timeout=30) as client:
        time.sleep(random.uniform(0, every_s))
        while not stop.is_set():
            client.get("/api/participant/state")
            time.sleep(every_s)


def pollers(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer(Path(tmp), f"sqlite:///{tmp}/bench.sqlite3").start()
        try:
            with httpx.Client(
                base_url=server.url, headers={"X-API-Key": "test-researcher-key"}, timeout=60
            ) as api:
                study = api.post("/api/studies", json={"name": "pollers"}).json()["id"]
                tokens = [
                    api.post(
                        f"/api/studies/{study}/sessions",
                        json=rest_body(method="human", seed=i),
                    ).json()["participant_token"]
                    for i in range(args.pollers)
                ]
            alone: list[float] = []
            stop = threading.Event()
            ref = threading.Thread(target=health_loop, args=(server.url, stop, alone, 0.1))
            ref.start()
            time.sleep(20)
            stop.set()
            ref.join()
            stop = threading.Event()
            threads = [
                threading.Thread(target=poll_loop, args=(server.url, t, stop)) for t in tokens
            ]
            for thread in threads:
                thread.start()
            time.sleep(5)
            loaded: list[float] = []
            ref = threading.Thread(target=health_loop, args=(server.url, stop, loaded, 0.1))
            ref.start()
            time.sleep(30)
            stop.set()
            for thread in [*threads, ref]:
                thread.join()
        finally:
            server.stop()
    ms = 1000
    print(
        f"GET /api/health with {args.pollers} participants polling their state once a second "
        f"(sessions without a live worker); {cpu_kind()}; {load()}"
    )
    for name, values in (("alone", alone), (f"{args.pollers} pollers", loaded)):
        print(
            f"  {name:14} n={len(values):4}  p50 {percentile(values, 50) * ms:7.1f} ms  "
            f"p95 {percentile(values, 95) * ms:7.1f} ms"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=["crowd", "pollers", "all"], default="all")
    parser.add_argument("--participants", type=int, default=30)
    parser.add_argument("--browsers", type=int, default=2)
    parser.add_argument("--advice", type=int, default=20)
    parser.add_argument("--think-s", type=float, default=1.5)
    parser.add_argument("--reading-s", type=float, default=5.0)
    parser.add_argument("--arrival-s", type=float, default=60.0)
    parser.add_argument("--pollers", type=int, default=100)
    parser.add_argument("--pool", type=int, default=8)
    parser.add_argument(
        "--browsers-idle",
        action="store_true",
        help="run the Chromium participants in Linux's SCHED_IDLE class: they take only CPU "
        "the server leaves (sharing it with the trainers), as if they were on the "
        "participants' own machines; a niceness would not do, since Chromium run as root "
        "raises its display threads to nice -8",
    )
    args = parser.parse_args([] if __name__ != "__main__" else None)
    random.seed(0)
    if args.scenario in ("pollers", "all"):
        pollers(args)
    if args.scenario in ("crowd", "all"):
        crowd(args)


if __name__ == "__main__":
    main()
