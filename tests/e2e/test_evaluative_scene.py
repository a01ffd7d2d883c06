"""The sorting robot under evaluative feedback in a real browser, with its live 3-D view:
each move the participant is asked to rate reaches the view as an advised step (replayed
as motion before Good and Bad light up), the robot's other moves as its own; the ratings
given by key are stored against exactly those steps."""

from __future__ import annotations

import re
from typing import Any

import pytest
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import Feedback
from tests.e2e.conftest import VIEWPORT, Live

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 3


def test_the_3d_view_replays_each_move_to_rate_and_the_keys_rate_it(
    live: Live, browser: Any
) -> None:
    session = live.human_session(
        "evaluative-scene", feedback="evaluative", advice_budget=BUDGET, rating_time_out_s=60
    )
    seen: list[Any] = []
    with live.app.state.hub.subscribe(
        session["id"], lambda event: seen.append(event.payload), kinds=["scene_step"]
    ):
        context = browser.new_context(viewport=VIEWPORT)
        page = context.new_page()
        page.goto(session["participant_url"])
        page.click("#agree")
        for step in (1, 2, 3):
            expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
            page.click("#start" if step == 3 else "#next")
        expect(page).to_have_url(re.compile(r"/advise$"), timeout=30_000)
        expect(page.locator("#scene")).to_have_count(1)
        good = page.locator("button.rate[data-rating='good']")
        for index, key in enumerate(["y", "n", "y"]):
            expect(page.locator("#rating")).to_have_attribute(
                "data-turn", str(index), timeout=180_000
            )
            expect(good).to_be_enabled(timeout=60_000)
            expect(page.locator("#rating-question")).to_contain_text(
                re.compile(r"chose “(Grab|Move right|Move left|Drop)”")
            )
            page.keyboard.press(key)
        expect(page).to_have_url(re.compile(r"/thanks$"), timeout=60_000)
        context.close()

    with live.app.state.session_factory() as db:
        rows = db.scalars(
            select(Feedback)
            .where(Feedback.session_id == session["id"])
            .order_by(Feedback.feedback_index)
        ).all()
    assert [r.judgement for r in rows] == [1.0, -1.0, 1.0]
    rated = {r.global_step: r.action for r in rows}
    advised = {e.global_step: e.action for e in seen if e.advised}
    assert advised == rated, "the view replays exactly the moves to rate, each as it was taken"
    assert any(not e.advised for e in seen), "the robot's own moves are shown without motion"
