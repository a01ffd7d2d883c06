"""The participant's page in a real browser (Debian's Chromium through Playwright), against
a real server on loopback at its default settings (the 3-D view in real time); two
scenarios.

`first-turn`: a participant who clicks straight through consent and the three induction
pages, with the 3-D view open as soon as the advice page loads: the time from their click
on Start to the action buttons becoming active (the aim: within 2 s). The session is made
through the API with `?pretrain=true` (as the dashboard makes its participants), `--head-start`
seconds before the participant opens the link (0: they open it at once, the worst case).
Median of `--runs`, with the machine's load average.

`weight`: the advice page over a throttled phone connection (Chromium's CDP
`Network.emulateNetworkConditions`: 1.6 Mbit/s down, 750 kbit/s up, 150 ms latency, the
DevTools' "Slow 4G"): bytes on the wire per kind (the page and its files, viser's client
in the frame, the scene over the websocket, the KUKA meshes included; `--task` picks the
task, `reach` for the other PyBullet scene) and the times to the
page's first contentful paint, to its buttons, and to the scene's arrival (when 90 % of
the websocket's bytes of the first 20 s had come).

`idle`: the CPU Chromium takes for an advice page that waits for the participant's advice,
nothing moving (the participant reads, or thinks), with the 3-D view shown and, as the
reference measured in the same run, hidden (`display: none`): without a GPU the view is
drawn in software on the participant's CPU, and on the benchmark's machine beside the
server's. Median of `--runs` 15-second windows, each on a fresh page.

    python -m benchmarks.bench_participant_page [--scenario first-turn|weight|idle|all] [--runs 3]
        [--pretraining-steps 1000] [--head-start 0] [--task sorting|gridworld|module:callable]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import rest_body

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking"]
SLOW_4G = {
    "offline": False,
    "latency": 150,
    "downloadThroughput": 1.6e6 / 8,
    "uploadThroughput": 750e3 / 8,
}
"""Bytes a second, as CDP takes them."""
ENABLED = "() => { const b = document.querySelector('button.action'); return b && !b.disabled; }"


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def _session(
    server: LiveServer, study: int, steps: int, budget: int = 100, task: str = "sorting"
) -> dict[str, Any]:
    body = rest_body(
        method="human", config={"pretraining_steps": steps}, advice_budget=budget, task=task
    )
    with server.client() as api:
        made = api.post(f"/api/studies/{study}/sessions?pretrain=true", json=body)
        assert made.status_code == 201, made.text
        return made.json()


VIEWERS = """async (token) => (await (await fetch('/api/participant/playback',
    {headers: {Authorization: `Bearer ${token}`}})).json()).viewers"""


def first_turn(browser: Any, server: LiveServer, study: int, args: argparse.Namespace) -> None:
    from tasks import get_task

    live = get_task(args.task).live_view  # else the task's frames: no 3-D view to wait for
    waits: list[float] = []
    views: list[float] = []
    for _ in range(args.runs):
        session = _session(server, study, args.pretraining_steps, task=args.task)
        time.sleep(args.head_start)
        context = browser.new_context(viewport={"width": 1280, "height": 800})
        page = context.new_page()
        page.goto(session["participant_url"])
        page.click("#agree")
        page.click("#next")
        page.click("#next")
        page.wait_for_selector("#start")
        started = time.perf_counter()
        page.click("#start")
        page.wait_for_function(ENABLED, timeout=600_000, polling=50)
        waits.append(time.perf_counter() - started)
        while live and page.evaluate(VIEWERS, session["participant_token"]) < 1:
            assert time.perf_counter() - started < 300, "the 3-D view never connected"
            time.sleep(0.05)
        views.append(time.perf_counter() - started)
        assert page.evaluate(ENABLED), "the buttons stay active once the view is open"
        context.close()
        with server.client() as api:
            api.post(f"/api/sessions/{session['id']}/stop")
        view = f"-> 3-D view open {views[-1]:.2f} s" if live else "(frames, no 3-D view)"
        print(f"  Start -> buttons active {waits[-1]:.2f} s, {view}")
    print(
        f"first turn in Chromium, task {args.task}, {args.pretraining_steps} pretraining steps, "
        f"head start {args.head_start:.0f} s, over {args.runs} runs: Start -> buttons active "
        f"median {statistics.median(waits):.2f} s ({min(waits):.2f}-{max(waits):.2f}); "
        + (
            f"-> 3-D view open {statistics.median(views):.2f} s "
            f"({min(views):.2f}-{max(views):.2f}); "
            if live
            else "(the task's frames, no 3-D view); "
        )
        + _load()
    )


class Wire:
    """What one page load brings over the network: bytes by resource type (data: URLs
    inside a document are not on the wire) and the websocket's frames, with their times."""

    def __init__(self, context: Any, page: Any) -> None:
        self.cdp = context.new_cdp_session(page)
        self.cdp.send("Network.enable")
        self.cdp.send("Network.emulateNetworkConditions", SLOW_4G)
        self.types: dict[str, str] = {}
        self.urls: dict[str, str] = {}
        self.sizes: dict[str, int] = {}
        self.frames: list[tuple[float, int]] = []
        self.cdp.on("Network.responseReceived", self._response)
        self.cdp.on("Network.loadingFinished", self._finished)
        # viser's client opens its websocket in the page: Playwright sees its frames, and
        # CDP's throttling covers it as one of the page's requests.
        page.on("websocket", lambda ws: ws.on("framereceived", self._frame))

    def _response(self, event: dict[str, Any]) -> None:
        self.types[event["requestId"]] = event["type"]
        self.urls[event["requestId"]] = event["response"]["url"]

    def _finished(self, event: dict[str, Any]) -> None:
        if not self.urls.get(event["requestId"], "").startswith("data:"):
            self.sizes[event["requestId"]] = int(event["encodedDataLength"])

    def _frame(self, payload: str | bytes) -> None:
        size = len(payload if isinstance(payload, bytes) else payload.encode())
        self.frames.append((time.perf_counter(), size))

    def reset(self) -> None:
        self.sizes.clear()
        self.frames.clear()

    def report(self, title: str, started: float, window_s: float) -> None:
        early = [(t, n) for t, n in self.frames if t - started <= window_s]
        socket = sum(n for _, n in early)
        seen, scene_at = 0, float("nan")
        for t, n in early:
            seen += n
            if seen >= 0.9 * socket:
                scene_at = t - started
                break
        by_kind: dict[str, int] = {}
        for request, size in self.sizes.items():
            kind = self.types.get(request, "Other")
            by_kind[kind] = by_kind.get(kind, 0) + size
        print(title)
        for kind, size in sorted(by_kind.items(), key=lambda kv: -kv[1]):
            print(f"  {kind:12} {size / 1024:8.1f} KiB")
            if os.environ.get("BENCH_VERBOSE"):
                for request, n in self.sizes.items():
                    if self.types.get(request) == kind and n > 1024:
                        print(f"      {n / 1024:8.1f} KiB {self.urls.get(request, '')[:70]}")
        print(
            f"  {'websocket':12} {socket / 1024:8.1f} KiB (first {window_s:.0f} s: the scene, "
            f"its meshes and moves; 90 % in by {scene_at:.2f} s)"
        )
        print(f"  {'all':12} {(sum(by_kind.values()) + socket) / 1024:8.1f} KiB")


