"""A participant's whole online visit in an evaluative condition, in a real browser through
nginx, on a desktop (keys and clicks) and on a phone at 390x844 (touch): the induction and
the check speak of rating, each turn shows the move the agent made (its word and its frame)
and takes Good or Bad within the run's time-out, a turn left alone goes on with no answer,
then the questionnaire and the code. The export's feedback rows hold each rating with the
page's decision time, and the server's time from showing to receiving agrees with this
test's own clock within 50 ms plus the round trip. Screenshots for the README."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import pytest
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import StudySession
from tasks import get_task
from tests.e2e.conftest import VIEWPORT, Live, save_screenshot
from tests.e2e.test_online_study import CODES, PROLIFIC, assert_returned, exported, token
from tests.server.test_online_study import table

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 4
TIME_OUT_S = 4.0
PHONE = {"width": 390, "height": 844}
RUN = {
    "method": "human",
    "task": "gridworld",
    "seed": 5,
    "feedback": "evaluative",
    "rating_time_out_s": TIME_OUT_S,
    "config": {"pretraining_steps": BUDGET + 20, "batch_size": 16, "memory_size": 500,
               "advice_budget": BUDGET, "episodes": 2, "max_episode_steps": 30},
}  # fmt: skip
ANSWERS = ["key-good", "bad", None, "good"]
"""Each turn's answer: by key (Y), by click or touch, none (the time-out)."""


def rating_study(live: Live) -> dict[str, Any]:
    design = {
        "conditions": {"rating": {"run": RUN, "target": 2}},
        "questionnaire": {"nasa_tlx": False, "trust": False, "demographics": False, "items": [
            {"id": "clarity", "kind": "likert", "text": "The moves were clear.", "required": True,
             "points": 5, "anchors": ["Disagree", "Agree"]}]},
        "panel": {"kind": "prolific", "codes": CODES, "return_delay_s": 4},
    }  # fmt: skip
    with live.api() as api:
        made = api.post("/api/studies", json={"name": "ratings online", "design": design})
        assert made.status_code == 201, made.text
        return made.json()


class Clock:
    """This test's own clock on the page's traffic: when each rating turn's state reached
    the browser, and when each rating's answer came back (with its round trip)."""

    def __init__(self, page: Any) -> None:
        self.shown: dict[int, float] = {}
        self.sent: dict[int, float] = {}
        self.answered: dict[int, tuple[float, float]] = {}
        page.on("request", self._request)
        page.on("response", self._response)

    def _request(self, request: Any) -> None:
        if request.url.endswith("/api/participant/rating") and request.method == "POST":
            self.sent[request.post_data_json["advice_index"]] = time.monotonic()

    def _response(self, response: Any) -> None:
        now = time.monotonic()
        if "/api/participant/state" in response.url and response.ok:
            state = response.json()
            if state.get("rated_action") is not None:
                self.shown.setdefault(state["advice_index"], now)
        elif response.url.endswith("/api/participant/rating") and response.ok:
            index = response.request.post_data_json["advice_index"]
            self.answered[index] = (now, now - self.sent[index])


