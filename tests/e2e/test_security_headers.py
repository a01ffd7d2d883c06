"""The pages work under their Content-Security-Policy: the advice page with its framed
3-D view (viser, on its own origin), and the dashboard with its inline plots, raise no
policy violation in the browser."""

from __future__ import annotations

import re
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import API_KEY, VIEWPORT, Live
from tests.e2e.scene import wait_for_scene

pytestmark = [pytest.mark.browser, pytest.mark.slow]
RECORD_VIOLATIONS = """
window.__violations = [];
document.addEventListener("securitypolicyviolation", (e) => {
  window.__violations.push(`${e.violatedDirective} ${e.blockedURI}`);
});
"""


def _violations(page: Any) -> list[str]:
    found: list[str] = []
    for frame in page.frames:
        try:
            found += frame.evaluate("() => window.__violations || []")
        except Exception:  # a frame navigating away
            continue
    return found


def test_the_advice_page_and_its_3d_view_run_under_the_policy(live: Live, browser: Any) -> None:
    session = live.human_session("csp")
    with live.api() as api:
        assert api.post(f"/api/sessions/{session['id']}/start").status_code == 200
    live.begin(session)  # consent and induction, so the link leads to the advice page
    context = browser.new_context(viewport=VIEWPORT)
    context.add_init_script(RECORD_VIOLATIONS)
    page = context.new_page()
    console: list[str] = []
    page.on("console", lambda m: console.append(m.text))
    try:
        response = page.goto(session["participant_url"])
        assert response is not None
        expect(page).to_have_url(re.compile(r"/advise$"))
        policy = page.evaluate(
            "async () => (await fetch(location.href)).headers.get('content-security-policy')"
        )
        assert "frame-src 'self'" in policy
        wait_for_scene(live, session["id"])
        expect(page.locator("button.action[data-action='0']")).to_be_enabled(timeout=180_000)
        expect(page.locator("#observation")).to_be_visible()
        assert _violations(page) == [], _violations(page)
        assert not [m for m in console if "Content Security Policy" in m], console
    finally:
        context.close()
        with live.api() as api:
            api.post(f"/api/sessions/{session['id']}/stop")


def test_the_dashboard_runs_under_the_policy(live: Live, browser: Any) -> None:
    live.human_session("csp dashboard")
    context = browser.new_context(viewport=VIEWPORT)
    context.add_init_script(RECORD_VIOLATIONS)
    page = context.new_page()
    console: list[str] = []
    page.on("console", lambda m: console.append(m.text))
    try:
        page.goto(f"{live.url}/dashboard")
        page.fill("#key", API_KEY)
        page.click("button[type=submit]")
        expect(page).to_have_url(re.compile(r"/dashboard$"))
        expect(page.locator("section.study").first).to_be_visible(timeout=60_000)
        expect(page.locator("tr[data-session]").first).to_be_visible()
        page.wait_for_timeout(1500)  # a few polls and redraws
        assert _violations(page) == [], _violations(page)
        assert not [m for m in console if "Content Security Policy" in m], console
    finally:
        context.close()
