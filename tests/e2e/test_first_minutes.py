"""A participant's first minutes (issue 21), in Chromium through nginx: the first turn comes
without the 3-D view replaying the robot's practice moves, and only the participant's own
advised moves are shown as motion; on a phone (390x844, and a tablet at one turn) the
scene, the status, the sentence, the choices left and the four buttons stay in view at every
turn, and the view's markers and the map beside the camera image show the arm's station; a
turn of the alternating strategy says how often the robot moved on its own since the last,
and the last choice's result shows before the page moves on."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from playwright.sync_api import expect

from sim.layout import Layout
from tests.e2e.conftest import Live, save_screenshot
from tests.e2e.scene import wait_for_scene, wait_idle

pytestmark = [pytest.mark.browser, pytest.mark.slow]
PRACTICE = 40
"""Random practice moves before the first turn (physics motion): the old view replayed those
it could keep up with as motion, and kept the buttons off meanwhile (this test took 33 s
with it, 13 s without)."""


@pytest.fixture(scope="module")
def paused(live: Live) -> Iterator[dict[str, Any]]:
    """A started human session, paused by the researcher before its practice began, so the
    participant's 3-D view is open for every practice move."""
    session = live.human_session(
        "first minutes",
        seed=3,
        advice_budget=3,
        config={"pretraining_steps": PRACTICE, "batch_size": 8, "memory_size": 500},
    )
    live.begin(session)
    with live.api() as api:
        assert api.post(f"/api/sessions/{session['id']}/pause").status_code == 200
    yield session
    with live.api() as api:
        api.post(f"/api/sessions/{session['id']}/stop")


def test_the_first_turn_does_not_wait_for_the_practice_to_be_replayed(
    live: Live, browser: Any, paused: dict[str, Any]
) -> None:
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    page.goto(paused["participant_url"])
    expect(page).to_have_url(re.compile(r"/advise$"))
    view = wait_for_scene(live, paused["id"])
    before = view.player.steps_received
    with live.api() as api:
        assert api.post(f"/api/sessions/{paused['id']}/resume").status_code == 200
    grab = page.locator("button.action[data-action='0']")
    expect(grab).to_be_enabled(timeout=180_000)
    practised = view.player.steps_received - before
    assert practised >= PRACTICE // 2, f"the view was open for the practice ({practised} moves)"
    assert view.player.steps_animated == 0, "no practice move was replayed as motion"
    assert live.app.state.viewer.playback_remaining_s(paused["id"]) == 0

    with live.api(paused["participant_token"]) as api:
        station = api.get("/api/participant/state").json()["station"]
    move = 1 if station == "left" else 2  # to a side table the arm is not at: a real move
    page.locator(f"button.action[data-action='{move}']").click()
    expect(page.locator("#advice-left")).to_have_text("2")
    expect(grab).to_be_enabled(timeout=60_000)
    wait_idle(live, paused["id"])
    assert view.player.steps_animated == 1, "the participant's own move was shown moving"
    context.close()


PHONE = {"width": 390, "height": 844}
TABLET = {"width": 820, "height": 1180}
SCENE_MIN = {390: 240, 820: 320}
"""The scene's stated minimum height at each width (px; web/static/site.css)."""
PHONE_PLAN = ("grab", "wrong", "right", "drop", "other", "grab", "wrong", "drop", "grab", "drop")
"""Grab, carry it to the wrong side and then the right one (by the study's colour rule),
drop it there, go empty-handed to the other side, grab, drop one on the wrong table (the
objects are laid out again, the arm back at the center): every station with and without
an object."""
MOVE = {"right": 1, "left": 2}


def phone_action(intent: str, info: dict[str, Any]) -> int:
    if intent in ("grab", "drop"):
        return 0 if intent == "grab" else 3
    side = "right" if info["held_color"] == "blue" else "left"  # the default rule, "color"
    if intent == "wrong" or intent == "other":
        current = side if intent == "wrong" else info["station"]
        side = "left" if current == "right" else "right"
    return MOVE[side]


IN_VIEW = [
    "#scene",
    "#status",
    "#holding",
    ".counter-block",
    *(f"button.action >> nth={i}" for i in range(4)),
]


def assert_all_in_view(page: Any) -> None:
    """The scene at its minimum height, the status, the sentence, the choices left and the
    four buttons inside the viewport without scrolling, nothing wider than it, buttons big
    enough to tap."""
    size = page.viewport_size
    width, height = size["width"], size["height"]
    assert page.evaluate("window.scrollY") == 0
    assert page.evaluate("document.documentElement.scrollWidth") <= width, "horizontal scroll"
    for selector in IN_VIEW:
        box = page.locator(selector).bounding_box()
        assert box is not None, f"{selector} is not shown"
        assert box["x"] >= 0 and box["x"] + box["width"] <= width + 0.5, (selector, box)
        assert box["y"] >= 0 and box["y"] + box["height"] <= height + 0.5, (selector, box)
        if selector.startswith("button"):
            assert box["height"] >= 44 and box["width"] >= 44, (selector, box)
    assert page.locator("#scene").bounding_box()["height"] >= SCENE_MIN[width]


