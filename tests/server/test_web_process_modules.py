"""The web process stays light: sessions train, episodes rerun and reports render in
processes of their own, so serving every page and route (all but building a report) never
loads the simulation, the learner's torch or the analysis' plotting and statistics.

The server runs as deployed (`ideeprl serve` on loopback), wrapped so that at its exit it
writes the names in its `sys.modules` to a file: the test reads the process from outside.
The routes are read from the app itself, every method and the viewer's websockets, and each
is requested as its user would (a person consents, starts, advises and is checked; a panel
id is joined and deleted; the dashboard makes a study, a design and a preview and plays an
episode back in its 3-D view; sessions are paused, stopped, deleted): a route added later
fails the test until it is requested too.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import viser
from fastapi.routing import APIRoute, APIWebSocketRoute
from starlette.routing import Route as StarletteRoute
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from server.main import create_app
from study.settings import Settings
from tests.server.live import API_KEY, LiveServer, fresh_database
from tests.server.participant import SimulatedParticipant
from tests.server.scale import rest_body, session_body, wait_for_status

HEAVY = ("matplotlib", "scipy", "torch", "pybullet")
"""What the web process must never hold: each is hundreds of milliseconds to import and
tens of megabytes resident, in the process whose CPU the participants' requests need."""
DUMP = """
import atexit, sys
path = sys.argv.pop(1)
atexit.register(lambda: open(path, "w").write("\\n".join(sorted(sys.modules))))
from cli.main import main
raise SystemExit(main(sys.argv[1:]))
"""
REPORT = "report"
"""Building a report renders figures in the web process: the routes left out."""
HEADERS = {"X-Requested-With": "test"}
Route = tuple[str, str]
"""(method, path template); a websocket's method is `WS`."""


class ModuleDumpingServer(LiveServer):
    """`ideeprl serve`, writing its `sys.modules` to `modules` when it exits."""

    def __init__(self, data_dir: Path, database_url: str, **settings: Any) -> None:
        super().__init__(data_dir, database_url, **settings)
        self.modules = data_dir / "modules.txt"

    @property
    def entry(self) -> list[str]:
        return [sys.executable, "-c", DUMP, str(self.modules)]


@pytest.fixture(scope="module")
def dumping(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ModuleDumpingServer]:
    data_dir = tmp_path_factory.mktemp("web_process")
    with fresh_database(data_dir) as url:
        live = ModuleDumpingServer(data_dir, url).start()
        try:
            yield live
        finally:
            live.stop()


def served_routes() -> set[Route]:
    """Every route the web app serves (API, pages, dashboard, the viewer's relay and
    websockets), read from the app itself, less building a report."""
    app = create_app(Settings(data_dir=Path(tempfile.mkdtemp(prefix="ideeprl-routes-"))))
    found: set[Route] = set()

    def walk(routes: list[Any], prefix: str) -> None:
        for route in routes:
            if isinstance(route, APIWebSocketRoute):
                found.add(("WS", prefix + route.path))
            elif isinstance(route, APIRoute | StarletteRoute):
                found.update((m, prefix + route.path) for m in route.methods or () if m != "HEAD")
            elif hasattr(route, "include_context"):  # an included router
                included = route.include_context
                walk(included.included_router.routes, prefix + included.prefix)

    walk(app.routes, "")
    return {(method, path) for method, path in found if REPORT not in path}


