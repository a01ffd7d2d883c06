"""The REST session body and the learner's run description (`learner.run.RunSpec`) cannot
drift apart, and a strategy's options given through REST reach the trainer."""

from __future__ import annotations

import dataclasses
import typing

import httpx
import pytest

from learner.run import MOTIONS, STRATEGY_OPTIONS, RunSpec
from learner.strategies import STRATEGY_NAMES
from server.schemas.sessions import Scenario, SessionCreate, StrategyOptions
from server.services import learning
from sim.scenario import ScenarioOptions
from tests.server.scale import SMALL_CONFIG, session_body, wait_for_status

REST_FIELD = {
    "seed": "seed",
    "config": "config",  # with preset, episodes, max_episode_steps, advice_budget
    "preset": "preset",
    "advisor": "method",
    "advisor_checkpoint": "advisor_checkpoint",
    "error_rate": "oracle_error_rate",
    "strategy": "strategy",
    "strategy_options": "strategy_options",
    "budget": "advice_budget",
    "motion": "motion",
    "sort_rule": "sort_rule",
    "scenario": "scenario",
    "learner": "method",  # sb3-dqn's method picks Stable-Baselines3's learner
    "sb3": "config",  # its sb3_* settings are mapped from the config
}
"""Where each of the run's fields is set in the REST body."""
NOT_THE_RUN = {"label", "participant", "keep_replay_memory", "idle_limit_s"}
"""Body fields that name a session or govern its worker, not the run's course."""
CONFIG_FIELDS = {"episodes", "max_episode_steps"}


def test_every_run_field_has_its_rest_field_and_back() -> None:
    ours = {f.name for f in dataclasses.fields(RunSpec)}
    assert ours == set(REST_FIELD), "a RunSpec field the REST body cannot set (or one gone)"
    rest = set(SessionCreate.model_fields)
    assert rest == set(REST_FIELD.values()) | NOT_THE_RUN | CONFIG_FIELDS
    options = {name for defaults in STRATEGY_OPTIONS.values() for name in defaults}
    assert set(StrategyOptions.model_fields) == options
    assert typing.get_args(SessionCreate.model_fields["strategy"].annotation) == STRATEGY_NAMES
    motion = SessionCreate.model_fields["motion"].annotation
    assert typing.get_args(typing.get_args(motion)[0]) == MOTIONS
    assert set(Scenario.model_fields) == {f.name for f in dataclasses.fields(ScenarioOptions)}


def _row(method: str, **columns: object) -> object:
    """A stand-in for a session row: the columns `learning.spec_of` reads."""
    return type("Row", (), {"method": method, **columns})()


def test_a_stored_session_reads_back_as_the_run_it_was_created_from() -> None:
    body = SessionCreate(
        **session_body("random", strategy="alternating", strategy_options={"interval": 3})
    )
    spec = learning.spec_from_body(body)
    assert spec.strategy_options == {"interval": 3}
    back = learning.spec_of(_row("random", **learning.stored(spec)))
    assert learning.identity("random", back) == learning.identity("random", spec)
    assert back.make_strategy().interval == 3  # type: ignore[union-attr]


def test_a_session_stored_before_strategy_options_is_the_run_of_their_defaults() -> None:
    """Rows written before migration 0006 hold NULL: the batch must still find them."""
    body = SessionCreate(**session_body("random", strategy="alternating"))
    spec = learning.spec_from_body(body)
    old = _row("random", **{**learning.stored(spec), "strategy_options": None})
    assert learning.session_identity(old) == learning.identity("random", spec)  # type: ignore[arg-type]
    other = learning.spec_from_body(
        body.model_copy(update={"strategy_options": StrategyOptions(interval=3)})
    )
    assert learning.session_identity(old) != learning.identity("random", other)  # type: ignore[arg-type]


def test_a_sessions_strategy_options_reach_its_trainer(api: httpx.Client) -> None:
    study = api.post("/api/studies", json={"name": "strategy-options"}).json()
    body = session_body(
        "random", strategy="alternating", strategy_options={"interval": 3}, advice_budget=6
    )
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body)
    assert created.status_code == 201, created.text
    session = created.json()
    assert session["strategy_options"] == {"interval": 3}
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