def weight(browser: Any, server: LiveServer, study: int, args: argparse.Namespace) -> None:
    session = _session(server, study, 200, budget=5, task=args.task)
    SimulatedParticipant(server.url, session["participant_token"]).begin()
    context = browser.new_context(viewport={"width": 390, "height": 844}, is_mobile=True)
    page = context.new_page()
    wire = Wire(context, page)
    window_s = 20.0
    for load in ("first load", "a reload (the browser's cache warm)"):
        wire.reset()
        started = time.perf_counter()
        if load == "first load":
            page.goto(f"{server.url}/p/{session['participant_token']}/advise")
        else:
            page.reload()
        page.wait_for_function(ENABLED, timeout=600_000, polling=50)
        buttons = time.perf_counter() - started
        paint = page.evaluate(
            "performance.getEntriesByName('first-contentful-paint')[0]?.startTime ?? -1"
        )
        # Playwright's sync API hands over events only while it is called: wait through it,
        # or the frames would be counted (and stamped) at the next call, the reload's.
        page.wait_for_timeout(max(0.0, window_s - (time.perf_counter() - started)) * 1000)
        wire.report(
            f"the advice page at 390x844 over Slow 4G (1.6 Mbit/s, 150 ms), {load}:",
            started,
            window_s,
        )
        print(
            f"  first contentful paint {paint / 1000:.2f} s, buttons active {buttons:.2f} s "
            f"after navigation; {_load()}"
        )
    context.close()
    with server.client() as api:
        api.post(f"/api/sessions/{session['id']}/stop")


