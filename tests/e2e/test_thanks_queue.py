"""The thank-you page while the robot waits for a training slot (issue 21): three queued
sessions show places 1, 2 and 3 with a time estimate and no empty plot, and the places fall
as a slot frees. Its own server (one trainer slot, a setting), reached by Chromium. The
sessions are made with `?pretrain=true`: they practise before anyone opens their link."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import save_screenshot
from tests.server.live import LiveServer, serving
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body

pytestmark = [pytest.mark.browser, pytest.mark.slow]
PHONE = {"width": 390, "height": 844}


@pytest.fixture(scope="module")
def one_slot(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    # Each alone (training_population=1): one slot, one session after another.
    with serving(
        tmp_path_factory.mktemp("queue"), max_trainers=1, training_population=1, heartbeat_s=1
    ) as live:
        yield live


def _until(check: Any, timeout: float = 120) -> Any:
    deadline = time.monotonic() + timeout
    while not (found := check()):
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.2)
    return found


def test_queued_sessions_show_their_place_and_it_falls(one_slot: LiveServer, browser) -> None:
    with one_slot.client() as api:
        study = api.post("/api/studies", json={"name": "queue"}).json()
        body = session_body("human", advice_budget=1, episodes=300)
        sessions = f"/api/studies/{study['id']}/sessions"
        assert api.post(f"{sessions}?pretrain=maybe", json=body).status_code == 422
        # Made to start practising at once (?pretrain=true), before any link is opened.
        made = [api.post(f"{sessions}?pretrain=true", json=body).json() for _ in "abcd"]
        progress = lambda s: api.get(f"/api/sessions/{s['id']}/progress").json()  # noqa: E731
        for session in made:
            _until(lambda s=session: progress(s)["global_step"] > 0)
            assert progress(session)["consented"] is False
        for i, session in enumerate(made):
            participant = SimulatedParticipant(one_slot.url, session["participant_token"])
            participant.begin()
            assert participant.next_request()["advice_index"] == 0
            assert participant.advise(0, 0).status_code == 200
            participant.close()
            if i == 0:  # the first takes the one slot and trains; the others queue
                _until(lambda s=session: progress(s)["stage"] == "train")
            else:
                _until(lambda s=session: progress(s)["queued"])
        training, *queued = made

        context = browser.new_context(viewport=PHONE)
        pages = []
        for session in queued:
            page = context.new_page()
            page.goto(session["participant_url"] + "/thanks")
            pages.append(page)
        for place, page in enumerate(pages, 1):
            expect(page.locator("#queue-place-text")).to_contain_text(f"number {place} in line")
            status = page.locator("#learning-status")
            expect(status).to_have_text(f"Waiting in line: number {place}")
            expect(page.locator("#curve")).to_be_hidden()
            expect(page.locator("#curve-waiting")).to_be_hidden()
            text = page.locator("main").inner_text().lower()
            for jargon in ("episode", "reward", "processor", "queued"):
                assert jargon not in text, f"{jargon!r} on the thank-you page"
        # Once the robot in the slot has finished a round, every place has an estimate,
        # later places later.
        waits = _until(lambda: _waits(one_slot, queued))
        assert waits == sorted(waits) and waits[0] < waits[-1], waits
        expect(pages[0].locator("#queue-wait")).to_contain_text("It should start practising in")
        save_screenshot(pages[1], "thank-you-queued", full_page=True)

        assert api.post(f"/api/sessions/{training['id']}/stop").status_code == 200
        expect(pages[0].locator("#queue")).to_be_hidden(timeout=60_000)
        expect(pages[0].locator("#learning-status")).to_contain_text("Practising: round")
        expect(pages[1].locator("#queue-place-text")).to_contain_text("number 1 in line")
        expect(pages[2].locator("#queue-place-text")).to_contain_text("number 2 in line")
        expect(pages[0].locator("#curve circle.dot").first).to_be_visible(timeout=120_000)
        expect(pages[0].locator("#curve-caption")).to_be_visible()
        context.close()
        for session in made:
            api.post(f"/api/sessions/{session['id']}/stop")


def _waits(live: LiveServer, sessions: list[dict[str, Any]]) -> list[float] | None:
    waits = []
    for session in sessions:
        with live.client(key=None, token=session["participant_token"]) as participant:
            curve = participant.get("/api/participant/learning-curve").json()
        if curve["wait_s"] is None:
            return None
        waits.append(curve["wait_s"])
    return waits
