"""A lab participant's visit to the reach task, in a real browser through nginx, with its
live 3-D view: the task's six buttons with their words and keys, the iiwa and the red ball
drawn from PyBullet's own bodies, every advice the oracle's move (by click and by key), the
view's hand where the worker's PyBullet put it after each, the thank-you page; the database
holds exactly that advice."""

from __future__ import annotations

import io
import re
import time

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect
from sqlalchemy import select

from server.viewer import ClientView
from study.db.models import Advice
from tasks.reach.env import lattice_point
from tests.e2e.conftest import VIEWPORT, Live, save_screenshot
from tests.e2e.scene import views, wait_idle

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 8
WORDS = ["Move forward", "Move back", "Move left", "Move right", "Move up", "Move down"]
KEYS = ["ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "u", "d"]
BODIES = 10
"""The floor, the iiwa's eight links and the ball: PyBullet's visual shapes."""
HAND = "arm/lbr_iiwa_link_7"


def request_info(live: Live, session_id: int) -> dict:
    request = live.app.state.manager.handles[session_id].live.request
    assert request is not None, "the robot waits for advice"
    return dict(request.info)


def scene_view(live: Live, session_id: int, timeout: float = 120) -> ClientView:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = [v for v in views(live, session_id) if len(v.mirror.handles) == BODIES]
        if found:
            return found[0]
        time.sleep(0.1)
    raise AssertionError(f"no 3-D view of session {session_id} drew the reach scene")


def red_pixels(page) -> int:
    """Pixels of the 3-D view that look like the red ball."""
    png = page.locator("#scene").screenshot(timeout=120_000, animations="disabled")
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    return int(((r > 150) & (g < 90) & (b < 90)).sum())


def test_a_reach_participant_advises_with_the_live_3d_view(live: Live, browser) -> None:
    session = live.human_session(
        "reach-lab",
        task="reach",
        motion=None,
        seed=5,
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
    expect(buttons).to_have_count(6)
    for i, word in enumerate(WORDS):
        expect(buttons.nth(i).locator(".action-name")).to_have_text(word)
    expect(page.locator("#scene")).to_be_visible()
    source = page.locator("#scene").get_attribute("data-src") or ""
    assert "initialCameraPosition=-0.55,-1,1.05" in source, "the reach task's own camera"
    expect(buttons.first).to_be_enabled(timeout=180_000)
    view = scene_view(live, session["id"])
    assert {type(h).__name__ for h in view.mirror.handles.values()} == {
        "BoxHandle",
        "MeshHandle",
        "IcosphereHandle",
    }
    deadline = time.monotonic() + 60
    while red_pixels(page) < 30:  # the ball, drawn in the participant's browser
        assert time.monotonic() < deadline, "the red ball never showed in the 3-D view"
        time.sleep(1)
    save_screenshot(page, "reach-advice")

    given: list[int] = []
    for index in range(BUDGET):
        expect(page.locator("#advice-left")).to_have_text(str(BUDGET - index), timeout=60_000)
        expect(buttons.first).to_be_enabled(timeout=60_000)
        info = request_info(live, session["id"])
        wait_idle(live, session["id"])
        deadline = time.monotonic() + 10
        while np.linalg.norm(view.mirror.positions()[HAND] - lattice_point(info["hand"])) > 0.005:
            assert time.monotonic() < deadline, f"the view's hand is not PyBullet's ({index})"
            time.sleep(0.05)
        action = info["correct_action"]
        if action is None:  # the hand is at the ball: any move
            action = 0
        if index % 3 == 2:
            page.keyboard.press(KEYS[action])
        else:
            buttons.nth(action).click()
        given.append(action)
        if index == 3:
            save_screenshot(page, "reach-advice-moving")
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=30_000)
    context.close()

    with live.app.state.session_factory() as db:
        rows = db.scalars(
            select(Advice).where(Advice.session_id == session["id"]).order_by(Advice.advice_index)
        ).all()
    assert [r.action for r in rows] == given, "the stored advice is what was clicked"
