"""An online study's visit around the advice: the comprehension check after the induction
(graded under the session's own sort rule, its last wrong try ending the visit as
excluded, the start refused until it is passed), the questionnaire after the advice (every
item's answer checked, stored once, scored as the instruments define), the export's
tables of both, and a lab study left exactly as it was."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from pydantic import ValidationError
from sqlalchemy import func, select, update

from sim.rules import SortRule
from study.db.engine import make_engine, make_session_factory
from study.db.models import CheckAttempt, QuestionnaireAnswer, Study, StudySession
from study.schemas.design import Condition, StudyDesign
from study.schemas.instruments import score_nasa_tlx, score_trust
from study.schemas.visit import CheckSpec, Item, QuestionnaireSpec
from study.services.visit import expected_answer
from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import export, session_body, wait_for_status
from tests.study.test_export_types import check_frictionless

ONE_CONDITION = {"a": Condition()}
"""A design's one condition (human advice, defaults); these sessions are made by hand."""

TLX = {"mental": 70, "physical": 10, "temporal": 55, "performance": 30, "effort": 65,
       "frustration": 40}  # fmt: skip
"""Hand-computed: (70 + 10 + 55 + 30 + 65 + 40) / 6 = 270 / 6 = 45."""
TRUST = [2, 1, 3, 2, 1, 6, 5, 6, 7, 6, 5, 4]
"""Hand-computed: items 1-5 reversed (8 - x) give 6 7 5 6 7 = 31, items 6-12 sum to 39;
(31 + 39) / 12 = 70 / 12."""


def trust_answers() -> dict[str, int]:
    return {f"item_{n:02d}": value for n, value in enumerate(TRUST, start=1)}


# --- the instruments and the specs, torch-free -------------------------------------------
def test_nasa_tlx_raw_is_the_unweighted_mean_of_the_six_subscales() -> None:
    assert score_nasa_tlx(TLX) == 45.0
    assert score_nasa_tlx({**TLX, "effort": None}) is None, "a scale needs every subscale"


def test_trust_reverses_the_five_distrust_items_before_the_mean() -> None:
    assert score_trust(trust_answers()) == pytest.approx(70 / 12)
    assert score_trust({k: 4 for k in trust_answers()}) == 4.0, "4 is its own reverse"
    assert score_trust({k: 7 for k in trust_answers()}) == pytest.approx((5 * 1 + 7 * 7) / 12)
    assert score_trust({**trust_answers(), "item_12": None}) is None


@pytest.mark.parametrize(
    ("rule", "blue_cube", "red_disk"),
    [("color", "right", "left"), ("shape", "left", "right"),
     ({**{f"{s}/{c}": "left" for s in ("cube", "cylinder", "disk") for c in ("red", "blue")},
       "cube/blue": "left", "disk/red": "right"}, "left", "right")],
)  # fmt: skip
def test_the_default_check_takes_its_answers_from_the_sessions_rule(
    rule: Any, blue_cube: str, red_disk: str
) -> None:
    questions = {q.id: q for q in CheckSpec.default().questions}
    parsed = SortRule.parse(rule)
    assert expected_answer(questions["blue_cube"], parsed) == blue_cube
    assert expected_answer(questions["red_disk"], parsed) == red_disk
    assert expected_answer(questions["drop_at_centre"], parsed) == "keep", "SPEC 1: drop"
    assert CheckSpec.default().tries == 2


CHOICES = [{"value": "a", "label": "A"}, {"value": "b", "label": "B"}]


