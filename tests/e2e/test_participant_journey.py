"""A participant's whole visit in a real browser, through nginx's one port as deployed:
the link, consent, the three induction pages, the live scene (no developer tools shown, the
held object said in words), all its advice (by click, by key, by key after dragging the
view), and the thank-you page reached by itself after the last advice, with the learning
curve; then the database holds exactly that advice."""

from __future__ import annotations

import io
import re
import time
from typing import Any

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import Advice
from tests.e2e.conftest import VIEWPORT, Live, save_screenshot
from tests.e2e.scene import canvas_pixels, colored, wait_for_scene

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 50
"""Half the paper's 100: every kind of turn comes several times, in half the CI time."""
RANDOM_STEPS = 20
"""Random pretraining steps before the first advice: with seed 3 the robot then holds the
red cube above the center table at the participant's first turn."""
PLAN = [0, 1, 3, 0, 2, 3]
"""A plausible participant: grab, carry right, drop; grab, carry left, drop; again."""
KEYS = {0: "g", 1: "ArrowRight", 2: "l", 3: "d"}
STATIONS = {
    "center": "above the center table",
    "left": "at the left table",
    "right": "at the right table",
}
DEVELOPER_TEXTS = ["Connected", "Inactive", "Scene tree", "Software WebGL rendering detected"]
THANKS_WITHIN_S = 10


def arm_sentence(info: dict[str, Any]) -> str:
    """What the page must say, from the server's ground truth of the request."""
    where = STATIONS[info["station"]]
    if not info["held"]:  # sim's info: "" or "shape/color", with held_shape and held_color
        return f"The robot is not holding anything; it is {where}."
    return f"The robot is holding the {info['held_color']} {info['held_shape']}, {where}."


def request_info(live: Live, session_id: int) -> dict[str, Any]:
    request = live.app.state.manager.handles[session_id].live.request
    assert request is not None, "the robot waits for advice"
    return request.info


def assert_no_developer_tools(page: Any) -> None:
    """viser's panel and notices are there (the test can fail) but hidden."""
    frame = page.frame_locator("#scene")
    expect(frame.locator("[data-testid='floating-panel']").first).to_be_attached(timeout=30_000)
    expect(frame.locator("[data-testid='floating-panel']").first).to_be_hidden()
    for text in DEVELOPER_TEXTS:
        for element in frame.get_by_text(text, exact=True).all():
            expect(element).to_be_hidden()
    notices = frame.locator(".mantine-Notification-root")
    for i in range(notices.count()):
        expect(notices.nth(i)).to_be_hidden()


def drag_the_view(page: Any) -> None:
    box = page.locator("#scene").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    for i in range(1, 9):
        page.mouse.move(x + 12 * i, y + 3 * i)
    page.mouse.up()