class Requests:
    """Requests routes by their templates and notes each one requested. Each must be
    answered by its handler: never a 5xx, and never the 422 FastAPI gives a request
    missing a field, which stops before the handler and so would prove nothing."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.values: dict[str, str] = {}
        self.done: set[Route] = set()
        self.researcher = httpx.Client(base_url=url, timeout=120, headers={"X-API-Key": API_KEY})
        self.browser = httpx.Client(base_url=url, timeout=120, headers=HEADERS)

    def __call__(
        self,
        method: str,
        template: str,
        client: httpx.Client | None = None,
        values: dict[str, Any] | None = None,
        **kw: Any,
    ) -> httpx.Response:
        if client is None:
            client = self.browser if template.startswith("/dashboard") else self.researcher
        response = client.request(
            method, template.format(**{**self.values, **(values or {})}), **kw
        )
        assert response.status_code < 500, (method, template, response.text)
        assert '"type":"missing"' not in response.text, (method, template, response.text)
        self.done.add((method, template))
        return response

    def participant(self, token: str) -> httpx.Client:
        return httpx.Client(
            base_url=self.url, timeout=120, headers={"Authorization": f"Bearer {token}"}
        )

    def socket(self, template: str) -> None:
        """Opens the websocket, as the 3-D view does, and reads viser's first message
        through the relay."""
        url = self.url.replace("http://", "ws://") + template.format(**self.values)
        cookies = "; ".join(f"{k}={v}" for k, v in self.browser.cookies.items())
        with connect(
            url,
            subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],
            additional_headers={"Cookie": cookies} if cookies else None,
            open_timeout=30,
            close_timeout=5,
        ) as socket:
            assert socket.recv(timeout=30)
        self.done.add(("WS", template))

    def close(self) -> None:
        self.researcher.close()
        self.browser.close()


ONLINE = {
    "conditions": {
        "only": {
            "run": {
                "method": "human",
                "config": {
                    "pretraining_steps": 20,
                    "advice_budget": 5,
                    "batch_size": 8,
                    "memory_size": 300,
                },
                "motion": "fast",
            }
        }
    },
    "capacity": 5,
    "pool": 0,
    "panel": {"kind": "prolific"},
}
CHECK = {"answers": {"blue_cube": "left", "red_disk": "right", "drop_at_centre": "keep"}}


def _sessions(ask: Requests) -> None:
    """A study with a finished tiny oracle session (episodes, advice) and a running human
    session whose participant consents, starts and advises: the values the routes' path
    parameters take."""
    study = ask("POST", "/api/studies", json={"name": "web process"}).json()["id"]
    ask.values["study_id"] = str(study)
    body = rest_body(
        method="oracle",
        seed=5,
        config={"pretraining_steps": 12, "batch_size": 8, "memory_size": 500},
        episodes=1,
        max_episode_steps=10,
        advice_budget=4,
        motion="fast",
    )
    oracle = ask("POST", "/api/studies/{study_id}/sessions", json=body).json()["id"]
    ask.values["session_id"] = str(oracle)
    assert ask("POST", "/api/sessions/{session_id}/start").status_code == 200
    human = ask(
        "POST", "/api/studies/{study_id}/sessions", json=session_body("human", advice_budget=2)
    ).json()
    ask.values["token"] = human["participant_token"]
    wait_for_status(ask.researcher, oracle, {"finished"})
    started = ask("POST", "/api/sessions/{session_id}/start", values={"session_id": human["id"]})
    assert started.status_code == 200, started.text
    with ask.participant(human["participant_token"]) as person:
        version = person.get("/api/participant/consent").json()["texts_version"]
        agreed = {"agree": True, "texts_version": version}
        assert ask("POST", "/api/participant/consent", person, json=agreed).status_code == 200
        assert ask("POST", "/api/participant/start", person).status_code == 200
        ask("POST", "/api/participant/check", person, json=CHECK)  # a lab study: 409
        ask("POST", "/api/participant/questionnaire", person, json={"answers": {}})  # 409
        waiting = SimulatedParticipant(ask.url, human["participant_token"])
        wanted = waiting.next_request()
        waiting.close()
        assert wanted["advice_wanted"], wanted
        advice = {"advice_index": wanted["advice_index"], "action": 0}
        assert ask("POST", "/api/participant/advice", person, json=advice).status_code == 200
        rating = {"advice_index": wanted["advice_index"], "rating": "good"}
        assert ask("POST", "/api/participant/rating", person, json=rating).status_code == 409
    ask.socket("/viewer/p/{token}")
    ask.socket("/viewer/p/{token}/")
    ask.values |= {"human_id": str(human["id"]), "advice_index": "0", "fitted_id": "1"}
    ask.values |= {"step": "1", "index": "0", "stage": "pretrain", "episode": "1"}


def _online_study(ask: Requests) -> None:
    """An online study: its link joined with a panel id and through its page, one
    participant's consent form and check, a preview, and a panel id deleted."""
    made = ask("POST", "/api/studies", json={"name": "online", "design": ONLINE})
    assert made.status_code == 201, made.text
    online = made.json()
    at = {"study_id": online["id"], "key": online["join_url"].rsplit("/", 1)[1]}
    ask.values["key"] = at["key"]
    changed = ask("PATCH", "/api/studies/{study_id}", values=at, json={"description": "routes"})
    assert changed.status_code == 200, changed.text
    query = {"PROLIFIC_PID": "P-web", "STUDY_ID": "s", "SESSION_ID": "x"}
    joined = ask("GET", "/join/{key}", ask.browser, params=query)
    assert joined.status_code == 303, joined.text
    token = joined.headers["location"].removeprefix("/p/")
    page = ask("POST", "/join/{key}", ask.browser, params={**query, "PROLIFIC_PID": "P-page"})
    assert page.status_code == 303, page.text
    form = {"decision": "agree"}
    ask("POST", "/p/{token}/consent", ask.browser, values={"token": token}, data=form)
    with ask.participant(token) as person:
        assert ask("POST", "/api/participant/check", person, json=CHECK).status_code == 200
    assert ask("POST", "/api/studies/{study_id}/preview", values=at).status_code == 201
    assert ask("DELETE", "/api/studies/{study_id}/preview", values=at).status_code == 204
    person_at = {**at, "panel_id": "P-web"}
    gone = ask("DELETE", "/api/studies/{study_id}/panel/{panel_id}", values=person_at)
    assert gone.status_code == 204, gone.text


