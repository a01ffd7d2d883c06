"""A study's fitted advisor models through the researcher API, and a session naming one
by its id (`fitted:ID`), which the server resolves to the model's file."""

from __future__ import annotations

from pathlib import Path

import httpx

from learner.fitted import Count, FittedModel
from study.db.engine import make_engine, make_session_factory
from study.db.models import FittedAdvisorModel
from tasks.sorting import HELD
from tests.server.live import LiveServer
from tests.server.scale import session_body


def test_a_studys_fitted_models_are_listed_read_and_named_by_sessions(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "fitted models"}).json()["id"]
    other = api.post("/api/studies", json={"name": "fitted models elsewhere"}).json()["id"]
    model = FittedModel(
        advice=200, sessions=[1], methods=["human"], overall=Count(200, 20),
        by_group={h: Count(60, 4) for h in HELD}, by_situation={"center/blue": Count(30, 6)},
        wrong_actions=[[0] * 4 for _ in range(4)], decision_time_median_s=2.0,
        decision_time_sigma=0.4, decision_time_quantiles=[], budget_used=[1.0, 0.5],
    )  # fmt: skip
    engine = make_engine(server.database_url)
    with make_session_factory(engine)() as db:
        row = FittedAdvisorModel(study_id=study, model=model.to_json(), session_ids=[])
        db.add(row)
        db.commit()
        fitted_id = row.id
    engine.dispose()

    (listed,) = api.get(f"/api/studies/{study}/fitted").json()
    assert listed["id"] == fitted_id and listed["model"] == model.to_json()
    assert listed["summary"]["stop_early_rate"] == 0.5
    assert listed["summary"]["error_rate_by_situation"]["center/blue"] == round(
        model.error_rate("center", "blue"), 4
    )
    assert api.get(f"/api/studies/{study}/fitted/{fitted_id}").json() == listed
    assert api.get(f"/api/studies/{other}/fitted").json() == []
    assert api.get(f"/api/studies/{other}/fitted/{fitted_id}").status_code == 404
    assert api.get(f"/api/studies/{study}/fitted/{2**40}").status_code == 422

    body = session_body("fitted", fitted_model=f"fitted:{fitted_id}", advice_budget=10)
    created = api.post(f"/api/studies/{study}/sessions", json=body)
    assert created.status_code == 201, created.text
    path = Path(created.json()["run"]["fitted_model"])
    assert path.is_relative_to(server.data_dir.resolve()) and path.is_file()
    for name, words in ((f"fitted:{2**40}", "no stored model"), ("/etc/hosts", "data folder")):
        body = session_body("fitted", fitted_model=name, advice_budget=10)
        refused = api.post(f"/api/studies/{study}/sessions", json=body)
        assert refused.status_code == 422 and words in refused.text, refused.text
    missing = api.post(f"/api/studies/{study}/sessions", json=session_body("fitted"))
    assert missing.status_code == 422 and "needs fitted_model" in missing.text


def _store(server: LiveServer, study: int, session_ids: list[int]) -> int:
    model = FittedModel(
        advice=1, sessions=session_ids, methods=["human"], overall=Count(1, 0), by_group={},
        by_situation={}, wrong_actions=[[0] * 4 for _ in range(4)],
        decision_time_median_s=None, decision_time_sigma=None, decision_time_quantiles=[],
        budget_used=[1.0],
    )  # fmt: skip
    engine = make_engine(server.database_url)
    with make_session_factory(engine)() as db:
        row = FittedAdvisorModel(study_id=study, model=model.to_json(), session_ids=session_ids)
        db.add(row)
        db.commit()
        fitted_id = row.id
    engine.dispose()
    return fitted_id


def _fitted_run(api: httpx.Client, study: int, fitted_id: int) -> int:
    """A `fitted` session advised by the stored model (created, not run)."""
    body = session_body("fitted", fitted_model=f"fitted:{fitted_id}", advice_budget=10)
    created = api.post(f"/api/studies/{study}/sessions", json=body)
    assert created.status_code == 201, created.text
    return int(created.json()["id"])


def test_deleting_a_participants_session_or_the_study_deletes_the_models_fitted_from_them(
    server: LiveServer, api: httpx.Client
) -> None:
    """...and the `fitted` runs those models advised, in any study: a person's advice lives
    on in them as it does in the model (and their reports would count agents whose model is
    gone, which no resume can finish)."""
    study = api.post("/api/studies", json={"name": "fitted deletion"}).json()["id"]
    elsewhere = api.post("/api/studies", json={"name": "fitted deletion, runs"}).json()["id"]
    ids = []
    for person in ("P1", "P2"):
        body = session_body("human", participant=person, advice_budget=10)
        ids.append(api.post(f"/api/studies/{study}/sessions", json=body).json()["id"])
    from_p1 = _store(server, study, [ids[0]])
    from_both = _store(server, study, ids)
    from_p2 = _store(server, study, [ids[1]])
    p1_runs = [_fitted_run(api, s, m) for s in (study, elsewhere) for m in (from_p1, from_both)]
    p2_runs = [_fitted_run(api, s, from_p2) for s in (study, elsewhere)]
    assert api.delete(f"/api/sessions/{ids[0]}").status_code == 204  # P1's data goes
    left = [m["id"] for m in api.get(f"/api/studies/{study}/fitted").json()]
    assert left == [from_p2] and from_p1 not in left and from_both not in left
    for run in p1_runs:
        assert api.get(f"/api/sessions/{run}").status_code == 404, run
    for run in p2_runs:
        assert api.get(f"/api/sessions/{run}").status_code == 200, run
    assert api.delete(f"/api/studies/{study}").status_code == 204
    engine = make_engine(server.database_url)
    with make_session_factory(engine)() as db:
        assert db.get(FittedAdvisorModel, from_p2) is None
    engine.dispose()
    assert api.get(f"/api/sessions/{p2_runs[1]}").status_code == 404, "P2's run elsewhere"
    assert api.get(f"/api/studies/{elsewhere}").status_code == 200
