"""An online study run through its one public link, in Chromium through nginx as deployed:
arrivals with Prolific's URL parameters assigned by the study's seeded blocks, a decline
that frees its worker at once and sends the participant back with the declined code, the
same panel id coming back to its own session, a full study turning the next arrival away
with the full code, an idle visit timing out with its place refilled, and the dashboard's
per-condition counts.

The excluded-by-check and completed-with-questionnaire journeys go through the visit pages
(comprehension check, questionnaire): they slot in as more participants of `study`.
"""

from __future__ import annotations

import io
import json
import re
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlencode, urlsplit

import pytest
from playwright.sync_api import expect

from study.db.models import Study
from study.services.assignment import block_order
from tests.e2e.conftest import VIEWPORT, Live, dashboard_page, save_screenshot
from tests.server.test_online_study import table
from tests.study.test_export_types import check_frictionless

pytestmark = [pytest.mark.browser, pytest.mark.slow]

RUN = {
    "method": "human",
    "seed": 3,
    "config": {
        "pretraining_steps": 12,
        "batch_size": 8,
        "memory_size": 500,
        "episodes": 2,
        "max_episode_steps": 25,
        "advice_budget": 6,
    },
    "motion": "fast",
}
CODES = {
    "completed": "C0MPL3TE",
    "declined": "D3CL1NED",
    "excluded": "EXCLUD3D",
    "timed_out": "T1MEDOUT",
    "full": "FULLFULL",
}
PROLIFIC = "https://app.prolific.com/**"


def design(target: int, capacity: int, idle_limit_s: float) -> dict[str, Any]:
    return {
        "conditions": {
            "early": {"run": {**RUN, "strategy": "early"}, "target": target},
            "alternating": {"run": {**RUN, "strategy": "alternating"}, "target": target},
        },
        "capacity": capacity,
        "pool": 0,
        "idle_limit_s": idle_limit_s,
        "panel": {"kind": "prolific", "codes": CODES, "return_delay_s": 1},
    }


def make_study(live: Live, name: str, **changes: Any) -> dict[str, Any]:
    with live.api() as api:
        made = api.post("/api/studies", json={"name": name, "design": design(**changes)})
        assert made.status_code == 201, made.text
        study = made.json()
    assert study["join_url"].startswith(live.url + "/join/"), "the link goes through nginx"
    return study


class Arrivals:
    """Each participant in a browser context of their own (their own cookies); Prolific's
    pages answered here, so a return to Prolific is seen without leaving the machine."""

    def __init__(self, browser: Any) -> None:
        self.browser = browser
        self.contexts: list[Any] = []

    def arrive(self, study: dict[str, Any], pid: str) -> Any:
        context = self.browser.new_context(viewport=VIEWPORT)
        context.route(PROLIFIC, lambda route: route.fulfill(body="<p>Back at Prolific</p>"))
        self.contexts.append(context)
        page = context.new_page()
        query = urlencode({"PROLIFIC_PID": pid, "STUDY_ID": "st-1", "SESSION_ID": f"se-{pid}"})
        page.goto(f"{study['join_url']}?{query}")
        return page

    def close(self) -> None:
        for context in self.contexts:
            context.close()


@pytest.fixture
def arrivals(browser: Any) -> Iterator[Arrivals]:
    made = Arrivals(browser)
    yield made
    made.close()


def token(page: Any) -> str:
    found = re.search(r"/p/([^/]+)/", urlsplit(page.url).path)
    assert found, page.url
    return found.group(1)


def sessions_by_token(live: Live, study: dict[str, Any]) -> dict[str, dict[str, Any]]:
    with live.api() as api:
        found = api.get(f"/api/studies/{study['id']}/sessions").json()
    return {s["participant_url"].rsplit("/", 1)[1]: s for s in found}


def seed_of(live: Live, study: dict[str, Any]) -> int:
    with live.app.state.session_factory() as db:
        return int(db.get(Study, study["id"]).assignment_seed)


