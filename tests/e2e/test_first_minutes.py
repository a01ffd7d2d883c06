"""A participant's first minutes (issue 21), in Chromium through nginx: the first turn comes
without the 3-D view replaying the robot's practice moves, and only the participant's own
advised moves are shown as motion."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import Live
from tests.e2e.scene import wait_for_scene, wait_idle
from tests.server.scale import rest_body

pytestmark = [pytest.mark.browser, pytest.mark.slow]
PRACTICE = 40
"""Random practice moves before the first turn: at five times real speed, the old view took
about a minute to replay them (physics motion, 1-2 s each)."""


@pytest.fixture(scope="module")
def paused(live: Live) -> Iterator[dict[str, Any]]:
    """A started human session, paused by the researcher before its practice began, so the
    participant's 3-D view is open for every practice move."""
    session = live.human_session(
        "first minutes",
        seed=3,
        advice_budget=3,
        config={"pretraining_steps": PRACTICE, "batch_size": 8, "memory_size": 500},
    )
    live.begin(session)
    with live.api() as api:
        assert api.post(f"/api/sessions/{session['id']}/pause").status_code == 200
    yield session
    with live.api() as api:
        api.post(f"/api/sessions/{session['id']}/stop")


def test_the_first_turn_does_not_wait_for_the_practice_to_be_replayed(
    live: Live, browser: Any, paused: dict[str, Any]
) -> None:
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    page.goto(paused["participant_url"])
    expect(page).to_have_url(re.compile(r"/advise$"))
    view = wait_for_scene(live, paused["id"])
    before = view.player.steps_received
    with live.api() as api:
        assert api.post(f"/api/sessions/{paused['id']}/resume").status_code == 200
    grab = page.locator("button.action[data-action='0']")
    expect(grab).to_be_enabled(timeout=180_000)
    practised = view.player.steps_received - before
    assert practised >= PRACTICE // 2, f"the view was open for the practice ({practised} moves)"
    assert view.player.steps_animated == 0, "no practice move was replayed as motion"
    assert live.app.state.viewer.playback_remaining_s(paused["id"]) == 0

    with live.api(paused["participant_token"]) as api:
        station = api.get("/api/participant/state").json()["station"]
    move = 1 if station == "left" else 2  # to a side table the arm is not at: a real move
    page.locator(f"button.action[data-action='{move}']").click()
    expect(page.locator("#advice-left")).to_have_text("2")
    expect(grab).to_be_enabled(timeout=60_000)
    wait_idle(live, paused["id"])
    assert view.player.steps_animated == 1, "the participant's own move was shown moving"
    context.close()


def test_a_session_made_with_pretrain_practises_before_its_link_is_opened(live: Live) -> None:
    with live.api() as api:
        study = api.post("/api/studies", json={"name": "made to practise"}).json()
        body = rest_body(
            method="human",
            seed=4,
            motion="fast",
            advice_budget=2,
            episodes=1,
            config={"pretraining_steps": 30, "batch_size": 8, "memory_size": 500},
        )
        made = api.post(f"/api/studies/{study['id']}/sessions?pretrain=true", json=body)
        assert made.status_code == 201, made.text
        session_id = made.json()["id"]
        progress = wait_for_progress(api, session_id, lambda p: p["global_step"] >= 20)
        assert progress["advice_given"] == 0 and progress["status"] == "running"
        bad = api.post(f"/api/studies/{study['id']}/sessions?pretrain=maybe", json=body)
        assert bad.status_code == 422
        api.post(f"/api/sessions/{session_id}/stop")


def wait_for_progress(api: Any, session_id: int, done: Any, timeout: float = 120) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        progress = api.get(f"/api/sessions/{session_id}/progress").json()
        if done(progress):
            return progress
        assert time.monotonic() < deadline, f"no progress: {progress}"
        time.sleep(0.2)
