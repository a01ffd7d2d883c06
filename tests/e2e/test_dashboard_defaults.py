"""The dashboard's defaults follow the study, in Chromium: the report's `auto` baseline says
what it takes (no autonomous sessions: none), every session's curve has its own colour
however many there are, and a pool's sessions, nobody's yet, offer no Pause or Stop."""

from __future__ import annotations

import time
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.e2e.conftest import Live, dashboard_page
from tests.e2e.test_online_study import design, make_study
from tests.server.scale import session_body

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def _study(live: Live, name: str, methods: list[str]) -> int:
    with live.api() as api:
        study = int(api.post("/api/studies", json={"name": name}).json()["id"])
        for i, method in enumerate(methods):
            body = session_body(method, seed=i, advice_budget=3)
            made = api.post(
                f"/api/studies/{study}/sessions", params={"pretrain": "false"}, json=body
            )
            assert made.status_code == 201, made.text
    return study


def test_the_auto_baseline_says_what_it_takes_in_this_study(live: Live, browser: Any) -> None:
    people = _study(live, "Baseline: people only", ["human", "oracle"])
    with_deeprl = _study(live, "Baseline: with DeepRL", ["human", "autonomous"])
    context, page = dashboard_page(browser, live)
    for study, words in ((people, "auto (none: no autonomous sessions)"),
                         (with_deeprl, "auto (autonomous)")):  # fmt: skip
        select = page.locator(f"section.study[data-study='{study}'] .report-baseline")
        expect(select.locator("option").nth(1)).to_have_text("none")
        expect(select.locator("option:checked")).to_have_text(words)
    context.close()


def test_every_session_has_its_own_colour(live: Live, browser: Any) -> None:
    study = _study(live, "Colours", ["oracle"] * 14)
    context, page = dashboard_page(browser, live)
    swatches = page.locator(f"section.study[data-study='{study}'] table.sessions .swatch")
    expect(swatches).to_have_count(14)
    colours = swatches.evaluate_all("all => all.map((s) => getComputedStyle(s).backgroundColor)")
    assert len(set(colours)) == 14, colours
    context.close()


def test_a_pools_session_offers_no_pause_or_stop(live: Live, browser: Any) -> None:
    study = make_study(live, "Dashboard: a pool", target=2, capacity=2, idle_limit_s=600)
    with live.api() as api:
        pooled = {**design(target=2, capacity=2, idle_limit_s=600), "pool": 1}
        pooled["conditions"].pop("alternating")
        changed = api.patch(f"/api/studies/{study['id']}", json={"design": pooled})
        assert changed.status_code == 200, changed.text
        deadline = time.monotonic() + 120
        while not any(
            s["pooled"] and s["status"] == "running"
            for s in api.get(f"/api/studies/{study['id']}/sessions").json()
        ):
            assert time.monotonic() < deadline, "the pool made no session"
            time.sleep(0.5)
    context, page = dashboard_page(browser, live)
    rows = page.locator(f"section.study[data-study='{study['id']}'] table.sessions tbody tr")
    row = rows.filter(has_text="kept for the next arrival")
    expect(row).to_have_count(1, timeout=60_000)
    expect(row.locator("button.command")).to_have_count(0)
    context.close()
    with live.api() as api:
        assert api.delete(f"/api/studies/{study['id']}").status_code == 204