@pytest.mark.parametrize(
    ("spec", "kind", "message"),
    [
        ({"questions": [{"id": "q", "text": "?", "choices": CHOICES, "answer": "c"}]},
         CheckSpec, "answer 'c' is not a choice value"),
        ({"questions": [{"id": "q", "text": "?", "choices": CHOICES}]},
         CheckSpec, "give either `answer` or `side_of`"),
        ({"questions": [{"id": "q", "text": "?", "choices": CHOICES, "side_of": "cube/green"}]},
         CheckSpec, "is not an object"),
        ({"questions": [{"id": "q", "text": "?", "choices": CHOICES, "side_of": "cube/red"}]},
         CheckSpec, "need the values left and right"),
        ({"tries": 0}, CheckSpec, "greater than or equal to 1"),
        ({"id": "x", "kind": "likert", "text": "?", "points": 5}, Item, "needs `anchors`"),
        ({"id": "x", "kind": "likert", "text": "?", "points": 5, "anchors": ["a", "b", "c"]},
         Item, "the two ends or each of the 5 points"),
        ({"id": "x", "kind": "number", "text": "?", "minimum": 5, "maximum": 1}, Item,
         "minimum must be below maximum"),
        ({"id": "x", "kind": "text", "text": "?", "choices": ["a", "b"]}, Item,
         "a text item takes no `choices`"),
        ({"id": "Bad id", "kind": "text", "text": "?"}, Item, "should match pattern"),
        ({"nasa_tlx": False, "trust": False, "demographics": False}, QuestionnaireSpec,
         "the questionnaire asks nothing"),
    ],
)  # fmt: skip
def test_a_bad_spec_says_what_is_wrong(spec: dict[str, Any], kind: Any, message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        kind.model_validate(spec)


def test_the_default_design_asks_the_specs_check_and_questionnaire() -> None:
    design = StudyDesign(conditions=ONE_CONDITION)
    assert design.check == CheckSpec.default() and len(design.check.questions) == 3
    sections = {s.instrument: s.items for s in QuestionnaireSpec.default().sections()}
    assert [len(sections[k]) for k in ("nasa_tlx", "trust", "demographics")] == [6, 12, 4]
    assert all(i.required for i in sections["nasa_tlx"] + sections["trust"])
    assert not any(i.required for i in sections["demographics"])
    assert all(i.prefer_not_to_say for i in sections["demographics"])
    tlx = sections["nasa_tlx"][0]
    assert (tlx.minimum, tlx.maximum, tlx.step) == (0, 100, 5)


# --- the participant API (a live server; sessions that start run their workers) ---------


def set_design(server: LiveServer, study_id: int, design: dict[str, Any] | None) -> None:
    """A study's design written straight into the database (the design API is the study
    side's)."""
    engine = make_engine(server.database_url)
    try:
        with make_session_factory(engine)() as db:
            db.execute(update(Study).where(Study.id == study_id).values(design=design))
            db.commit()
    finally:
        engine.dispose()


def stored(server: LiveServer, session_id: int) -> StudySession:
    engine = make_engine(server.database_url)
    try:
        with make_session_factory(engine)() as db:
            row = db.get(StudySession, session_id)
            assert row is not None
            db.expunge(row)
            return row
    finally:
        engine.dispose()


@pytest.fixture
def online(
    server: LiveServer, api: httpx.Client, request: pytest.FixtureRequest
) -> Iterator[dict[str, Any]]:
    """An online study with the default design (a study of its own per test)."""
    study = api.post("/api/studies", json={"name": request.node.name[:100]}).json()
    set_design(server, study["id"], StudyDesign(conditions=ONE_CONDITION).model_dump(mode="json"))
    yield study


def new_participant(
    server: LiveServer, api: httpx.Client, study_id: int, **run: Any
) -> tuple[dict[str, Any], SimulatedParticipant]:
    body = session_body("human", **{"advice_budget": 2, "sort_rule": "shape", **run})
    created = api.post(f"/api/studies/{study_id}/sessions", json=body).json()
    return created, SimulatedParticipant(server.url, created["participant_token"])


RIGHT = {"blue_cube": "left", "red_disk": "right", "drop_at_centre": "keep"}
"""Under the sort rule by shape: cubes left, disks right."""


@pytest.mark.slow
def test_the_check_is_graded_under_the_sessions_rule_and_gates_the_start(
    server: LiveServer, api: httpx.Client, online: dict[str, Any]
) -> None:
    """And a design without a questionnaire completes the visit with the last advice."""
    set_design(
        server,
        online["id"],
        StudyDesign(conditions=ONE_CONDITION, questionnaire=None).model_dump(mode="json"),
    )
    created, participant = new_participant(server, api, online["id"])
    client = participant.client
    before = client.post("/api/participant/check", json={"answers": RIGHT})
    assert before.status_code == 409 and "consent first" in before.text
    participant.consent()
    shown = client.get("/api/participant/check").json()
    assert shown["required"] and shown["tries"] == 2 and shown["tries_used"] == 0
    assert [q["id"] for q in shown["questions"]] == list(RIGHT)
    assert "answer" not in str(shown["questions"][0].keys()), "never the answers"

    for bad, where in [
        ({"answers": {**RIGHT, "extra": "left"}}, "no question 'extra'"),
        ({"answers": {"blue_cube": "left"}}, "answer question 'red_disk' too"),
        ({"answers": {**RIGHT, "blue_cube": "up"}}, "takes one of left, right, centre"),
        ({"answers": {**RIGHT, "blue_cube": 1}}, "string"),
        ({"answer": RIGHT}, "unknown field 'answer'"),
    ]:
        refused = client.post("/api/participant/check", json=bad)
        assert refused.status_code == 422 and where in refused.text, (bad, refused.text)
    assert client.get("/api/participant/check").json()["tries_used"] == 0, "nothing counted"

    # The colour rule's answers are wrong under this session's rule by shape.
    wrong = client.post("/api/participant/check", json={"answers": {**RIGHT, "blue_cube": "right"}})
    assert wrong.status_code == 200, wrong.text
    result = wrong.json()
    assert not result["correct"] and result["wrong"] == ["blue_cube"] and not result["excluded"]
    assert result["tries_used"] == 1 and not result["passed"]
    early = client.post("/api/participant/start")
    assert early.status_code == 409 and "comprehension check comes first" in early.text

    passed = client.post("/api/participant/check", json={"answers": RIGHT}).json()
    assert passed["correct"] and passed["passed"] and passed["tries_used"] == 2
    again = client.post("/api/participant/check", json={"answers": RIGHT})
    assert again.status_code == 409 and "already passed" in again.text
    started = client.post("/api/participant/start")
    assert started.status_code == 200, started.text
    assert stored(server, created["id"]).outcome is None, "a pass ends nothing"

    assert participant.next_request()["advice_index"] == 0
    assert participant.advise(0, 0).status_code == 200
    assert stored(server, created["id"]).outcome is None, "one advice of two"
    assert participant.next_request()["advice_index"] == 1
    assert participant.advise(1, 0).status_code == 200
    row = stored(server, created["id"])
    assert row.outcome == "completed", "no questionnaire: the last advice completes"
    assert row.status in ("running", "finished"), "the learner trains on"
    token = created["participant_token"]
    for path in ("", "/questionnaire", "/advise", "/thanks", "/check"):
        page = httpx.get(f"{server.url}/p/{token}{path}", follow_redirects=False)
        assert page.headers["location"].endswith(f"/p/{token}/end"), path
    assert client.get("/api/participant/questionnaire").json()["required"] is False
    wait_for_status(api, created["id"], {"finished"})
    participant.client.close()


@pytest.mark.slow
def test_every_try_wrong_excludes_the_participant_and_stops_the_session(
    server: LiveServer, api: httpx.Client, online: dict[str, Any]
) -> None:
    created, participant = new_participant(server, api, online["id"])
    participant.consent()
    client = participant.client
    wrong = {"answers": {**RIGHT, "drop_at_centre": "release"}}
    first = client.post("/api/participant/check", json=wrong).json()
    assert not first["excluded"] and first["tries"] - first["tries_used"] == 1
    last = client.post("/api/participant/check", json=wrong).json()
    assert last["excluded"] and not last["passed"] and last["wrong"] == ["drop_at_centre"]
    row = stored(server, created["id"])
    assert row.outcome == "excluded" and row.outcome_at is not None
    assert row.status == "excluded"
    more = client.post("/api/participant/check", json={"answers": RIGHT})
    assert more.status_code == 409 and "every try" in more.text
    assert client.post("/api/participant/start").status_code == 409
    page = httpx.get(f"{server.url}/p/{created['participant_token']}", follow_redirects=False)
    assert page.headers["location"].endswith(f"/p/{created['participant_token']}/end")
    assert stored(server, created["id"]).status == "excluded", "the link started nothing"
    participant.client.close()

    assert api.delete(f"/api/sessions/{created['id']}").status_code == 204
    engine = make_engine(server.database_url)
    try:
        with make_session_factory(engine)() as db:
            query = select(func.count()).where(CheckAttempt.session_id == created["id"])
            assert db.scalar(query) == 0, "deletion deletes the check's tries"
    finally:
        engine.dispose()


@pytest.mark.slow
def test_a_lab_study_asks_no_check_and_no_questionnaire(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "lab visit"}).json()
    created, participant = new_participant(server, api, study["id"])
    client = participant.client
    participant.consent()
    assert client.get("/api/participant/check").json() == {
        "required": False, "questions": [], "tries": 0, "tries_used": 0, "passed": False,
        "excluded": False,
    }  # fmt: skip
    refused = client.post("/api/participant/check", json={"answers": RIGHT})
    assert refused.status_code == 409 and "asks no comprehension check" in refused.text
    assert client.get("/api/participant/questionnaire").json()["required"] is False
    answer = client.post("/api/participant/questionnaire", json={"answers": {}})
    assert answer.status_code == 409 and "asks no questionnaire" in answer.text
    token = created["participant_token"]
    page = httpx.get(f"{server.url}/p/{token}/induction/3").text
    assert 'id="start"' in page and f"/p/{token}/check" not in page
    assert (
        httpx.get(f"{server.url}/p/{token}/check", follow_redirects=False)
        .headers["location"]
        .endswith("/induction/3")
    )
    assert client.post("/api/participant/start").status_code == 200
    assert stored(server, created["id"]).outcome is None
    assert api.post(f"/api/sessions/{created['id']}/stop").status_code == 200
    participant.client.close()


