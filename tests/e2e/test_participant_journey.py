"""A participant's whole visit in a real browser: the link, consent, the three induction
pages, the live scene, all 100 advice (by click and by key), the thank-you page with the
learning curve; then the database holds exactly that advice."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect
from sqlalchemy import select

from server.db.models import Advice
from tests.e2e.conftest import VIEWPORT, Live, save_screenshot
from tests.e2e.scene import canvas_pixels, colored, dismiss_notices, wait_for_scene

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 100
PLAN = [0, 1, 3, 0, 2, 3]
"""A plausible participant: grab, carry right, drop; grab, carry left, drop; again."""
KEYS = {0: "g", 1: "ArrowRight", 2: "l", 3: "d"}


def test_a_participant_gives_all_advice_and_is_thanked(live: Live, browser) -> None:
    session = live.human_session(
        "journey",
        seed=5,
        advice_budget=BUDGET,
        config={"pretraining_steps": BUDGET, "batch_size": 32, "memory_size": 2000},
        episodes=6,
        max_episode_steps=30,
    )
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
    dismiss_notices(page)
    pixels = canvas_pixels(page)
    assert pixels.std() > 12, "the 3-D view is blank"
    assert min(colored(pixels).values()) > 50, "the red and blue objects are drawn"
    expect(page.locator("#advice-left")).to_have_text(str(BUDGET))
    image = page.locator("#observation")
    expect(image).to_be_visible()
    assert image.evaluate("i => [i.naturalWidth, i.naturalHeight]") == [64, 64]
    assert image.evaluate("i => getComputedStyle(i).imageRendering") == "pixelated"
    dismiss_notices(page, wait_s=1)
    save_screenshot(page, "advice")

    given: list[int] = []
    for index in range(BUDGET):
        action = PLAN[index % len(PLAN)]
        if index % 10 == 9:  # some by keyboard
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
    expect(page.locator("#advice-left")).to_have_text("0", timeout=30_000)

    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=60_000)
    expect(page.locator("h1")).to_have_text("Thank you for your help")
    expect(page.locator("#curve circle.dot").nth(2)).to_be_attached(timeout=180_000)
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
