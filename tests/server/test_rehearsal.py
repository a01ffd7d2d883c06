"""A rehearsal: a fitted advisor (or evaluator) answers a human session through the
participant's HTTP calls, and the session stores its advice (or ratings) with the decision
times it drew."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import pytest

from cli.main import main
from learner.fitted import Count, FittedModel, fit
from learner.fitted_ratings import RatingSeen, SessionRatings, fit_ratings
from runs.rehearsal import fails_check, study_check
from study.schemas.design import Condition, StudyDesign
from tasks import get_task
from tasks.sorting import HELD
from tests.learner.test_fitted_tasks import recorded
from tests.server.live import API_KEY, LiveServer
from tests.server.scale import export, session_body, wait_for_status
from tests.study.test_visit import set_design

pytestmark = pytest.mark.slow
BUDGET = 5


def test_a_fitted_advisor_advises_a_human_session_through_its_link(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = FittedModel(
        advice=300, sessions=[1], methods=["human"], overall=Count(300, 0),
        by_group={h: Count(100, 0) for h in HELD}, by_situation={},
        wrong_actions=[[0] * 4 for _ in range(4)], decision_time_median_s=0.2,
        decision_time_sigma=0.3, decision_time_quantiles=[], budget_used=[1.0],
    )  # fmt: skip
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model.to_json()))
    study = api.post("/api/studies", json={"name": "rehearsal"}).json()
    body = session_body("human", advice_budget=BUDGET, pretraining_steps=16, episodes=1,
                        max_episode_steps=20)  # fmt: skip
    response = api.post(f"/api/studies/{study['id']}/sessions", json=body)
    assert response.status_code == 201, response.text
    created = response.json()
    link = f"{server.url}/p/{created['participant_token']}"

    code = main(["rehearse", "--model", str(path), "--link", link, "--speed", "4", "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    (done,) = json.loads(out)["participants"]
    assert done["advice"] == BUDGET and not done["left_early"]
    assert done["viewer_messages"] >= 1  # the view's socket was accepted with this link's token

    wait_for_status(api, created["id"], {"finished"})
    advice = api.get(f"/api/sessions/{created['id']}/advice").json()
    assert [a["advisor"] for a in advice] == ["human"] * BUDGET
    assert [a["decision_time_s"] for a in advice] == pytest.approx(done["decision_times_s"])
    waited = zip(advice, done["decision_times_s"], strict=True)
    assert all(a["response_time_s"] >= t / 4 for a, t in waited)  # it waited before answering


def test_a_rehearsal_compares_advice_and_ratings_through_their_links(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two conditions, advice against evaluation: the same fitted person advises one session
    and rates the other's moves (Good where it would have advised the move), each answer
    stored with its drawn decision time, the summary given per kind."""
    model = FittedModel(
        advice=300, sessions=[1], methods=["human"], overall=Count(300, 0),
        by_group={h: Count(100, 0) for h in HELD}, by_situation={},
        wrong_actions=[[0] * 4 for _ in range(4)], decision_time_median_s=0.2,
        decision_time_sigma=0.3, decision_time_quantiles=[], budget_used=[1.0],
    )  # fmt: skip
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model.to_json()))
    study = api.post("/api/studies", json={"name": "rehearsal by kind"}).json()
    made = {}
    for kind in ("advice", "evaluative"):
        body = session_body("human", advice_budget=BUDGET, pretraining_steps=16, episodes=1,
                            max_episode_steps=20, feedback=kind)  # fmt: skip
        response = api.post(f"/api/studies/{study['id']}/sessions", json=body)
        assert response.status_code == 201, response.text
        made[kind] = response.json()
    links = [f"{server.url}/p/{made[k]['participant_token']}" for k in ("advice", "evaluative")]

    argv = ["rehearse", "--model", str(path), "--speed", "4"]
    code = main([*argv, "--link", links[0], "--link", links[1], "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    advised, rated = json.loads(out)["participants"]
    assert advised["feedback"] == "advice" and rated["feedback"] == "evaluative"
    assert advised["advice"] == BUDGET and rated["advice"] + rated["lapsed"] == BUDGET

    wait_for_status(api, made["evaluative"]["id"], {"finished"})
    files = export(api, study["id"])
    rows = list(csv.DictReader(io.StringIO(files["feedback.csv"].decode())))
    assert [r["session_id"] for r in rows] == [str(made["evaluative"]["id"])] * BUDGET
    sent = [float(r["decision_time_s"]) for r in rows if r["decision_time_s"]]
    assert sent == pytest.approx(rated["decision_times_s"])
    assert all(r["judgement"] in ("1.0", "-1.0") for r in rows if r["decision_time_s"])
    advice = list(csv.DictReader(io.StringIO(files["advice.csv"].decode())))
    assert [r["session_id"] for r in advice] == [str(made["advice"]["id"])] * BUDGET


def test_an_online_study_of_advice_against_evaluation_is_rehearsed_through_its_link(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two conditions, advice and evaluative feedback: synthetic participants arrive through
    the study link with panel ids of their own, pass the check (the rating question in
    the evaluative condition), give their turns, answer the questionnaire and complete
    their visits; the summary and the export are per condition."""
    model = FittedModel(
        advice=300, sessions=[1], methods=["human"], overall=Count(300, 0),
        by_group={h: Count(100, 0) for h in HELD}, by_situation={},
        wrong_actions=[[0] * 4 for _ in range(4)], decision_time_median_s=0.2,
        decision_time_sigma=0.3, decision_time_quantiles=[], budget_used=[1.0],
    )  # fmt: skip
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model.to_json()))
    run = {"method": "human", "seed": 3, "config": {
        "pretraining_steps": 16, "batch_size": 8, "memory_size": 500, "episodes": 1,
        "max_episode_steps": 20, "advice_budget": BUDGET}}  # fmt: skip
    design = {
        "conditions": {"advice": {"run": run, "target": 1},
                       "evaluation": {"run": {**run, "feedback": "evaluative"}, "target": 1}},
        "panel": {"kind": "prolific", "codes": {"completed": "C-DONE"}},
    }  # fmt: skip
    made = api.post("/api/studies", json={"name": "advice or ratings", "design": design})
    assert made.status_code == 201, made.text
    study = made.json()
    link = server.url + urlsplit(study["join_url"]).path

    argv = ["rehearse", "--model", str(path), "--speed", "4", "--study-link", link]
    code = main([*argv, "--participants", "2", "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    done = json.loads(out)["participants"]
    assert sorted(r["feedback"] for r in done) == ["advice", "evaluative"]
    assert all(r["check_tries"] == 1 and r["questionnaire"] for r in done), done

    files = export(api, study["id"])
    sessions = list(csv.DictReader(io.StringIO(files["sessions.csv"].decode())))
    assert sorted(r["condition"] for r in sessions) == ["advice", "evaluation"]
    assert [r["outcome"] for r in sessions] == ["completed", "completed"]
    by_condition = {r["condition"]: r["session_id"] for r in sessions}
    feedback = list(csv.DictReader(io.StringIO(files["feedback.csv"].decode())))
    advice = list(csv.DictReader(io.StringIO(files["advice.csv"].decode())))
    assert {r["session_id"] for r in feedback} == {by_condition["evaluation"]}
    assert {r["session_id"] for r in advice} == {by_condition["advice"]}
    assert len(advice) == BUDGET and len(feedback) == BUDGET

    code = main([*argv, "--participants", "1", "--seed", "7"])  # a third panel id
    printed = capsys.readouterr()
    assert code == 1 and "did not admit" in printed.err + printed.out  # the study is full


def test_fitted_people_of_a_grid_world_study_rehearse_its_sessions(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The grid world's page shows frames, no ground truth: the simulated people advise
    its four moves as often as the fitted people did, with no 3-D view to keep open."""
    task = get_task("gridworld")
    model = fit(recorded("gridworld", 300), task=task)
    path = tmp_path / "grid.json"
    path.write_text(json.dumps(model.to_json()))
    study = api.post("/api/studies", json={"name": "grid world rehearsal"}).json()
    design = StudyDesign(conditions={"a": Condition(run={"method": "human", "task": "gridworld"})})
    set_design(server, study["id"], design.model_dump(mode="json"))
    body = session_body("human", task="gridworld", motion=None, advice_budget=BUDGET,
                        pretraining_steps=16, episodes=1, max_episode_steps=20)  # fmt: skip
    made = []
    for _ in range(2):
        response = api.post(f"/api/studies/{study['id']}/sessions", json=body)
        assert response.status_code == 201, response.text
        made.append(response.json())
    links = [a for m in made for a in ("--link", f"{server.url}/p/{m['participant_token']}")]

    code = main(["rehearse", "--model", str(path), *links, "--speed", "8", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    done = json.loads(out)["participants"]
    assert [d["advice"] for d in done] == [BUDGET, BUDGET]
    assert all(d["viewer_messages"] == 0 for d in done)
    for created, rehearsed in zip(made, done, strict=True):
        wait_for_status(api, created["id"], {"finished"})
        advice = api.get(f"/api/sessions/{created['id']}/advice").json()
        assert [a["advisor"] for a in advice] == ["human"] * BUDGET
        assert {a["action"] for a in advice} <= set(range(task.n_actions))
        assert [a["decision_time_s"] for a in advice] == pytest.approx(
            rehearsed["decision_times_s"]
        )


GRID_CHECK = {
    "tries": 2,
    "questions": [
        {"id": "goal_colour", "text": "What colour is the square the triangle must reach?",
         "choices": [{"value": "red", "label": "Red"}, {"value": "green", "label": "Green"},
                     {"value": "blue", "label": "Blue"}],
         "answer": "green"},
        {"id": "into_a_wall", "text": "What happens when the triangle walks into a wall?",
         "choices": [{"value": "ends", "label": "The round ends"},
                     {"value": "stays", "label": "It stays where it is"}],
         "answer": "stays"},
    ],
}  # fmt: skip
"""A researcher's own check for the grid world: neither right answer is the first choice,
so a participant who guessed would not pass at its first try."""


def grid_study_with_own_check(api: httpx.Client, name: str, target: int) -> dict[str, Any]:
    """An online grid world study `name` asking `GRID_CHECK`, with `target` places: its
    create body and the created study."""
    run = {"method": "human", "task": "gridworld", "seed": 3, "config": {
        "pretraining_steps": 16, "batch_size": 8, "memory_size": 500, "episodes": 1,
        "max_episode_steps": 20, "advice_budget": BUDGET}}  # fmt: skip
    body = {
        "name": name,
        "design": {"conditions": {"a": {"run": run, "target": target}}, "check": GRID_CHECK,
                   "panel": {"kind": "prolific", "codes": {"completed": "C-DONE"}}},
    }  # fmt: skip
    made = api.post("/api/studies", json=body)
    assert made.status_code == 201, made.text
    return {"body": body, "study": made.json()}


def test_a_study_s_own_check_is_passed_by_rehearsed_people_and_failed_by_their_share(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A grid world study with its own comprehension check: given the study's file, a
    rehearsed participant answers it right at its first try and goes on to its turns and
    the questionnaire; with a failure share of one half, the other answers it wrong on both
    tries and is excluded, as the check says, its session never started."""
    model = fit(recorded("gridworld", 300), task=get_task("gridworld"))
    path = tmp_path / "grid.json"
    path.write_text(json.dumps(model.to_json()))
    made = grid_study_with_own_check(api, "grid world, own check", 2)
    design_file = tmp_path / "study.yaml"
    design_file.write_text(json.dumps(made["body"]))  # JSON is YAML
    link = server.url + urlsplit(made["study"]["join_url"]).path

    argv = ["rehearse", "--model", str(path), "--speed", "8", "--study-link", link]
    code = main([*argv, "--participants", "2", "--design", str(design_file),
                 "--check-failures", "0.5", "--json"])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0, err
    passed, failed = json.loads(out)["participants"]
    assert passed["check_tries"] == 1
    assert passed["advice"] == BUDGET and passed["questionnaire"]
    assert failed["status"] == "excluded" and failed["check_tries"] == GRID_CHECK["tries"]
    assert failed["advice"] == 0 and not failed["questionnaire"]

    files = export(api, made["study"]["id"])
    sessions = list(csv.DictReader(io.StringIO(files["sessions.csv"].decode())))
    assert sorted(r["outcome"] for r in sessions) == ["completed", "excluded"]


def arrivals(api: httpx.Client, study_id: int) -> list[dict[str, Any]]:
    """The study's sessions that participants took (not its pools' waiting ones)."""
    found = api.get(f"/api/studies/{study_id}/sessions").json()
    return [s for s in found if not s["pooled"] and not s["preview"]]


def test_a_study_s_own_check_is_read_with_the_researcher_key_and_never_guessed(
    server: LiveServer,
    api: httpx.Client,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without the study's design or the researcher key, a rehearsal of a study with its
    own check stops at the first participant's check, before any answer, naming the
    questions it cannot answer (no other participant arrives); a key the server does not
    hold is refused before anyone arrives; with the key, the rehearsal reads the check
    from the study's design through the researcher API and passes it at its first try."""
    monkeypatch.delenv("IDEEPRL_API_KEY", raising=False)
    model = fit(recorded("gridworld", 300), task=get_task("gridworld"))
    path = tmp_path / "grid.json"
    path.write_text(json.dumps(model.to_json()))
    study = grid_study_with_own_check(api, "grid world, own check read", 2)["study"]
    link = server.url + urlsplit(study["join_url"]).path
    argv = ["rehearse", "--model", str(path), "--speed", "8", "--study-link", link, "--json"]

    code = main([*argv, "--participants", "3"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert "goal_colour ('What colour is the square the triangle must reach?')" in err, err
    assert "into_a_wall" in err and "does not guess" in err and "--api-key" in err
    (arrived,) = arrivals(api, study["id"])  # the first alone
    token = arrived["participant_url"].rpartition("/p/")[2]
    with server.client(key=None, token=token) as participant:
        check = participant.get("/api/participant/check").json()
    assert check["required"] and check["tries_used"] == 0 and not check["passed"]
    # the key finds a participant link's study too; a lab study's link asks no check
    read = study_check(f"{server.url}/p/{token}", API_KEY)
    assert read is not None and [q.id for q in read.questions] == ["goal_colour", "into_a_wall"]
    lab = api.post("/api/studies", json={"name": "lab, no check"}).json()
    body = session_body("human", advice_budget=BUDGET, pretraining_steps=16, episodes=1,
                        max_episode_steps=20)  # fmt: skip
    response = api.post(f"/api/studies/{lab['id']}/sessions", json=body)
    assert response.status_code == 201, response.text
    lab_link = f"{server.url}/p/{response.json()['participant_token']}"
    assert study_check(lab_link, API_KEY) is None

    assert main([*argv, "--participants", "1", "--api-key", "not-the-key"]) == 1
    assert "the server refused the researcher key (403)" in capsys.readouterr().err
    assert len(arrivals(api, study["id"])) == 1

    code = main([*argv, "--participants", "1", "--seed", "5", "--api-key", API_KEY])
    out, err = capsys.readouterr()
    assert code == 0, err
    (passed,) = json.loads(out)["participants"]
    assert passed["check_tries"] == 1 and passed["advice"] == BUDGET and passed["questionnaire"]


def test_the_failure_share_is_spread_evenly_and_bounded(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert [fails_check(i, 0.5) for i in range(4)] == [False, True, False, True]
    assert sum(fails_check(i, 0.3) for i in range(10)) == 3
    assert all(fails_check(i, 1.0) for i in range(5))
    assert not any(fails_check(i, 0.0) for i in range(5))
    argv = ["rehearse", "--model", "m.json", "--study-link", "http://127.0.0.1:9/join/x"]
    assert main([*argv, "--participants", "1", "--check-failures", "1.5"]) == 2
    assert "--check-failures takes a share from 0 to 1" in capsys.readouterr().err


def test_a_fitted_evaluator_rates_an_evaluative_session_through_its_link(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model fitted to ratings (`ideeprl fit` of evaluative sessions) rehearses an
    evaluative session: it rates every move (its people never let a turn pass), each
    rating stored with its drawn decision time; it cannot advise an advice session."""
    model = fit_ratings([SessionRatings(1, [RatingSeen("center", "nothing", True, 1.0, 0.2)] * 20)])
    path = tmp_path / "evaluator.json"
    path.write_text(json.dumps(model.to_json()))
    study = api.post("/api/studies", json={"name": "rehearsed evaluators"}).json()
    made = {}
    for kind in ("evaluative", "advice"):
        body = session_body("human", advice_budget=BUDGET, pretraining_steps=16, episodes=1,
                            max_episode_steps=20, feedback=kind)  # fmt: skip
        response = api.post(f"/api/studies/{study['id']}/sessions", json=body)
        assert response.status_code == 201, response.text
        made[kind] = response.json()
    link = f"{server.url}/p/{made['evaluative']['participant_token']}"
    code = main(["rehearse", "--model", str(path), "--link", link, "--speed", "4", "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    (rated,) = json.loads(out)["participants"]
    assert rated["feedback"] == "evaluative"
    assert (rated["advice"], rated["lapsed"]) == (BUDGET, 0)
    wait_for_status(api, made["evaluative"]["id"], {"finished"})
    rows = list(csv.DictReader(io.StringIO(export(api, study["id"])["feedback.csv"].decode())))
    assert [float(r["decision_time_s"]) for r in rows] == pytest.approx(rated["decision_times_s"])
    assert all(r["judgement"] in ("1.0", "-1.0") for r in rows)

    advice_link = f"{server.url}/p/{made['advice']['participant_token']}"
    code = main(["rehearse", "--model", str(path), "--link", advice_link, "--speed", "4"])
    out = capsys.readouterr()
    assert code != 0 and "fitted to ratings" in out.out + out.err