def exported(live: Live, study: dict[str, Any], folder: Path) -> Path:
    with live.api() as api:
        response = api.get(f"/api/studies/{study['id']}/export")
    assert response.status_code == 200, response.text
    zipfile.ZipFile(io.BytesIO(response.content)).extractall(folder)
    return folder


def assert_returned(page: Any, outcome: str) -> None:
    """The outcome page shows its code, then sends the participant to Prolific with it."""
    expect(page.locator("[data-page=end]")).to_have_attribute("data-outcome", outcome)
    expect(page.locator("#outcome-code")).to_have_text(CODES[outcome])
    page.wait_for_url(f"https://app.prolific.com/submissions/complete?cc={CODES[outcome]}")


def test_an_online_study_runs_through_its_link(
    live: Live, browser: Any, arrivals: Arrivals, tmp_path: Path
) -> None:
    study = make_study(live, "Online: early or alternating", target=3, capacity=6, idle_limit_s=600)
    pages = [arrivals.arrive(study, f"PID{i}") for i in range(6)]
    for page in pages:
        expect(page.locator("[data-page=consent]")).to_be_visible()
    tokens = [token(page) for page in pages]
    made = sessions_by_token(live, study)
    seed = seed_of(live, study)
    order = [c for block in range(3) for c in block_order(seed, block, ["alternating", "early"])]
    assert [made[t]["condition"] for t in tokens] == order, "assigned in the seed's order"
    save_screenshot(pages[0], "online-join-consent")

    turned_away = arrivals.arrive(study, "PID6")
    expect(turned_away.locator("[data-page=end]")).to_have_attribute("data-outcome", "full")
    save_screenshot(turned_away, "online-full")
    assert_returned(turned_away, "full")
    assert len(sessions_by_token(live, study)) == 6, "the 7th arrival got no session"

    again = arrivals.arrive(study, "PID1")
    expect(again.locator("[data-page=consent]")).to_be_visible()
    assert token(again) == tokens[1], "the same panel id gets its own session again"

    decliner = pages[0]
    session_id = made[tokens[0]]["id"]
    handle = live.app.state.manager.handles[session_id]
    assert handle.process.is_alive(), "opening the link started the session's worker"
    clicked = time.monotonic()
    decliner.click("#decline")
    while handle.process.is_alive():
        assert time.monotonic() - clicked < 60, "the decliner's worker still runs"
        time.sleep(0.01)
    freed_s = time.monotonic() - clicked
    print(f"\ndecline to worker gone: {freed_s * 1000:.0f} ms (pid {handle.process.pid})")
    expect(decliner.locator("#outcome-code")).to_have_text(CODES["declined"])
    save_screenshot(decliner, "online-declined")
    assert_returned(decliner, "declined")
    assert sessions_by_token(live, study)[tokens[0]]["status"] == "declined"
    back = arrivals.arrive(study, "PID0")
    expect(back.locator("#outcome-code")).to_have_text(CODES["declined"])

    refill = arrivals.arrive(study, "PID7")
    expect(refill.locator("[data-page=consent]")).to_be_visible()
    now = sessions_by_token(live, study)
    assert now[token(refill)]["condition"] == now[tokens[0]]["condition"], "the freed place"

    dashboard, page = dashboard_page(browser, live)
    section = page.locator(f"section.study[data-study='{study['id']}']")
    declined_in = now[tokens[0]]["condition"]
    row = section.locator(f".conditions tr[data-condition='{declined_in}'] td")
    expect(row).to_have_text([declined_in, "3", "0", "3", "1", "0", "0"])
    badge = section.locator(f"tr[data-session='{session_id}'] .badge")
    expect(badge).to_have_text("declined")
    save_screenshot(page, "online-dashboard")
    section.locator(".design-editor summary").click()
    editor = section.locator(".design-json")
    shown = json.loads(editor.input_value())
    assert shown["panel"]["codes"] == CODES and shown["capacity"] == 6
    editor.fill(json.dumps({**shown, "capacity": "lots"}))
    section.locator(".save-design").click()
    refused = section.locator(".design-error")
    expect(refused).to_be_visible()
    expect(refused).to_contain_text("design.capacity: Input should be a valid integer")
    editor.fill(json.dumps({**shown, "capacity": 8}))
    section.locator(".save-design").click()
    expect(editor).to_have_value(re.compile(r'"capacity": 8'))
    expect(refused).to_be_hidden(timeout=30_000)  # the save's round trip, beside the pools' work
    with live.api() as api:
        stored = api.get(f"/api/studies/{study['id']}").json()["design"]
    assert stored == {**shown, "capacity": 8}, "the design edited on the dashboard, stored"

    with dashboard.expect_page() as opened:
        section.locator("button.preview").click()
    preview = opened.value
    expect(preview.locator("[data-page=consent]")).to_be_visible()
    previewed = sessions_by_token(live, study)[token(preview)]
    assert previewed["preview"] and len(sessions_by_token(live, study)) == 8
    expect(row).to_have_text([declined_in, "3", "0", "3", "1", "0", "0"]), "it takes no place"
    section.locator("button.delete-previews").click()
    expect(section.locator(f"tr[data-session='{previewed['id']}']")).to_have_count(0)
    assert len(sessions_by_token(live, study)) == 7
    dashboard.close()

    folder = exported(live, study, tmp_path)
    check_frictionless(folder)
    rows = {name: table(folder, name) for name in ("sessions", "assignments", "panel_ids")}
    assert len(rows["sessions"]) == len(rows["assignments"]) == len(rows["panel_ids"]) == 7
    outcomes = {r["session_id"]: r["outcome"] for r in rows["sessions"]}
    assert outcomes[str(session_id)] == "declined"
    assert [r["refills_session_id"] for r in rows["assignments"]].count(str(session_id)) == 1
    assert not {f"PID{i}" for i in range(8)} & {r["panel_id"] for r in rows["panel_ids"]}