@pytest.mark.slow
def test_the_texts_say_when_this_participant_advises_and_how_long_they_may_take(
    server: LiveServer, api: httpx.Client, online: dict[str, Any]
) -> None:
    """The induction's plan follows the session's strategy (the first N actions, or one in
    every k with moves of its own between), the time rule the study's (no limit in a lab
    study, the design's idle limit in an online one), and what follows the last choice the
    visit's (a lab study's progress page; an online study's questions and code: its visit
    ends there, so it promises no progress to watch)."""
    lab = api.post("/api/studies", json={"name": "lab texts"}).json()
    design = StudyDesign(conditions=ONE_CONDITION, idle_limit_s=300).model_dump(mode="json")
    set_design(server, online["id"], design)
    made = []
    watch, code = "you can watch its progress", "you receive your completion code"
    for study, run, plan, limit, after, not_after in (
        (lab, {}, "For the next 2 actions", "<strong>no time limit</strong>", watch, code),
        (
            online,
            {"strategy": "alternating", "interval": 3, "advice_budget": 4},
            "choose 4 of its actions, one action in every 3",
            "Only if you give no answer for 5 minutes does the study end early",
            "you answer a few questions about the study, and then " + code,
            watch,
        ),
    ):
        created, participant = new_participant(server, api, study["id"], **run)
        made.append(created["id"])
        page = f"{server.url}/p/{created['participant_token']}"
        assert limit in httpx.get(f"{page}/consent").text
        participant.consent()
        assert plan in httpx.get(f"{page}/induction/1").text
        last = httpx.get(f"{page}/induction/3").text
        assert limit in last and after in last and not_after not in last
        participant.client.close()
    for session_id in made:
        assert api.post(f"/api/sessions/{session_id}/stop").status_code == 200