def _dashboard(ask: Requests) -> None:
    """The dashboard's own routes, logged in: a study, a participant, a design, a preview,
    a session's commands, an episode opened for playback and its 3-D view."""
    assert ask("POST", "/dashboard/login", data={"key": API_KEY}).status_code == 303
    new = ask("POST", "/dashboard/api/studies", json={"name": "from the dashboard"}).json()
    at = {"study_id": new["id"]}
    for method, template, kw in (
        ("POST", "/dashboard/api/studies/{study_id}/participants", {"json": {}}),
        ("POST", "/dashboard/api/studies/{study_id}/design", {"json": {"design": ONLINE}}),
        ("POST", "/dashboard/api/studies/{study_id}/preview", {}),
        ("DELETE", "/dashboard/api/studies/{study_id}/preview", {}),
    ):
        got = ask(method, template, values=at, **kw)
        assert got.status_code < 300, (template, got.text)
    for command in ("pause", "resume"):
        human = {"session_id": ask.values["human_id"], "command": command}
        got = ask("POST", "/dashboard/api/sessions/{session_id}/{command}", values=human)
        assert got.status_code == 200, got.text
    opened = ask("POST", "/dashboard/api/sessions/{session_id}/episodes/{stage}/{episode}/playback")
    assert opened.status_code == 201, opened.text
    ask.values["playback_id"] = opened.json()["id"]
    ask.values["dashboard_study"] = str(new["id"])


def _ending(ask: Requests) -> None:
    """What ends things, last: the playback shown and closed, the human session paused,
    resumed, stopped and deleted, a study deleted, the researcher logged out."""
    for _ in range(60):
        shown = ask("POST", "/dashboard/api/playbacks/{playback_id}/show", json={"index": 0})
        if shown.status_code == 200:
            break
        time.sleep(1)  # 409 until the episode's rerun is ready
    assert shown.status_code == 200, shown.text
    ask.socket("/viewer/playback/{playback_id}")
    ask.socket("/viewer/playback/{playback_id}/")
    assert ask("DELETE", "/dashboard/api/playbacks/{playback_id}").status_code == 204
    human = {"session_id": ask.values["human_id"]}
    for command in ("pause", "resume", "stop"):
        got = ask("POST", "/api/sessions/{session_id}/" + command, values=human)
        assert got.status_code == 200, got.text
    wait_for_status(ask.researcher, int(human["session_id"]), {"stopped", "finished"})
    assert ask("DELETE", "/api/sessions/{session_id}", values=human).status_code == 204
    new = {"study_id": ask.values["dashboard_study"]}
    dropped = ask("DELETE", "/api/studies/{study_id}", values=new)
    assert dropped.status_code == 204, dropped.text
    assert ask("POST", "/dashboard/logout").status_code == 303


@pytest.mark.slow
def test_importing_the_web_app_loads_none_of_them() -> None:
    """The quick check (`make test-fast`): what `server.main` imports at the top."""
    code = f"import sys, server.main; print([m for m in {HEAVY!r} if m in sys.modules])"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


@pytest.mark.slow  # a tiny session trains, a person advises, an episode reruns
def test_serving_every_route_loads_no_simulation_torch_or_plotting(
    dumping: ModuleDumpingServer,
) -> None:
    ask = Requests(dumping.url)
    routes = served_routes()
    assert len(routes) > 70, sorted(routes)
    try:
        _sessions(ask)
        _online_study(ask)
        _dashboard(ask)
        bearer = {"Authorization": f"Bearer {ask.values['token']}"}
        for method, template in sorted(routes - ask.done):
            if method == "GET":
                headers = bearer if template.startswith("/api/participant") else {}
                ask("GET", template, headers=headers)
        _ending(ask)
    finally:
        ask.close()
    assert not routes - ask.done, f"never requested: {sorted(routes - ask.done)}"
    dumping.stop()
    held = set(dumping.modules.read_text().split())
    assert "server.main" in held, "the dump is the web process's"
    loaded = sorted(name for name in HEAVY if name in held)
    assert not loaded, f"the web process loaded {loaded}"
