"""In a real browser, through nginx as deployed: a participant of an online study (a study
with a design) consents, reads the induction, answers the comprehension check wrong once
(the page says which question, the start stays refused) and right the second time, gives
the advice, is sent to the questionnaire instead of the thank-you page, fills it in (the
page refuses it with a required item left), and lands on the visit's end page. The
database then holds both tries, every item, and the completed outcome. Screenshots of the
check and the questionnaire, on a desktop and on a phone (390x844)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import expect
from sqlalchemy import select

from study.db.models import CheckAttempt, QuestionnaireAnswer, StudySession
from study.schemas.visit import Item
from tests.e2e.conftest import Live, save_screenshot
from tests.e2e.test_online_study import CODES, RUN, Arrivals, assert_returned, exported, token
from tests.server.test_online_study import table
from tests.study.test_export_types import check_frictionless

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUDGET = 20
"""Enough turns for the visit's whole course; the paper's 100 only lengthen the run."""
PHONE = {"width": 390, "height": 844}
RIGHT = {"blue_cube": "right", "red_disk": "left", "drop_at_centre": "keep"}
"""Under the default sort rule by colour: blue right, red left."""
TLX = {"mental": 60, "physical": 10, "temporal": 50, "performance": 25, "effort": 55,
       "frustration": 20}  # fmt: skip
"""The answers; `temporal` is the slider's midpoint, answered by a click where it stands."""


CUSTOM = [
    Item(id="clarity", kind="likert", text="The robot's moves were clear.", required=True,
         points=5, anchors=["Strongly disagree", "Disagree", "Neutral", "Agree", "Strongly agree"]),
    Item(id="minutes", kind="number", text="About how many minutes did it take?", minimum=0,
         maximum=120),
    Item(id="comments", kind="text", text="Anything else?", max_length=500),
]  # fmt: skip
"""The researcher's own items, after the built-ins."""


def online_study(live: Live) -> dict[str, Any]:
    """A study with one condition of `BUDGET` advice, the default check, the built-in
    questionnaire with the researcher's own items, and Prolific's codes."""
    run = {
        **RUN,
        "config": {**RUN["config"], "pretraining_steps": BUDGET + 20, "advice_budget": BUDGET},
    }
    design = {
        "conditions": {"early": {"run": run, "target": 2}},
        "questionnaire": {"items": [item.model_dump(exclude_unset=True) for item in CUSTOM]},
        "panel": {"kind": "prolific", "codes": CODES, "return_delay_s": 4},
    }
    with live.api() as api:
        made = api.post("/api/studies", json={"name": "online visit", "design": design})
        assert made.status_code == 201, made.text
        return made.json()


def phone_screenshot(browser, url: str, name: str) -> None:
    """The same page on a phone, side by side with the desktop one (a GET changes nothing)."""
    context = browser.new_context(viewport=PHONE, device_scale_factor=2, is_mobile=True)
    page = context.new_page()
    page.goto(url)
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= PHONE["width"], f"the page is {width} px wide on a phone"
    save_screenshot(page, name)
    context.close()


def through_the_induction(page: Any) -> None:
    page.click("#agree")
    for step in (1, 2, 3):
        expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
        expect(page.locator("#start")).to_have_count(0)
        page.click("#next")


def test_an_online_participant_passes_the_check_advises_and_answers_the_questionnaire(
    live: Live, browser: Any, tmp_path: Path
) -> None:
    """Through the study's link with Prolific's parameters: one participant fails the
    check on both tries (excluded: its code, back to Prolific); the next passes on the
    second try, gives all its advice, answers the questionnaire and is sent back to
    Prolific with the completed code; the export holds it all and validates."""
    study = online_study(live)
    arrivals = Arrivals(browser)
    try:
        failing = arrivals.arrive(study, "PID-X")
        through_the_induction(failing)
        expect(failing).to_have_url(re.compile(r"/check$"))
        for _ in range(2):
            for question, value in {**RIGHT, "red_disk": "right"}.items():
                failing.check(f"input[name='{question}'][value='{value}']")
            failing.click("#submit")
        assert_returned(failing, "excluded")

        page = arrivals.arrive(study, "PID-C")
        expect(page).to_have_url(re.compile(r"/consent$"))
        participant = token(page)
        complete_the_visit(live, browser, page, participant)
        expect(page.locator("#outcome-code")).to_have_text(CODES["completed"])
        save_screenshot(page, "online-completed")
        assert_returned(page, "completed")
    finally:
        arrivals.close()
    with live.app.state.session_factory() as db:
        session_id = db.scalar(
            select(StudySession.id).where(StudySession.participant_token == participant)
        )
    check_the_records(live, session_id)
    folder = exported(live, study, tmp_path)
    check_frictionless(folder)
    outcomes = {r["outcome"] for r in table(folder, "sessions")}
    assert outcomes == {"excluded", "completed"}
    assert len(table(folder, "assignments")) == len(table(folder, "panel_ids")) == 2
    assert {r["result"] for r in table(folder, "check")} >= {"retry", "passed", "excluded"}
    assert len(table(folder, "questionnaire")) == 6 + 12 + 4 + 3
    scales = table(folder, "scales")
    assert {r["scale"] for r in scales} >= {"nasa_tlx", "trust"}