@pytest.mark.slow
def test_an_alternating_turn_says_how_often_the_robot_moved_on_its_own(
    server: LiveServer, api: httpx.Client
) -> None:
    """One action in every 3 advised: the second turn comes after 2 moves of the robot's
    own, which the state says (the page words it), also once the session is resumed."""
    study = api.post("/api/studies", json={"name": "own moves"}).json()
    created, participant = new_participant(
        server, api, study["id"], strategy="alternating", interval=3, advice_budget=2
    )
    assert participant.begin().status_code == 200
    first = participant.next_request()
    assert first["advice_index"] == 0 and first["own_moves"] is None, "no choice before"
    assert participant.advise(0, 1).status_code == 200
    second = participant.next_request()
    assert second["advice_index"] == 1 and second["own_moves"] == 2

    assert api.post(f"/api/sessions/{created['id']}/stop").status_code == 200
    wait_for_status(api, created["id"], {"stopped"})
    assert participant.state()["own_moves"] is None, "no turn while stopped"
    assert api.post(f"/api/sessions/{created['id']}/resume").status_code == 200
    resumed = participant.next_request()
    assert resumed["advice_index"] == 1 and resumed["own_moves"] == 2, "from the stored advice"
    assert api.post(f"/api/sessions/{created['id']}/stop").status_code == 200
    participant.client.close()


