"""A lab participant's visit to a task other than the sorting robot's (the grid world), in
a real browser through nginx: its own buttons and keys with its words, its frames in place
of the 3-D view, every advice the correct move (by click and by key), the thank-you page;
the database holds exactly that advice, and an action the task does not have is refused."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import Advice
from tests.e2e.conftest import VIEWPORT, Live, save_screenshot

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 12
WORDS = ["Up", "Right", "Down", "Left"]
KEYS = ["ArrowUp", "ArrowRight", "ArrowDown", "ArrowLeft"]


def correct_action(live: Live, session_id: int) -> int:
    request = live.app.state.manager.handles[session_id].live.request
    assert request is not None, "the agent waits for advice"
    return int(request.info["correct_action"])


def test_a_grid_world_participant_advises_with_the_tasks_buttons_and_frames(
    live: Live, browser
) -> None:
    session = live.human_session(
        "gridworld-lab",
        task="gridworld",
        motion=None,
        seed=4,
        advice_budget=BUDGET,
        config={"pretraining_steps": BUDGET + 20, "batch_size": 16, "memory_size": 500},
        episodes=2,
        max_episode_steps=30,
    )
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.goto(session["participant_url"])
    page.click("#agree")
    for step in (1, 2, 3):
        expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
        page.click("#start" if step == 3 else "#next")

    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    buttons = page.locator("button.action")
    expect(buttons).to_have_count(4)
    for i, word in enumerate(WORDS):
        expect(buttons.nth(i).locator(".action-name")).to_have_text(word)
    assert page.locator("#scene").count() == 0, "no 3-D view for a task without one"
    expect(buttons.first).to_be_enabled(timeout=180_000)
    frame = page.locator("#frame")
    expect(frame).to_be_visible()
    assert frame.evaluate("i => [i.naturalWidth, i.naturalHeight]") == [256, 256]
    save_screenshot(page, "gridworld-advice")

    given: list[int] = []
    for index in range(BUDGET):
        expect(page.locator("#advice-left")).to_have_text(str(BUDGET - index), timeout=60_000)
        expect(buttons.first).to_be_enabled(timeout=60_000)
        action = correct_action(live, session["id"])
        if index % 3 == 2:
            page.keyboard.press(KEYS[action])
        else:
            buttons.nth(action).click()
        given.append(action)
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=30_000)
    context.close()

    with live.api(session["participant_token"]) as participant:
        refused = participant.post(
            "/api/participant/advice", json={"advice_index": BUDGET, "action": 4}
        )
    assert refused.status_code == 422 and "0 to 3" in refused.text

    with live.app.state.session_factory() as db:
        rows = db.scalars(
            select(Advice).where(Advice.session_id == session["id"]).order_by(Advice.advice_index)
        ).all()
    assert [r.action for r in rows] == given, "the stored advice is what was clicked"
    observation = np.asarray(Image.open(io.BytesIO(rows[0].observation_png)))
    assert observation.shape == (64, 64, 3)
