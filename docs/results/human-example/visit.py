"""One person's visit to the example study through its link, in Chromium: consent, the
induction, the check (one answer wrong on the first try), the grid world's advice (right and
down in turn, what a person who sees the goal in the far corner might press), the
questionnaire (NASA-TLX, trust, demographics), and the completion code.

    python docs/results/human-example/visit.py JOIN_URL [PANEL_ID]
"""

from __future__ import annotations

import re
import sys
import time
from urllib.parse import urlencode

from playwright.sync_api import expect, sync_playwright

from tasks import get_task

CHROMIUM = "/usr/bin/chromium"
TLX = {"mental": 60, "physical": 10, "temporal": 45, "performance": 25, "effort": 55,
       "frustration": 20}  # fmt: skip
MOVES = (1, 2)  # right, down


def visit(join_url: str, panel_id: str) -> str:
    task = get_task("gridworld")
    right = {q.id: "abcdefgh"[q.choices.index(q.answer)] for q in task.check_questions}
    first = task.check_questions[0]
    wrong = "abcdefgh"[(first.choices.index(first.answer) + 1) % len(first.choices)]
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"]
        )
        page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
        query = urlencode({"PROLIFIC_PID": panel_id, "STUDY_ID": "example", "SESSION_ID": "s1"})
        page.goto(f"{join_url}?{query}")
        expect(page).to_have_url(re.compile(r"/consent$"), timeout=60_000)
        page.click("#agree")
        for step in (1, 2, 3):
            expect(page).to_have_url(re.compile(rf"/induction/{step}$"))
            page.click("#next")

        expect(page).to_have_url(re.compile(r"/check$"))
        for question, value in {**right, first.id: wrong}.items():
            page.check(f"input[name='{question}'][value='{value}']")
        page.click("#submit")
        expect(page.locator("#check-error")).to_contain_text("Some answers are not right")
        page.check(f"input[name='{first.id}'][value='{right[first.id]}']")
        page.click("#submit")

        expect(page).to_have_url(re.compile(r"/advise$"), timeout=120_000)
        given = 0
        while "/advise" in page.url:
            button = page.locator(f"button.action[data-action='{MOVES[given % 2]}']")
            try:
                expect(button).to_be_enabled(timeout=5_000)
            except AssertionError:
                continue  # the learner is between turns, or the advice is over
            time.sleep(1.0)  # looking at the frame before pressing
            button.click()
            given += 1
            print(f"advice {given}: {task.actions[MOVES[(given - 1) % 2]].word}", flush=True)

        expect(page).to_have_url(re.compile(r"/questionnaire$"), timeout=120_000)
        for item, value in TLX.items():
            page.fill(f"input[name='nasa_tlx.{item}']", str(value))
        for number in range(1, 13):
            page.check(f"input[name='trust.item_{number:02d}'][value='{1 + number % 7}']")
        page.check("input[name='demographics.age'][value='25-34']")
        page.check("input[name='demographics.gender.prefer']")
        page.click("#submit")
        code = page.locator("#outcome-code")
        expect(code).not_to_be_empty(timeout=60_000)
        text = code.inner_text()
        browser.close()
    return text


if __name__ == "__main__":
    done = visit(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else "BROWSER-1")
    print(f"completion code: {done}")