def test_a_phone_visit_keeps_scene_sentence_budget_and_buttons_in_view(
    live: Live, browser: Any
) -> None:
    budget = 10
    session = live.human_session(
        "phone",
        seed=5,
        advice_budget=budget,
        motion="fast",
        config={"pretraining_steps": budget + 8, "batch_size": 8, "memory_size": 500},
    )
    context = browser.new_context(viewport=PHONE, has_touch=True, is_mobile=True)
    page = context.new_page()
    page.goto(session["participant_url"])
    page.locator("#agree").tap()
    for step in (1, 2, 3):
        expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
        assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]
        if step == 3:
            expect(page.locator(".prose")).to_contain_text("with the mouse or a finger")
            expect(page.locator(".preview-buttons kbd").first).to_be_hidden()
            # The viewport only: a full-page capture drops the touch emulation meanwhile.
            save_screenshot(page, "induction-3-phone")
        page.locator("#start" if step == 3 else "#next").tap()
    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    expect(page.locator(".scene-hint .for-touch")).to_be_visible()
    expect(page.locator("button.action kbd").first).to_be_hidden()
    seen = set()
    for index in range(budget):
        expect(page.locator("button.action").first).to_be_enabled(timeout=120_000)
        # a lit turn shows no choice made: the last one's green mark read as chosen already
        assert page.evaluate("document.querySelectorAll('button.action.chosen').length") == 0
        info = request_info(live, session["id"])
        action = phone_action(PHONE_PLAN[index], info)
        button = page.locator(f"button.action[data-action='{action}']")
        expect(button).to_be_enabled()
        station = info["station"]
        expect(page.locator("#station-map")).to_have_attribute("data-station", station)
        assert_spot_on(live, session["id"], station)
        assert_all_in_view(page)
        held = "holding" if info["held"] else "empty"
        seen.add((station, held))
        if os.environ.get("IDEEPRL_SCREENSHOTS_TO_DOCS") == "1":  # the README's pictures
            save_screenshot(page, f"station-{station}-{held}")
        if index == 0:
            save_screenshot(page, "advice-phone")
        if index == 4:
            page.set_viewport_size(TABLET)
            assert_all_in_view(page)
            page.wait_for_timeout(1500)  # viser redraws its canvas at the new size
            save_screenshot(page, "advice-tablet")
            page.set_viewport_size(PHONE)
            assert_all_in_view(page)
        button.tap()
        expect(page.locator("#advice-left")).to_have_text(str(budget - index - 1))
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=30_000)
    assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]
    context.close()
    assert seen == {(s, h) for s in ("center", "left", "right") for h in ("holding", "empty")}


def test_an_alternating_visit_says_the_robots_own_moves_and_shows_the_last_result(
    live: Live, browser: Any
) -> None:
    """One action in every 3 advised, on a phone: the second turn says that the robot
    moved twice by itself, in view; after the last choice the page shows what that choice
    earned before it goes on to the thanks."""
    session = live.human_session(
        "alternating phone", seed=5, advice_budget=2, strategy="alternating", interval=3
    )
    live.begin(session)
    context = browser.new_context(viewport=PHONE, has_touch=True, is_mobile=True)
    page = context.new_page()
    page.goto(session["participant_url"])
    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    grab = page.locator("button.action[data-action='0']")
    expect(grab).to_be_enabled(timeout=120_000)
    expect(page.locator("#own-moves")).to_be_hidden()
    grab.tap()
    expect(page.locator("#advice-left")).to_have_text("1")
    expect(grab).to_be_enabled(timeout=60_000)
    sentence = page.locator("#own-moves")
    expect(sentence).to_have_text("Since your last choice it moved 2 times on its own.")
    expect(page.locator("#holding")).to_contain_text("The robot is")
    assert_all_in_view(page)
    wait_for_scene(live, session["id"])
    wait_idle(live, session["id"])
    save_screenshot(page, "advice-phone-own-moves")

    station = request_info(live, session["id"])["station"]
    page.locator(f"button.action[data-action='{1 if station == 'left' else 2}']").tap()
    last = page.locator("#history li").first
    expect(last.locator(".history-index")).to_have_text("#2")
    expect(last.locator(".reward")).to_have_text(re.compile(r"^[+-]?\d"), timeout=10_000)
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=30_000)
    context.close()


def request_info(live: Live, session_id: int) -> dict[str, Any]:
    request = live.app.state.manager.handles[session_id].live.request
    assert request is not None, "the robot waits for advice"
    return request.info


def assert_spot_on(live: Live, session_id: int, station: str) -> None:
    """The 3-D view's plumb line hangs from the suction cup to a spot on the station's
    table (within its top), however the perspective makes it look."""
    view = wait_for_scene(live, session_id)
    wait_idle(live, session_id)
    cup = view.mirror.positions()["arm/suction_cup"]
    plumb = np.asarray(view.mirror.markers["plumb"].position)
    spot = np.asarray(view.mirror.markers["spot"].position)
    assert np.allclose(plumb[:2], cup[:2]) and np.allclose(spot[:2], cup[:2])
    table = getattr(Layout(), f"{station}_table")
    inside = np.abs(spot[:2] - np.asarray(table.center)) <= np.asarray(table.half_size)
    assert inside.all(), f"the spot {spot} is not on the {station} table"