def visit(browser: Any, study: dict[str, Any], pid: str, phone: bool) -> tuple[str, Clock]:
    options = {"viewport": PHONE, "is_mobile": True, "has_touch": True} if phone else {}
    context = browser.new_context(**{"viewport": VIEWPORT, **options})
    context.route(PROLIFIC, lambda route: route.fulfill(body="<p>Back at Prolific</p>"))
    page = context.new_page()
    clock = Clock(page)
    query = urlencode({"PROLIFIC_PID": pid, "STUDY_ID": "st-1", "SESSION_ID": f"se-{pid}"})
    page.goto(f"{study['join_url']}?{query}")
    shot = "-phone" if phone else ""
    try:
        expect(page).to_have_url(re.compile(r"/consent$"))
        participant = token(page)
        page.click("#agree")
        for step in (1, 2, 3):
            expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
            if step == 1:
                expect(page.locator("main")).to_contain_text("a person's judgement")
                expect(page.locator("main")).to_contain_text(f"within {TIME_OUT_S:g} seconds")
            if step == 3:
                expect(page.locator(".preview-buttons span")).to_have_text(["Good Y", "Bad N"])
                save_screenshot(page, f"evaluative-induction-3{shot}")
            page.click("#next")
        expect(page).to_have_url(re.compile(r"/check$"))
        expect(page.locator("fieldset[data-question='rating']")).to_contain_text("Good or Bad")
        questions = get_task("gridworld").check_questions
        right = {q.id: "abcdefgh"[q.choices.index(q.answer)] for q in questions}
        for question, value in {**right, "rating": "a"}.items():
            page.check(f"input[name='{question}'][value='{value}']")
        page.click("#submit")

        expect(page).to_have_url(re.compile(r"/advise$"), timeout=60_000)
        expect(page.locator("button.rate")).to_have_count(2)
        expect(page.locator("button.action:not(.rate)")).to_have_count(0)
        for index, answer in enumerate(ANSWERS):
            good = page.locator("button.rate[data-rating='good']")
            expect(good).to_be_enabled(timeout=180_000)
            question = page.locator("#rating-question")
            expect(question).to_contain_text(re.compile(r"chose “(Up|Right|Down|Left)”"))
            expect(page.locator("#frame")).to_be_visible()
            if index == 0:
                expect(page.locator("#rating-left")).to_contain_text("s left to rate")
                save_screenshot(page, f"evaluative-rating{shot}")
            expect(page.locator("#rating")).to_have_attribute("data-turn", str(index))
            if answer is None:  # the next turn says so
                expect(page.locator("#rating")).to_have_attribute(
                    "data-turn", str(index + 1), timeout=TIME_OUT_S * 1000 + 15_000
                )
                expect(page.locator("#feedback")).to_contain_text("No answer to the last move")
                continue
            if answer == "key-good":
                page.keyboard.press("y")
            else:
                button = page.locator(f"button.rate[data-rating='{answer}']")
                button.tap() if phone else button.click()
            if index < BUDGET - 1:
                expect(page.locator("#rating")).to_have_attribute("data-turn", str(index + 1))
        if phone:
            width = page.evaluate("document.documentElement.scrollWidth")
            assert width <= PHONE["width"], f"the page is {width} px wide on a phone"

        expect(page).to_have_url(re.compile(r"/questionnaire$"), timeout=60_000)
        page.check("input[name='custom.clarity'][value='4']")
        page.click("#submit")
        expect(page.locator("#outcome-code")).to_have_text(CODES["completed"], timeout=30_000)
        assert_returned(page, "completed")
        return participant, clock
    finally:
        context.close()


def test_a_participant_rates_the_agents_moves_through_a_whole_online_visit(
    live: Live, browser: Any, tmp_path: Path
) -> None:
    study = rating_study(live)
    clocks: dict[str, Clock] = {}
    for pid, phone in (("PID-E1", False), ("PID-E2", True)):
        participant, clock = visit(browser, study, pid, phone)
        with live.app.state.session_factory() as db:
            found = db.scalar(
                select(StudySession.id).where(StudySession.participant_token == participant)
            )
        clocks[str(found)] = clock

    folder = exported(live, study, tmp_path)
    sessions = table(folder, "sessions")
    assert [r["outcome"] for r in sessions] == ["completed", "completed"]
    by_token = {r["session_id"]: r for r in sessions}
    assert set(by_token) == set(clocks)
    rows = table(folder, "feedback")
    assert len(rows) == 2 * BUDGET
    for session_id in by_token:
        mine = [r for r in rows if r["session_id"] == session_id]
        assert [r["evaluator"] for r in mine] == ["human"] * BUDGET
        assert [r["judgement"] for r in mine] == ["1.0", "-1.0", "", "1.0"]
        assert [r["shaping"] for r in mine] == ["1.0", "-1.0", "0.0", "1.0"]
        answered = [r for r in mine if r["judgement"]]
        assert all(0 < float(r["decision_time_s"]) < TIME_OUT_S for r in answered)
        assert mine[2]["decision_time_s"] == ""
        assert TIME_OUT_S - 0.5 < float(mine[2]["response_time_s"]) <= TIME_OUT_S + 0.5
        assert all(r["action_name"] in ("up", "right", "down", "left") for r in mine)
    agreements = []
    for session_id, clock in clocks.items():
        mine = {int(r["feedback_index"]): r for r in rows if r["session_id"] == session_id}
        assert set(clock.answered) == {0, 1, 3}
        for index, (back, round_trip) in clock.answered.items():
            ours = back - clock.shown[index]
            server_s = float(mine[index]["response_time_s"])
            agreements.append((round(server_s, 3), round(ours, 3), round(round_trip, 3)))
            assert abs(server_s - ours) <= 0.05 + round_trip, (index, server_s, ours, round_trip)
            assert float(mine[index]["decision_time_s"]) <= server_s
    print("server s, test's s, round trip s:", agreements)
