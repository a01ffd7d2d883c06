"""The first turn as a new participant meets it, in Chromium through nginx: until the 3-D
view has drawn its first frame the page says the view is loading (the turn waits for it a
moment, never long), and a new turn clears the line saying the last choice was sent."""

from __future__ import annotations

import re
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import VIEWPORT, Live
from tests.e2e.scene import wait_for_scene

pytestmark = [pytest.mark.browser, pytest.mark.slow]
VIEWER = re.compile(r".*/viewer/.*")


def test_the_page_says_the_view_is_loading_until_its_first_frame(live: Live, browser: Any) -> None:
    session = live.human_session("first turn", advice_budget=3)
    live.begin(session)
    context = browser.new_context(viewport=VIEWPORT)
    context.route(VIEWER, lambda route: route.abort())  # a view that does not come
    page = context.new_page()
    page.goto(session["participant_url"])
    expect(page).to_have_url(re.compile(r"/advise$"))
    loading = page.locator("#scene-loading")
    expect(loading).to_be_visible()
    expect(loading).to_contain_text("loading")
    grab = page.locator("button.action[data-action='0']")
    expect(grab).to_be_enabled(timeout=180_000)  # the turn does not wait for it for ever
    expect(loading).to_be_visible()

    context.unroute(VIEWER)
    page.evaluate(
        """() => { const scene = document.getElementById("scene");
                   const url = window.sceneUrl(scene);
                   scene.src = "about:blank";
                   setTimeout(() => (scene.src = url), 100); }"""
    )
    wait_for_scene(live, session["id"])
    expect(loading).to_be_hidden(timeout=60_000)
    context.close()
    with live.api() as api:
        api.post(f"/api/sessions/{session['id']}/stop")


def test_a_new_turn_clears_the_line_saying_the_last_choice_was_sent(
    live: Live, browser: Any
) -> None:
    session = live.human_session("first turn", advice_budget=3)
    live.begin(session)
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.goto(session["participant_url"])
    grab = page.locator("button.action[data-action='0']")
    expect(grab).to_be_enabled(timeout=180_000)
    grab.click()
    feedback = page.locator("#feedback")
    expect(feedback).to_have_text(re.compile("Sent"))
    expect(page.locator("#advice-left")).to_have_text("2", timeout=60_000)
    expect(grab).to_be_enabled(timeout=120_000)
    expect(feedback).to_have_text("")
    context.close()
    with live.api() as api:
        api.post(f"/api/sessions/{session['id']}/stop")
