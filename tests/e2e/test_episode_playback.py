"""A researcher plays a participant's episode back in the dashboard: a worker reruns it,
the page plays, pauses and steps through it showing each step as the database logged it,
the advice turns (numbered from 1, as the participant's page does) with the participant's
decision times and the image they were shown,
and the 3-D view draws the step shown. Leaving the page closes the playback."""

from __future__ import annotations

import io
import re
import time
from typing import Any

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect
from sqlalchemy import select

import sim
from study.db.models import Advice, Episode, Step
from tests.e2e.conftest import Live, dashboard_page, save_screenshot
from tests.server.participant import SimulatedParticipant
from tests.server.scale import wait_for_status

pytestmark = [pytest.mark.browser, pytest.mark.slow]
ADVICE = [0, 1, 3, 0, 2, 3]
"""The participant's choices: grab, right, drop, grab, left, drop."""
CM = 0.01


def decision_time(index: int) -> float:
    return 1.25 + 0.5 * index


def advise_all(live: Live, session: dict[str, Any]) -> None:
    """The participant's advice over their API, with the decision times a page measures."""
    participant = SimulatedParticipant(live.url, session["participant_token"])
    try:
        for index, action in enumerate(ADVICE):
            state = participant.next_request()
            assert state["advice_wanted"], state
            body = {
                "advice_index": state["advice_index"],
                "action": action,
                "decision_time_s": decision_time(index),
            }
            response = participant.client.post("/api/participant/advice", json=body)
            assert response.status_code == 200, response.text
            participant.version = response.json()["version"]
    finally:
        participant.close()


def recorded(live: Live, session_id: int) -> tuple[Episode, list[Any], list[Advice]]:
    """The episode the participant advised most, its logged steps and its advice."""
    with live.app.state.session_factory() as db:
        episode = db.scalars(
            select(Episode)
            .where(Episode.session_id == session_id, Episode.advised_steps > 0)
            .order_by(Episode.advised_steps.desc(), Episode.first_global_step)
        ).first()
        assert episode is not None
        span = (episode.first_global_step, episode.last_global_step)
        steps = list(
            db.execute(
                select(Step.episode_step, Step.action, Step.action_source, Step.reward)
                .where(Step.session_id == session_id, Step.global_step.between(*span))
                .order_by(Step.global_step)
            )
        )
        advice = list(
            db.scalars(
                select(Advice)
                .where(Advice.session_id == session_id, Advice.global_step.between(*span))
                .order_by(Advice.advice_index)
            )
        )
        db.expunge_all()
    return episode, steps, advice


def shown_step(page: Any) -> int:
    return int(page.locator("#step-number").inner_text())


def expect_step(page: Any, row: Any) -> None:
    """The page shows the logged step `row` (episode_step, action, source, reward)."""
    expect(page.locator("#step-number")).to_have_text(str(row.episode_step))
    expect(page.locator("#step-action")).to_have_text(sim.ACTION_NAMES[row.action])
    expect(page.locator("#step-source")).to_have_text(row.action_source)
    expect(page.locator("#step-reward")).to_have_text(f"{row.reward:.2f}")


def pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def wait_drawn(live: Live, playback_id: str, index: int, timeout: float = 120) -> None:
    """The playback's 3-D view shows the poses before step `index + 1`'s action."""
    playback = live.app.state.playbacks.get(playback_id, touch=False)
    rerun = playback.rerun
    wanted = rerun.start.poses if index == 0 else rerun.steps[index - 1].scene.poses
    viewer = live.app.state.playback_viewer
    deadline = time.monotonic() + timeout
    while True:
        views = [v for v in viewer.views(playback_id) if len(v.mirror.handles) >= 20]
        if views and viewer.remaining_s(playback_id) == 0:
            shown = views[0].mirror.positions()
            far = {
                n: float(np.linalg.norm(shown[n] - np.asarray(p.position)))
                for n, p in wanted.items()
                if n in shown
            }
            if max(far.values()) < CM:
                return
        assert time.monotonic() < deadline, (
            f"the 3-D view never drew the step shown: {len(viewer.views(playback_id))} views, "
            f"{[len(v.mirror.handles) for v in viewer.views(playback_id)]} bodies, "
            f"{viewer.refused} refused, {viewer.remaining_s(playback_id)} s to play"
        )
        time.sleep(0.1)