CUSTOM = [
    {"id": "clarity", "kind": "likert", "text": "The robot's moves were clear.", "required": True,
     "points": 5, "anchors": ["Strongly disagree", "Disagree", "Neutral", "Agree",
                              "Strongly agree"]},
    {"id": "minutes", "kind": "number", "text": "About how many minutes did it take?",
     "minimum": 0, "maximum": 120},
    {"id": "comments", "kind": "text", "text": "Anything else?", "max_length": 500},
    {"id": "strategy", "kind": "choice", "text": "How did you choose?",
     "choices": ["By colour", "By shape", "Other"]},
]  # fmt: skip
"""The researcher's own items, one of each kind, after the built-ins."""


def full_answers() -> dict[str, dict[str, Any]]:
    return {
        "nasa_tlx": dict(TLX),
        "trust": trust_answers(),
        "demographics": {"age": "25-34", "gender": "Prefer not to say", "robots": "Some"},
        "custom": {"clarity": 4, "minutes": 7.5, "strategy": "By colour"},
    }


@pytest.mark.slow
def test_the_questionnaire_comes_once_after_the_advice_and_completes_the_visit(
    server: LiveServer, api: httpx.Client, online: dict[str, Any], tmp_path: Path
) -> None:
    design = StudyDesign(
        conditions=ONE_CONDITION, questionnaire=QuestionnaireSpec.model_validate({"items": CUSTOM})
    )
    set_design(server, online["id"], design.model_dump(mode="json"))
    created, participant = new_participant(server, api, online["id"])
    client = participant.client
    participant.consent()
    assert client.post("/api/participant/check", json={"answers": RIGHT}).json()["passed"]
    too_soon = client.post("/api/participant/questionnaire", json={"answers": full_answers()})
    assert too_soon.status_code == 409 and "after the advice" in too_soon.text
    assert client.post("/api/participant/start").status_code == 200
    for index in range(2):
        assert participant.next_request()["advice_index"] == index
        assert participant.advise(index, 0, wait=5).status_code == 200
    shown = client.get("/api/participant/questionnaire").json()
    assert shown["available"] and shown["submitted_at"] is None
    token = created["participant_token"]
    page = httpx.get(f"{server.url}/p/{token}", follow_redirects=False)
    assert page.headers["location"].endswith("/questionnaire"), "not thanks: questions first"

    def with_(instrument: str, item: str, value: Any) -> dict[str, Any]:
        answers = full_answers()
        answers[instrument] = {**answers.get(instrument, {}), item: value}
        return {"answers": answers}

    for bad, where in [
        (with_("nasa_tlx", "mental", 101), "from 0 to 100 in steps of 5"),
        (with_("nasa_tlx", "mental", 52), "from 0 to 100 in steps of 5"),
        (with_("nasa_tlx", "mental", None), "nasa_tlx.mental must be answered"),
        (with_("trust", "item_03", 8), "from 1 to 7"),
        (with_("trust", "item_03", 2.5), "from 1 to 7"),
        (with_("trust", "item_03", True), "trust"),
        (with_("trust", "item_13", 3), "no item trust.item_13"),
        (with_("demographics", "age", "17"), "not one of the choices"),
        (with_("demographics", "gender", "x" * 101), "at most 100 characters"),
        (with_("custom", "q", 1), "no item custom.q"),
        (with_("custom", "clarity", 6), "from 1 to 5"),
        (with_("custom", "clarity", None), "custom.clarity must be answered"),
        (with_("custom", "minutes", 121), "a number from 0 to 120"),
        (with_("custom", "minutes", "7"), "a number from 0 to 120"),
        (with_("custom", "strategy", "By size"), "By colour; By shape; Other"),
    ]:
        refused = client.post("/api/participant/questionnaire", json=bad)
        assert refused.status_code == 422 and where in refused.text, (where, refused.text)
    assert stored(server, created["id"]).outcome is None, "nothing stored by a refusal"

    sent = client.post("/api/participant/questionnaire", json={"answers": full_answers()})
    assert sent.status_code == 200, sent.text
    assert sent.json()["submitted_at"] is not None
    row = stored(server, created["id"])
    assert row.outcome == "completed" and row.status in ("running", "finished"), row.status
    twice = client.post("/api/participant/questionnaire", json={"answers": full_answers()})
    assert twice.status_code == 409 and "already submitted" in twice.text
    page = httpx.get(f"{server.url}/p/{token}", follow_redirects=False)
    assert page.headers["location"].endswith(f"/p/{token}/end")
    wait_for_status(api, created["id"], {"finished"})

    files = export(api, online["id"])
    folder = tmp_path / "export"
    folder.mkdir()
    for name, data in files.items():
        if name.endswith("/"):
            continue
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)
    check_frictionless(folder)

    def rows(name: str) -> list[dict[str, str]]:
        found = csv.DictReader(io.StringIO(files[name].decode()))
        return [r for r in found if r["session_id"] == str(created["id"])]

    answers = rows("questionnaire.csv")
    assert len(answers) == 6 + 12 + 4 + 4, "one row per item shown, skipped ones too"
    by_item = {(r["instrument"], r["item"]): r for r in answers}
    assert by_item["nasa_tlx", "mental"]["value_number"] == "70.0"
    assert by_item["trust", "item_01"]["value_number"] == "2.0", "stored as answered"
    assert by_item["demographics", "gender"]["value_text"] == "Prefer not to say"
    assert by_item["demographics", "ai"]["value_text"] == "", "skipped"
    assert by_item["custom", "minutes"]["value_number"] == "7.5"
    assert by_item["custom", "strategy"]["value_text"] == "By colour"
    assert by_item["custom", "comments"]["text"] == "Anything else?"
    scales = {r["scale"]: r for r in rows("scales.csv")}
    assert float(scales["nasa_tlx"]["score"]) == 45.0
    assert float(scales["trust"]["score"]) == pytest.approx(70 / 12)
    assert scales["trust"]["items_answered"] == "12"
    check = rows("check.csv")
    assert [(r["attempt"], r["question"], r["result"]) for r in check] == [
        ("1", q, "passed") for q in RIGHT
    ]
    participant.client.close()

    assert api.delete(f"/api/sessions/{created['id']}").status_code == 204
    engine = make_engine(server.database_url)
    try:
        with make_session_factory(engine)() as db:
            for model in (CheckAttempt, QuestionnaireAnswer):
                query = select(func.count()).where(model.session_id == created["id"])
                assert db.scalar(query) == 0, f"deletion deletes {model.__tablename__}"
    finally:
        engine.dispose()
