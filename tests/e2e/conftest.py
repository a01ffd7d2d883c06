"""A real study server (uvicorn on loopback, in this process so tests can look at its viser
scenes and hub) behind Debian's nginx, a real SQLite file, and Debian's Chromium driven by
Playwright."""

from __future__ import annotations

import os
import shutil
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn
from fastapi import FastAPI

from server.main import UVICORN_OPTIONS, create_app
from study.settings import Settings
from tests.e2e.proxy import config, nginx, nginx_available
from tests.server.live import API_KEY, free_port
from tests.server.scale import rest_body

ROOT = Path(__file__).absolute().parents[2]
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
]
ARTIFACTS = ROOT / "test-artifacts" / "screenshots"
DOCS_SCREENSHOTS = ROOT / "docs" / "screenshots"
PLAYBACK_SPEED = 5.0
"""The tests watch the robot at five times real speed (the pages wait for playback); the
test of smooth motion plays in real time."""
VIEWPORT = {"width": 1280, "height": 800}


@dataclass
class Live:
    """The running server: its app (hub, viewer, database) and its URL."""

    app: FastAPI
    url: str
    """Where the browser reaches it: nginx, in front of uvicorn."""
    data_dir: Path
    proxy_port: int
    server_port: int
    """uvicorn's own port, behind nginx."""

    def api(self, token: str | None = None) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {"X-API-Key": API_KEY}
        return httpx.Client(base_url=self.url, headers=headers, timeout=120)

    def human_session(self, study: str, **fields: Any) -> dict[str, Any]:
        """A human session at reduced scale in study `study` (made if new)."""
        body = rest_body(
            **{
                "method": "human",
                "seed": 3,
                "config": {"pretraining_steps": 12, "batch_size": 8, "memory_size": 500},
                "episodes": 2,
                "max_episode_steps": 25,
                "advice_budget": 6,
                "motion": "physics",
                **fields,
            }
        )
        with self.api() as api:
            studies = {s["name"]: s["id"] for s in api.get("/api/studies").json()}
            study_id = studies.get(study)
            if study_id is None:
                study_id = api.post("/api/studies", json={"name": study}).json()["id"]
            response = api.post(f"/api/studies/{study_id}/sessions", json=body)
            assert response.status_code == 201, response.text
            return response.json()

    def begin(self, session: dict[str, Any]) -> None:
        """What the participant does before advising, over their API: consent (to the
        texts as shown) and the induction's Start."""
        with self.api(session["participant_token"]) as participant:
            version = participant.get("/api/participant/consent").json()["texts_version"]
            agreed = participant.post(
                "/api/participant/consent", json={"agree": True, "texts_version": version}
            )
            assert agreed.status_code == 200, agreed.text
            started = participant.post("/api/participant/start")
            assert started.status_code == 200, started.text


@pytest.fixture(scope="package")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Live]:
    """The study server behind Debian's nginx, as deployed (docs/deploy.md): the browser
    reaches everything, the 3-D view's websocket included, through nginx's one port."""
    if not nginx_available():
        pytest.skip("nginx not found: install Debian's nginx (apt-get install nginx)")
    data_dir = tmp_path_factory.mktemp("e2e_data")
    port, proxy_port = free_port(), free_port()
    settings = Settings(
        database_url=f"sqlite:///{data_dir / 'study.sqlite3'}",
        api_key=API_KEY,
        data_dir=data_dir,
        host="127.0.0.1",
        port=port,
        public_url=f"http://localhost:{proxy_port}",
        # Pages on localhost, the 3-D view on 127.0.0.1, both through nginx's one port: two
        # sites, so Chromium draws the view in a process of its own. With software WebGL on
        # two busy cores, a view in the page's process starves the page (seconds per
        # request); a GPU makes this moot, and a deployment uses one origin (the default).
        viewer_public_url=f"http://127.0.0.1:{proxy_port}/viewer/",
        viser_port=0,
        viewer_playback_speed=PLAYBACK_SPEED,
        heartbeat_s=1,
        checkpoint_every_episodes=5,
    )
    app = create_app(settings)
    server = uvicorn.Server(
        uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", **UVICORN_OPTIONS)
    )
    thread = threading.Thread(target=server.run, name="e2e-uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "the server did not start"
        time.sleep(0.05)
    try:
        folder = data_dir / "nginx"
        conf = config(folder, proxy_port, port)
        with nginx(folder, conf, f"http://127.0.0.1:{proxy_port}/api/health"):
            yield Live(app, f"http://localhost:{proxy_port}", data_dir, proxy_port, port)
    finally:
        server.should_exit = True
        thread.join(120)


# Package scope: Playwright's sync API leaves an event loop running on the main thread
# while it lives, which would break asyncio.run() in the tests that come after these.
@pytest.fixture(scope="package")
def browser() -> Iterator[Any]:
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} not found: install Debian's chromium (apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    with sync_api.sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


def dashboard_page(browser: Any, live: Live) -> tuple[Any, Any]:
    """A new browser context logged in to the dashboard, and its page (close the context)."""
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.goto(f"{live.url}/dashboard/login")
    page.fill("#key", API_KEY)
    page.click("button[type=submit]")
    return context, page


def save_screenshot(page: Any, name: str, **options: Any) -> Path:
    """Save a page's screenshot as a test artifact (and under docs/screenshots when
    IDEEPRL_SCREENSHOTS_TO_DOCS=1, to refresh the README's pictures)."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), timeout=120_000, animations="disabled", **options)
    if os.environ.get("IDEEPRL_SCREENSHOTS_TO_DOCS") == "1":
        DOCS_SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, DOCS_SCREENSHOTS / path.name)
    return path
