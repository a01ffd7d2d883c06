"""Evaluative feedback in Chromium through nginx, beyond the shaping of the rated step: a
person's ratings train the learner's model of the rating (feedback_method rating_model),
whose state the finished run's checkpoint holds; and the rating page on a tablet, portrait
(820x1180) and landscape (1180x820), keeps the 3-D view, the sentence that asks and the two
buttons in view without scrolling, as the advice page does on a phone, with the scene drawn
in the view at each size."""

from __future__ import annotations

import re
import time
from typing import Any

import pytest
from playwright.sync_api import expect
from sqlalchemy import select

from learner.checkpoint import read_checkpoint
from study.db.models import Feedback, StudySession
from tests.e2e.conftest import VIEWPORT, Live, save_screenshot
from tests.e2e.scene import canvas_pixels, wait_for_scene

pytestmark = [pytest.mark.browser, pytest.mark.slow]

PORTRAIT = {"width": 820, "height": 1180}
LANDSCAPE = {"width": 1180, "height": 820}
SCENE_MIN_PX = 320
"""The scene's stated minimum height from 820 px wide (web/static/site.css)."""


def _rows(live: Live, session_id: int) -> list[Feedback]:
    with live.app.state.session_factory() as db:
        query = select(Feedback).where(Feedback.session_id == session_id)
        return list(db.scalars(query.order_by(Feedback.feedback_index)))


def _rate(page: Any, turn: int, rating: str, tap: bool = False) -> None:
    expect(page.locator("#rating")).to_have_attribute("data-turn", str(turn), timeout=120_000)
    button = page.locator(f"button.rate[data-rating='{rating}']")
    expect(button).to_be_enabled(timeout=60_000)
    button.tap() if tap else button.click()


def test_a_persons_ratings_train_the_learners_rating_model(live: Live, browser: Any) -> None:
    """Three moves of the grid world rated Good, Bad, Good on the page: the run learns from
    them with a model of the rating, which the finished run's checkpoint holds trained on
    exactly those three (its last at the last rated step), each stored with its shaping."""
    session = live.human_session(
        "rating model visit",
        task="gridworld",
        motion=None,
        feedback="evaluative",
        feedback_method="rating_model",
        feedback_weight=0.5,
        advice_budget=3,
        rating_time_out_s=60,
        config={"pretraining_steps": 10, "batch_size": 8, "memory_size": 300},
        episodes=1,
        max_episode_steps=15,
    )
    live.begin(session)  # consent and the induction's Start, over the participant's API
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.goto(session["participant_url"])
    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    for turn, rating in enumerate(("good", "bad", "good")):
        _rate(page, turn, rating)
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=60_000)
    context.close()

    _wait_finished(live, session["id"])
    rows = _rows(live, session["id"])
    assert [r.judgement for r in rows] == [1.0, -1.0, 1.0]
    assert [r.shaping for r in rows] == [0.5, -0.5, 0.5]
    with live.app.state.session_factory() as db:
        found = db.get(StudySession, session["id"])
        assert found is not None and found.checkpoint_path
        assert found.spec.feedback_method == "rating_model"
        path = found.checkpoint_path
    model = read_checkpoint(path)["rating_model"]
    assert model is not None, "the learner has a model of the rating"
    assert model["ratings"] == 3 and model["last_rated_step"] == rows[-1].global_step
    weights = model["weights"]
    rated = {r.action for r in rows}
    for action in range(weights.shape[0]):  # a rated action's weights moved, no other's
        assert bool(weights[action].abs().sum() > 0) == (action in rated), action


def _wait_finished(live: Live, session_id: int) -> None:
    with live.api() as api:
        for _ in range(240):
            status = api.get(f"/api/sessions/{session_id}").json()["status"]
            if status == "finished":
                return
            assert status in ("created", "running"), status
            time.sleep(0.5)
    raise AssertionError(f"session {session_id} did not finish")


IN_VIEW = ["#scene", "#rating-question", "button.rate >> nth=0", "button.rate >> nth=1"]


def assert_rating_in_view(page: Any) -> None:
    """The 3-D view at its minimum height, the sentence that asks and both buttons inside
    the viewport without scrolling, nothing wider than it, the buttons big enough to tap."""
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
    assert page.locator("#scene").bounding_box()["height"] >= SCENE_MIN_PX


def assert_scene_drawn(live: Live, page: Any, session_id: int, timeout: float = 120) -> None:
    """The 3-D view has built the scene (server side), the page no longer says it is
    loading, viser's canvas fills the frame at its size, and its middle is drawn: not one
    flat colour. Waits for that up to `timeout` (a software WebGL draws slowly)."""
    wait_for_scene(live, session_id)
    expect(page.locator("#scene-loading")).to_be_hidden(timeout=timeout * 1000)
    canvas = page.frame_locator("#scene").locator("canvas").first
    deadline = time.monotonic() + timeout
    while True:
        frame = page.locator("#scene").bounding_box()
        drawn = canvas.bounding_box()
        fills = (
            drawn is not None
            and abs(drawn["width"] - frame["width"]) <= 2
            and abs(drawn["height"] - frame["height"]) <= 2
        )
        spread = float(canvas_pixels(page).std()) if fills else 0.0
        if fills and spread > 12:
            return
        assert time.monotonic() < deadline, (
            f"the 3-D view is not drawn: canvas {drawn} in frame {frame}, spread {spread:.1f}"
        )
        time.sleep(0.5)


def test_the_rating_page_keeps_scene_sentence_and_buttons_in_view_on_a_tablet(
    live: Live, browser: Any
) -> None:
    """Portrait, then the same page turned to landscape: at each size the 3-D view shows
    the scene (drawn, at the frame's new size) before the screenshot."""
    session = live.human_session(
        "rating tablet",
        seed=5,
        motion="fast",
        feedback="evaluative",
        advice_budget=2,
        rating_time_out_s=300,  # room to wait for the 3-D view at each size
        config={"pretraining_steps": 10, "batch_size": 8, "memory_size": 300},
    )
    live.begin(session)
    context = browser.new_context(viewport=PORTRAIT, has_touch=True, is_mobile=True)
    page = context.new_page()
    page.goto(session["participant_url"])
    expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
    for turn, (size, name) in enumerate(((PORTRAIT, "portrait"), (LANDSCAPE, "landscape"))):
        page.set_viewport_size(size)
        expect(page.locator("#rating")).to_have_attribute("data-turn", str(turn), timeout=120_000)
        expect(page.locator("button.rate").first).to_be_enabled(timeout=60_000)
        expect(page.locator("#rating-question")).to_contain_text(
            re.compile(r"chose “(Grab|Move right|Move left|Drop)”")
        )
        assert_rating_in_view(page)
        assert_scene_drawn(live, page, session["id"])
        save_screenshot(page, f"evaluative-rating-tablet-{name}")
        _rate(page, turn, "good", tap=True)
    expect(page).to_have_url(re.compile(r"/thanks$"), timeout=60_000)
    context.close()
    assert [r.judgement for r in _rows(live, session["id"])] == [1.0, 1.0]