def idle(browser: Any, server: LiveServer, study: int, args: argparse.Namespace) -> None:
    from benchmarks.bench_capacity import CpuMeter  # which imports this module's constants

    window_s, settle_s = 15.0, 8.0
    cores: dict[str, list[float]] = {"shown": [], "hidden": []}
    for _ in range(args.runs):
        session = _session(server, study, 200, budget=5, task=args.task)
        SimulatedParticipant(server.url, session["participant_token"]).begin()
        for view in ("shown", "hidden"):
            context = browser.new_context(viewport={"width": 1280, "height": 800})
            page = context.new_page()
            page.goto(f"{server.url}/p/{session['participant_token']}/advise")
            page.wait_for_function(ENABLED, timeout=600_000, polling=100)
            if view == "hidden":
                page.evaluate("document.querySelector('#scene').style.display = 'none'")
            time.sleep(settle_s)  # the scene arrives and is drawn; the page settles
            assert server.process is not None, "the server runs"
            meter, started = CpuMeter(server.process.pid).start(), time.perf_counter()
            time.sleep(window_s)
            used = meter.stop()["browsers"] / (time.perf_counter() - started)
            cores[view].append(used)
            context.close()
            print(f"  3-D view {view}: Chromium {used:.2f} cores; {_load()}")
        with server.client() as api:
            api.post(f"/api/sessions/{session['id']}/stop")
    shown, hidden = statistics.median(cores["shown"]), statistics.median(cores["hidden"])
    print(
        f"an advice page waiting for advice, 1280x800, over {args.runs} runs of {window_s:.0f} s: "
        f"Chromium median {shown:.2f} cores with the 3-D view shown "
        f"({min(cores['shown']):.2f}-{max(cores['shown']):.2f}), {hidden:.2f} with it hidden; "
        f"the view costs {shown - hidden:.2f} cores; {_load()}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    scenarios = ["first-turn", "weight", "idle", "all"]
    parser.add_argument("--scenario", choices=scenarios, default="all")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--pretraining-steps", type=int, default=1000)
    parser.add_argument("--head-start", type=float, default=0.0)
    parser.add_argument("--task", default="sorting", help="the run's task (first-turn and weight)")
    args = parser.parse_args([] if __name__ != "__main__" else None)
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as playwright:
        server = LiveServer(Path(tmp), f"sqlite:///{tmp}/bench.sqlite3").start()
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            with server.client() as api:
                study = api.post("/api/studies", json={"name": "participant page"}).json()["id"]
            if args.scenario in ("weight", "all"):
                weight(browser, server, study, args)
            if args.scenario in ("first-turn", "all"):
                first_turn(browser, server, study, args)
            if args.scenario in ("idle", "all"):
                idle(browser, server, study, args)
        finally:
            browser.close()
            server.stop()


if __name__ == "__main__":
    main()
