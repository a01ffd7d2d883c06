"""In a real browser: a human session started early by the researcher still shows its
participant the consent page first; a decline and a consent are recorded with the texts
shown, and the export carries them. And the decision time the page measures is the time
the participant took after the buttons became active, not the server's time, which also
counts the 3-D replay."""

from __future__ import annotations

import csv
import io
import re
import zipfile

import pytest
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import Advice, StudySession
from tests.e2e.conftest import VIEWPORT, Live

pytestmark = [pytest.mark.browser, pytest.mark.slow]

WAIT_S = 1.5
"""How long the test's participant thinks before each click, after the buttons come on."""

WATCH_BUTTONS = """
// From the page's first moment: note when the action buttons become active.
window.__activeAt = null;
new MutationObserver((changes) => {
  for (const change of changes) {
    const on = change.target.classList?.contains("action") && !change.target.disabled;
    if (on) window.__activeAt = performance.now();
  }
}).observe(document, { subtree: true, attributes: true, attributeFilter: ["disabled"] });
"""

CLICK_AFTER_ACTIVE = """async ([selector, waitMs]) => {
  // Once the buttons are active, click a known time after they became so: the page's own
  // clock must find that time.
  const button = document.querySelector(selector);
  while (button.disabled || window.__activeAt === null) {
    await new Promise((resolve) => setTimeout(resolve, 5));
  }
  const activeAt = window.__activeAt;
  for (let left = waitMs; left > 0; left = waitMs - (performance.now() - activeAt)) {
    await new Promise((resolve) => setTimeout(resolve, left));
  }
  const waited = performance.now() - activeAt;
  window.__activeAt = null;
  button.click();
  return waited / 1000;
}"""


def _csv(archive: zipfile.ZipFile, name: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(archive.read(name).decode())))


def test_a_session_started_through_the_api_still_shows_consent_first(live: Live, browser) -> None:
    texts = {"consent": "## Consent, version one\nYou will advise {advice_budget} times."}
    with live.api() as api:
        study = api.post("/api/studies", json={"name": "server consent", "texts": texts}).json()
    session = live.human_session("server consent", advice_budget=4)
    with live.api() as api:
        started = api.post(f"/api/sessions/{session['id']}/start")
        assert started.status_code == 200 and started.json()["status"] == "running"

    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.goto(session["participant_url"])
    expect(page).to_have_url(re.compile(r"/consent$"))
    expect(page.locator(".prose")).to_contain_text("You will advise 4 times.")
    for path in ("advise", "induction/2"):  # no way around it
        page.goto(f"{live.url}/p/{session['participant_token']}/{path}")
        expect(page).to_have_url(re.compile(r"/consent$"))
    page.click("#decline")
    expect(page).to_have_url(re.compile(r"/declined$"))
    with live.app.state.session_factory() as db:
        row = db.get(StudySession, session["id"])
        assert row is not None and row.declined_at is not None and row.consented_at is None
        declined_version = row.texts_version_id

    page.goto(session["participant_url"])  # changed their mind
    expect(page).to_have_url(re.compile(r"/consent$"))
    page.click("#agree")
    expect(page).to_have_url(re.compile(r"/induction/1$"))
    page.click("#next")
    page.click("#next")
    expect(page).to_have_url(re.compile(r"/induction/3$"))
    page.click("#start")
    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    expect(page.locator("button.action[data-action='0']")).to_be_enabled(timeout=180_000)
    page.locator("button.action[data-action='0']").click()
    expect(page.locator("#advice-left")).to_have_text("3", timeout=60_000)
    context.close()

    with live.app.state.session_factory() as db:
        row = db.get(StudySession, session["id"])
        assert row is not None and row.consented_at and row.induction_done_at
        assert row.declined_at < row.consented_at < row.induction_done_at
        assert row.texts_version_id == declined_version, "the same texts, one version"
        first = db.scalar(select(Advice).where(Advice.session_id == session["id"]))
        assert first is not None and first.answered_at > row.induction_done_at
    with live.api() as api:
        api.post(f"/api/sessions/{session['id']}/stop")
        archive = zipfile.ZipFile(io.BytesIO(api.get(f"/api/studies/{study['id']}/export").content))
    sessions = {int(r["session_id"]): r for r in _csv(archive, "sessions.csv")}
    exported = sessions[session["id"]]
    assert exported["consented_at"] and exported["declined_at"]
    versions = {r["texts_version"]: r for r in _csv(archive, "texts_versions.csv")}
    seen = versions[exported["texts_version"]]
    assert seen["consent"] == "## Consent, version one\nYou will advise 4 times."


def test_the_page_measures_the_participants_decision_time(live: Live, browser) -> None:
    session = live.human_session("decision time", advice_budget=3)
    live.begin(session)
    context = browser.new_context(viewport=VIEWPORT)
    context.add_init_script(WATCH_BUTTONS)
    page = context.new_page()
    # Not waiting for the 3-D view to load: the clicks must be timed from the first turn.
    page.goto(session["participant_url"], wait_until="domcontentloaded")
    expect(page).to_have_url(re.compile(r"/advise$"))
    waited = []
    for index in range(3):
        selector = f"button.action[data-action='{index % 4}']"
        waited.append(page.evaluate(CLICK_AFTER_ACTIVE, [selector, WAIT_S * 1000]))
        expect(page.locator("#advice-left")).to_have_text(str(2 - index), timeout=60_000)
    context.close()
    with live.app.state.session_factory() as db:
        rows = db.scalars(
            select(Advice).where(Advice.session_id == session["id"]).order_by(Advice.advice_index)
        ).all()
    assert len(rows) == 3
    for row, known in zip(rows, waited, strict=True):
        assert WAIT_S <= known < WAIT_S + 0.5, f"the test's participant waited {waited}"
        assert row.decision_time_s is not None
        assert abs(row.decision_time_s - known) < 0.2, (row.decision_time_s, known)
        # The server's clock starts when the page reads the request, before the replay of
        # the last move; the participant's decision starts when the buttons come on.
        assert row.response_time_s > row.decision_time_s, (row.response_time_s, row.decision_time_s)
    with live.api() as api:
        api.post(f"/api/sessions/{session['id']}/stop")
