"""Scenario options (reward scheme, realism) from the REST body to the environment."""

from __future__ import annotations

import io

import httpx
import pandas as pd

from learner.run import RunSpec
from tests.server.scale import export, session_body, wait_for_status


def test_a_session_runs_under_its_scenario_options(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "scenario"}).json()
    scenario = {"reward_scheme": "authors-interactive", "knock_off_rate": 0.25}
    created = api.post(
        f"/api/studies/{study['id']}/sessions",
        json=session_body("autonomous", scenario=scenario),
    )
    assert created.status_code == 201, created.text
    session = created.json()
    assert session["run"]["scenario"] == {**scenario, "grasp_failure_rate": 0.0}
    env = RunSpec.from_json(session["run"]).make_env()
    assert (env.reward_scheme, env.knock_off_rate) == ("authors-interactive", 0.25)
    env.close()
    assert api.post(f"/api/sessions/{session['id']}/start").status_code == 200
    wait_for_status(api, session["id"], {"finished"})
    episodes = api.get(f"/api/sessions/{session['id']}/episodes").json()
    assert any(e["lost"] > 0 for e in episodes), "knock-offs at 0.25 lose objects"
    steps = pd.read_csv(io.BytesIO(export(api, study["id"])["steps.csv"]))
    train = steps[steps["stage"] == "train"]
    costs = train.loc[(train["reward"] <= 0) & ~train["terminated"].astype(bool), "reward"]
    assert len(costs) and (costs == -0.01).all()  # flat -0.01 from step 1, never 0
    assert (train["episode_step"] <= 18).any()


def test_bad_scenario_options_are_422(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "bad-scenario"}).json()
    for scenario in (
        {"reward_scheme": "keras"},
        {"knock_off_rate": 1.5},
        {"grasp_failure_rate": -0.1},
        {"surprise": 1},
    ):
        response = api.post(
            f"/api/studies/{study['id']}/sessions",
            json=session_body("autonomous", scenario=scenario),
        )
        assert response.status_code == 422, (scenario, response.text)