def complete_the_visit(live: Live, browser: Any, page: Any, token: str) -> None:
    """Consent, induction, the check (wrong once), all the advice, the questionnaire."""
    through_the_induction(page)

    expect(page).to_have_url(re.compile(r"/check$"))
    expect(page.locator("h1")).to_have_text("A few questions about the task")
    expect(page.locator("#tries-left")).to_have_text("2")
    phone_screenshot(browser, page.url, "check-phone")
    for question, value in {**RIGHT, "blue_cube": "left"}.items():
        page.check(f"input[name='{question}'][value='{value}']")
    page.click("#submit")
    expect(page.locator("#check-error")).to_contain_text("Some answers are not right")
    expect(page.locator("#tries-left")).to_have_text("1")
    wrong = page.locator("fieldset[data-question='blue_cube'] .field-error")
    expect(wrong).to_be_visible()
    expect(page.locator("fieldset[data-question='red_disk'] .field-error")).to_be_hidden()
    save_screenshot(page, "check", full_page=True)
    with live.api(token) as participant:
        refused = participant.post("/api/participant/start")
        assert refused.status_code == 409, "no advice before the check is passed"
    page.check("input[name='blue_cube'][value='right']")
    page.click("#submit")

    expect(page).to_have_url(re.compile(r"/advise$"), timeout=60_000)
    for index in range(BUDGET):
        button = page.locator(f"button.action[data-action='{index % 4}']")
        expect(button).to_be_enabled(timeout=180_000)
        button.click()
        if index < BUDGET - 1:
            expect(page.locator("#advice-left")).to_have_text(str(BUDGET - index - 1))

    expect(page).to_have_url(re.compile(r"/questionnaire$"), timeout=60_000)
    expect(page.locator("section.q-section")).to_have_count(4)
    phone_screenshot(browser, page.url, "questionnaire-phone")
    page.click("#submit")
    expect(page.locator("#questionnaire-error")).to_contain_text("Please answer the 19 questions")
    for item, value in TLX.items():
        if item != "temporal":
            page.fill(f"input[name='nasa_tlx.{item}']", str(value))
    page.click("input[name='nasa_tlx.temporal']")  # its midpoint, 50: no input event comes
    expect(page.locator("fieldset[data-item='temporal'] .slider-value")).to_have_text("50")
    for number in range(1, 13):
        page.check(f"input[name='trust.item_{number:02d}'][value='{1 + number % 7}']")
    page.check("input[name='demographics.age'][value='25-34']")
    page.check("input[name='demographics.gender.prefer']")
    page.check("input[name='custom.clarity'][value='4']")
    page.fill("input[name='custom.minutes']", "12.5")
    page.fill("input[name='custom.comments']", "Fun, if slow.")
    expect(page.locator(".slider-value").first).to_have_text("60")
    expect(page.locator("fieldset[data-item='mental'] .field-error")).to_be_hidden()
    expect(page.locator("#questionnaire-error")).to_be_hidden()
    save_screenshot(page, "questionnaire", full_page=True)
    page.click("#submit")
    expect(page).to_have_url(re.compile(rf"/p/{token}/end"), timeout=30_000)


def check_the_records(live: Live, session_id: int) -> None:
    with live.app.state.session_factory() as db:
        row = db.get(StudySession, session_id)
        assert row.outcome == "completed" and row.outcome_at is not None
        tries = db.scalars(
            select(CheckAttempt).where(CheckAttempt.session_id == row.id).order_by("attempt")
        ).all()
        assert [t.correct for t in tries] == [False, True]
        assert tries[0].answers["blue_cube"] == "left" and tries[1].expected == RIGHT
        query = select(QuestionnaireAnswer).where(QuestionnaireAnswer.session_id == row.id)
        answers = {(a.instrument, a.item): a for a in db.scalars(query)}
    assert len(answers) == 6 + 12 + 4 + 3
    assert {k: answers["nasa_tlx", k].value_number for k in TLX} == TLX
    assert answers["trust", "item_06"].value_number == 7
    assert answers["demographics", "gender"].value_text == "Prefer not to say"
    assert answers["demographics", "robots"].value_text is None, "skipped"
    assert answers["custom", "clarity"].value_number == 4
    assert answers["custom", "minutes"].value_number == 12.5
    assert answers["custom", "comments"].value_text == "Fun, if slow."


def test_a_participant_who_leaves_a_turn_is_warned_before_the_visit_ends(
    live: Live, browser: Any
) -> None:
    """An online study's idle limit ends a visit whose turn goes unanswered: the texts say
    so, and the advice page warns, with the time left, before it happens."""
    run = {**RUN, "config": {**RUN["config"], "pretraining_steps": 30, "advice_budget": 3}}
    design = {
        "conditions": {"early": {"run": run, "target": 1}},
        "panel": {"kind": "prolific", "codes": CODES, "return_delay_s": 4},
        "idle_limit_s": 24,
        "pool": 0,
    }
    with live.api() as api:
        made = api.post("/api/studies", json={"name": "online idle turn", "design": design})
        assert made.status_code == 201, made.text
        study = made.json()
    arrivals = Arrivals(browser)
    try:
        page = arrivals.arrive(study, "PID-IDLE")
        expect(page.locator("[data-page=consent]")).to_contain_text("no answer for 1 minute")
        through_the_induction(page)
        for question, value in RIGHT.items():
            page.check(f"input[name='{question}'][value='{value}']")
        page.click("#submit")
        expect(page).to_have_url(re.compile(r"/advise$"), timeout=60_000)
        expect(page.locator("button.action").first).to_be_enabled(timeout=120_000)
        status = page.locator("#status-text")
        expect(status).to_have_text("Your turn: what should the robot do?")
        # Warned at half the limit (at most 90 s before its end), the seconds left said.
        expect(status).to_have_text(
            "Are you still there? Please choose within about 12 seconds, or the study ends.",
            timeout=20_000,
        )
        expect(page.locator("[data-page=end]")).to_be_visible(timeout=60_000)
        assert_returned(page, "timed_out")
    finally:
        arrivals.close()