def test_a_researcher_plays_back_a_participants_episode(live: Live, browser: Any) -> None:
    session = live.human_session(
        "Playback", seed=4, motion="fast", episodes=1, max_episode_steps=15
    )
    with live.api() as api:
        assert api.post(f"/api/sessions/{session['id']}/start").status_code == 200
        live.begin(session)
        advise_all(live, session)
        wait_for_status(api, session["id"], {"finished"})
    episode, steps, advice = recorded(live, session["id"])
    assert len(advice) >= 2 and len(steps) >= 3

    context, page = dashboard_page(browser, live)
    expect(page).to_have_url(re.compile(r"/dashboard$"))
    page.locator(f"tr[data-session='{session['id']}'] a.playback-link").click()
    expect(page).to_have_url(re.compile(rf"/dashboard/sessions/{session['id']}/playback$"))
    expect(page.locator("h1")).to_contain_text(f"#{session['id']} human · {session['participant']}")
    page.select_option("#episode", f"{episode.stage}/{episode.episode}")
    page.click("#open")
    expect(page.locator("#player")).to_be_visible(timeout=120_000)
    expect_step(page, steps[0])
    playback_id = page.locator("#scene").get_attribute("data-socket").rsplit("/", 1)[1]
    wait_drawn(live, playback_id, 0)

    # Play, then pause: the step shown moves on, then stays.
    page.click("#play")
    expect(page.locator("#step-number")).not_to_have_text("1", timeout=30_000)
    page.click("#play")
    expect(page.locator("#play")).to_have_text("Play")
    paused = shown_step(page)
    page.wait_for_timeout(2000)  # longer than two played steps take
    assert shown_step(page) == paused
    expect_step(page, steps[paused - 1])

    # Step forward and back, each step as the database logged it.
    if paused < len(steps):
        page.click("#step-forward")
        expect_step(page, steps[paused])
    page.click("#step-back")
    page.click("#step-back")
    back = min(paused + 1, len(steps)) - 3
    expect_step(page, steps[back])
    wait_drawn(live, playback_id, back)

    # The advice turns as the participant saw them, with their decision times.
    rows = page.locator("#advice-list tr")
    expect(rows).to_have_count(len(advice))
    for row, given in zip(rows.all(), advice, strict=True):
        expect(row.locator(".advice-index")).to_have_text(f"#{given.advice_index + 1}")
        expect(row.locator(".decision-time")).to_have_text(f"{given.decision_time_s:.2f} s")
        expect(row.locator(".advice-action")).to_have_text(sim.ACTION_NAMES[given.action])
    assert [a.decision_time_s for a in advice] == [decision_time(a.advice_index) for a in advice]
    turn = advice[1]  # after the first advice: the robot holds something, as a rule
    index = turn.global_step - episode.first_global_step
    page.locator(f"#advice-list tr[data-advice='{turn.advice_index}']").click()
    expect_step(page, steps[index])
    expect(page.locator("#step-source")).to_have_text("advisor")
    expect(page.locator("#advice-number")).to_have_text(f"#{turn.advice_index + 1}")
    expect(page.locator("#step-advice")).to_contain_text(
        f"the participant chose {sim.ACTION_NAMES[turn.action]} after {turn.decision_time_s:.2f} s"
    )
    image = page.request.get(page.evaluate("document.getElementById('step-image').src"))
    assert image.ok and np.array_equal(pixels(image.body()), pixels(turn.observation_png))
    wait_drawn(live, playback_id, index)
    save_screenshot(page, "dashboard-playback", full_page=True)

    # The episode's end: the scene after the last action, which no step follows.
    page.locator("#scrub").fill(str(len(steps)))
    expect(page.locator("#step-number")).to_have_text("end")
    expect(page.locator("#step-action")).to_have_text("—")
    total = f"{episode.collected_reward:.2f}"
    expect(page.locator("#step-collected")).to_have_text(f"{total} of {total}")
    expect(page.locator("#step-forward")).to_be_disabled()
    assert abs(sum(row.reward for row in steps) - episode.collected_reward) < 1e-9
    wait_drawn(live, playback_id, len(steps))

    # Leaving the page closes the playback.
    assert playback_id in live.app.state.playbacks.open_ids()
    page.goto(f"{live.url}/dashboard")
    deadline = time.monotonic() + 30
    while playback_id in live.app.state.playbacks.open_ids():
        assert time.monotonic() < deadline, "the playback outlived its page"
        time.sleep(0.1)
    context.close()
