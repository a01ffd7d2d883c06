"""The researchers' dashboard in a real browser: log in, watch sessions and their live
learning curves, hand out a participant link, start/pause/resume/stop, export."""

from __future__ import annotations

import io
import re
import time
import zipfile

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import VIEWPORT, Live, dashboard_page, save_screenshot
from tests.server.live import API_KEY
from tests.server.scale import rest_body

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
            fields = {
                "method": "oracle",
                "seed": seed,
                "error_rate": error,
                "config": {"pretraining_steps": 40, "batch_size": 16, "memory_size": 2000},
                "episodes": 10,
                "max_episode_steps": 30,
                "advice_budget": 20,
                "label": f"oracle, {int(error * 100)} % wrong",
            }
            body = rest_body(**fields)
            oracle.append(api.post(f"/api/studies/{study['id']}/sessions", json=body).json())
        advice_only = ("error_rate", "advice_budget")
        baseline = {k: v for k, v in fields.items() if k not in advice_only}
        baseline.update(method="autonomous", seed=1, label="autonomous")
        made = api.post(f"/api/studies/{study['id']}/sessions", json=rest_body(**baseline))
        oracle.append(made.json())

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
    expect(section.locator("svg path.series")).to_have_count(3, timeout=30_000)

    # The paper's analysis at the press of a button, the same as the REST API's report.
    expect(section.locator(".report")).to_be_hidden()
    section.locator("button.build-report").click()
    report = section.locator(".report")
    expect(report).to_be_visible(timeout=120_000)
    with live.api() as api:
        built = api.get(f"/api/studies/{study['id']}/report").json()
    assert built["baseline"] == "autonomous" and sorted(built["sessions"]) == sorted(
        s["id"] for s in oracle
    )
    for method in built["methods"]:
        row = report.locator(f"tr[data-method='{method['method']}']")
        expect(row.locator("td").nth(1)).to_have_text(str(method["agents"]))
        expect(row.locator("td").nth(3)).to_have_text(f"{method['R_T']:.2f}")
    figures = report.locator(".report-figures img")
    pngs = [f for f in built["files"] if f["kind"] == "figure" and f["name"].endswith(".png")]
    expect(figures).to_have_count(len(pngs))
    figures.first.scroll_into_view_if_needed()
    page.wait_for_function(
        "() => [...document.querySelectorAll('.report-figures img')]"
        ".every(i => i.complete && i.naturalWidth > 0)",
        timeout=60_000,
    )
    save_screenshot(page, "dashboard-report", full_page=True)

    # Another baseline, chosen on the page: the oracle with no errors, against which the
    # others are measured (the report the REST API serves is the same one).
    baseline = section.locator("select.report-baseline")
    expect(baseline.locator("option")).to_have_count(4)  # auto, none, autonomous, oracle
    baseline.select_option("oracle")
    section.locator("button.build-report").click()
    expect(report.locator(".report-when")).to_contain_text("against oracle", timeout=120_000)
    with live.api() as api:
        assert api.get(f"/api/studies/{study['id']}/report").json()["baseline"] == "oracle"
    expect(report.locator("tr[data-method='autonomous'] td").nth(4)).not_to_have_text("—")

    # The pseudonym's pattern is the API's: the browser itself refuses a space (a pattern
    # that today's regular expressions reject is ignored by Chromium, which checks nothing).
    pseudonym = section.locator(".new-participant input")
    pseudonym.fill("P 01")
    assert pseudonym.evaluate("input => input.validity.patternMismatch") is True
    pseudonym.fill("P01")
    assert pseudonym.evaluate("input => input.validity.valid") is True
    section.locator(".new-participant button").click()
    human = section.locator("tr", has_text="P01")
    expect(human.locator("a.link")).to_have_attribute("href", re.compile(r"/p/[\w-]{20,}$"))
    human_id = int(human.get_attribute("data-session"))
    # Not before the participant's consent: the button is off, and the server refuses too.
    expect(human.locator("button.start")).to_be_disabled()
    expect(human).to_contain_text("not consented yet")
    token = human.locator("a.link").get_attribute("href").rsplit("/", 1)[1]
    with live.api(token) as participant:
        version = participant.get("/api/participant/consent").json()["texts_version"]
        participant.post("/api/participant/consent", json={"agree": True, "texts_version": version})
    expect(human.locator("button.start")).to_be_enabled(timeout=30_000)
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
    assert sessions_csv.count("\n") >= 5  # header and four sessions

    # Deleting a session removes its study's report (a participant's data lives on in it):
    # the page drops the report and its links rather than point at removed files.
    assert report.is_visible()
    with live.api() as api:
        assert api.delete(f"/api/sessions/{human_id}").status_code == 204
        gone = api.get(f"/api/studies/{study['id']}/report")
        assert gone.status_code == 404 and "removed when a session was deleted" in gone.text
    expect(report).to_be_hidden(timeout=15_000)
    expect(section.locator("button.build-report")).to_have_text("Build report")
    context.close()


def test_a_failed_build_leaves_the_button_as_it_was(live: Live, browser) -> None:
    """A build refused (nothing finished yet) shows why and keeps "Build report": there is
    nothing to rebuild; "Rebuild report" once one is built."""
    from study.db.engine import make_engine, make_session_factory
    from study.db.models import Episode, Status, StudySession

    with live.api() as api:
        study = api.post("/api/studies", json={"name": "Nothing finished yet"}).json()
        body = rest_body(method="autonomous", seed=1, episodes=2, max_episode_steps=30)
        ids = [api.post(f"/api/studies/{study['id']}/sessions", json=body).json()["id"]]
        body = rest_body(method="autonomous", seed=2, episodes=2, max_episode_steps=30)
        ids.append(api.post(f"/api/studies/{study['id']}/sessions", json=body).json()["id"])
    context, page = dashboard_page(browser, live)
    section = page.locator(f"section.study[data-study='{study['id']}']")
    button = section.locator("button.build-report")
    expect(button).to_have_text("Build report")
    button.click()
    expect(page.locator("#dashboard-error")).to_contain_text(
        f"study {study['id']} has no finished session. Not finished yet:", timeout=60_000
    )
    expect(button).to_be_enabled()
    expect(button).to_have_text("Build report")
    expect(section.locator(".report")).to_be_hidden()

    engine = make_engine(f"sqlite:///{live.data_dir / 'study.sqlite3'}")
    with make_session_factory(engine)() as db:
        for session_id in ids:
            session = db.get(StudySession, session_id)
            assert session is not None
            session.status = Status.finished.value
            for i in (1, 2):
                db.add(
                    Episode(
                        session_id=session_id, stage="train", episode=i,
                        collected_reward=float(i + session_id), steps=30, placed_correct=1,
                        misplaced=0, lost=0, success=False, terminated=False, truncated=True,
                        advised_steps=0, epsilon=0.5, first_global_step=(i - 1) * 30 + 1,
                        last_global_step=i * 30, wall_time=0.0,
                    )
                )  # fmt: skip
        db.commit()
    engine.dispose()
    button.click()
    expect(section.locator(".report")).to_be_visible(timeout=120_000)
    expect(button).to_have_text("Rebuild report")
    context.close()