def test_a_participant_gives_all_advice_and_is_thanked(live: Live, browser) -> None:
    session = live.human_session(
        "journey",
        seed=3,
        advice_budget=BUDGET,
        config={"pretraining_steps": BUDGET + RANDOM_STEPS, "batch_size": 32, "memory_size": 2000},
        episodes=6,
        max_episode_steps=30,
    )
    assert session["participant_url"].startswith(live.url), "links point at the proxy"
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()

    page.goto(session["participant_url"])
    expect(page).to_have_url(re.compile(r"/consent$"))
    expect(page.locator("h1")).to_have_text("Information and consent")
    expect(page.locator(".prose")).to_contain_text(f"{BUDGET} times")
    save_screenshot(page, "consent", full_page=True)
    page.click("#agree")

    for step, title in enumerate(
        ["The robot and the experiment", "The task, and how to solve it", "Your screen"], 1
    ):
        expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
        expect(page.locator("h1")).to_have_text(title)
        save_screenshot(page, f"induction-{step}", full_page=True)
        if step == 2:
            expect(page.locator(".prose")).to_contain_text(
                "put the blue objects on the right table and the red objects on the left table"
            )
        page.click("#start" if step == 3 else "#next")

    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    buttons = {a: page.locator(f"button.action[data-action='{a}']") for a in range(4)}
    expect(buttons[0]).to_be_enabled(timeout=180_000)
    view = wait_for_scene(live, session["id"])
    first = request_info(live, session["id"])
    assert first["held"], "seed 3 holds an object at the first turn"
    expect(page.locator("#holding")).to_have_text(arm_sentence(first))
    expect(page.locator("#holding")).to_contain_text("The robot is holding the red cube")
    assert_no_developer_tools(page)
    pixels = canvas_pixels(page)
    assert pixels.std() > 12, "the 3-D view is blank"
    assert min(colored(pixels).values()) > 50, "the red and blue objects are drawn"
    expect(page.locator("#advice-left")).to_have_text(str(BUDGET))
    image = page.locator("#observation")
    expect(image).to_be_visible()
    assert image.evaluate("i => [i.naturalWidth, i.naturalHeight]") == [64, 64]
    assert image.evaluate("i => getComputedStyle(i).imageRendering") == "pixelated"
    save_screenshot(page, "advice")

    given: list[int] = []
    for index in range(BUDGET):
        action = PLAN[index % len(PLAN)]
        if index in (1, 4, 30):  # what the page says is what the robot holds
            expect(buttons[action]).to_be_enabled(timeout=60_000)
            expect(page.locator("#holding")).to_have_text(
                arm_sentence(request_info(live, session["id"]))
            )
        if index % 10 == 7:  # a key right after dragging the view
            expect(buttons[action]).to_be_enabled(timeout=60_000)
            drag_the_view(page)
            page.keyboard.press(KEYS[action])
            expect(page.locator("#advice-left")).to_have_text(str(BUDGET - index - 1))
        elif index % 10 == 9:  # some by keyboard
            expect(buttons[action]).to_be_enabled(timeout=60_000)
            page.keyboard.press(KEYS[action])
        else:
            buttons[action].click(timeout=60_000)
        given.append(action)
        if index % 25 == 0:
            expect(page.locator("#feedback")).to_contain_text("✓ Sent")
            expect(page.locator("#advice-left")).to_have_text(str(BUDGET - index - 1))
            expect(page.locator("#history li").first).to_contain_text(f"#{index + 1}")
        if index == 40:
            assert len(view.mirror.handles) >= 20 and view.player.updates > 40
    last_advice = time.monotonic()

    # By itself, without a reload, while the learner trains on (and the view replays it).
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=THANKS_WITHIN_S * 1000)
    waited = time.monotonic() - last_advice
    assert waited < THANKS_WITHIN_S, f"the thank-you page came {waited:.1f} s after the advice"
    navigation = page.evaluate("performance.getEntriesByType('navigation')[0].type")
    assert navigation == "navigate" and page.evaluate("document.referrer").endswith("/advise")
    expect(page.locator("h1")).to_have_text("Thank you for your help")
    expect(page.locator("#curve-caption")).to_contain_text("Each dot is one round")
    expect(page.locator("#curve circle.dot").nth(2)).to_be_visible(timeout=180_000)
    save_screenshot(page, "thank-you", full_page=True)
    context.close()

    with live.app.state.session_factory() as db:
        rows = db.scalars(
            select(Advice).where(Advice.session_id == session["id"]).order_by(Advice.advice_index)
        ).all()
    assert [r.advice_index for r in rows] == list(range(BUDGET))
    assert [r.action for r in rows] == given, "the stored advice is what was clicked"
    assert all(r.advisor == "human" and r.response_time_s > 0 for r in rows)
    for row in rows[:: BUDGET // 10]:
        observation = np.asarray(Image.open(io.BytesIO(row.observation_png)))
        assert observation.shape == (64, 64, 3) and observation.std() > 10
