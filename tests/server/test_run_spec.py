"""A run's strategy options, given through REST, reach the trainer; options a strategy
does not take are refused before anything is stored."""

from __future__ import annotations

import httpx
import pytest

from tests.server.scale import SMALL_CONFIG, session_body, wait_for_status


def test_a_sessions_strategy_options_reach_its_trainer(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "strategy-options"}).json()
    body = session_body(
        "random", strategy="alternating", strategy_options={"interval": 3}, advice_budget=6
    )
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body)
    assert created.status_code == 201, created.text
    session = created.json()
    assert session["run"]["strategy_options"] == {"interval": 3, "threshold": None}
    assert api.post(f"/api/sessions/{session['id']}/start").status_code == 200
    wait_for_status(api, session["id"], {"finished"})
    advice = api.get(f"/api/sessions/{session['id']}/advice").json()
    training = [a["global_step"] - SMALL_CONFIG["pretraining_steps"] for a in advice]
    assert len(training) >= 2, training
    assert all((t - 1) % 3 == 0 for t in training), training  # 1, 4, 7, ...: every third


@pytest.mark.parametrize(
    ("strategy", "options"),
    [
        ("alternating", {"threshold": 0.2}),
        ("early", {"interval": 2}),
        ("alternating", {"interval": 0}),
    ],
)
def test_options_a_strategy_does_not_take_are_422(
    api: httpx.Client, strategy: str, options: dict[str, float]
) -> None:
    study = api.post("/api/studies", json={"name": f"bad-options-{strategy}-{options}"}).json()
    body = session_body("random", strategy=strategy, strategy_options=options, advice_budget=5)
    response = api.post(f"/api/studies/{study['id']}/sessions", json=body)
    assert response.status_code == 422, response.text
    assert "strategy_options" in str(response.json()["detail"][0]["loc"])