def test_an_idle_visit_times_out_and_its_place_is_refilled(
    live: Live, browser: Any, arrivals: Arrivals
) -> None:
    study = make_study(live, "Online: idle", target=1, capacity=2, idle_limit_s=2)
    idle = arrivals.arrive(study, "IDLE1")
    expect(idle.locator("[data-page=consent]")).to_be_visible()
    left = token(idle)
    deadline = time.monotonic() + 180
    while sessions_by_token(live, study)[left]["outcome"] is None:
        assert time.monotonic() < deadline, "the idle visit never timed out"
        time.sleep(0.5)
    assert sessions_by_token(live, study)[left]["status"] == "timed_out"
    idle.reload()
    assert_returned(idle, "timed_out")
    refill = arrivals.arrive(study, "IDLE2")
    expect(refill.locator("[data-page=consent]")).to_be_visible()
    now = sessions_by_token(live, study)
    assert now[token(refill)]["condition"] == now[left]["condition"], "the freed place"


def test_a_pools_session_is_nobodys_on_the_dashboard(live: Live, browser: Any) -> None:
    """A pool's session practises for the next arrival: its row says so, asks no consent of
    anyone and offers no link to hand out (the study link gives it, as the blocks assign);
    deleting the study ends it rather than being refused."""
    study = make_study(live, "Online: with a pool", target=2, capacity=2, idle_limit_s=600)
    with live.api() as api:
        pooled = api.patch(
            f"/api/studies/{study['id']}",
            json={"design": {**design(target=2, capacity=2, idle_limit_s=600), "pool": 1}},
        )
        assert pooled.status_code == 200, pooled.text
    context, page = dashboard_page(browser, live)
    section = page.locator(f"section.study[data-study='{study['id']}']")
    rows = section.locator("table.sessions tbody tr")
    expect(rows).to_have_count(2, timeout=60_000)
    for condition in ("early", "alternating"):
        row = rows.filter(has_text=f"kept for the next arrival in {condition}")
        expect(row).to_have_count(1)
        expect(row).not_to_contain_text("not consented")
        expect(row.locator("td").nth(4)).to_have_text("the study link's")
        expect(row.locator("td").nth(4).locator("a")).to_have_count(0)
    context.close()
    with live.api() as api:
        gone = api.delete(f"/api/studies/{study['id']}")
        assert gone.status_code == 204, gone.text
