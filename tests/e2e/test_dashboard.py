"""The researchers' dashboard in a real browser: log in, watch sessions and their live
learning curves, hand out a participant link, start/pause/resume/stop, export."""

from __future__ import annotations

import io
import re
import time
import zipfile

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import VIEWPORT, Live, save_screenshot
from tests.server.live import API_KEY

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def _status(live: Live, session_id: int) -> str:
    with live.api() as api:
        return api.get(f"/api/sessions/{session_id}").json()["status"]


def _wait_status(live: Live, session_id: int, wanted: str, timeout: float = 180) -> None:
    deadline = time.monotonic() + timeout
    while _status(live, session_id) != wanted:
        assert time.monotonic() < deadline, f"session {session_id} never became {wanted}"
        time.sleep(0.3)


def test_a_researcher_runs_a_study_from_the_dashboard(live: Live, browser) -> None:
    with live.api() as api:
        study = api.post(
            "/api/studies",
            json={"name": "Pilot study", "description": "Oracle advisors before the people come."},
        ).json()
        oracle = []
        for seed, error in ((1, 0.0), (2, 0.3)):
            body = {
                "method": "oracle",
                "seed": seed,
                "oracle_error_rate": error,
                "config": {"pretraining_steps": 40, "batch_size": 16, "memory_size": 2000},
                "episodes": 10,
                "max_episode_steps": 30,
                "advice_budget": 20,
                "label": f"oracle, {int(error * 100)} % wrong",
            }
            oracle.append(api.post(f"/api/studies/{study['id']}/sessions", json=body).json())

    context = browser.new_context(viewport=VIEWPORT, accept_downloads=True)
    page = context.new_page()
    page.goto(f"{live.url}/dashboard")
    expect(page).to_have_url(re.compile(r"/dashboard/login$"))
    page.fill("#key", "not the key")
    page.click("button[type=submit]")
    expect(page.locator(".error-text")).to_contain_text("not the researcher key")
    page.fill("#key", API_KEY)
    page.click("button[type=submit]")
    expect(page).to_have_url(re.compile(r"/dashboard$"))
    assert API_KEY not in page.url
    cookie = next(c for c in context.cookies() if c["name"] == "ideeprl_dashboard")
    assert cookie["httpOnly"] and API_KEY not in cookie["value"]
    assert "ideeprl_dashboard" not in page.evaluate("document.cookie")

    section = page.locator(f"section.study[data-study='{study['id']}']")
    expect(section.locator(".study-name")).to_have_text("Pilot study")
    for session in oracle:
        row = section.locator(f"tr[data-session='{session['id']}']")
        expect(row.locator(".badge")).to_have_text("created")
        row.locator("button.start").click()
    for session in oracle:
        row = section.locator(f"tr[data-session='{session['id']}']")
        expect(row.locator(".badge")).to_have_text("finished", timeout=240_000)
    expect(section.locator("svg path.series")).to_have_count(2, timeout=30_000)

    section.locator(".new-participant input").fill("P01")
    section.locator(".new-participant button").click()
    human = section.locator("tr", has_text="P01")
    expect(human.locator("a.link")).to_have_attribute("href", re.compile(r"/p/[\w-]{20,}$"))
    human_id = int(human.get_attribute("data-session"))
    for command, status in (("start", "running"), ("pause", "paused"), ("resume", "running")):
        human.locator(f"button.{command}").click()
        expect(human.locator(".badge")).to_have_text(status, timeout=180_000)
        assert _status(live, human_id) == status
    save_screenshot(page, "dashboard", full_page=True)
    human.locator("button.stop").click()
    expect(human.locator(".badge")).to_have_text("stopped", timeout=180_000)

    with page.expect_download() as download:
        section.locator("a.export").click()
    archive = zipfile.ZipFile(io.BytesIO(download.value.path().read_bytes()))
    assert {"sessions.csv", "episodes.csv", "steps.csv", "advice.csv"} <= set(archive.namelist())
    sessions_csv = archive.read("sessions.csv").decode()
    assert sessions_csv.count("\n") >= 4  # header and three sessions
    context.close()
