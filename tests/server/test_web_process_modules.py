"""The web process stays light: sessions train, episodes rerun and reports render in
processes of their own, so serving every page and route (all but building a report) never
loads the simulation, the learner's torch or the analysis' plotting and statistics.

The server runs as deployed (`ideeprl serve` on loopback), wrapped so that at its exit it
writes the names in its `sys.modules` to a file: the test reads the process from outside.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.routing import APIRoute

from server.routes import dashboard, pages, playback
from server.viewer import proxy
from tests.server.live import API_KEY, LiveServer, fresh_database
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
"""Building a report renders figures in the web process: the one route left out."""
PAGE_ROUTERS = (pages.router, dashboard.router, playback.router, proxy.router)
"""The routes outside the OpenAPI document (pages, the dashboard, the viewer)."""
HEADERS = {"X-Requested-With": "test"}


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


def _get_routes(document: dict[str, Any]) -> list[str]:
    """Every GET route's path template: the API's from its OpenAPI document, the pages'
    from their routers."""
    api = [path for path, operations in document["paths"].items() if "get" in operations]
    page = [
        route.path
        for router in PAGE_ROUTERS
        for route in router.routes
        if isinstance(route, APIRoute) and "GET" in route.methods
    ]
    return [path for path in (*api, *page) if REPORT not in path]


def _study(api: httpx.Client) -> dict[str, str]:
    """A study with a finished tiny oracle session (episodes, advice) and a human session
    (a participant's token): the values the routes' path parameters take."""
    study = api.post("/api/studies", json={"name": "web process"}).json()["id"]
    body = rest_body(
        method="oracle",
        seed=5,
        config={"pretraining_steps": 12, "batch_size": 8, "memory_size": 500},
        episodes=1,
        max_episode_steps=10,
        advice_budget=4,
        motion="fast",
    )
    oracle = api.post(f"/api/studies/{study}/sessions", json=body).json()["id"]
    assert api.post(f"/api/sessions/{oracle}/start").status_code == 200
    human = api.post(
        f"/api/studies/{study}/sessions", json=session_body("human", advice_budget=2)
    ).json()
    wait_for_status(api, oracle, {"finished"})
    return {
        "study_id": str(study),
        "session_id": str(oracle),
        "token": human["participant_token"],
        "advice_index": "0",
        "fitted_id": "1",
        "step": "1",
        "index": "0",
    }


def test_importing_the_web_app_loads_none_of_them() -> None:
    """The quick check (`make test-fast`): what `server.main` imports at the top."""
    code = f"import sys, server.main; print([m for m in {HEAVY!r} if m in sys.modules])"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


@pytest.mark.slow  # a tiny session trains and an episode reruns first
def test_serving_every_route_loads_no_simulation_torch_or_plotting(
    dumping: ModuleDumpingServer,
) -> None:
    with (
        dumping.client() as api,
        httpx.Client(base_url=dumping.url, timeout=120, headers=HEADERS) as browser,
    ):
        values = _study(api)
        assert browser.post("/dashboard/login", data={"key": API_KEY}).status_code == 303
        opened = browser.post(
            f"/dashboard/api/sessions/{values['session_id']}/episodes/pretrain/1/playback"
        )
        assert opened.status_code == 201, opened.text
        values["playback_id"] = opened.json()["id"]
        participant = {"Authorization": f"Bearer {values['token']}"}
        routes = _get_routes(api.get("/openapi.json").json())
        assert len(routes) > 30, routes
        for template in routes:
            path = template.format(**values)
            headers = participant if path.startswith("/api/participant") else {}
            response = browser.get(path, headers={"X-API-Key": API_KEY, **headers})
            assert response.status_code < 500, (path, response.text)
    dumping.stop()
    held = set(dumping.modules.read_text().split())
    assert "server.main" in held, "the dump is the web process's"
    loaded = sorted(name for name in HEAVY if name in held)
    assert not loaded, f"the web process loaded {loaded}"
