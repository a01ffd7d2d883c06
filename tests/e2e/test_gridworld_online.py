"""A participant's whole online visit to the grid world through the study link, in a real
browser through nginx: the join page and the consent speak of the task (no robot), the
induction shows its goal and its buttons, the check asks the task's own questions (wrong
once), the advice uses the task's buttons and frames (every advice the correct move), the
questionnaire, and the completion code; the export holds the check's tries and the advice.
Screenshots for the README beside the sorting robot's."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import StudySession
from tasks import get_task
from tests.e2e.conftest import Live, save_screenshot
from tests.e2e.test_gridworld_visit import correct_action
from tests.e2e.test_online_study import CODES, Arrivals, assert_returned, exported, token
from tests.server.test_online_study import table

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 8
RUN = {
    "method": "human",
    "task": "gridworld",
    "seed": 5,
    "config": {"pretraining_steps": BUDGET + 20, "batch_size": 16, "memory_size": 500,
               "advice_budget": BUDGET, "episodes": 2, "max_episode_steps": 30},
}  # fmt: skip


def grid_study(live: Live) -> dict[str, Any]:
    design = {
        "conditions": {"grid": {"run": RUN, "target": 2}},
        "questionnaire": {"nasa_tlx": False, "trust": False, "demographics": False, "items": [
            {"id": "clarity", "kind": "likert", "text": "The moves were clear.", "required": True,
             "points": 5, "anchors": ["Disagree", "Agree"]}]},
        "panel": {"kind": "prolific", "codes": CODES, "return_delay_s": 4},
    }  # fmt: skip
    with live.api() as api:
        made = api.post("/api/studies", json={"name": "grid world online", "design": design})
        assert made.status_code == 201, made.text
        return made.json()


def test_a_grid_world_participant_goes_through_the_whole_online_visit(
    live: Live, browser: Any, tmp_path: Path
) -> None:
    task = get_task("gridworld")
    study = grid_study(live)
    arrivals = Arrivals(browser)
    try:
        page = arrivals.arrive(study, "PID-G")
        expect(page).to_have_url(re.compile(r"/consent$"))
        expect(page.locator("main")).not_to_contain_text("robot")
        save_screenshot(page, "gridworld-consent", full_page=True)
        participant = token(page)
        page.click("#agree")
        for step in (1, 2, 3):
            expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
            expect(page.locator("main")).not_to_contain_text("robot")
            if step == 2:
                expect(page.locator("main")).to_contain_text(task.goal)
            if step == 3:
                expect(page.locator(".preview-buttons span")).to_have_count(4)
                save_screenshot(page, "gridworld-induction-3")
            page.click("#next")

        expect(page).to_have_url(re.compile(r"/check$"))
        questions = task.check_questions
        for question in questions:
            expect(page.locator(f"fieldset[data-question='{question.id}']")).to_contain_text(
                question.text
            )
        right = {q.id: "abcdefgh"[q.choices.index(q.answer)] for q in questions}
        for question, value in {**right, questions[0].id: "c"}.items():
            page.check(f"input[name='{question}'][value='{value}']")
        page.click("#submit")
        expect(page.locator("#check-error")).to_contain_text("Some answers are not right")
        save_screenshot(page, "gridworld-check", full_page=True)
        page.check(f"input[name='{questions[0].id}'][value='{right[questions[0].id]}']")
        page.click("#submit")

        expect(page).to_have_url(re.compile(r"/advise$"), timeout=60_000)
        expect(page.locator("button.action")).to_have_count(4)
        with live.app.state.session_factory() as db:
            session_id = db.scalar(
                select(StudySession.id).where(StudySession.participant_token == participant)
            )
        given = []
        for index in range(BUDGET):
            first = page.locator("button.action").first
            expect(first).to_be_enabled(timeout=180_000)
            if index == 0:
                expect(page.locator("#frame")).to_be_visible()
                save_screenshot(page, "gridworld-online-advice")
            action = correct_action(live, session_id)
            given.append(action)
            page.locator(f"button.action[data-action='{action}']").click()
            if index < BUDGET - 1:
                expect(page.locator("#advice-left")).to_have_text(str(BUDGET - index - 1))

        expect(page).to_have_url(re.compile(r"/questionnaire$"), timeout=60_000)
        page.check("input[name='custom.clarity'][value='4']")
        page.click("#submit")
        expect(page.locator("#outcome-code")).to_have_text(CODES["completed"], timeout=30_000)
        save_screenshot(page, "gridworld-completed")
        assert_returned(page, "completed")
    finally:
        arrivals.close()
    folder = exported(live, study, tmp_path)
    assert [r["outcome"] for r in table(folder, "sessions")] == ["completed"]
    check = table(folder, "check")  # a row per question and try
    assert [r["result"] for r in check] == ["retry"] * 2 + ["passed"] * 2
    assert {r["question"] for r in check} == {q.id for q in task.check_questions}
    advice = table(folder, "advice")
    assert [int(r["action"]) for r in advice] == given
    assert {r["action_name"] for r in advice} <= {a.word for a in task.actions}
